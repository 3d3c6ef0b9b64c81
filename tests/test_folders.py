"""Output and input folders (habitsim.folders): a record of what habitsim wrote, one run
at a time, no links out."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest
from helpers import hold

from habitsim.errors import InputPathError, OutputBusyError, OutputFolderError
from habitsim.fileio import atomic_write_text, make_dirs
from habitsim.folders import (
    LOCK_NAME,
    WRITTEN_NAME,
    check_inside,
    claim_output_folder,
    input_files,
    is_written,
)


def _files(root: Path) -> list[str]:
    return sorted(p.relative_to(root).as_posix() for p in root.rglob("*") if p.is_file())


def test_overwrite_removes_only_what_habitsim_wrote(tmp_path: Path) -> None:
    out = tmp_path / "out"
    with claim_output_folder(out, command="eval"):
        atomic_write_text(out / "rows" / "a.json", "{}")
        atomic_write_text(out / "run.json", "{}")
    assert is_written(out / "rows" / "a.json") and not (out / LOCK_NAME).exists()
    (out / "rows" / "mine.json").write_text("a file of the user's")
    # an earlier run and a foreign file: refused without --overwrite
    with pytest.raises(OutputFolderError, match="--overwrite"):
        with claim_output_folder(out, command="eval", resume=True):
            pass
    (out / "rows" / "mine.json").unlink()
    with pytest.raises(OutputFolderError, match="--resume"):
        with claim_output_folder(out, command="eval"):
            pass
    with claim_output_folder(out, command="eval", resume=True) as claim:
        assert claim.earlier == "eval"
    (out / "rows" / "mine.json").write_text("a file of the user's")
    with claim_output_folder(out, command="eval", overwrite=True) as claim:
        assert claim.removed == 2
        assert _files(out) == [LOCK_NAME, WRITTEN_NAME, "rows/mine.json"]
        # a file habitsim did not write is never replaced
        with pytest.raises(OutputFolderError):
            atomic_write_text(out / "rows" / "mine.json", "{}")
    assert (out / "rows" / "mine.json").read_text() == "a file of the user's"


def test_a_killed_runs_temporaries_are_its_own(tmp_path: Path) -> None:
    out = tmp_path / "out"
    with claim_output_folder(out, command="data synth"):
        atomic_write_text(out / "train" / "cat" / "x.npz", "x")
    (out / "train" / "cat" / ".x.npz.ab12cd34.tmp").write_text("half")
    with claim_output_folder(out, command="data synth", overwrite=True) as claim:
        assert claim.removed == 2
    assert _files(out) == [WRITTEN_NAME] and not (out / "train").exists()


def test_links_out_of_the_output_folder_are_not_followed(tmp_path: Path) -> None:
    outside = tmp_path / "outside"
    (outside / "cat").mkdir(parents=True)
    (outside / "cat" / "x.npz").write_text("someone's data")
    out = tmp_path / "out"
    out.mkdir()
    (out / "val").symlink_to(outside, target_is_directory=True)
    with pytest.raises(OutputFolderError, match="val"):
        with claim_output_folder(out, command="data import-bvh"):
            pass
    with claim_output_folder(out, command="data import-bvh", overwrite=True):
        with pytest.raises(OutputFolderError, match="link"):
            atomic_write_text(out / "val" / "cat" / "x.npz", "new")
        with pytest.raises(OutputFolderError, match="link"):
            make_dirs(out / "val" / "dog")
    assert _files(outside) == ["cat/x.npz"] and (outside / "cat" / "x.npz").read_text() == (
        "someone's data"
    )


def test_a_second_run_is_refused_and_a_killed_runs_lock_taken_over(tmp_path: Path) -> None:
    out = tmp_path / "out"
    with hold(out) as proc:
        with pytest.raises(OutputBusyError, match=str(proc.pid)):
            with claim_output_folder(out, command="eval", overwrite=True):
                pass
    assert json.loads((out / LOCK_NAME).read_text())["pid"] == proc.pid
    notes: list[str] = []
    with claim_output_folder(out, command="eval", resume=True, log=notes.append):
        assert json.loads((out / LOCK_NAME).read_text())["pid"] == os.getpid()
        with claim_output_folder(out, command="data synth"):
            pass  # this process's own nested claim
    assert len(notes) == 1 and str(proc.pid) in notes[0]
    assert not (out / LOCK_NAME).exists()


def test_input_links_leading_out_are_refused(tmp_path: Path) -> None:
    src = tmp_path / "src"
    (src / "sub").mkdir(parents=True)
    (src / "a.bvh").write_text("x")
    (src / "sub" / "b.BVH").write_text("x")
    (src / "inside.bvh").symlink_to(src / "a.bvh")
    (src / "notes.txt").write_text("x")
    secret = tmp_path / "secret"
    secret.mkdir()
    (secret / "key.bvh").write_text("do not echo me")
    assert [p.relative_to(src).as_posix() for p in input_files(src, (".bvh",))] == [
        "a.bvh",
        "inside.bvh",
        "sub/b.BVH",
    ]
    (src / "out.bvh").symlink_to(secret / "key.bvh")
    with pytest.raises(InputPathError, match="follow-symlinks") as e:
        input_files(src, (".bvh",))
    assert "do not echo" not in str(e.value)
    assert len(input_files(src, (".bvh",), follow_symlinks=True)) == 4
    (src / "out.bvh").unlink()
    (src / "linked").symlink_to(secret, target_is_directory=True)
    with pytest.raises(InputPathError, match="linked"):
        input_files(src, (".bvh",))
    (secret / "loop").symlink_to(src, target_is_directory=True)  # walked once
    assert len(input_files(src, (".bvh",), follow_symlinks=True)) == 4
    with pytest.raises(InputPathError):
        check_inside(src, src / "linked" / "key.bvh")
    check_inside(src, src / "linked" / "key.bvh", follow_symlinks=True)


def test_a_run_that_fails_before_writing_leaves_no_folder(tmp_path: Path) -> None:
    out = tmp_path / "new" / "out"
    with pytest.raises(ValueError), claim_output_folder(out, command="train"):
        raise ValueError("bad configuration")
    assert not (tmp_path / "new").exists()
    # a folder that existed, or one the failed run wrote into, stays
    (tmp_path / "kept").mkdir()
    with pytest.raises(ValueError), claim_output_folder(tmp_path / "kept", command="train"):
        raise ValueError("bad configuration")
    assert (tmp_path / "kept").is_dir()
    with pytest.raises(ValueError), claim_output_folder(out, command="train"):
        atomic_write_text(out / "partial.json", "{}")
        raise ValueError("failed later")
    assert is_written(out / "partial.json")


def test_a_record_line_torn_by_a_full_disk_does_not_hide_the_next(tmp_path: Path) -> None:
    out = tmp_path / "out"
    with claim_output_folder(out, command="eval"):
        with open(out / WRITTEN_NAME, "a") as fh:
            fh.write('"torn.js')  # the disk filled in the middle of a line
        atomic_write_text(out / "next.json", "{}")
        assert is_written(out / "next.json")
