"""``habitsim bench real`` on a small BVH folder the test writes itself."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from habitsim.bvh import write_bvh
from habitsim.cli import main
from habitsim.errors import SkeletonMappingError
from habitsim.evaluation.bench.real import (
    BenchRealError,
    evaluate_targets,
    exit_code,
    read_clip,
    source_files,
    survival_runs,
)
from habitsim.evaluation.bench.real_report import LEGEND, format_row, format_summary
from habitsim.gait_stats import GALLOP_FROUDE, PEAK_SPAN_S
from habitsim.gaits import generate
from habitsim.gaits.lying import lying_pose, with_lying_start
from habitsim.motion import Motion

pytestmark = pytest.mark.usefixtures("torch_one_thread")


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("bvh")
    write_bvh(generate("dog", "walk", seed=3, duration_s=3.0), d / "walk.bvh")
    (d / "notes.txt").write_text("not a clip")
    return d


@pytest.mark.slow
def test_bench_real_rows_and_json(folder: Path, tmp_path: Path, capsys) -> None:
    out = tmp_path / "rows.json"
    args = [
        "bench",
        "real",
        "--data",
        str(folder),
        "--targets",
        "cat",
        "--methods",
        "direct",
        "--seconds",
        "2",
        "--refine",
        "A",
        "--controller",
        "servo",
        "--workers",
        "1",
        "--repeats",
        "2",
        "--json",
        str(out),
    ]
    code = main(args)
    text = capsys.readouterr().out
    doc = json.loads(out.read_text())
    (row,) = doc["rows"]
    assert row["status"] == "ok", row["note"]
    assert (row["clip"], row["target"], row["method"], row["frames"]) == (
        "walk.bvh",
        "cat",
        "direct",
        60,
    )
    assert row["import_contact_f1"] is None  # the importer reports none (yet): "-"
    for k in (
        "skate_mm_before",
        "skate_mm_after",
        "jerk_before",
        "jerk_after",
        "penetration_mm_before",
        "penetration_mm_after",
        "survival",
        "sim_mpjpe_per_leg",
        "time_transfer_s",
        "time_refine_s",
        "time_track_s",
        "reference_residual_mg",
        "reference_torque_saturation",
        "source_froude_peak",
        "source_flight_share",
    ):
        assert isinstance(row[k], float), k
    assert row["source_froude_peak"] > 0.0 and 0.0 <= row["source_flight_share"] <= 1.0
    assert 0.0 <= row["reference_torque_saturation"] <= 1.0
    assert row["refine_check"] in ("kept", "reverted", "fallback")
    assert row["walking_stance"] is None  # direct keeps the source's labels
    assert "contacts source 1 (walking stance 0)" in text
    # --repeats 2: the row's own run, then one from a perturbed initial state
    assert len(row["survival_runs"]) == 2 and row["survival_runs"][0] == row["survival"]
    assert row["whole_runs"] == sum(x >= 1.0 for x in row["survival_runs"])
    assert "2 runs per window" in text and "over every run (2)" in text
    names = [t["name"] for t in doc["targets"]]
    assert len(names) == 5 and doc["targets"][1]["verdict"] == "n/a"  # servo, not mpc
    assert "targets:" in text and "walk@" in text
    assert code == int(any(t["verdict"] == "MISSED" for t in doc["targets"]))


def test_bench_real_no_track_no_refine_meets_what_applies(folder: Path, capsys) -> None:
    args = [
        "bench",
        "real",
        "--data",
        str(folder),
        "--targets",
        "cat",
        "--methods",
        "direct",
        "--seconds",
        "2",
        "--refine",
        "none",
        "--no-track",
        "--workers",
        "1",
    ]
    assert main(args) == 0
    text = capsys.readouterr().out
    assert "n/a" in text and "MISSED" not in text


def _row(method: str, survival: float, **kw) -> dict:
    r = {
        "status": "ok",
        "method": method,
        "survival": survival,
        "sim_mpjpe_per_leg": 0.05,
        "skate_mm_before": 20.0,
        "skate_mm_after": 0.5,
        "jerk_before": 100.0,
        "jerk_after": 50.0,
        "penetration_mm_before": 5.0,
        "penetration_mm_after": 0.0,
        "time_transfer_s": 0.5,
        "time_refine_s": 1.0,
        "time_track_s": 2.0,
    }
    r.update(kw)
    return r


def test_targets_and_exit_code() -> None:
    rows = [_row("habit", 1.0), _row("direct", 0.5)]
    t = evaluate_targets(rows, seconds=4)
    assert [x.verdict for x in t] == ["met"] * 5 and exit_code(t) == 0
    rows = [_row("habit", 0.4, skate_mm_after=3.0), _row("direct", 1.0)]
    t = evaluate_targets(rows, seconds=4)
    v = {x.name.split(":")[0].split(" ")[0]: x.verdict for x in t}
    assert v["refinement"] == "MISSED" and v["habit"] == "MISSED" and exit_code(t) == 1
    slow = [_row("habit", 1.0, time_refine_s=20.0)]
    assert evaluate_targets(slow, seconds=4)[-1].verdict == "MISSED"
    assert evaluate_targets(slow, seconds=10)[-1].verdict == "met"  # 25 s per 10 s window
    t = evaluate_targets(rows, seconds=4, refine="none", tracked=False)
    assert [x.verdict for x in t][:4] == ["n/a"] * 4
    # the MPJPE target is the habit windows' median; every tracked window's is shown
    mixed = [
        _row("habit", 1.0, sim_mpjpe_per_leg=0.2),
        _row("direct", 1.0, sim_mpjpe_per_leg=0.1),
        _row("direct", 1.0, sim_mpjpe_per_leg=0.1),
    ]
    m = next(x for x in evaluate_targets(mixed, seconds=4) if "MPJPE" in x.name)
    assert m.value == pytest.approx(0.2) and m.verdict == "MISSED"
    assert m.shown == "0.200 of 1 (all tracked windows 0.100)"
    mixed[0]["sim_mpjpe_per_leg"] = 0.09
    m = next(x for x in evaluate_targets(mixed, seconds=4) if "MPJPE" in x.name)
    assert m.value == pytest.approx(0.09) and m.verdict == "met"


def test_gallop_windows_are_shown_beside_the_survival_target() -> None:
    """A source window above the gallop Froude number is reported, not counted."""
    rows = [
        _row("habit", 1.0, source_froude_peak=1.2),
        _row("habit", 1.0, source_froude_peak=GALLOP_FROUDE),  # at the boundary: counted
        _row("habit", 1.0, source_froude_peak=None),  # unknown: counted
        _row("habit", 0.4, source_froude_peak=3.7, survival_runs=[0.4, 1.0]),
        _row("direct", 1.0),
    ]
    t = next(x for x in evaluate_targets(rows, seconds=4) if "surviving" in x.name)
    assert t.value == pytest.approx(1.0) and t.verdict == "met"
    assert t.shown == "100 % of 3; gallops (Fr > 2.5, not counted): 1/2 whole"
    rows[1]["survival"] = 0.5
    t = next(x for x in evaluate_targets(rows, seconds=4) if "surviving" in x.name)
    assert t.value == pytest.approx(2 / 3) and t.verdict == "MISSED"
    only = [_row("habit", 0.4, source_froude_peak=3.7)]
    t = next(x for x in evaluate_targets(only, seconds=4) if "surviving" in x.name)
    assert t.verdict == "n/a"


def test_survival_targets_count_every_run_of_every_window() -> None:
    """With ``--repeats`` a window that survives one run in two counts half."""
    rows = [
        _row("habit", 1.0, survival_runs=[1.0, 0.5]),
        _row("habit", 1.0, survival_runs=[1.0, 1.0]),
        _row("direct", 1.0, survival_runs=[1.0, 1.0]),
    ]
    t = {x.name.split(" ")[0]: x for x in evaluate_targets(rows, seconds=4)}
    habit = next(x for x in evaluate_targets(rows, seconds=4) if "surviving" in x.name)
    assert habit.value == pytest.approx(0.75) and habit.verdict == "MISSED"
    assert habit.shown == "75 % of 4 runs"
    assert t["habit"].value == pytest.approx(0.875 - 1.0)  # mean over runs, not rows
    assert t["habit"].verdict == "MISSED"
    assert survival_runs(_row("direct", 0.3)) == [0.3]  # one run without repeats
    assert survival_runs(_row("direct", None)) == []


def test_summary_shows_survival_per_target() -> None:
    """Each target's line averages every run of its windows, per method."""
    rows = [
        _row("habit", 1.0, target="cat", survival_runs=[1.0, 0.5]),
        _row("habit", 1.0, target="horse"),
        _row("direct", 0.8, target="cat", survival_runs=[0.8, 1.0]),
        _row("direct", None, target="horse", status="error"),
    ]
    text = format_summary(rows, evaluate_targets(rows, seconds=4))
    lines = text.splitlines()
    head = lines.index("  mean survival per target over every run (habit / direct):")
    assert lines[head + 1].split() == ["cat", "0.75", "/", "0.90"]
    assert lines[head + 2].split() == ["horse", "1.00", "/", "-"]
    untracked = [_row("habit", None, target="cat")]
    assert "per target" not in format_summary(untracked, evaluate_targets(untracked, seconds=4))


