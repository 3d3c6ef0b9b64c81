"""Contacts, hinge angles, kinematic plausibility metrics and ``habitsim motion stats``."""

from __future__ import annotations

import json
import math
import time

import numpy as np
import pytest

from habitsim import get_skeleton, load_species
from habitsim.cli import main
from habitsim.contacts import (
    CONTACT_HEIGHT_PER_LEG,
    ContactOptions,
    bearing_contacts,
    contacts_by_duty,
    contacts_from_feet,
    detect_contacts,
    ground_reach,
    touchdown_frames,
)
from habitsim.errors import InvalidMotionError
from habitsim.hinges import (
    HINGE_NAMES,
    compose_hinges,
    hinge_angles,
    hinge_limits,
    hinge_residual_rad,
)
from habitsim.metrics.kinematic import (
    KINEMATIC_KEYS,
    bone_length_error_mm,
    kinematic_metrics,
)
from habitsim.motion import Motion
from habitsim.rotations import quat_mul, rot_x, rot_y
from habitsim.stance.labels import stance_runs

FPS = 30.0
LEG = load_species("dog").leg_length  # 0.61 m


def standing(t: int = 60, fps: float = FPS) -> Motion:
    r, q = get_skeleton("dog").standing_pose()
    return Motion("dog", fps, np.repeat(r[None], t, 0), np.repeat(q[None], t, 0))


def shifted(m: Motion, root: np.ndarray) -> Motion:
    return Motion(m.species, m.fps, root, m.rotations)


# ----------------------------------------------------------------------------- contacts


def test_standing_pose_is_in_contact_everywhere() -> None:
    m = standing()
    c = detect_contacts(m)
    assert c.shape == (60, 4) and c.dtype == bool
    assert c.all()
    assert np.array_equal(m.detect_contacts(), c)


def test_raised_body_has_no_contact() -> None:
    m = standing()
    up = shifted(m, m.root_positions + [0.0, 0.0, 0.10])
    assert not detect_contacts(up).any()
    # Just above the 2 % threshold (12.2 mm for the dog): still no contact.
    up2 = shifted(m, m.root_positions + [0.0, 0.0, 1.1 * CONTACT_HEIGHT_PER_LEG * LEG])
    assert not detect_contacts(up2).any()
    # Just below: contact.
    down = shifted(m, m.root_positions + [0.0, 0.0, 0.9 * CONTACT_HEIGHT_PER_LEG * LEG])
    assert detect_contacts(down).all()


def test_fast_sliding_foot_is_not_in_contact() -> None:
    # 1 cm/frame at 30 fps = 0.3 m/s > 0.3 L/s = 0.183 m/s.
    m = standing()
    root = m.root_positions.copy()
    root[:, 0] += 0.01 * np.arange(60)
    assert not detect_contacts(shifted(m, root)).any()
    # 5 mm/frame = 0.15 m/s < 0.183 m/s: in contact.
    root = m.root_positions.copy()
    root[:, 0] += 0.005 * np.arange(60)
    assert detect_contacts(shifted(m, root)).all()


def test_ground_reach_bounds_every_detected_contact() -> None:
    """A labelled foot bears weight up to the highest height detection keeps in contact."""
    reach = ground_reach(LEG)
    assert reach == pytest.approx(CONTACT_HEIGHT_PER_LEG * ContactOptions().hysteresis * LEG)
    m = standing()
    for dz, held in ((0.99 * reach, True), (1.01 * reach, False), (-0.05, True)):
        up = shifted(m, m.root_positions + [0.0, 0.0, dz])
        heights = up.foot_positions()[..., 2]
        assert bearing_contacts(np.ones((60, 4), bool), heights, LEG).all() == held
    assert not bearing_contacts(np.zeros((60, 4), bool), heights, LEG).any()
    with pytest.raises(InvalidMotionError):
        bearing_contacts(np.ones((60, 4), bool), heights[:, :3], LEG)


def _one_foot(z: np.ndarray, x: np.ndarray | None = None) -> np.ndarray:
    feet = np.zeros((len(z), 1, 3))
    feet[:, 0, 2] = z
    if x is not None:
        feet[:, 0, 0] = x
    return feet


