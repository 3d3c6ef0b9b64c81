"""One pipeline path: transfer keeps the source's footfalls, the labels travel from stage
to stage, refinement that makes a clip track worse is reported and not kept, one model
cache."""

from __future__ import annotations

import math
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from habitsim.contacts import (
    drop_short_runs,
    fill_support,
    lengthen_stance,
    warp_contacts,
)
from habitsim.errors import InvalidMotionError
from habitsim.gaits import generate
from habitsim.models import transfer
from habitsim.motion import resample_motion
from habitsim.pipeline import PipelineError, refine_mode, run_clip, stance_toe_height
from habitsim.stance.bounds import bound_heading, bound_height, bound_speed
from habitsim.stance.labels import stance_f1, stance_runs
from habitsim.stance.ladder import plant_partly, trim_to_reach
from habitsim.stance.level import level_trunk
from habitsim.stance.policy import ConformPolicy
from habitsim.stance.schedule import transfer_contacts, walking_stance

pytestmark = pytest.mark.usefixtures("torch_one_thread")

#: The default knobs of conforming a decoded motion.
POLICY = ConformPolicy()
#: The planting ladder without its last rungs: no restepping, no partial planting.
NO_FALLBACKS = ConformPolicy(restep_min_period=math.inf, partial_passes=0)


def _reaches(report: dict) -> bool:
    """A planting report of ``metadata["transfer"]["planted"]`` within the default limits."""
    return (
        report["max_reach_error_per_leg"] <= POLICY.plant_max_reach_per_leg
        and report.get("max_swing_reach_error_per_leg", 0.0) <= POLICY.plant_max_swing_reach_per_leg
        and report["max_pelvis_drop_per_leg"] <= POLICY.plant_max_drop_per_leg
    )


@pytest.fixture(scope="module")
def trot():
    return generate("horse", "trot", seed=5, duration_s=3.0)


@pytest.fixture(scope="module")
def walk():
    return generate("dog", "walk", seed=2, duration_s=2.0)


# ---------------------------------------------------------------------------- contacts


def test_drop_short_runs_and_warp() -> None:
    c = np.array([[1, 1, 0, 1, 1, 0, 0, 1, 0, 0, 1]], bool).T
    out = drop_short_runs(c, 2)[:, 0].astype(int).tolist()
    # the one-frame gap is filled, the lone stance frames are removed (also at the end)
    assert out == [1, 1, 1, 1, 1, 0, 0, 0, 0, 0, 0]
    lab = np.zeros((10, 4), bool)
    lab[2:6] = True
    np.testing.assert_array_equal(warp_contacts(lab, 10), lab)
    w = warp_contacts(lab, 19)  # twice the frames over the same span
    assert w.shape == (19, 4) and w[:, 0].sum() == 8 and w[4:11, 0].all()


def test_lengthen_stance_keeps_the_middles_of_the_runs() -> None:
    c = np.zeros((60, 3), bool)
    c[10:20, 0] = c[40:50, 0] = True  # stands 1/3 of the clip
    c[0:6, 1] = True  # a run at the clip's start, 10 %
    c[:45, 2] = True  # already stands 75 %
    out = lengthen_stance(c, 0.5)
    # foot 0: 3 frames more at both ends of both runs, 32 of 60 (2 more give 28 < 30)
    assert stance_runs(out[:, :1]) == [[(7, 23), (37, 53)]]
    # foot 1 grows inward only; foot 2 is kept; nothing else changes
    assert stance_runs(out[:, 1:2]) == [[(0, 30)]]
    np.testing.assert_array_equal(out[:, 2], c[:, 2])
    np.testing.assert_array_equal(lengthen_stance(c, 0.0), c)
    with pytest.raises(InvalidMotionError, match="min_share"):
        lengthen_stance(c, 1.5)
    with pytest.raises(InvalidMotionError, match="shape"):
        lengthen_stance(c[:, 0], 0.5)


def test_fill_support_lengthens_the_nearest_run() -> None:
    c = np.zeros((30, 4), bool)
    c[0:10, 0] = c[12:30, 0] = True  # foot 0 lifts for frames 10-11
    c[0:8, 1] = True  # foot 1 lifted off at frame 8 ...
    c[15:30, 1] = True  # ... and lands again at 15
    c[:, 2] = False  # foot 2 never stands
    c[0:3, 3] = c[25:30, 3] = True
    out = fill_support(c, 2)
    assert (out.sum(axis=1) >= 2).all()
    assert (out | ~c).all()  # stance only grows
    # frames 8-14 had one foot or none: each short frame took the nearest run, one frame
    # at a time (foot 1 held on from frame 8, foot 0 from frame 10, foot 1 again from 12):
    # both gaps close, feet 2 and 3 are untouched
    assert out[:, 0].all() and out[:, 1].all()
    np.testing.assert_array_equal(out[:, 3], c[:, 3])
    np.testing.assert_array_equal(out[:, 2], c[:, 2])
    # a frame no run can reach stays short
    lone = np.zeros((5, 2), bool)
    lone[:, 0] = True
    np.testing.assert_array_equal(fill_support(lone, 2), lone)
    np.testing.assert_array_equal(fill_support(c, 0), c)
    with pytest.raises(InvalidMotionError, match="min_feet"):
        fill_support(c, 5)
    with pytest.raises(InvalidMotionError, match="shape"):
        fill_support(c[:, 0], 2)