def test_summary_splits_survival_by_gait_regime() -> None:
    """Windows whose source peaks above the gallop Froude number are counted apart."""
    rows = [
        _row("habit", 1.0, source_froude_peak=0.4, survival_runs=[1.0, 1.0]),
        _row("habit", 0.3, source_froude_peak=4.5, survival_runs=[0.3, 1.0]),
        _row("habit", 0.2, source_froude_peak=GALLOP_FROUDE + 0.1),
        _row("direct", 1.0, source_froude_peak=GALLOP_FROUDE),  # at the boundary: not a gallop
        _row("direct", 1.0, source_froude_peak=None),  # unknown: left out
    ]
    lines = format_summary(rows, evaluate_targets(rows, seconds=4)).splitlines()
    head = next(i for i, x in enumerate(lines) if "per gait regime" in x)
    assert lines[head + 1].split(";") == [
        "    habit    Fr ≤ 2.5: 1 window(s), whole runs 2/2, mean survival 1.00",
        " Fr > 2.5: 2 window(s), whole runs 1/3, mean survival 0.50",
    ]
    assert lines[head + 2].split(";") == [
        "    direct   Fr ≤ 2.5: 1 window(s), whole runs 1/1, mean survival 1.00",
        " Fr > 2.5: 0 window(s), whole runs 0/0, mean survival -",
    ]
    assert f"Fr {GALLOP_FROUDE:g}" in lines[head] and f"{PEAK_SPAN_S:g} s" in lines[head]
    assert f"over {PEAK_SPAN_S:g} s (above {GALLOP_FROUDE:g} a gallop)" in LEGEND
    assert "  Fr 4.5  " in format_row(
        {**rows[1], "clip": "a.bvh", "start_s": 0.0, "target": "cat", "reference_residual_mg": 0.1}
    )
    untracked = [_row("habit", None, source_froude_peak=1.0)]
    assert "regime" not in format_summary(untracked, evaluate_targets(untracked, seconds=4))