def test_touchdown_and_liftoff_frames_are_exact() -> None:
    # Swing (moving forward 5 cm/frame, lifted) until frame 9, planted 10..19, swing after.
    t = np.arange(30)
    z = np.where((t >= 10) & (t < 20), 0.0, 0.05)
    x = np.where(t < 10, 0.05 * t, np.where(t < 20, 0.5, 0.5 + 0.05 * (t - 19)))
    c = contacts_from_feet(_one_foot(z, x), FPS, LEG)[:, 0]
    assert np.array_equal(np.flatnonzero(c), np.arange(10, 20))


def test_single_frame_flickers_are_removed() -> None:
    h = CONTACT_HEIGHT_PER_LEG * LEG
    z = np.full(20, 0.2 * h)
    z[7] = 3.0 * h  # one-frame spike inside a stance phase
    c = contacts_from_feet(_one_foot(z), FPS, LEG)[:, 0]
    assert c.all()
    z = np.full(20, 5.0 * h)
    z[7] = 0.0  # one-frame dip during a swing
    c = contacts_from_feet(_one_foot(z), FPS, LEG)[:, 0]
    assert not c.any()


def test_hysteresis_keeps_but_does_not_start_contact() -> None:
    h = CONTACT_HEIGHT_PER_LEG * LEG
    hover = np.full(20, 1.2 * h)  # within 1.5·h but never below h
    assert not contacts_from_feet(_one_foot(hover), FPS, LEG).any()
    z = np.concatenate([np.full(10, 0.5 * h), np.full(10, 1.2 * h), np.full(10, 3 * h)])
    c = contacts_from_feet(_one_foot(z), FPS, LEG)[:, 0]
    assert np.array_equal(np.flatnonzero(c), np.arange(20))
    # the hysteresis is an option: without it the hovering half is swing
    c = contacts_from_feet(_one_foot(z), FPS, LEG, ContactOptions(hysteresis=1.0))[:, 0]
    assert np.array_equal(np.flatnonzero(c), np.arange(10))


def test_stance_runs_and_touchdowns() -> None:
    c = np.array(
        [[1, 0], [1, 0], [0, 1], [0, 1], [1, 0], [1, 1]],
        dtype=bool,
    )
    segs = stance_runs(c)
    assert segs == [[(0, 2), (4, 6)], [(2, 4), (5, 6)]]
    td = touchdown_frames(c)
    assert td[0].tolist() == [4] and td[1].tolist() == [2, 5]
    assert stance_runs(np.zeros((5, 4), bool)) == [[], [], [], []]


# ----------------------------------------------------------------------------- hinges


def test_hinge_round_trip_any_angles() -> None:
    rng = np.random.default_rng(0)
    t = 7
    angles = {h: rng.uniform(-3.0, 3.0, t) for h in HINGE_NAMES}
    q = compose_hinges(angles)
    back = hinge_angles(q)
    assert list(back) == list(HINGE_NAMES)
    for h in HINGE_NAMES:
        np.testing.assert_allclose(back[h], angles[h], atol=1e-9, err_msg=h)
    assert hinge_residual_rad(q).max() < 1e-6


def test_hinge_convention_matches_skeleton_docstring() -> None:
    # Shoulder: R = R_x(ABDUCTION_SIGN·abd) · R_y(flex), built here independently.
    flex, abd = 0.4, 0.3
    q = compose_hinges({"lf_shoulder_flex": flex, "lf_shoulder_abd": abd, "rh_hip_abd": abd})
    j = get_skeleton("dog").index
    expected = quat_mul(rot_x(abd), rot_y(flex))  # left: outward = +x rotation
    np.testing.assert_allclose(q[0, j("lf_shoulder")], expected, atol=1e-12)
    np.testing.assert_allclose(q[0, j("rh_hip")], rot_x(-abd), atol=1e-12)


def test_positive_abduction_moves_either_foot_outward() -> None:
    skel = get_skeleton("dog")
    r, q = skel.standing_pose()
    base = skel.fk(r, q)
    ang = hinge_angles(q[None])
    for leg, toe, outward in (("lh", "lh_toe", +1.0), ("rh", "rh_toe", -1.0)):
        a = {k: v for k, v in ang.items()}
        a[f"{leg}_hip_abd"] = np.array([0.2])
        pos = skel.fk(r, compose_hinges(a, base=q[None])[0])
        dy = pos[skel.index(toe), 1] - base[skel.index(toe), 1]
        assert outward * dy > 0.01, leg


