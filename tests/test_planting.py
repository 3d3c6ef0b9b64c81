"""Planting (habitsim.stance.planting, habitsim.stance.ladder): the source's stance labels,
planting a motion's own feet, the stance-driven root, and the planting ladder's fallbacks on
transferred motions."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

import habitsim
from habitsim.gaits import generate
from habitsim.models import network_transfer, transfer
from habitsim.stance.labels import stance_runs
from habitsim.stance.ladder import plant_partly, trim_to_reach
from habitsim.stance.planting import PlantingOptions, label_source_stance
from habitsim.stance.policy import ConformPolicy
from habitsim.stance.report import PlantReason


def test_label_source_stance_floor_and_hold():
    # One foot: planted at a 3 cm marker height, lifted 10 cm in the middle; another held
    # still in the air for the whole clip never counts as stance.
    fps, leg, t = 60.0, 0.6, 120
    x = np.linspace(0.0, 1.2, t)
    pts = []
    z = np.full(t, 0.03)
    z[40:80] += 0.1 * np.sin(np.linspace(0, np.pi, 40))
    xf = np.where(np.arange(t) < 40, 0.2, np.where(np.arange(t) >= 80, 0.7, x))
    pts.append(np.stack([xf, np.zeros(t), z], -1)[:, None])
    pts.append(np.stack([x * 0 + 0.3, np.zeros(t), np.full(t, 0.2)], -1)[:, None])
    pts.append(np.stack([x * 0, np.zeros(t), np.full(t, 0.03)], -1)[:, None])
    pts.append(np.stack([x * 0, np.zeros(t), np.full(t, 0.03)], -1)[:, None])
    st = label_source_stance(pts, fps, leg)
    assert st.contacts[:35, 0].all() and st.contacts[85:, 0].all()
    assert not st.contacts[45:75, 0].any()
    assert not st.contacts[:, 1].any()  # held in the air: 17 cm above the lowest floor
    assert st.contacts[:, 2].all() and st.contacts[:, 3].all()


def test_label_source_stance_follows_a_floor_that_steps_down():
    # Four feet walking (stride 0.5 s, duty 0.6, 6 cm swings) on a capture floor that is
    # 2 cm lower after 2 s (a mat's edge, a sloping floor): every stance frame on either
    # side is found, also the ones just before the step, where a floor window much
    # longer than a stride would already reach the lower floor.
    fps, leg, t = 60.0, 0.6, 240
    tt = np.arange(t) / fps
    floor = np.where(tt < 2.0, 0.03, 0.01)
    ph = (tt % 0.5) / 0.5
    stance = ph < 0.6
    sw = np.clip((ph - 0.6) / 0.4, 0, 1)
    z = floor + np.where(stance, 0.0, 0.06 * np.sin(np.pi * sw))
    x = np.floor(tt / 0.5) * 0.5 + np.where(stance, 0.0, 0.5 * (3 * sw**2 - 2 * sw**3))
    pts = [np.stack([x + o, np.zeros(t), z], -1)[:, None] for o in (0.0, 0.1, 0.2, 0.3)]
    st = label_source_stance(pts, fps, leg)
    for k in range(4):
        assert st.contacts[stance, k].mean() >= 0.99
        assert not st.contacts[(sw > 0.2) & (sw < 0.8), k].any()  # swings stay swings


def test_label_source_stance_of_a_fast_gait_whose_paws_roll():
    # A run at 4 m/s (stride 0.4 s, duty 0.3): on the ground the paw's lowest point rolls
    # forward at 1 m/s (a quarter of the body's speed, far above the 0.18 m/s rest speed
    # of a 0.6 m leg), in swing it lifts 8 cm and catches up. Each stance is found by the
    # speed relative to the body; by the absolute rest speed alone, none is.
    fps, leg, t, v = 120.0, 0.6, 480, 4.0
    tt = np.arange(t) / fps
    feet = []
    stance_all = []
    for k, phase in enumerate((0.0, 0.1, 0.5, 0.6)):
        ph = (tt / 0.4 + phase) % 1.0
        stance = ph < 0.3
        sw = np.clip((ph - 0.3) / 0.7, 0, 1)
        # forward speed: v/4 in stance, and the rest of the stride's travel in swing
        speed = np.where(stance, v / 4, (v - 0.3 * v / 4) / 0.7 * 2 * np.sin(np.pi * sw) ** 2)
        x = np.cumsum(speed) / fps + 0.3 * k
        z = 0.02 + np.where(stance, 0.0, 0.08 * np.sin(np.pi * sw))
        feet.append(np.stack([x, np.zeros(t), z], -1)[:, None])
        stance_all.append(stance)
    st = label_source_stance(feet, fps, leg)
    for k in range(4):
        assert st.contacts[stance_all[k], k].mean() >= 0.8, k
        mid = ~stance_all[k] & (np.abs(((tt / 0.4 + (0.0, 0.1, 0.5, 0.6)[k]) % 1.0) - 0.65) < 0.2)
        assert not st.contacts[mid, k].any()
    alone = PlantingOptions(stance_speed_per_body=0.0)
    assert label_source_stance(feet, fps, leg, alone).contacts.mean() < 0.05


def test_plant_motion_plants_own_feet_and_lifts_swing():
    from habitsim.motion import Motion
    from habitsim.stance.planting import leg_pose_angles, plant_motion

    m = habitsim.generate("cat", "trot", seed=1, duration_s=2.0)
    leg = m.species_info.leg_length
    # the legs' own angles re-solve the motion exactly
    g, i = leg_pose_angles(m)
    from habitsim.ik import pose_from_targets

    p = pose_from_targets("cat", m.root_positions, m.rotations, m.foot_positions(), g, i)
    np.testing.assert_allclose(p.reach_error, 0.0, atol=1e-9)
    # hovering feet (the whole body 3 % of a leg too high) and a swing floor of 3 %
    up = m.root_positions.copy()
    up[:, 2] += 0.03 * leg
    hover = Motion("cat", m.fps, up, m.rotations, m.contacts)
    floor = np.where(m.contacts, np.nan, 0.03 * leg)
    out, rep = plant_motion(hover, m.contacts, floor)
    toes = out.foot_positions()[..., 2]
    assert np.all(np.abs(toes[m.contacts]) <= 0.002 * leg)
    assert toes.min() >= -1e-9
    # swing toes reach the floor wherever the leg can reach its target at all
    reach = rep.reach_error[~m.contacts] < 1e-6
    assert reach.mean() > 0.8
    assert np.all(toes[~m.contacts][reach] >= 0.03 * leg - 1e-6)
    feet = out.foot_positions()[..., :2]
    both = m.contacts[1:] & m.contacts[:-1]
    assert np.linalg.norm(np.diff(feet, axis=0), axis=-1)[both].max() <= 0.002 * leg


def test_stance_driven_root_measures_how_far_the_legs_carry_the_body():
    from habitsim.motion import Motion
    from habitsim.stance.planting import stance_driven_root

    m = habitsim.generate("dog", "walk", seed=2, duration_s=2.0)  # no flight phase
    assert m.contacts.any(axis=1).all()
    # feet that rest: the legs carry the whole travel, the path is unchanged
    same, ratio = stance_driven_root(m, m.contacts)
    assert ratio == pytest.approx(1.0, abs=0.03)
    np.testing.assert_allclose(same.root_positions, m.root_positions, atol=0.03 * 0.5)
    # the same legs with the body sliding twice as far: the stance legs carry half of it,
    # and held still they put the body back on the legs' own path
    fast = m.root_positions.copy()
    fast[:, :2] = fast[0, :2] + 2.0 * (fast[:, :2] - fast[0, :2])
    slide = Motion("dog", m.fps, fast, m.rotations, m.contacts)
    back, ratio = stance_driven_root(slide, m.contacts)
    assert ratio == pytest.approx(0.5, abs=0.03)
    np.testing.assert_array_equal(back.root_positions[:, 2], fast[:, 2])
    # the global joint positions at hand give the same path, and must match the motion
    held, ratio_g = stance_driven_root(slide, m.contacts, slide.global_positions())
    np.testing.assert_array_equal(held.root_positions, back.root_positions)
    assert ratio_g == ratio
    with pytest.raises(habitsim.errors.InvalidMotionError, match="contacts must have shape"):
        stance_driven_root(m, m.contacts[:-1])
    with pytest.raises(habitsim.errors.InvalidMotionError, match="glob must have shape"):
        stance_driven_root(m, m.contacts, m.global_positions()[:-1])


def test_centred_footholds_hold_the_sweep_under_the_joint_and_reach_further():
    from habitsim.motion import Motion
    from habitsim.skeleton import JOINT_NAMES
    from habitsim.stance.planting import FOOT_ANCHORS, plant_motion, stance_reach_shortfall

    m = habitsim.generate("dog", "walk", seed=2, duration_s=2.0)
    leg = m.species_info.leg_length
    c = m.contacts

    def sliding(k):  # the same legs, the body travelling k times as far: feet slide
        fast = m.root_positions.copy()
        fast[:, :2] = fast[0, :2] + k * (fast[:, :2] - fast[0, :2])
        return Motion("dog", m.fps, fast, m.rotations, c)

    slide = sliding(1.3)
    out, rep = plant_motion(slide, c, centre=True)
    toes = out.foot_positions()
    anchors = slide.global_positions()[:, [JOINT_NAMES.index(n) for n in FOOT_ANCHORS]]
    checked = 0
    for k, runs in enumerate(stance_runs(c)):
        for a, b in runs:
            travel = anchors[b - 1, k, :2] - anchors[a, k, :2]
            if np.linalg.norm(travel) < 0.2 * leg or a == 0 or b == len(c):
                continue  # short or cut runs blend towards the toe path's median
            u = travel / np.linalg.norm(travel)
            hold = toes[a:b, k, :2].mean(axis=0)
            mid = 0.5 * (anchors[a, k, :2] + anchors[b - 1, k, :2])
            assert abs((hold - mid) @ u) <= 0.01 * leg  # centred along the travel
            assert np.ptp(toes[a:b, k, :2], axis=0).max() <= 0.01 * leg  # and held
            checked += 1
    assert checked >= 6
    for k in (1.3, 1.6, 2.0):
        s = sliding(k)
        med = plant_motion(s, c)[1].reach_error[c].max()
        cen = plant_motion(s, c, centre=True)[1].reach_error[c].max()
        assert cen <= med + 1e-9, k
    # the reach test without IK: nothing out of reach for the clip's own stance, and a
    # shortfall beyond the limit whenever the IK cannot hold the footholds either
    assert stance_reach_shortfall(m, c) == 0.0
    for k in (1.6, 3.0):
        s = sliding(k)
        short = stance_reach_shortfall(s, c, max_drop=0.1 * leg)
        _, rep = plant_motion(s, c)
        assert short > 0.05 * leg
        assert rep.reach_error.max() > 0.05 * leg or rep.pelvis_drop.max() > 0.1 * leg
    with pytest.raises(habitsim.errors.InvalidMotionError, match="contacts must have shape"):
        stance_reach_shortfall(m, c[:-1])


def test_free_stance_runs_keep_their_own_toe_path_and_the_reach_test_skips_them():
    from habitsim.motion import Motion
    from habitsim.stance.planting import plant_motion, stance_run_shortfall

    m = habitsim.generate("dog", "walk", seed=2, duration_s=2.0)
    leg = m.species_info.leg_length
    c = m.contacts
    fast = m.root_positions.copy()
    fast[:, :2] = fast[0, :2] + 1.3 * (fast[:, :2] - fast[0, :2])  # feet slide in stance
    slide = Motion("dog", m.fps, fast, m.rotations, c)
    runs = stance_runs(c)[0]
    a, b = next((a, b) for a, b in runs if a > 0 and b < len(c))  # an inner LF run
    free = np.zeros_like(c)
    free[a + 1, 0] = True  # one frame marks the whole run
    out, _ = plant_motion(slide, c, centre=True, free=free)
    held, _ = plant_motion(slide, c, centre=True)
    toes, raw = out.foot_positions(), slide.foot_positions()
    # the free run follows the sliding toe path; held, it stays put
    np.testing.assert_allclose(toes[a:b, 0, :2], raw[a:b, 0, :2], atol=0.01 * leg)
    assert np.ptp(raw[a:b, 0, :2], axis=0).max() > 0.05 * leg
    assert np.ptp(held.foot_positions()[a:b, 0, :2], axis=0).max() <= 0.01 * leg
    # the other runs are held as before
    other = c.copy()
    other[a:b, 0] = False
    np.testing.assert_allclose(toes[other], held.foot_positions()[other], atol=0.01 * leg)
    # the per-frame reach test: zero off stance and on free runs
    k = 3.0
    far = m.root_positions.copy()
    far[:, :2] = far[0, :2] + k * (far[:, :2] - far[0, :2])
    s = Motion("dog", m.fps, far, m.rotations, c)
    short = stance_run_shortfall(s, c, centre=True)
    assert short.shape == c.shape and (short[~c] == 0).all() and short.max() > 0.05 * leg
    mask = np.zeros_like(c)
    mask[:, 0] = c[:, 0]
    assert (stance_run_shortfall(s, c, True, 0.0, mask)[:, 0] == 0).all()
    with pytest.raises(habitsim.errors.InvalidMotionError, match="free must have shape"):
        plant_motion(slide, c, free=free[:-1])
    # joint positions handed in give the same planting; a wrong shape is refused
    glob = slide.global_positions()
    again, rep = plant_motion(slide, c, centre=True, free=free, glob=glob)
    np.testing.assert_array_equal(again.rotations, out.rotations)
    np.testing.assert_array_equal(again.root_positions, out.root_positions)
    # the report's stance heights and lowest toe are the planted motion's own
    z = out.foot_positions()[..., 2]
    med = [np.median(z[c[:, k], k]) for k in range(4)]
    np.testing.assert_allclose(rep.stance_toe_height, med, atol=1e-12)
    assert rep.min_toe_height == pytest.approx(z.min(), abs=1e-12)
    with pytest.raises(habitsim.errors.InvalidMotionError, match="glob must have shape"):
        plant_motion(slide, c, glob=glob[:, :-1])


def test_pelvis_lowering_is_a_slow_carriage_not_a_dip_per_stance():
    from habitsim.motion import Motion
    from habitsim.stance.planting import plant_motion

    m = habitsim.generate("dog", "walk", seed=2, duration_s=3.0)
    leg = m.species_info.leg_length
    fast = m.root_positions.copy()
    fast[:, :2] = fast[0, :2] + 1.6 * (fast[:, :2] - fast[0, :2])  # strides out of reach
    s = Motion("dog", m.fps, fast, m.rotations, m.contacts)
    _, rep = plant_motion(s, m.contacts)
    drop = rep.pelvis_drop
    assert drop.max() > 0.02 * leg  # the pelvis does come down
    # no dip per stance: over one stride (about 0.6 s) the lowering changes by a small
    # share of its depth, and its frame-to-frame rate stays that of a slow sink
    rate = np.abs(np.diff(drop)) * m.fps
    assert rate.max() <= drop.max() / PlantingOptions().drop_smooth_s
    mid = drop[len(drop) // 4 : -len(drop) // 4]
    assert np.ptp(mid) <= 0.5 * drop.max()
    # the smoothing is the options': a short one dips, and dips faster
    short = PlantingOptions(drop_smooth_s=0.05)
    _, dip = plant_motion(s, m.contacts, options=short)
    assert np.abs(np.diff(dip.pelvis_drop)).max() > np.abs(np.diff(drop)).max()


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


@pytest.mark.usefixtures("torch_one_thread")
def test_planting_out_of_reach_keeps_the_decoded_feet_and_says_why(trot) -> None:
    # the horse's trot at the cat's Froude speed and the horse's cadence: strides of
    # more leg lengths than the cat's legs sweep; without restepping and partial planting
    # nothing holds the feet
    out, conformed = network_transfer("habit", trot, "cat", seed=0, policy=NO_FALLBACKS)
    raw = transfer(trot, to="cat", method="habit", seed=0, plant=False)
    report = out.metadata["transfer"]["planted"]
    planted = conformed.planted
    assert planted is not None and planted.to_dict() == report
    assert not report["kept"] and planted.reason_codes[0] is PlantReason.OUT_OF_REACH
    assert planted.reason_codes[-1] is PlantReason.DECODED_FEET_KEPT
    assert report["max_reach_error_per_leg"] > POLICY.plant_max_reach_per_leg
    np.testing.assert_array_equal(out.rotations, raw.rotations)


@pytest.mark.usefixtures("torch_one_thread")
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


@pytest.mark.usefixtures("torch_one_thread")
def test_planting_steps_faster_when_the_body_outruns_the_decoded_stride(walk) -> None:
    # a dog walk sent to the cat: the decoder keeps the dog's cadence and gives the cat its
    # own speed, so one stance would have to hold while the body travels further than a
    # cat's leg sweeps; the labels are played faster instead
    from habitsim.contacts import stride_period
    from habitsim.gait_stats import gait_statistics

    out, conformed = network_transfer("habit", walk, "cat", seed=0)
    raw = transfer(walk, to="cat", method="habit", seed=0, plant=False)
    report = out.metadata["transfer"]["planted"]
    assert report["kept"] and report["root"] == "decoded" and _reaches(report), report
    step = report["restep"]
    assert conformed.planted is not None
    assert step["rate"] > 1.2 and conformed.planted.reason_codes[-1] is PlantReason.RESTEPPED
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


@pytest.mark.usefixtures("torch_one_thread")
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
    out, conformed = network_transfer("habit", walk, "giraffe", seed=0)
    report = out.metadata["transfer"]["planted"]
    assert report["kept"] and "free_runs" in report and conformed.planted is not None
    codes = conformed.planted.reason_codes
    assert PlantReason.PARTLY_ON_RESTEP in codes and codes[-1] is PlantReason.PARTLY
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


@pytest.mark.usefixtures("torch_one_thread")
def test_planting_out_of_reach_moves_the_body_as_far_as_its_legs_carry_it(trot):
    # the horse's trot sent to the tiger: the decoded stance feet slide, so a foothold
    # held for a whole stance run is out of reach with the decoded root path
    # (with the median footholds alone: the centred ones reach with the decoded root)
    carry = ConformPolicy(foothold_rules=(False,), plant_min_speed_ratio=0.2)
    out, conformed = network_transfer("habit", trot, "tiger", seed=0, policy=carry)
    raw = transfer(trot, to="tiger", method="habit", seed=0, plant=False)
    report = out.metadata["transfer"]["planted"]
    assert report["kept"] and report["root"] == "carried", report
    assert conformed.planted is not None
    assert conformed.planted.reason_codes == (PlantReason.OUT_OF_REACH, PlantReason.CARRIED)
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
    slow, conformed = network_transfer("habit", trot, "tiger", seed=0, policy=stiff)
    report = slow.metadata["transfer"]["planted"]
    assert conformed.planted is not None
    assert not report["kept"] and PlantReason.CARRY_TOO_SLOW in conformed.planted.reason_codes
    np.testing.assert_array_equal(slow.root_positions, raw.root_positions)


@pytest.mark.usefixtures("torch_one_thread")
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


@pytest.mark.usefixtures("torch_one_thread")
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


@pytest.mark.usefixtures("torch_one_thread")
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


def _resting(m, labels) -> float:
    v = np.linalg.norm(np.diff(m.foot_positions(), axis=0), axis=-1) * m.fps
    on = labels[1:] & labels[:-1]
    return float((v[on] <= 0.1 * m.species_info.leg_length).mean())


def test_planting_options_are_checked_and_shared():
    from habitsim.refine import RefineOptions
    from habitsim.stance.planting import PlantingOptionsError

    for bad in ({"smooth_s": 0.0}, {"drop_smooth_s": math.nan}, {"floor_rise_per_leg": -0.1}):
        with pytest.raises(PlantingOptionsError):
            PlantingOptions(**bad)
    with pytest.raises(PlantingOptionsError):
        PlantingOptions(min_rest_frames=0)
    # one default object, the same for the importer, the ladder and refinement
    assert ConformPolicy().planting == RefineOptions().planting == PlantingOptions()