def test_bad_input(folder: Path, tmp_path: Path, capsys) -> None:
    empty = tmp_path / "empty"
    empty.mkdir()
    (empty / "a.txt").write_text("x")
    with pytest.raises(BenchRealError, match=r"no source clips \(.bvh, .glb, .gltf files\)"):
        source_files(empty)
    with pytest.raises(SkeletonMappingError, match="valid: .bvh, .glb, .gltf"):
        read_clip(tmp_path / "clip.fbx", "dog")
    out = tmp_path / "never.json"
    base = ["bench", "real", "--workers", "1", "--json", str(out)]
    assert main([*base, "--data", str(empty)]) == 2
    assert "no source clips" in capsys.readouterr().err
    lying = tmp_path / "lying"
    lying.mkdir()
    root, quats = lying_pose("dog")
    write_bvh(
        Motion("dog", 30.0, np.tile(root, (60, 1)), np.tile(quats, (60, 1, 1))), lying / "l.bvh"
    )
    assert main([*base, "--data", str(lying)]) == 2
    err = capsys.readouterr().err
    assert "l.bvh: skipped, no stretch of 1 s or more" in err and "lying 0.00–2.00 s" in err
    assert main([*base, "--data", str(folder), "--targets", "cat,hores"]) == 2
    assert "unknown species 'hores'" in capsys.readouterr().err
    assert main([*base, "--data", str(folder), "--methods", "nope"]) == 2
    assert "valid:" in capsys.readouterr().err
    assert main([*base, "--data", str(folder), "--repeats", "0"]) == 2
    assert "--repeats 0; valid: 1 to" in capsys.readouterr().err
    assert main([*base, "--data", str(folder), "--perturb", "-1"]) == 2
    assert "--perturb must be a finite rate > 0" in capsys.readouterr().err
    bad_map = tmp_path / "map.json"
    bad_map.write_text('{"map": {"lh_hip": "A"}, "colour": 1}')
    assert main([*base, "--data", str(folder), "--map", str(bad_map)]) == 2
    assert "unknown keys ['colour']" in capsys.readouterr().err
    with pytest.raises(SystemExit) as e:
        main([*base, "--data", str(folder), "--units", "furlong"])
    assert e.value.code == 2
    assert not out.exists()


