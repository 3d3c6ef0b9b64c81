"""Writing files safely (habitsim.fileio): typed errors for unwritable paths, outputs as all-or-
none transactions."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from helpers import files_under

from habitsim.errors import OutputPathError
from habitsim.fileio import atomic_write_text, check_writable, output_transaction


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