def test_rx_swings_a_downward_bone_to_the_left() -> None:
    # The geometric fact the abduction sign rests on (independent of ABDUCTION_SIGN).
    from habitsim.rotations import quat_apply

    v = quat_apply(rot_x(0.3), np.array([0.0, 0.0, -1.0]))
    np.testing.assert_allclose(v, [0.0, math.sin(0.3), -math.cos(0.3)], atol=1e-12)


def test_hinge_residual_detects_off_convention_rotation() -> None:
    q = compose_hinges({"lh_knee_flex": 0.5})
    j = get_skeleton("dog").index("lh_knee")
    q[0, j] = quat_mul(rot_x(0.1), q[0, j])  # a knee cannot abduct
    res = hinge_residual_rad(q)
    assert res.max() > 0.05


def test_hinge_limits_map_roles() -> None:
    lim = hinge_limits("dog")
    sp = load_species("dog")
    assert lim["lh_knee_flex"] == sp.joint_limits["hind_lower_flex"]
    assert lim["rf_shoulder_abd"] == sp.joint_limits["fore_upper_abd"]
    assert lim["spine2_yaw"] == sp.joint_limits["spine_yaw"]
    assert lim["tail2_pitch"] == sp.joint_limits["tail_pitch"]
    assert lim["neck_yaw"] == sp.joint_limits["neck_yaw"]
    assert len(lim) == 34


# ----------------------------------------------------------------------------- metrics


def test_standing_pose_is_perfectly_plausible() -> None:
    km = kinematic_metrics(standing())
    assert set(km) == set(KINEMATIC_KEYS)
    for k in (
        "penetration_mm",
        "float_mm",
        "skate_mm",
        "skate_ratio",
        "jerk",
        "bone_length_error_mm",
        "joint_limit_violation_rad",
    ):
        assert abs(km[k]) < 1e-6, k


def test_float() -> None:
    m = standing()
    km = kinematic_metrics(shifted(m, m.root_positions + [0, 0, 0.10]))
    assert km["float_mm"] == pytest.approx(100.0, abs=1e-6)
    assert km["float_per_leg"] == pytest.approx(0.1 / LEG, rel=1e-9)
    assert km["penetration_mm"] == 0.0
    # 5 mm is below the 1 % tolerance (6.1 mm): no float.
    assert kinematic_metrics(shifted(m, m.root_positions + [0, 0, 0.005]))["float_mm"] == 0.0
    # Half the frames 10 cm up: mean over frames = 50 mm.
    root = m.root_positions.copy()
    root[::2, 2] += 0.10
    assert kinematic_metrics(shifted(m, root))["float_mm"] == pytest.approx(50.0, abs=1e-6)


def test_penetration() -> None:
    m = standing()
    km = kinematic_metrics(shifted(m, m.root_positions - [0, 0, 0.005]))
    assert km["penetration_mm"] == pytest.approx(5.0, abs=1e-6)
    assert km["penetration_per_leg"] == pytest.approx(0.005 / LEG, rel=1e-6)
    assert km["float_mm"] == 0.0 and km["skate_mm"] == pytest.approx(0.0, abs=1e-9)


def test_skate_fast_slide() -> None:
    m = standing()
    root = m.root_positions.copy()
    root[:, 0] += 0.01 * np.arange(m.num_frames)  # 1 cm per frame, 0.3 m/s
    km = kinematic_metrics(shifted(m, root))
    assert km["skate_mm"] == pytest.approx(10.0, abs=1e-6)
    assert km["skate_per_leg"] == pytest.approx(0.01 / LEG, rel=1e-6)
    assert km["skate_ratio"] == pytest.approx(1.0)
    # With contact labels saying "no contact", nothing skates.
    km2 = kinematic_metrics(shifted(m, root), contacts=np.zeros((m.num_frames, 4), bool))
    assert km2["skate_mm"] == 0.0 and km2["skate_ratio"] == 0.0