def test_walking_stance_only_where_the_target_walks() -> None:
    """A cat at a walking Froude number gets no aerial phase; a trot, a faster clip and a
    jump keep their labels."""
    slow = generate("cat", "walk", seed=1, duration_s=3.0, froude=0.3, duty_factor=0.35)
    assert slow.contacts is not None and slow.contacts.mean(0).max() < POLICY.walk_min_duty
    labels, info = walking_stance(slow, slow.contacts, slow)
    labels = labels.array
    assert info is not None and info["froude"] <= info["walk_froude_max"] == 0.45
    assert labels.mean(0).min() >= POLICY.walk_min_duty
    assert (labels.sum(axis=1) >= POLICY.walk_min_feet).all()  # never fewer than two feet down
    assert (labels | ~slow.contacts).all()  # stance only grows
    assert info["duty_after"] == pytest.approx(labels.mean(0).round(3).tolist())
    # the same footfalls with no action known: decided by the Froude number alone
    bare = slow.slice(0)
    bare.metadata = {}
    np.testing.assert_array_equal(walking_stance(bare, slow.contacts, bare)[0], labels)
    # a trot is a trot
    trot = generate("cat", "trot", seed=1, duration_s=3.0, froude=0.6, duty_factor=0.4)
    kept, none = walking_stance(trot, trot.contacts, trot)
    assert none is None and (kept.array == trot.contacts).all()
    # faster than the cat walks, no action known: kept
    bare = trot.slice(0)
    bare.metadata = {}
    assert walking_stance(bare, trot.contacts, bare)[1] is None
    # a jump is not a cyclic gait
    jump = generate("cat", "jump", seed=1)
    assert walking_stance(jump, jump.contacts, jump)[1] is None


def test_transfer_keeps_the_source_footfalls(trot) -> None:
    assert trot.contacts is not None
    src = drop_short_runs(warp_contacts(trot.contacts, trot.num_frames))
    # direct_relabelled carries the source's schedule over
    out = transfer(trot, to="cat", method="direct_relabelled", seed=0)
    assert out.metadata["transfer"]["contacts"]["method"] == "source"
    np.testing.assert_array_equal(out.contacts, src)
    # the network's decoded contacts, checked foot by foot against the source's schedule
    # (before planting, which may step the legs faster: see the restep test)
    out = transfer(trot, to="cat", method="habit", seed=0, plant=False)
    how = out.metadata["transfer"]["contacts"]
    assert how["method"] == "decoded" and len(how["source_f1"]) == 4
    for k, foot in enumerate(("LF", "RF", "LH", "RH")):
        f1 = stance_f1(out.contacts[:, k : k + 1], src[:, k : k + 1])[0]
        if foot in how.get("feet_from_source", []):
            np.testing.assert_array_equal(out.contacts[:, k], src[:, k])
        else:  # kept: it agreed with the source's footfalls and stands as long
            assert f1 >= POLICY.min_source_agreement and how["source_f1"][k] == pytest.approx(
                f1, abs=1e-3
            )
            assert abs(out.contacts[:, k].mean() - src[:, k].mean()) <= POLICY.max_duty_gap


def _resting(m, labels) -> float:
    v = np.linalg.norm(np.diff(m.foot_positions(), axis=0), axis=-1) * m.fps
    on = labels[1:] & labels[:-1]
    return float((v[on] <= 0.1 * m.species_info.leg_length).mean())