def test_windows_per_clip_all_plans_every_whole_window(tmp_path: Path, capsys) -> None:
    """A 9.5 s clip in 2 s windows from where it moves: `all` plans every whole window,
    a count at most that many; anything else is a usage error naming what is valid."""
    from habitsim.cli import build_parser
    from habitsim.cli.bench_real import options
    from habitsim.evaluation.bench.real import clip_windows, plan
    from habitsim.motion import resample_motion

    d = tmp_path / "clips"
    d.mkdir()
    write_bvh(generate("dog", "walk", seed=3, duration_s=9.5), d / "walk.bvh")
    argv = ["bench", "real", "--data", str(d), "--seconds", "2", "--targets", "cat"]
    argv += ["--methods", "direct"]
    parser = build_parser()
    motion = resample_motion(read_clip(d / "walk.bvh", "dog"), 30)
    every = [w.start for w in clip_windows(motion, 60, motion.num_frames, 30)[0]]
    assert len(every) >= 4
    tasks = plan(options(parser.parse_args([*argv, "--windows-per-clip", "all"]))).tasks
    assert [round(t.start_s * 30) for t in tasks] == every
    tasks = plan(options(parser.parse_args([*argv, "--windows-per-clip", "2"]))).tasks
    assert [round(t.start_s * 30) for t in tasks] == every[:2]
    with pytest.raises(SystemExit) as usage:
        main([*argv, "--windows-per-clip", "most"])
    assert usage.value.code == 2
    assert "valid: a count >= 1 or 'all'" in capsys.readouterr().err
    assert main([*argv, "--windows-per-clip", "0"]) == 2
    assert "must be >= 1 or 'all'" in capsys.readouterr().err


def test_short_clips_run_as_one_short_window_and_lying_is_kept_out(tmp_path: Path) -> None:
    """A clip shorter than a window is one shorter window (marked short, never skipped);
    a lying start is named in a note and no window holds a frame of it."""
    from habitsim.cli import build_parser
    from habitsim.cli.bench_real import options
    from habitsim.evaluation.bench.real import plan

    d = tmp_path / "clips"
    d.mkdir()
    write_bvh(generate("dog", "trot", seed=1, duration_s=2.5), d / "run.bvh")
    walk = generate("dog", "walk", seed=3, duration_s=5.0)
    write_bvh(with_lying_start(walk, lying_s=2.0, rise_s=1.0), d / "lie_walk.bvh")
    argv = ["bench", "real", "--data", str(d), "--targets", "cat", "--methods", "direct"]
    planned = plan(options(build_parser().parse_args([*argv, "--windows-per-clip", "all"])))
    by_clip: dict[str, list] = {}
    for t in planned.tasks:
        by_clip.setdefault(t.clip, []).append(t)
    assert set(by_clip) == {"run.bvh", "lie_walk.bvh"}
    (short,) = by_clip["run.bvh"]
    assert short.short and short.start_s == 0.0 and short.motion.num_frames == 75
    assert "locomotion (trot)" in short.activity
    assert any(
        "run.bvh: the clip is shorter than one 4 s window: runs as one 2.50 s" in n
        for n in planned.notes
    )
    assert any(n.startswith("lie_walk.bvh: lying 0.00–") and "kept out" in n for n in planned.notes)
    (lie,) = by_clip["lie_walk.bvh"]
    assert not lie.short and lie.start_s >= 2.0 and lie.motion.num_frames == 120
    row = {
        "clip": "run.bvh",
        "start_s": 0.0,
        "target": "cat",
        "method": "direct",
        "status": "ok",
        "short_window": True,
        "window_s": 2.5,
    }
    assert "short window 2.50 s" in format_row(row)