def test_skate_slow_slide_is_below_ratio_threshold() -> None:
    m = standing()
    root = m.root_positions.copy()
    root[:, 0] += 0.001 * np.arange(m.num_frames)  # 0.03 m/s < 10 % of L/s = 0.061 m/s
    km = kinematic_metrics(shifted(m, root))
    assert km["skate_mm"] == pytest.approx(1.0, abs=1e-6)
    assert km["skate_ratio"] == 0.0


def test_skate_only_counts_contacting_feet_and_pairs() -> None:
    m = standing()
    root = m.root_positions.copy()
    root[:, 0] += 0.01 * np.arange(m.num_frames)
    c = np.zeros((m.num_frames, 4), bool)
    c[:30, 0] = True  # LF in contact for frames 0..29: 29 pairs of 1 cm each
    km = kinematic_metrics(shifted(m, root), contacts=c)
    assert km["skate_mm"] == pytest.approx(10.0, abs=1e-6)
    assert km["skate_ratio"] == pytest.approx(29 / 59)


def test_jerk_of_cubic_root_path() -> None:
    a = 0.7
    m = standing(45)
    t = np.arange(45) / FPS
    root = m.root_positions.copy()
    root[:, 0] += a * t**3
    km = kinematic_metrics(shifted(m, root))
    assert km["jerk"] == pytest.approx(6 * a, rel=1e-5)
    # Diagonal cubic: norm of (6a, 6a, 0).
    root = m.root_positions.copy()
    root[:, 0] += a * t**3
    root[:, 1] += a * t**3
    got = kinematic_metrics(shifted(m, root))["jerk"]
    assert got == pytest.approx(6 * a * math.sqrt(2), rel=1e-5)
    assert math.isnan(kinematic_metrics(standing(3))["jerk"])


def test_bone_length_error_is_computed_from_positions() -> None:
    m = standing(5)
    skel = m.skeleton
    pos = m.global_positions()
    assert bone_length_error_mm(m, pos) < 1e-9
    toe, hock = skel.index("lh_toe"), skel.index("lh_hock")
    d = pos[:, toe] - pos[:, hock]
    pos[2, toe] += 0.003 * d[2] / np.linalg.norm(d[2])  # stretch one bone by 3 mm
    assert bone_length_error_mm(m, pos) == pytest.approx(3.0, abs=1e-9)


def test_joint_limit_violation_exact() -> None:
    m = standing(10)
    ang = hinge_angles(m)
    lo, hi = hinge_limits("dog")["lh_knee_flex"]
    excess = math.radians(10.0)
    ang["lh_knee_flex"] = np.full(10, hi + excess)
    q = compose_hinges(ang, base=m.rotations)
    km = kinematic_metrics(Motion("dog", FPS, m.root_positions, q))
    # 34 hinges: 4 legs × (4 flex + 1 abd) + 3 spine × 2 + neck 2 + head 2 + 2 tail × 2.
    assert km["joint_limit_violation_rad"] == pytest.approx(excess / 34, rel=1e-9)
    # Outward abduction of the LEFT shoulder 5° beyond +25°: R_x angle is negative.
    ang = hinge_angles(m)
    lo, hi = hinge_limits("dog")["lf_shoulder_abd"]
    ang["lf_shoulder_abd"] = np.full(10, hi + math.radians(5.0))
    ang["rf_shoulder_abd"] = np.concatenate([np.full(5, lo - math.radians(4.0)), np.zeros(5)])
    q = compose_hinges(ang, base=m.rotations)
    got = kinematic_metrics(Motion("dog", FPS, m.root_positions, q))["joint_limit_violation_rad"]
    assert got == pytest.approx((math.radians(5.0) + 0.5 * math.radians(4.0)) / 34, rel=1e-9)


def test_metrics_are_fast() -> None:
    m = standing(180)
    kinematic_metrics(m)
    detect_contacts(m)
    t0 = time.perf_counter()
    kinematic_metrics(m)
    detect_contacts(m)
    assert time.perf_counter() - t0 < 0.1


# ----------------------------------------------------------------------------- CLI


REQUIRED = (
    "duration_s",
    "speed_mps",
    "froude",
    "duty_factor",
    "duty_factor_per_foot",
    "phase_offsets",
    "stability_margin_min_m",
    "stability_margin_mean_m",
    "statically_stable_fraction",
    *KINEMATIC_KEYS,
)


