"""The activity timeline of a clip on its own skeleton, its default span and the windows
a benchmark cuts from it (habitsim.activity), on synthetic clips the project makes."""

from __future__ import annotations

import functools
import json
from pathlib import Path

import numpy as np
import pytest

from habitsim.activity import (
    Activity,
    ActivityError,
    ActivityOptions,
    Timeline,
    choose_windows,
    default_span,
    timeline,
)
from habitsim.gaits import generate
from habitsim.gaits.lying import lying_pose, with_lying_start
from habitsim.motion import Motion


@functools.cache
def _clip(action: str, seconds: float = 4.0) -> Motion:
    return generate("dog", action, seed=0, duration_s=seconds)


def _covers(tl: Timeline) -> None:
    """Segments are consecutive, from frame 0 to the last."""
    assert tl.segments[0].start == 0
    assert tl.segments[-1].stop == tl.n_frames
    for a, b in zip(tl.segments[:-1], tl.segments[1:], strict=True):
        assert a.stop == b.start
        assert a.activity is not b.activity or a.gait != b.gait


@pytest.mark.parametrize(("action", "gait"), [("walk", "walk"), ("trot", "trot")])
def test_a_gait_is_one_locomotion_segment_named_by_its_footfalls(action: str, gait: str) -> None:
    tl = timeline(_clip(action))
    _covers(tl)
    assert [s.activity for s in tl.segments] == [Activity.LOCOMOTION]
    seg = tl.segments[0]
    assert seg.gait == gait
    assert not seg.backward and not seg.trunk_on_ground
    speed = np.linalg.norm(np.diff(_clip(action).root_positions[:, :2], axis=0), axis=1).sum()
    expect = speed / _clip(action).duration / _clip(action).species_info.leg_length
    assert seg.speed_per_leg == pytest.approx(expect, rel=0.15)


def test_standing_still_is_standing() -> None:
    tl = timeline(_clip("idle"))
    assert [s.activity for s in tl.segments] == [Activity.STANDING]
    assert tl.segments[0].hind_height == pytest.approx(1.0, abs=0.05)


def test_backward_walk_reads_backward() -> None:
    tl = timeline(_clip("walk_backward"))
    loco = tl.of(Activity.LOCOMOTION)
    assert loco and all(s.backward for s in loco)


def test_a_sit_ends_sitting_with_the_trunk_on_the_ground() -> None:
    tl = timeline(_clip("sit"))
    _covers(tl)
    assert tl.segments[0].activity is Activity.STANDING
    last = tl.segments[-1]
    assert last.activity is Activity.SITTING and last.trunk_on_ground
    assert last.hind_height < 0.5 < last.fore_height
    assert last.duration > 1.5
    assert tl.resting()[-1] and not tl.resting()[0]


def test_a_lying_start_is_found_and_left_out() -> None:
    walk = _clip("walk")
    m = with_lying_start(walk, lying_s=2.0, rise_s=1.0)
    assert m.num_frames == walk.num_frames + 90
    tl = timeline(m)
    _covers(tl)
    first = tl.segments[0]
    assert first.activity is Activity.LYING and first.trunk_on_ground
    assert 1.8 <= first.end_s <= 3.0
    start, stop = default_span(tl)
    assert stop == m.num_frames
    # the clip's own first frame (90), within the smoothing window (8 frames)
    assert tl.segments[0].stop <= start and abs(start - 90) <= 8
    assert default_span(timeline(walk)) == (0, walk.num_frames)
    assert not tl.resting()[start:].any()
    for w in choose_windows(tl, 60, 10):
        assert not tl.resting()[w.start : w.stop].any()
        assert w.start >= start and not w.short
    assert tl.labels()[0] == "lying"


def test_lying_pose_rests_trunk_and_toes_on_the_ground() -> None:
    from habitsim.skeleton import get_skeleton

    root, quats = lying_pose("dog")
    skel = get_skeleton("dog")
    pos = skel.fk(root[None], quats[None])[0]
    assert pos[skel.foot_indices, 2].min() == pytest.approx(0.0, abs=1e-9)
    trunk = [skel.index(n) for n in ("pelvis", "spine1", "spine2", "spine3")]
    assert pos[trunk, 2].max() < 0.2 * skel.fk(*[x[None] for x in skel.standing_pose()])[0][0, 2]


def test_a_clip_shorter_than_a_window_is_one_short_window() -> None:
    m = _clip("trot", 2.0)
    tl = timeline(m)
    (w,) = choose_windows(tl, 4 * int(m.fps), 3, min_frames=int(m.fps))
    assert w.short and w.start == 0 and w.stop == m.num_frames
    assert choose_windows(tl, 4 * int(m.fps), 3, min_frames=m.num_frames + 1) == []


def test_windows_are_consecutive_from_the_first_locomotion_frame() -> None:
    m = _clip("walk")
    tl = timeline(m)
    wins = choose_windows(tl, 30, 100)
    assert len(wins) == m.num_frames // 30
    assert [w.start for w in wins] == [30 * i for i in range(len(wins))]
    assert len(choose_windows(tl, 30, 2)) == 2


def test_a_clip_that_only_lies_has_no_span() -> None:
    root, quats = lying_pose("dog")
    n = 60
    m = Motion("dog", 30.0, np.tile(root, (n, 1)), np.tile(quats, (n, 1, 1)))
    tl = timeline(m)
    assert [s.activity for s in tl.segments] == [Activity.LYING]
    with pytest.raises(ActivityError, match="no standing or locomotion segment"):
        default_span(tl)
    assert choose_windows(tl, 30, 1) == []


