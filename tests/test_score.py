"""``habitsim score`` and :mod:`habitsim.evaluation.score`: motions from anywhere scored as
they are, the same figures from a ``.npz`` and its BVH export, typed errors per file."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest
from helpers import hold, run_cli

from habitsim.bvh import bvh_text, write_bvh
from habitsim.errors import OutputPathError
from habitsim.evaluation.score import (
    STANCE_DETECTED,
    STANCE_FROM_FILE,
    ScoreError,
    ScoreOptions,
    bvh_species,
    motion_files,
    read_motion,
    score_files,
    stance_of,
)
from habitsim.gaits import generate

#: Figures that must agree between a motion's .npz and its BVH export [relative].
SAME = (
    "root_residual_mg",
    "root_residual_torque_mgl",
    "skate_mm",
    "penetration_mm",
    "float_mm",
    "jerk",
    "bone_length_error_mm",
    "joint_limit_violation_rad",
    "biomech_score",
)


@pytest.fixture(scope="module")
def walk_pair(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder with a dog walk as .npz (planned stance labels) and as BVH."""
    folder = tmp_path_factory.mktemp("score")
    walk = generate("dog", "walk", seed=3, duration_s=1.5)
    walk.save(folder / "walk.npz")
    write_bvh(walk, folder / "walk.bvh")
    return folder


def _by_file(rows: list[dict]) -> dict[str, dict]:
    return {r["file"]: r for r in rows}


def _close(a: float, b: float, rel: float = 0.01) -> bool:
    return abs(a - b) <= rel * max(abs(a), abs(b)) + 1e-6  # 1e-6: a micrometre, in mm


def test_npz_and_its_bvh_export_score_alike(walk_pair: Path) -> None:
    """Geometry stance for both: every physics figure within 1 %, ``torque_saturation``
    too (the ground force is split over the stance feet with the least norm, so the
    BVH's rounding of 1e-9 rad cannot move a joint torque across its limit)."""
    res = score_files([walk_pair], ScoreOptions(contacts="geometry"))
    rows = _by_file(res.rows)
    a, b = rows["walk.npz"], rows["walk.bvh"]
    assert a["status"] == b["status"] == "ok"
    assert a["stance"] == b["stance"] == STANCE_DETECTED
    for k in SAME:
        assert _close(a[k], b[k]), (k, a[k], b[k])
    assert _close(a["torque_saturation"], b["torque_saturation"])
    assert (a["pred_species"], a["pred_action"]) == (b["pred_species"], b["pred_action"])


@pytest.mark.slow
def test_npz_and_its_bvh_export_track_alike(walk_pair: Path) -> None:
    res = score_files([walk_pair], ScoreOptions(contacts="geometry", track=True))
    a, b = (_by_file(res.rows)[f] for f in ("walk.npz", "walk.bvh"))
    for k in ("survival", "sim_mpjpe_mm", "contact_f1"):
        assert _close(a[k], b[k]), (k, a[k], b[k])
    assert a["track_status"] == b["track_status"]


def test_stance_says_where_it_came_from(walk_pair: Path) -> None:
    res = score_files([walk_pair], ScoreOptions(dynamic=False))
    rows = _by_file(res.rows)
    assert rows["walk.npz"]["stance"] == STANCE_FROM_FILE
    assert rows["walk.bvh"]["stance"] == STANCE_DETECTED
    walk = read_motion(walk_pair / "walk.npz")
    labels, how = stance_of(walk, "auto")
    assert how == STANCE_FROM_FILE and np.array_equal(labels, walk.contacts)
    assert stance_of(walk, "geometry")[1] == STANCE_DETECTED


def test_labels_asked_of_a_bvh_is_a_typed_error_for_that_file(walk_pair: Path) -> None:
    res = score_files([walk_pair], ScoreOptions(contacts="labels", dynamic=False))
    rows = _by_file(res.rows)
    assert rows["walk.npz"]["status"] == "ok"
    assert (rows["walk.bvh"]["status"], rows["walk.bvh"]["error"]) == ("error", "ScoreError")
    assert res.exit_code == 2


def test_habitsim_bvh_names_its_species(walk_pair: Path) -> None:
    from habitsim.bvh_mapping import read_source

    assert bvh_species(read_source(walk_pair / "walk.bvh")) == "dog"
    assert read_motion(walk_pair / "walk.bvh").species == "dog"
    assert read_motion(walk_pair / "walk.bvh").contacts is None  # the importer's guess dropped


def test_a_bvh_of_no_known_species_needs_species(tmp_path: Path) -> None:
    walk = generate("dog", "walk", seed=3, duration_s=0.5)
    text = re.sub(
        r"OFFSET ([-\d.e]+) ([-\d.e]+) ([-\d.e]+)",
        lambda m: "OFFSET " + " ".join(f"{1.1 * float(v):.6f}" for v in m.groups()),
        bvh_text(walk),
    )
    (tmp_path / "odd.bvh").write_text(text)
    with pytest.raises(ScoreError):
        read_motion(tmp_path / "odd.bvh")
    assert read_motion(tmp_path / "odd.bvh", species="dog").species == "dog"