def test_habit_transfer_plants_its_feet_on_its_labels(trot) -> None:
    planted = transfer(trot, to="elephant", method="habit", seed=0)
    raw = transfer(trot, to="elephant", method="habit", seed=0, plant=False)
    np.testing.assert_array_equal(planted.contacts, raw.contacts)  # same labels
    assert raw.metadata["transfer"]["planted"] is False
    report = planted.metadata["transfer"]["planted"]
    assert report["kept"] and len(report["stance_toe_height_per_leg"]) == 4
    assert report["max_reach_error_per_leg"] <= POLICY.plant_max_reach_per_leg
    c = planted.contacts
    assert _resting(planted, c) >= 0.95 > _resting(raw, c)
    z = planted.foot_positions()[..., 2][c] / planted.species_info.leg_length
    assert np.median(np.abs(z)) <= 0.01  # stance toes on the ground
    # swing feet are lifted: in the middle of each swing run the toe is near the
    # elephant's habitual swing height, not shuffling at the ground as decoded
    leg = planted.species_info.leg_length
    height = planted.species_info.habits.swing_height * leg
    mid_planted, mid_raw = [], []
    for f, runs in enumerate(stance_runs(~c)):
        for a, b in runs:
            if b - a >= 5 and a > 0 and b < len(c):  # whole swings between two stances
                mid_planted.append(planted.foot_positions()[(a + b) // 2, f, 2])
                mid_raw.append(raw.foot_positions()[(a + b) // 2, f, 2])
    assert mid_planted and np.median(mid_planted) >= 0.8 * height
    assert np.median(mid_raw) < 0.5 * height
    # the trunk is the decoder's: planting re-solves the legs only
    np.testing.assert_allclose(planted.root_positions[:, :2], raw.root_positions[:, :2], atol=1e-9)


def test_planting_out_of_reach_keeps_the_decoded_feet_and_says_why(trot) -> None:
    # the horse's trot at the cat's Froude speed and the horse's cadence: strides of
    # more leg lengths than the cat's legs sweep; without restepping and partial planting
    # nothing holds the feet
    out = transfer(trot, to="cat", method="habit", seed=0, policy=NO_FALLBACKS)
    raw = transfer(trot, to="cat", method="habit", seed=0, plant=False)
    report = out.metadata["transfer"]["planted"]
    assert not report["kept"] and "do not reach" in report["reason"]
    assert report["max_reach_error_per_leg"] > POLICY.plant_max_reach_per_leg
    np.testing.assert_array_equal(out.rotations, raw.rotations)


def test_planting_falls_back_to_footholds_centred_under_the_joints(trot) -> None:
    # the horse's trot sent to the tiger: the decoded stance feet slide, and the median of
    # a sliding toe path lies too far ahead of or behind the shoulder / hip at one end of
    # a run; the foothold half-way along the joint's travel is in reach
    out = transfer(trot, to="tiger", method="habit", seed=0)
    raw = transfer(trot, to="tiger", method="habit", seed=0, plant=False)
    report = out.metadata["transfer"]["planted"]
    assert report["kept"] and report["root"] == "decoded" and report["footholds"] == "centred"
    assert _reaches(report) and report["solved"] and "free_runs" not in report
    c = out.contacts
    assert _resting(out, c) >= 0.95 > _resting(raw, c)
    # with the median footholds alone the decoded root path is not planted
    median_only = replace(NO_FALLBACKS, foothold_rules=(False,))
    median = transfer(trot, to="tiger", method="habit", seed=0, policy=median_only)
    median = median.metadata["transfer"]["planted"]
    assert median["footholds"] == "median"
    assert not (median["kept"] and median["root"] == "decoded")


def test_planting_steps_faster_when_the_body_outruns_the_decoded_stride(walk) -> None:
    # a dog walk sent to the cat: the decoder keeps the dog's cadence and gives the cat its
    # own speed, so one stance would have to hold while the body travels further than a
    # cat's leg sweeps; the labels are played faster instead
    from habitsim.contacts import stride_period
    from habitsim.gait_stats import gait_statistics

    out = transfer(walk, to="cat", method="habit", seed=0)
    raw = transfer(walk, to="cat", method="habit", seed=0, plant=False)
    report = out.metadata["transfer"]["planted"]
    assert report["kept"] and report["root"] == "decoded" and _reaches(report), report
    step = report["restep"]
    assert step["rate"] > 1.2 and "step faster" in report["reason"]
    before, after = raw.contacts, out.contacts
    assert stride_period(after) == pytest.approx(stride_period(before) / step["rate"], rel=0.15)
    assert step["period_s"][1] < step["period_s"][0]
    assert after.mean() == pytest.approx(before.mean(), abs=0.05)  # duty factor kept
    p0 = gait_statistics(raw).phase_offsets
    p1 = gait_statistics(out).phase_offsets
    for foot in ("LF", "RF", "RH"):  # the footfall sequence kept
        d = (p0[foot] - p1[foot]) % 1.0
        assert min(d, 1.0 - d) <= 0.1, (foot, p0, p1)
    assert _resting(out, after) >= 0.95
    # the body is the decoder's; only the legs step on the new labels
    np.testing.assert_allclose(out.root_positions[:, :2], raw.root_positions[:, :2], atol=1e-9)
    # a swing toe clears the ground by the cat's habitual swing height at mid-swing
    toes = out.foot_positions()[..., 2]
    assert toes[~after].max() >= 0.5 * out.species_info.habits.swing_height * (
        out.species_info.leg_length
    )


def test_partial_planting_holds_the_faster_steps_when_restepping_misses() -> None:
    # the example dog walk (motion capture) sent to the giraffe: the decoder's stride is
    # too slow for its body and even the faster steps leave the pelvis too low; the
    # partial planting then holds the runs the legs reach on the faster labels, which
    # hold far more of the stance than the decoder's slower ones
    from importlib import resources

    from habitsim.bvh_mapping import import_bvh
    from habitsim.contacts import stride_period

    walk = import_bvh(resources.files("habitsim.examples") / "dog_walk.bvh", "dog")[0]
    raw = transfer(walk, to="giraffe", method="habit", seed=0, plant=False)
    out = transfer(walk, to="giraffe", method="habit", seed=0)
    report = out.metadata["transfer"]["planted"]
    assert report["kept"] and "free_runs" in report and "on the faster steps" in report["reason"]
    assert report["restep"]["max_pelvis_drop_per_leg"] > POLICY.plant_max_drop_per_leg
    rate = report["restep"]["rate"]
    assert rate > 1.2
    assert stride_period(out.contacts) == pytest.approx(
        stride_period(raw.contacts) / rate, rel=0.15
    )
    slower = ConformPolicy(partly_on_restep=False)
    slow = transfer(walk, to="giraffe", method="habit", seed=0, policy=slower)
    assert stride_period(slow.contacts) == pytest.approx(stride_period(raw.contacts), rel=0.15)
    free = slow.metadata["transfer"]["planted"]["free_share"]
    assert report["free_share"] < 0.5 < free
    assert _resting(out, out.contacts) > _resting(slow, slow.contacts) + 0.3


def test_planting_out_of_reach_moves_the_body_as_far_as_its_legs_carry_it(trot):
    # the horse's trot sent to the tiger: the decoded stance feet slide, so a foothold
    # held for a whole stance run is out of reach with the decoded root path
    # (with the median footholds alone: the centred ones reach with the decoded root)
    carry = ConformPolicy(foothold_rules=(False,), plant_min_speed_ratio=0.2)
    out = transfer(trot, to="tiger", method="habit", seed=0, policy=carry)
    raw = transfer(trot, to="tiger", method="habit", seed=0, plant=False)
    report = out.metadata["transfer"]["planted"]
    assert report["kept"] and report["root"] == "carried", report
    assert "do not reach" in report["reason"] and "carry" in report["reason"]
    assert _reaches(report)
    c = out.contacts
    assert _resting(out, c) >= 0.95 > _resting(raw, c)

    # the body travels less than the decoder's, by the ratio the report gives
    def travel(m):
        return np.linalg.norm(np.diff(m.root_positions[:, :2], axis=0), axis=1).sum()

    assert travel(out) / travel(raw) == pytest.approx(report["speed_ratio"], abs=2e-3)
    assert 0.2 <= report["speed_ratio"] < 0.99
    # a body its legs carry too little is not moved: the decoded feet are kept
    stiff = replace(NO_FALLBACKS, foothold_rules=(False,), plant_min_speed_ratio=0.99)
    slow = transfer(trot, to="tiger", method="habit", seed=0, policy=stiff)
    report = slow.metadata["transfer"]["planted"]
    assert not report["kept"] and "carry the body only" in report["reason"]
    np.testing.assert_array_equal(slow.root_positions, raw.root_positions)


def test_transfer_contacts_time_warped_when_the_length_changes(trot) -> None:
    slower = resample_motion(trot.with_contacts(trot.contacts), trot.fps * 1.5)
    slower.contacts = None  # an output of another length, labelled from the source
    labels, info = transfer_contacts(slower, trot)
    labels = labels.array
    assert info == {"method": "source", "source_frames": trot.num_frames, "time_warped": True}
    assert labels.shape == (slower.num_frames, 4)
    np.testing.assert_array_equal(
        labels, drop_short_runs(warp_contacts(trot.contacts, slower.num_frames))
    )
    # the same footfall schedule: the stance share of every foot is kept
    np.testing.assert_allclose(labels.mean(0), trot.contacts.mean(0), atol=0.03)


def test_transfer_without_source_labels_falls_back_and_says_so(trot) -> None:
    bare = trot.slice(0)
    bare.contacts = None
    for method in ("habit", "direct_relabelled"):
        out = transfer(bare, to="cat", method=method, seed=0)
        how = out.metadata["transfer"]["contacts"]
        assert how["method"] in ("detected", "duty") and "no stance labels" in how["reason"]
        assert out.contacts is not None and out.contacts.shape == (out.num_frames, 4)


# ---------------------------------------------------------------------------- pipeline


def test_refine_modes() -> None:
    assert [refine_mode(m) for m in ("none", "A", "B", "kinematic", "dynamics")] == [
        "none",
        "A",
        "B",
        "A",
        "B",
    ]
    with pytest.raises(PipelineError, match="valid: .*A"):
        refine_mode("fast")
    with pytest.raises(PipelineError, match="Motion"):
        run_clip("not a motion", "cat")  # type: ignore[arg-type]


def test_labels_travel_without_refinement(walk) -> None:
    run = run_clip(walk, "cat", method="direct", refine="none", track=False)
    assert run.transferred.contacts_method == "source"
    np.testing.assert_array_equal(run.transferred.contacts, walk.contacts)
    assert run.refined.contacts is run.transferred.contacts and run.refined.status == "none"
    assert run.refine_verdict == "none" and run.tracked.status == "off"
    assert set(run.times) == {"transfer", "refine", "track"}
    assert run.transferred.qpos.shape == (walk.num_frames, run.model.nq)
    assert run.source.contacts_method == "labels"
    assert run.source.metrics["stance_toe_height_per_leg"] == pytest.approx(
        stance_toe_height(walk, walk.contacts)
    )


@pytest.mark.slow
def test_refined_labels_reach_tracking_and_a_worse_refinement_is_reverted(
    walk, monkeypatch
) -> None:
    import habitsim.pipeline as pl

    run = run_clip(walk, "cat", method="direct", refine="A", controller="servo")
    assert run.refined.status != "none" and run.refine_result is not None
    np.testing.assert_array_equal(run.refined.contacts, run.transferred.contacts)
    # tracking got the refined labels as its reference schedule, detected nothing itself
    np.testing.assert_array_equal(run.track_result.reference_contacts, run.refined.contacts)
    assert run.refine_verdict in ("kept", "reverted")  # the refinement succeeded
    assert run.tracked.metrics["survival"] == run.track_result.survival
    monkeypatch.setattr(pl, "_worse", lambda refined, plain: "survival 0.10 < 1.00 unrefined")
    bad = run_clip(walk, "cat", method="direct", refine="A", controller="servo")
    assert bad.refine_verdict == "reverted" and "kept the unrefined" in bad.refine_note
    assert bad.track_result is bad.input_track_result and bad.reference is bad.transferred.motion
    np.testing.assert_array_equal(bad.track_result.reference_contacts, bad.transferred.contacts)


def test_worse_rule() -> None:
    from habitsim.pipeline import GuardOptions, _worse

    def res(s: float, e: float) -> SimpleNamespace:
        return SimpleNamespace(survival=s, metrics={"sim_mpjpe_per_leg": e})

    assert "survival" in _worse(res(0.5, 0.01), res(1.0, 0.2))
    assert "MPJPE" in _worse(res(1.0, 0.20), res(1.0, 0.10))
    assert _worse(res(1.0, 0.105), res(1.0, 0.10)) is None  # not clearly higher
    assert _worse(res(1.0, 0.5), res(0.5, 0.01)) is None  # survives longer
    strict = GuardOptions(mpjpe_ratio=1.0, mpjpe_margin_per_leg=0.0)  # any rise is worse
    assert "MPJPE" in _worse(res(1.0, 0.105), res(1.0, 0.10), strict)


def test_one_model_cache_and_explicit_track_contacts(walk) -> None:
    from habitsim.qpos import species_model
    from habitsim.sim import SimulationError, _species_model, track

    assert species_model("dog") is species_model("dog", False) is _species_model("dog", False)
    assert species_model("dog", servos=True) is _species_model("dog", True)
    with pytest.raises(SimulationError, match=r"contacts must have shape \(60, 4\)"):
        track(walk.slice(0, 60), contacts=np.ones((10, 4), bool))


def test_partial_planting_holds_the_runs_the_legs_reach(walk) -> None:
    # the dog walk with its body travelling three times as fast over its second half:
    # the stance runs there are out of reach, the first half's are held
    from habitsim.motion import Motion

    c = walk.contacts
    leg = walk.species_info.leg_length
    t = len(c)
    half = t // 2
    step = np.diff(walk.root_positions[:, :2], axis=0)
    step[half:] *= 3.0
    root = walk.root_positions.copy()
    root[1:, :2] = root[0, :2] + np.cumsum(step, axis=0)
    fast = Motion("dog", walk.fps, root, walk.rotations, c)
    moved, rep = plant_partly(fast, c)
    assert rep.free_runs is not None and rep.free_share is not None
    assert rep.free_runs[0] >= 1 and 0 < rep.free_share <= 0.5
    assert rep.max_reach_error_per_leg <= POLICY.plant_max_reach_per_leg
    assert rep.max_pelvis_drop_per_leg <= POLICY.plant_max_drop_per_leg
    toes = moved.foot_positions()
    early = 0
    for k, runs in enumerate(stance_runs(c)):
        for a, b in runs:
            if b <= half - 2:  # a run of the slow half: held
                assert np.ptp(toes[a:b, k, :2], axis=0).max() <= 0.01 * leg
                early += 1
    assert early >= 3
    np.testing.assert_array_equal(moved.root_positions[:, :2], fast.root_positions[:, :2])
    # the whole clip that fast: most runs are free, the ones the legs reach still held
    step = np.diff(walk.root_positions[:, :2], axis=0) * 3.0
    root[1:, :2] = root[0, :2] + np.cumsum(step, axis=0)
    moved, rep = plant_partly(Motion("dog", walk.fps, root, walk.rotations, c), c)
    assert rep.free_runs is not None and rep.free_share is not None
    loose, runs = rep.free_runs
    assert rep.free_share > 0.5 and 0 < runs - loose
    toes = moved.foot_positions()
    still = sum(
        np.ptp(toes[a:b, k, :2], axis=0).max() <= 0.01 * leg
        for k, segs in enumerate(stance_runs(c))
        for a, b in segs
    )
    assert still >= runs - loose
    # six times as fast: no run can be held
    root[1:, :2] = root[0, :2] + np.cumsum(2.0 * step, axis=0)
    assert plant_partly(Motion("dog", walk.fps, root, walk.rotations, c), c) is None


def test_out_of_reach_stance_runs_are_trimmed_to_their_reachable_middle(walk) -> None:
    # the dog walk with its body three times as fast: long stance runs sweep beyond the
    # legs; trimmed at both ends they are held, and fewer stance frames slide
    from habitsim.motion import Motion

    c = walk.contacts
    step = np.diff(walk.root_positions[:, :2], axis=0) * 3.0
    root = walk.root_positions.copy()
    root[1:, :2] = root[0, :2] + np.cumsum(step, axis=0)
    fast = Motion("dog", walk.fps, root, walk.rotations, c)
    labels, rep = trim_to_reach(fast, c)
    labels = labels.array
    assert rep is not None and rep.runs >= 3
    assert not (labels & ~c).any()  # only stance frames are taken off
    assert rep.frames == int((c & ~labels).sum()) > 0
    t = len(c)
    shortest = max(2, round(POLICY.trim_min_run_s * walk.fps))
    for k, segs in enumerate(stance_runs(c)):
        for a, b in segs:
            kept = np.flatnonzero(labels[a:b, k])
            if kept.size == b - a:
                continue
            assert kept.size >= shortest and np.all(np.diff(kept) == 1)  # one run left
            head, tail = kept[0], (b - a) - 1 - kept[-1]
            if 0 < a and b < t:
                assert abs(int(head) - int(tail)) <= 1  # centred: the footfall phase stays
    # only the runs asked for
    first = np.zeros_like(c)
    first[: len(c) // 4] = True
    part, _ = trim_to_reach(fast, c, only=first)
    part = part.array
    assert np.array_equal(part[len(c) // 2 :], c[len(c) // 2 :]) and (part != c).any()
    # the partial planting holds more of the stance on the trimmed labels, and with
    # ``trim`` it trims the runs it would leave free and steps on the new labels
    _, loose = plant_partly(fast, c)
    _, tight = plant_partly(fast, labels)
    assert loose.free_frames is not None and tight.free_frames is not None
    assert loose.free_share is not None and tight.free_share is not None
    assert labels.sum() - tight.free_frames > c.sum() - loose.free_frames
    assert tight.free_share < loose.free_share
    moved, rep = plant_partly(fast, c, trim=True)
    assert rep.trimmed is not None and rep.free_share is not None
    assert rep.trimmed.frames > 0 and rep.free_share < loose.free_share
    assert not (moved.contacts & ~c).any() and (moved.contacts != c).any()
    leg = walk.species_info.leg_length
    toes = moved.foot_positions()
    held_runs = [
        (k, a, b)
        for k, segs in enumerate(stance_runs(moved.contacts))
        for a, b in segs
        if np.ptp(toes[a:b, k, :2], axis=0).max() <= 0.01 * leg
    ]
    assert loose.free_runs is not None
    assert len(held_runs) > loose.free_runs[1] - loose.free_runs[0]


def test_decoded_speed_is_bounded_by_the_source_speed_at_equal_froude(walk) -> None:
    from habitsim.motion import Motion

    cat = generate("cat", like=walk)
    assert cat.num_frames == walk.num_frames
    # a cat walking where the source dog walks at the same Froude number: unchanged
    same, info = bound_speed(cat, walk)
    assert info is None and same is cat
    # ... where the dog stands still: the cat's body does not travel either
    t = walk.num_frames
    still = Motion(
        "dog",
        walk.fps,
        np.repeat(walk.root_positions[:1], t, axis=0),
        np.repeat(walk.rotations[:1], t, axis=0),
    )
    stood, info = bound_speed(cat, still)
    assert info is not None and info["frames"] >= t - 2
    travel = np.linalg.norm(np.diff(stood.root_positions[:, :2], axis=0), axis=1).sum()
    assert travel <= 1e-6
    np.testing.assert_allclose(stood.rotations, cat.rotations, atol=1e-12)
    np.testing.assert_allclose(stood.root_positions[:, 2], cat.root_positions[:, 2], atol=1e-12)
    # ... and where the dog runs three times as fast: the cat speeds up to a third of it
    # (the band's lower edge) along its own path
    root = walk.root_positions.copy()
    root[:, :2] = root[0, :2] + 3.0 * 1.5 * (root[:, :2] - root[0, :2])
    quick = Motion("dog", walk.fps, root, walk.rotations)
    sped, info = bound_speed(cat, quick)
    assert info is not None
    v0 = np.linalg.norm(np.diff(cat.root_positions[:, :2], axis=0), axis=1).sum()
    v1 = np.linalg.norm(np.diff(sped.root_positions[:, :2], axis=0), axis=1).sum()
    assert v1 / v0 == pytest.approx(3.0 * 1.5 / POLICY.speed_band, rel=0.1)


def test_decoded_height_excursions_are_bounded_by_the_source(walk) -> None:
    from habitsim.motion import Motion

    cat = generate("cat", like=walk)
    leg = cat.species_info.leg_length
    # the same gait's bob: unchanged
    same, info = bound_height(cat, walk)
    assert info is None and same is cat
    # a body that sinks by a fifth of its leg over the clip while the dog walks level:
    # the sinking is cut to the band around the dog's own bob
    t = cat.num_frames
    root = cat.root_positions.copy()
    root[:, 2] -= np.linspace(0.0, 0.2 * leg, t)
    sinking = Motion("cat", cat.fps, root, cat.rotations)
    level, info = bound_height(sinking, walk)
    assert info is not None and info["range_per_leg"][0] > 0.15
    dev = walk.root_positions[:, 2] - np.median(walk.root_positions[:, 2])
    src = np.abs(dev).max() / walk.species_info.leg_length
    allowed = max(POLICY.height_band * src, POLICY.height_floor_per_leg)
    z = level.root_positions[:, 2]
    assert np.abs(z - np.median(root[:, 2])).max() <= 1.2 * allowed * leg  # smoothed envelope
    np.testing.assert_allclose(level.root_positions[:, :2], root[:, :2])
    # a source that jumps keeps the target's jump
    jump = generate("dog", "jump", seed=0)
    leap = generate("cat", like=jump)
    _, info = bound_height(leap, jump)
    assert info is None or info["range_per_leg"][1] >= 0.95 * info["range_per_leg"][0]


def test_a_wagging_decoded_heading_is_slowed_to_the_bound(walk) -> None:
    from habitsim.models.features import heading_yaw
    from habitsim.motion import Motion
    from habitsim.rotations import quat_from_axis_angle, quat_mul

    cat = generate("cat", like=walk)
    t = cat.num_frames
    axis = np.broadcast_to(np.array([0.0, 0.0, 1.0]), (t, 3))

    def turned(angle: np.ndarray) -> Motion:
        rot = cat.rotations.copy()
        rot[:, 0] = quat_mul(quat_from_axis_angle(axis, angle), rot[:, 0])
        return Motion("cat", cat.fps, cat.root_positions, rot, cat.contacts)

    def rate(m: Motion) -> np.ndarray:
        dev = np.unwrap(heading_yaw(m.rotations[:, 0])) - np.unwrap(
            heading_yaw(cat.rotations[:, 0])
        )
        return np.abs(np.gradient(dev)) * m.fps

    # the same heading, or a slow drift of 20° over the clip: left as decoded
    same, info = bound_heading(cat, walk)
    assert info is None and same is cat
    drift = turned(np.linspace(0.0, np.radians(20.0), t))
    assert bound_heading(drift, walk)[1] is None
    # the body wagged by ±60° at 4 Hz about the pelvis (a decoder off its data):
    # the wag is low-passed away, the root path and every other joint kept
    sec = np.arange(t) / cat.fps
    wag = turned(np.radians(60.0) * np.sin(2.0 * np.pi * 4.0 * sec))
    assert rate(wag).max() > 5.0 * POLICY.heading_max_rate
    calm, info = bound_heading(wag, walk)
    assert info is not None and info["max_rate"][0] > 5.0 * POLICY.heading_max_rate
    inner = rate(calm)[t // 4 : -t // 4]  # away from the ends the filter pads
    assert inner.max() < POLICY.heading_max_rate
    np.testing.assert_array_equal(calm.root_positions, wag.root_positions)
    np.testing.assert_allclose(calm.rotations[:, 1:], wag.rotations[:, 1:], atol=1e-12)
    # a steady turn away to 90° over the clip (a target turning at its own rate): kept
    away = turned(np.linspace(0.0, np.radians(90.0), t))
    assert bound_heading(away, walk)[1] is None
    # a swing out to 80° and back within a second, under the rate bound: cut to the band
    # about the departure's slow trend
    swing = np.radians(80.0) * np.exp(-0.5 * ((sec - sec.mean()) / 0.3) ** 2)
    assert rate(turned(swing)).max() < POLICY.heading_max_rate
    held, info = bound_heading(turned(swing), walk)
    assert info is not None and info["max_departure_deg"][0] > 79.0
    dev = np.unwrap(heading_yaw(held.rotations[:, 0])) - np.unwrap(heading_yaw(cat.rotations[:, 0]))
    # the 1 s trend of a 0.3 s swing rises by about a quarter of it: 45° + ~24°
    assert np.radians(60.0) < np.abs(dev).max() < np.radians(72.0)


def test_a_sloping_decoded_trunk_is_levelled_about_the_pelvis(walk) -> None:
    from habitsim.models.features import heading_yaw
    from habitsim.motion import Motion
    from habitsim.rotations import quat_from_axis_angle, quat_mul

    gir = generate("giraffe", like=walk)
    c = gir.contacts
    # its own walk stands level: left as it is
    same, info = level_trunk(gir, c)
    assert info is None and same is gir
    # the trunk tipped nose-down by 8° about the pelvis: the fore toes go under the ground
    # by 6 % of a leg more than the hind ones; pitched back to within the tolerance (a
    # second pass finds nothing to do), legs and root path untouched
    yaw = heading_yaw(gir.rotations[:, 0])
    left = np.stack([-np.sin(yaw), np.cos(yaw), np.zeros_like(yaw)], axis=-1)
    rot = gir.rotations.copy()
    rot[:, 0] = quat_mul(quat_from_axis_angle(left, np.full(len(yaw), np.radians(8.0))), rot[:, 0])
    sloped = Motion("giraffe", gir.fps, gir.root_positions, rot, c)
    level, info = level_trunk(sloped, c)
    assert info is not None and info["fore_minus_hind_per_leg"] < -0.05
    assert -8.0 < info["pitch_deg"] < -4.0
    assert level_trunk(level, c)[1] is None
    np.testing.assert_allclose(level.rotations[:, 1:], sloped.rotations[:, 1:], atol=1e-12)
    np.testing.assert_array_equal(level.root_positions, sloped.root_positions)
    # tipped the other way: pitched the other way
    rot[:, 0] = quat_mul(
        quat_from_axis_angle(left, np.full(len(yaw), np.radians(-8.0))), gir.rotations[:, 0]
    )
    _, info = level_trunk(Motion("giraffe", gir.fps, gir.root_positions, rot, c), c)
    assert info is not None and 4.0 < info["pitch_deg"] < 8.0
    # no frame with both girdles in stance: nothing to compare
    fore = np.zeros_like(c)
    fore[:, :2] = True
    assert level_trunk(sloped, fore)[1] is None


def test_planting_judgement_keeps_swing_misses_at_the_clip_ends_apart() -> None:
    from habitsim.stance.planting import PlantReport
    from habitsim.stance.report import Planting

    c = np.zeros((6, 4), dtype=bool)
    c[:3] = True
    c[5, 1] = True  # foot RF steps again: its frames 3-4 are an inner swing
    err = np.zeros((6, 4))
    err[1, 2] = 0.02  # a stance toe 2 cm off
    err[5, 0] = 0.30  # LF's swing after its last stance: left behind at the clip's end
    rep = PlantReport(err, np.zeros(6), np.zeros(4), 0.0)
    p = Planting.judged(rep, c, 1.0, "median")
    assert p.max_reach_error_per_leg == pytest.approx(0.02)
    assert p.max_edge_reach_error_per_leg == pytest.approx(0.30)
    assert p.reaches(POLICY)  # an edge swing does not decide whether a planting is kept
    assert _reaches(p.to_dict()) and p.to_dict()["max_edge_reach_error_per_leg"] == 0.3
    inner = err.copy()
    inner[3, 1] = 0.30  # ... an inner swing does
    p = Planting.judged(PlantReport(inner, np.zeros(6), np.zeros(4), 0.0), c, 1.0, "median")
    assert p.max_swing_reach_error_per_leg == pytest.approx(0.30) and not p.reaches(POLICY)
    inner[3, 1] = 0.5 * (POLICY.plant_max_reach_per_leg + POLICY.plant_max_swing_reach_per_leg)
    p = Planting.judged(PlantReport(inner, np.zeros(6), np.zeros(4), 0.0), c, 1.0, "median")
    assert p.reaches(POLICY)  # a swing may miss by more than a stance foot
    assert not p.reaches(replace(POLICY, plant_max_swing_reach_per_leg=0.05))
    # a free stance run is not judged either
    free = np.zeros_like(c)
    free[:3, 2] = True
    assert Planting.judged(rep, c, 1.0, "median", free).max_reach_error_per_leg == 0.0


def test_a_transfer_keeps_the_sources_frame_count_through_the_models_rate(walk) -> None:
    # 120 fps, 478 frames: 3.98 s that the model's 30 fps grid does not divide; the
    # round trip to its rate and back would add or drop a frame at the end, and the
    # source-relative bounds (speed, height, heading) compare frame for frame
    long = generate("dog", "walk", seed=2, duration_s=4.5)
    src = resample_motion(long, 120.0, 478)
    assert src.num_frames == 478
    held = resample_motion(walk, 120.0, 300)  # 2.5 s of a 2 s clip: its last frame held
    np.testing.assert_allclose(held.root_positions[-60:], walk.root_positions[[-1] * 60])
    with pytest.raises(InvalidMotionError, match="num_frames"):
        resample_motion(walk, 120.0, 0)
    for method in ("habit", "direct_relabelled"):
        out = transfer(src, to="cat", method=method, seed=0)
        assert out.num_frames == src.num_frames and out.fps == src.fps
        assert out.contacts is not None and out.contacts.shape == (src.num_frames, 4)
