"""Writing files safely (habitsim.fileio): typed errors for unwritable paths, outputs as all-or-
none transactions."""

from __future__ import annotations

import errno
import os
from pathlib import Path

import pytest
from helpers import files_under

from habitsim.errors import OutputPathError, OutputWriteError
from habitsim.fileio import atomic_write, atomic_write_text, check_writable, output_transaction


def test_check_writable_file_where_a_folder_should_be(tmp_path: Path) -> None:
    (tmp_path / "f").write_text("x")
    with pytest.raises(OutputPathError, match="file where a folder should be"):
        check_writable(tmp_path / "f" / "sub" / "r.json", "--report")
    with pytest.raises(OutputPathError, match="is a folder"):
        check_writable(tmp_path, "--out")
    assert files_under(tmp_path) == ["f"]


def test_atomic_write_into_a_file_is_typed(tmp_path: Path) -> None:
    (tmp_path / "f").write_text("x")
    with pytest.raises(OutputPathError, match="file where a folder should be"):
        atomic_write_text(tmp_path / "f" / "r.json", "{}")


@pytest.mark.skipif(os.geteuid() == 0, reason="the super-user writes into read-only folders")
def test_read_only_folder_is_typed(tmp_path: Path) -> None:
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        with pytest.raises(OutputPathError):
            check_writable(ro / "r.json")
        with pytest.raises(OutputPathError):
            atomic_write_text(ro / "r.json", "{}")
    finally:
        ro.chmod(0o755)


def test_read_only_folder_is_typed_even_for_root(tmp_path: Path, monkeypatch) -> None:
    """What a read-only folder (or file system) answers, simulated: EACCES on create."""
    import tempfile

    def denied(*args, **kwargs):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(tempfile, "mkstemp", denied)
    with pytest.raises(OutputPathError, match="Permission denied"):
        check_writable(tmp_path / "r.json", "--report")
    with pytest.raises(OutputPathError, match="Permission denied"):
        atomic_write_text(tmp_path / "r.json", "{}")
    assert files_under(tmp_path) == []


def test_transaction_all_or_none(tmp_path: Path) -> None:
    a, b = tmp_path / "a.txt", tmp_path / "sub" / "b.txt"
    with pytest.raises(RuntimeError):
        with output_transaction({"a": a, "b": b}):
            atomic_write_text(a, "1")
            raise RuntimeError("work failed after the first write")
    assert files_under(tmp_path) == []
    a.write_text("old")
    with output_transaction({"a": a, "b": b}):
        atomic_write_text(a, "new")
        atomic_write_text(b, "new")
        assert a.read_text() == "old"  # nothing moves before the end of the block
    assert a.read_text() == b.read_text() == "new"
    assert files_under(tmp_path) == ["a.txt", "sub", "sub/b.txt"]


def test_transaction_rolls_back_a_failed_commit(tmp_path: Path, monkeypatch) -> None:
    a, b = tmp_path / "a.txt", tmp_path / "b.txt"
    a.write_text("old")
    real_replace = os.replace

    def failing_replace(src, dst):
        if str(dst) == str(b):
            raise PermissionError(13, "Permission denied")
        return real_replace(src, dst)

    monkeypatch.setattr(os, "replace", failing_replace)
    with pytest.raises(OutputPathError, match="b.txt"):
        with output_transaction({"a": a, "b": b}):
            atomic_write_text(a, "new")
            atomic_write_text(b, "new")
    assert a.read_text() == "old"
    assert files_under(tmp_path) == ["a.txt"]


def test_transaction_refuses_one_path_twice(tmp_path: Path) -> None:
    with pytest.raises(OutputPathError, match="same file"):
        with output_transaction({"--out": tmp_path / "x", "--report": tmp_path / "." / "x"}):
            pass


def test_make_dirs_read_only_even_for_root(tmp_path: Path, monkeypatch) -> None:
    from habitsim.fileio import make_dirs

    def denied(self, *args, **kwargs):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(Path, "mkdir", denied)
    with pytest.raises(OutputPathError, match="Permission denied"):
        make_dirs(tmp_path / "x" / "y", "checkpoint folder")


def _no_space(*args, **kwargs):
    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


@pytest.mark.parametrize("where", ["write", "fsync", "replace"])
def test_a_full_disk_while_writing_is_typed_and_leaves_nothing(
    tmp_path: Path, monkeypatch, where: str
) -> None:
    (tmp_path / "r.json").write_text("old")
    if where == "fsync":
        monkeypatch.setattr(os, "fsync", _no_space)
    elif where == "replace":
        monkeypatch.setattr(os, "replace", _no_space)
    with pytest.raises(OutputWriteError) as e:
        with atomic_write(tmp_path / "r.json", "w") as fh:
            fh.write("new")
            if where == "write":
                _no_space()
    assert e.value.exit_code == 1 and e.value.errno is None
    assert files_under(tmp_path) == ["r.json"] and (tmp_path / "r.json").read_text() == "old"


def test_an_error_of_another_file_inside_a_write_is_not_an_output_error(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError):
        with atomic_write(tmp_path / "r.json", "w"):
            open(tmp_path / "missing.txt")  # noqa: SIM115 - an input the writer reads
    assert files_under(tmp_path) == []


def test_a_full_disk_in_a_transaction_keeps_the_old_files(tmp_path: Path, monkeypatch) -> None:
    for name in ("a", "b"):
        (tmp_path / name).write_text("old")
    real = os.replace
    calls = []

    def second_fails(src, dst):
        calls.append(dst)
        if len(calls) == 2:
            _no_space()
        real(src, dst)

    monkeypatch.setattr(os, "replace", second_fails)
    with pytest.raises(OutputWriteError):
        with output_transaction():
            atomic_write_text(tmp_path / "a", "new")
            atomic_write_text(tmp_path / "b", "new")
    monkeypatch.undo()
    assert files_under(tmp_path) == ["a", "b"]
    assert {(tmp_path / n).read_text() for n in "ab"} == {"old"}