def test_cli_stats_json(tmp_path, capsys) -> None:
    m = standing(30)
    root = m.root_positions.copy()
    root[:, 2] += 0.1
    path = shifted(m, root).save(tmp_path / "m.npz")
    assert main(["motion", "stats", str(path), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    for k in REQUIRED:
        assert k in out, k
    assert out["species"] == "dog" and out["contacts_source"] == "detected"
    assert out["float_mm"] == pytest.approx(100.0, abs=1e-6)
    assert set(out["phase_offsets"]) == {"LF", "RF", "LH", "RH"}
    assert out["phase_offsets"]["LF"] is None  # no touchdowns: null, not NaN


def test_cli_stats_table(tmp_path, capsys) -> None:
    path = standing(30).save(tmp_path / "m.npz")
    assert main(["motion", "stats", str(path)]) == 0
    out = capsys.readouterr().out
    for k in (
        "froude",
        "duty_factor",
        "phase_offsets",
        "skate_mm",
        "penetration_mm",
        "stability_margin_min_m",
    ):
        assert k in out
    assert "LF=" in out


def test_cli_stats_bad_files(tmp_path, capsys) -> None:
    assert main(["motion", "stats", str(tmp_path / "missing.npz")]) == 2
    assert capsys.readouterr().err.startswith("error:")
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip file")
    assert main(["motion", "stats", str(bad), "--json"]) == 2
    assert capsys.readouterr().err.startswith("error:")


def test_contacts_by_duty_finds_stance_of_a_skating_gait():
    # A trot whose stance feet slide at a third of the body speed: no frame rests, so the
    # resting detector finds nothing, but the slow-and-low ranking finds each stance phase.
    fps, leg, duty, period = 30.0, 0.6, 0.6, 24
    t = np.arange(120)
    phase = (t[:, None] / period + np.array([0.0, 0.5, 0.5, 0.0])[None, :]) % 1.0
    stance = phase < duty
    body_v = 1.2  # m/s
    vx = np.where(stance, body_v / 3.0, body_v * (1 + (1 - 1 / 3) * duty / (1 - duty)))
    x = np.cumsum(vx, axis=0) / fps
    z = np.where(stance, 0.005, 0.08 * np.sin(np.pi * (phase - duty) / (1 - duty)).clip(0))
    feet = np.stack([x, np.zeros_like(x), z], axis=-1)
    assert not contacts_from_feet(feet, fps, leg).any()
    got = contacts_by_duty(feet, fps, leg, duty)
    assert (got == stance).mean() > 0.95
    with pytest.raises(InvalidMotionError, match="duty factors must lie in"):
        contacts_by_duty(feet, fps, leg, 1.2)


def test_stride_period_and_quicken_contacts_keep_the_footfall_pattern():
    from habitsim.contacts import quicken_contacts, stride_period, touchdown_frames

    # a trot: diagonal pairs, 20-frame strides, duty 0.5, 100 frames
    t = np.arange(100)
    a = (t % 20) < 10
    c = np.stack([a, ~a, ~a, a], axis=1)
    assert stride_period(c) == 20.0
    assert stride_period(np.ones((50, 4), bool)) is None  # standing: no stride
    same = quicken_contacts(c, np.ones(100), 20.0)
    np.testing.assert_array_equal(same, c)
    fast = quicken_contacts(c, np.full(100, 2.0), 20.0)
    assert stride_period(fast) == 10.0  # twice the cadence, over the whole clip
    assert fast.mean(axis=0) == pytest.approx(c.mean(axis=0), abs=0.03)  # duty kept
    np.testing.assert_array_equal(fast[:, 0], fast[:, 3])  # the diagonals stay paired
    np.testing.assert_array_equal(fast[:, 0], ~fast[:, 1])
    # past the schedule's end it keeps stepping in its last stride
    assert len(touchdown_frames(fast)[0]) >= 9
    with pytest.raises(InvalidMotionError, match="rate"):
        quicken_contacts(c, np.full(100, 0.5), 20.0)
    with pytest.raises(InvalidMotionError, match="period"):
        quicken_contacts(c, np.ones(100), 200.0)
