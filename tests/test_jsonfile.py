"""Bounded JSON and TOML reading (habitsim.jsonfile)."""

from __future__ import annotations

from pathlib import Path

import pytest

from habitsim.errors import DatasetError, JSONFileError
from habitsim.jsonfile import DocumentLimits, depth, load_json, load_toml, loads_json, loads_toml

SECRET = "s3cr3t-token"


def test_depth_counts_brackets_outside_strings() -> None:
    lim = DocumentLimits(max_depth=2)
    assert loads_json('{"a": "[[[[[[", "b": [1]}', "t", options=lim) == {"a": "[[[[[[", "b": [1]}
    assert loads_json('["\\"[[[["]', "t", options=lim) == ['"[[[[']
    with pytest.raises(JSONFileError):
        loads_json('{"a": [[1]]}', "t", options=lim)


@pytest.mark.parametrize(
    "text",
    [
        "[" * 100_000 + "]" * 100_000,  # deep: a RecursionError in the parser before
        '{"a": ' + "9" * 5000 + "}",  # past Python's 4,300-digit int-conversion limit
        '{"a": -' + "1" * 41 + "}",
        b"\xff\xfe",
        '{"a": 1,}',
    ],
)
def test_out_of_bounds_json_is_the_callers_typed_error(text: str | bytes) -> None:
    with pytest.raises(DatasetError):
        loads_json(text, "t", error=DatasetError)


def test_integer_digits_and_size_are_options() -> None:
    assert loads_json("[" + "9" * 40 + "]", "t") == [int("9" * 40)]
    with pytest.raises(JSONFileError):
        loads_json("[123]", "t", options=DocumentLimits(max_int_digits=2))
    with pytest.raises(JSONFileError):
        loads_json("[1, 2, 3]", "t", options=DocumentLimits(max_bytes=4))


@pytest.mark.parametrize(
    "text",
    [
        "a = " + "[" * 5000 + "]" * 5000,  # tomllib's own recursion
        "[" + ".".join(["t"] * 100) + "]\nx = 1",  # deep tables from dotted keys
        "a = " + "9" * 5000,
        "a = " + "9" * 50,
        "a = [",
    ],
)
def test_out_of_bounds_toml_is_typed(text: str) -> None:
    with pytest.raises(JSONFileError):
        loads_toml(text, "t")


def test_files_messages_name_the_file_never_its_content(tmp_path: Path) -> None:
    p = tmp_path / "x.json"
    p.write_text('{"a": "' + SECRET + '" oops}')
    with pytest.raises(JSONFileError) as ei:
        load_json(p, "thing")
    assert "x.json" in str(ei.value) and SECRET not in str(ei.value)
    with pytest.raises(JSONFileError):
        load_json(tmp_path / "missing.json")
    with pytest.raises(JSONFileError):
        load_json(tmp_path)  # a folder
    big = tmp_path / "big.json"
    big.write_text("[" + "1," * 100 + "1]")
    with pytest.raises(JSONFileError):
        load_json(big, options=DocumentLimits(max_bytes=50))
    t = tmp_path / "x.toml"
    t.write_text(f'a = "{SECRET}"\nb = = 1\n')
    with pytest.raises(JSONFileError) as ei:
        load_toml(t)
    assert SECRET not in str(ei.value)


def test_depth_of_parsed_values() -> None:
    assert depth(1, 5) == 0
    assert depth({"a": [1, {"b": []}]}, 5) == 4
    deep: list = []
    for _ in range(10_000):
        deep = [deep]
    assert depth(deep, 5) == 6
