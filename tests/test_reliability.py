"""Regression tests of issue 17 (reliability): every bad input found by the probe ends in
a typed :class:`~habitsim.errors.HabitsimError` (``error: …``, exit 2, a message of
bounded length), and a command that writes several files leaves all of them or none."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from habitsim.cli import main
from habitsim.errors import HabitsimError, OutputPathError
from habitsim.fileio import atomic_write_text, check_writable, output_transaction


@pytest.fixture(scope="module")
def motion_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from habitsim.gaits import generate

    p = tmp_path_factory.mktemp("motion") / "walk.npz"
    generate("dog", "walk", seed=0, duration_s=0.5).save(p)
    return p


def run_cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    """Exit code and stderr of ``habitsim ARGV`` run in this process."""
    code = main([str(a) for a in argv])
    err = capsys.readouterr().err
    return code, err


def files_under(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


# ------------------------------------------------------------------ outputs as transactions


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


@pytest.mark.parametrize(
    "extra",
    [["--report", "{blocker}/r.json"], ["--qpos", "{blocker}/q.npz"]],
    ids=["report", "qpos"],
)
def test_refine_unwritable_second_output_leaves_nothing(
    tmp_path: Path, motion_file: Path, capsys, extra: list[str]
) -> None:
    blocker = tmp_path / "blocker"
    blocker.write_text("a file where a folder should be")
    out = tmp_path / "ok.npz"
    extra = [e.format(blocker=blocker) for e in extra]
    code, err = run_cli(["refine", motion_file, "--out", out, *extra], capsys)
    assert code == 2 and err.startswith("error: ") and "file where a folder" in err
    assert files_under(tmp_path) == ["blocker"]


@pytest.mark.parametrize(
    "extra",
    [["--report", "{blocker}/r.json"], ["--video", "{blocker}/v.gif"]],
    ids=["report", "video"],
)
def test_track_unwritable_second_output_leaves_nothing(
    tmp_path: Path, motion_file: Path, capsys, extra: list[str]
) -> None:
    blocker = tmp_path / "blocker"
    blocker.write_text("x")
    extra = [e.format(blocker=blocker) for e in extra]
    code, err = run_cli(["track", motion_file, "--out", tmp_path / "sim.npz", *extra], capsys)
    assert code == 2 and err.startswith("error: "), err
    assert files_under(tmp_path) == ["blocker"]


def test_transfer_unwritable_bvh_leaves_nothing(tmp_path: Path, motion_file: Path, capsys) -> None:
    blocker = tmp_path / "blocker"
    blocker.write_text("x")
    code, err = run_cli(
        ["transfer", motion_file, "--to", "cat", "--method", "direct",
         "--out", tmp_path / "ok.npz", "--bvh", blocker / "x.bvh"],
        capsys,
    )
    assert code == 2 and "file where a folder" in err
    assert files_under(tmp_path) == ["blocker"]


def test_transfer_writes_both_outputs(tmp_path: Path, motion_file: Path, capsys) -> None:
    code, _ = run_cli(
        ["transfer", motion_file, "--to", "cat", "--method", "direct",
         "--out", tmp_path / "ok.npz", "--bvh", tmp_path / "x.bvh"],
        capsys,
    )
    assert code == 0
    assert files_under(tmp_path) == ["ok.npz", "x.bvh"]