def test_another_species_is_an_error_per_file_and_the_table_is_whole(
    walk_pair: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cat = tmp_path / "in"
    cat.mkdir()
    generate("cat", "walk", seed=1, duration_s=0.5).save(cat / "cat.npz")
    out = tmp_path / "out"
    code, err = run_cli(
        ["score", walk_pair, cat, "--species", "dog", "--no-dynamic", "--out", out, "--report"],
        capsys,
    )
    assert code == 2
    # the file not scored is named on stderr, as every command's errors are
    assert any(ln.startswith("error: ") and "cat.npz" in ln for ln in err.splitlines()), err
    rows = _by_file(json.loads((out / "scores.json").read_text())["rows"])
    assert set(rows) == {"walk.npz", "walk.bvh", "cat.npz"}
    assert (rows["cat.npz"]["status"], rows["cat.npz"]["error"]) == ("error", "ScoreError")
    assert rows["walk.npz"]["status"] == rows["walk.bvh"]["status"] == "ok"
    assert (out / "scores.csv").read_text().count("\n") == 4
    assert (out / "report.html").is_file() and (out / "report.md").is_file()


def test_cli_scores_as_given_and_exits_0(
    walk_pair: Path, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    argv = ["score", walk_pair / "walk.npz", "--no-evaluator", "--out", tmp_path]
    code, err = run_cli(argv, capsys)
    assert code == 0, err
    row = json.loads((tmp_path / "scores.json").read_text())["rows"][0]
    assert row["stance"] == STANCE_FROM_FILE and "pred_species" not in row
    assert row["refine_status"] == "none"  # judged as it is


def test_unwritable_out_fails_before_scoring(walk_pair: Path, tmp_path: Path, capsys) -> None:
    (tmp_path / "scores.csv").mkdir()
    with pytest.raises(OutputPathError):
        score_files([walk_pair], ScoreOptions(dynamic=False)).write(tmp_path)
    code, _ = run_cli(["score", walk_pair, "--out", tmp_path], capsys)
    assert code == 2 and not (tmp_path / "scores.json").exists()


def test_motion_files(walk_pair: Path, tmp_path: Path) -> None:
    assert [f.name for f in motion_files([walk_pair, walk_pair / "walk.npz"])] == [
        "walk.bvh",
        "walk.npz",
    ]
    with pytest.raises(ScoreError):
        motion_files([tmp_path])  # empty
    (tmp_path / "notes.txt").write_text("x")
    with pytest.raises(ScoreError):
        motion_files([tmp_path / "notes.txt"])
    with pytest.raises(ScoreError):
        motion_files([tmp_path / "missing"])


def test_links_out_of_a_folder_are_refused(walk_pair: Path, tmp_path: Path) -> None:
    from habitsim.errors import InputPathError

    (tmp_path / "in").mkdir()
    (tmp_path / "in" / "theirs.npz").symlink_to(walk_pair / "walk.npz")
    with pytest.raises(InputPathError):
        motion_files([tmp_path / "in"])
    assert [f.name for f in motion_files([tmp_path / "in"], follow_symlinks=True)] == ["theirs.npz"]


def test_out_is_written_by_one_run_and_keeps_foreign_files(
    walk_pair: Path, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    out = tmp_path / "out"
    argv = ["score", walk_pair / "walk.npz", "--no-evaluator", "--no-dynamic", "--out", out]
    assert run_cli(argv, capsys)[0] == 0
    (out / "mine.txt").write_text("a file of the user's")
    assert run_cli(argv, capsys)[0] == 0  # a new run replaces its own files
    assert (out / "mine.txt").read_text() == "a file of the user's"
    busy = tmp_path / "busy"
    with hold(busy):
        code, _ = run_cli([*argv[:-1], busy], capsys)
    assert code == 2 and not (busy / "scores.json").exists()


def test_options_are_checked() -> None:
    for bad in ({"contacts": "guess"}, {"refine": "all"}, {"controller": "nope"}):
        with pytest.raises(ScoreError):
            ScoreOptions(**bad)


def test_a_floating_motion_reads_floating(tmp_path: Path) -> None:
    """The point of scoring: a walk lifted 0.5 m needs the body weight from nowhere."""
    walk = generate("dog", "walk", seed=3, duration_s=1.0)
    from habitsim.motion import Motion

    lifted = Motion(
        walk.species, walk.fps, walk.root_positions + [0, 0, 0.5], walk.rotations, walk.contacts
    )
    lifted.save(tmp_path / "lifted.npz")
    row = score_files([tmp_path]).rows[0]
    assert row["root_residual_mg"] > 0.9 and math.isfinite(row["float_mm"])