def test_bad_options_are_refused() -> None:
    with pytest.raises(ActivityError, match="lying_ratio"):
        ActivityOptions(lying_ratio=0.9, sitting_hind_ratio=0.5)
    with pytest.raises(ActivityError, match="min_segment_s"):
        ActivityOptions(min_segment_s=-1.0)
    with pytest.raises(ActivityError, match="frames"):
        choose_windows(timeline(_clip("idle")), 0, 1)


def test_options_change_the_answer() -> None:
    """A speed threshold above the walk's speed (and no stepping allowance) reads it as
    standing: the knobs are read."""
    opts = ActivityOptions(moving_speed_per_leg=50.0, stepping_share=1.0)
    tl = timeline(_clip("walk"), opts)
    assert Activity.LOCOMOTION not in [s.activity for s in tl.segments]


def test_inspect_bvh_prints_the_timeline(tmp_path, capsys) -> None:
    from habitsim.bvh import write_bvh
    from habitsim.cli import main

    p = tmp_path / "lie_walk.bvh"
    write_bvh(with_lying_start(_clip("walk"), lying_s=2.0, rise_s=1.0), p)
    assert main(["data", "inspect-bvh", str(p)]) == 0
    out = capsys.readouterr().out
    lines = out[out.index("activity on the dog") :].splitlines()
    assert "lying (trunk on the ground)" in lines[1]
    assert lines[1].split()[0] == "0.00–"
    assert any("locomotion (walk)" in x for x in lines[2:5])
    assert "default span: from" in out and "lying start is left out" in out


GO2 = Path(__file__).parent / "robots" / "unitree_go2" / "scene.xml"


def _retarget_lying_start(tmp_path: Path, capsys, *extra: str) -> dict:
    from habitsim.cli import main

    src = tmp_path / "lie_walk.npz"
    with_lying_start(_clip("walk"), lying_s=2.0, rise_s=1.0).save(src)
    out = tmp_path / "q.npz"
    assert (
        main(["retarget", str(src), "--robot", str(GO2), "--out", str(out), "--json", *extra]) == 0
    )
    return json.loads(capsys.readouterr().out)


def test_retarget_leaves_a_lying_start_out(tmp_path: Path, capsys) -> None:
    from habitsim.retarget import load_robot_clip

    summary = _retarget_lying_start(tmp_path, capsys)
    assert "start left out: the clip begins lying 0.00–" in summary["trimmed_start"]
    clip = load_robot_clip(tmp_path / "q.npz")
    walk = _clip("walk").num_frames
    assert abs(len(clip.qpos) - walk) <= 8  # the lying seconds and the rise are gone
    # a span the user gives is taken as given
    summary = _retarget_lying_start(tmp_path, capsys, "--start", "0")
    assert summary["trimmed_start"] is None
    assert len(load_robot_clip(tmp_path / "q.npz").qpos) == walk + 90
    # a clip that starts on its legs is retargeted whole, and says nothing
    src = tmp_path / "walk.npz"
    _clip("walk").save(src)
    from habitsim.cli import main

    out = tmp_path / "w.npz"
    assert main(["retarget", str(src), "--robot", str(GO2), "--out", str(out), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["trimmed_start"] is None
    assert len(load_robot_clip(out).qpos) == walk


@pytest.mark.slow
def test_a_lying_start_never_makes_a_robot_run_fail(tmp_path: Path, capsys) -> None:
    summary = _retarget_lying_start(tmp_path, capsys, "--track")
    assert summary["trimmed_start"]
    assert not summary["track"]["fell"] and summary["track"]["survival"] == 1.0


def test_a_clip_lying_throughout_is_a_typed_error(tmp_path: Path, capsys) -> None:
    from habitsim.cli import main

    root, quats = lying_pose("dog")
    src = tmp_path / "lie.npz"
    Motion("dog", 30.0, np.tile(root, (60, 1)), np.tile(quats, (60, 1, 1))).save(src)
    out = tmp_path / "q.npz"
    assert main(["retarget", str(src), "--robot", str(GO2), "--out", str(out)]) == 2
    assert "no standing or locomotion segment" in capsys.readouterr().err
    assert not out.exists()


def test_a_lying_reference_is_never_a_fall_of_the_controller() -> None:
    """The fall rule's clauses at a frame where the reference lies are recorded as the
    reference resting, not a fall; the same body state under a standing reference, or
    with the resting rule off, is a fall."""
    import mujoco

    from habitsim.qpos import motion_to_qpos, species_model
    from habitsim.rotations import rot_x
    from habitsim.sim import FallCause, FallDetector, FallOptions

    model = species_model("dog")
    root, quats = lying_pose("dog")
    lie = Motion("dog", 30.0, np.tile(root, (3, 1)), np.tile(quats, (3, 1, 1)))
    q_lie = motion_to_qpos(lie, model).qpos
    q_stand = motion_to_qpos(_clip("idle").slice(0, 3), model).qpos
    data = mujoco.MjData(model)
    data.qpos[:] = q_lie[0]
    data.qpos[3:7] = rot_x(1.5)  # rolled onto its side
    mujoco.mj_forward(model, data)
    leg = lie.species_info.leg_length
    det = FallDetector(model, q_lie, 30.0, leg)
    assert det.ref_resting.all()
    assert det.fall(1, data) is None
    assert det.resting is not None and det.resting.frame == 1
    assert det.resting.cause is FallCause.TILT and det.resting.trunk_ratio < 0.3
    assert "reference lying at 0.03 s" in det.resting.describe(30.0)
    standing = FallDetector(model, q_stand, 30.0, leg)
    assert not standing.ref_resting.any()
    assert standing.fall(1, data) is not None and standing.resting is None
    off = FallDetector(model, q_lie, 30.0, leg, options=FallOptions(rest_height_ratio=0.0))
    fall = off.fall(1, data)
    assert fall is not None and fall.cause is FallCause.TILT
