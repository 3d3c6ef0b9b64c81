"""Gait statistics: duty factor, stride period, phase offsets, Froude, stability margin."""

from __future__ import annotations

import json
import math
import time

import numpy as np
import pytest

from habitsim import get_skeleton, load_species
from habitsim.errors import InvalidMotionError
from habitsim.gait_stats import (
    GRAVITY,
    GaitStats,
    circular_mean,
    gait_statistics,
    peak_froude,
    stability_margins,
)
from habitsim.motion import Motion
from habitsim.species import FEET

SP = load_species("dog")


def moving(t: int, fps: float, speed: float, heading: float = 0.0) -> Motion:
    """The dog's standing pose translated at constant horizontal speed [m/s]."""
    r, q = get_skeleton("dog").standing_pose()
    root = np.repeat(r[None], t, 0)
    d = np.arange(t) / fps * speed
    root[:, 0] += d * math.cos(heading)
    root[:, 1] += d * math.sin(heading)
    return Motion("dog", fps, root, np.repeat(q[None], t, 0))


def table(t: int, period: int, stance: int, offsets: dict[str, float], start: int) -> np.ndarray:
    """Contacts: foot f touches down at start + offset_f·period + k·period, stays `stance`."""
    c = np.zeros((t, 4), bool)
    frames = np.arange(t)
    for k, f in enumerate(FEET):
        td = start + round(offsets[f] * period)
        c[:, k] = ((frames - td) % period) < stance
    return c


def circ_close(a: float, b: float, tol: float = 1e-9) -> bool:
    d = (a - b) % 1.0
    return min(d, 1.0 - d) <= tol


def test_trot_table() -> None:
    fps, period, stance = 60.0, 30, 12  # 0.5 s stride, duty factor 0.4
    speed = 1.8
    trot = {"LH": 0.0, "LF": 0.5, "RH": 0.5, "RF": 0.0}
    m = moving(360, fps, speed)
    c = table(360, period, stance, trot, start=5)
    s = gait_statistics(m, c)
    assert isinstance(s, GaitStats)
    assert s.duration_s == pytest.approx(6.0)
    assert s.speed_mps == pytest.approx(speed, rel=1e-9)
    h = SP.hip_height
    assert s.froude == pytest.approx(speed**2 / (GRAVITY * h), rel=1e-9)
    assert s.duty_factor == pytest.approx(0.4, abs=1e-9)
    for f in FEET:
        assert s.duty_factor_per_foot[f] == pytest.approx(0.4, abs=1e-9)
        assert s.stride_period_per_foot[f] == pytest.approx(0.5)
    assert s.stride_period_s == pytest.approx(0.5)
    assert s.stride_frequency_hz == pytest.approx(2.0)
    assert s.stride_length_m == pytest.approx(0.9)
    assert s.relative_stride_length == pytest.approx(0.9 / h)
    for f, ph in trot.items():
        assert circ_close(s.phase_offsets[f], ph), (f, s.phase_offsets[f])
        assert 0.0 <= s.phase_offsets[f] < 1.0


def test_walk_table_with_clip_not_a_whole_number_of_strides() -> None:
    fps, period, stance = 60.0, 40, 28  # duty factor 0.7
    walk = {"LH": 0.0, "LF": 0.25, "RH": 0.5, "RF": 0.75}
    m = moving(257, fps, 0.6, heading=0.7)  # heading does not matter
    c = table(257, period, stance, walk, start=13)
    s = gait_statistics(m, c)
    assert s.speed_mps == pytest.approx(0.6, rel=1e-9)
    assert s.duty_factor == pytest.approx(0.7, abs=1e-9)  # complete strides only
    assert s.stride_period_s == pytest.approx(period / fps)
    for f, ph in walk.items():
        assert circ_close(s.phase_offsets[f], ph), (f, s.phase_offsets[f])
    assert s.statically_stable_fraction >= 0.0


def test_phase_offsets_at_30fps_within_a_frame() -> None:
    # 0.5 s stride at 30 fps: a half-stride offset is 7.5 frames -> rounded to 8.
    fps, period = 30.0, 15
    trot = {"LH": 0.0, "LF": 0.5, "RH": 0.5, "RF": 0.0}
    s = gait_statistics(moving(180, fps, 1.5), table(180, period, 6, trot, start=2))
    for f, ph in trot.items():
        assert circ_close(s.phase_offsets[f], ph, tol=1.0 / period + 1e-9)
    assert s.duty_factor == pytest.approx(0.4)


def test_phase_offsets_robust_to_circular_wrap() -> None:
    # A foot touching down a hair before LH reads ≈ 0.97, not -0.03, and the mean of
    # phases scattered around 0 stays near 0 (circular mean).
    assert circ_close(circular_mean(np.array([0.98, 0.02, 0.99, 0.01])), 0.0, 1e-9)
    assert circular_mean(np.array([0.25])) == pytest.approx(0.25)
    assert math.isnan(circular_mean(np.array([])))
    c = table(240, 30, 12, {"LH": 0.0, "LF": 29 / 30, "RH": 0.5, "RF": 0.5}, start=3)
    s = gait_statistics(moving(240, 60.0, 1.0), c)
    assert s.phase_offsets["LF"] == pytest.approx(29 / 30)


def test_motion_labels_are_used_when_present() -> None:
    trot = {"LH": 0.0, "LF": 0.5, "RH": 0.5, "RF": 0.0}
    c = table(120, 30, 12, trot, start=4)
    m = moving(120, 60.0, 1.0).with_contacts(c)
    s = gait_statistics(m)
    assert s.duty_factor == pytest.approx(0.4)
    assert circ_close(s.phase_offsets["LF"], 0.5)


def test_standing_still() -> None:
    m = moving(90, 30.0, 0.0)
    s = gait_statistics(m)  # detected contacts: all four feet down throughout
    assert s.speed_mps == 0.0 and s.froude == 0.0
    assert s.duty_factor == 1.0
    assert math.isnan(s.stride_period_s) and math.isnan(s.stride_length_m)
    assert all(math.isnan(v) for v in s.phase_offsets.values())
    assert s.stability_margin_min_m > 0.02
    assert s.stability_margin_mean_m == pytest.approx(s.stability_margin_min_m)
    assert s.stability_margin_per_leg == pytest.approx(s.stability_margin_min_m / SP.leg_length)
    assert s.statically_stable_fraction == 1.0
    d = s.to_dict()
    assert d["phase_offsets"]["LF"] is None and d["stride_period_s"] is None
    json.dumps(d, allow_nan=False)  # finite numbers or null only


def test_no_contacts_at_all() -> None:
    m = moving(30, 30.0, 1.0)
    s = gait_statistics(m, np.zeros((30, 4), bool))
    assert s.duty_factor == 0.0
    assert math.isnan(s.stability_margin_min_m) and math.isnan(s.statically_stable_fraction)
    assert all(math.isnan(v) for v in s.phase_offsets.values())
    json.dumps(s.to_dict(), allow_nan=False)
    one = gait_statistics(moving(1, 30.0, 0.0))
    assert one.speed_mps == 0.0 and one.duration_s == pytest.approx(1 / 30)


def test_bad_contact_shape() -> None:
    from habitsim.errors import InvalidMotionError

    with pytest.raises(InvalidMotionError):
        gait_statistics(moving(10, 30.0, 1.0), np.ones((9, 4), bool))


def test_stability_margin_geometry() -> None:
    sq = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    tri = np.array([[0.0, 0.0], [4.0, 0.0], [0.0, 3.0], [9.0, 9.0]])
    cases = [
        # (com, feet, contacts, expected margin)
        ((0.5, 0.5), sq, (1, 1, 1, 1), 0.5),  # centre of the unit square
        ((0.2, 0.5), sq, (1, 1, 1, 1), 0.2),  # nearest edge x = 0
        ((2.0, 0.5), sq, (1, 1, 1, 1), -1.0),  # outside, 1 m from edge x = 1
        ((2.0, 2.0), sq, (1, 1, 1, 1), -math.sqrt(2.0)),  # outside, nearest is a corner
        # triangle (0,0),(1,0),(1,1): (0.5, 0.4) inside, nearest edge the diagonal y = x
        ((0.5, 0.4), sq, (1, 1, 1, 0), 0.1 / math.sqrt(2.0)),
        ((0.5, 0.6), sq, (1, 1, 1, 0), -0.1 / math.sqrt(2.0)),  # just across the diagonal
        ((0.5, 0.5), sq, (1, 1, 0, 0), -0.5),  # two feet: segment
        ((0.5, 0.5), sq, (1, 0, 1, 0), 0.0),  # on the diagonal segment
        ((0.5, 0.5), sq, (0, 0, 1, 0), -math.sqrt(0.5)),  # one foot: point
        # 3-4-5 triangle, (1, 1) is its incentre: inradius (3 + 4 - 5) / 2 = 1
        ((1.0, 1.0), tri, (1, 1, 1, 0), 1.0),
        # adding (9, 9) moves the hypotenuse away (distances 32/√106, 24/√117 > 1)
        ((1.0, 1.0), tri, (1, 1, 1, 1), 1.0),
        ((2.0, 2.5), tri, (1, 1, 1, 1), min(2.0, 2.5, 32 / math.sqrt(106) - 0.0 * 0, 10.0)),
    ]
    # Last case: edges y = 0 (2.5), x = 0 (2.0), (4,0)-(9,9): |5·2.5 − 9·(2−4)| / √106,
    # (9,9)-(0,3): |(−9)(2.5−9) − (−6)(2−9)| / √117.
    last = min(
        2.5,
        2.0,
        abs(5 * 2.5 - 9 * (2 - 4)) / math.sqrt(106),
        abs(-9 * (2.5 - 9) + 6 * (2 - 9)) / math.sqrt(117),
    )
    com = np.array([c[0] for c in cases])
    feet = np.stack([c[1] for c in cases])
    con = np.array([c[2] for c in cases], bool)
    exp = np.array([c[3] for c in cases])
    exp[-1] = last
    np.testing.assert_allclose(stability_margins(com, feet, con), exp, atol=1e-12)
    assert math.isnan(stability_margins(com[:1], feet[:1], np.zeros((1, 4), bool))[0])


def test_collinear_support_is_a_segment() -> None:
    feet = np.array([[[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [3.0, 0.0]]])
    got = stability_margins(np.array([[1.5, 0.25]]), feet, np.ones((1, 4), bool))
    assert got[0] == pytest.approx(-0.25)
    got = stability_margins(np.array([[4.0, 0.0]]), feet, np.ones((1, 4), bool))
    assert got[0] == pytest.approx(-1.0)


def _seg_dist(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    t = np.clip(np.dot(p - a, b - a) / np.dot(b - a, b - a), 0.0, 1.0)
    return float(np.linalg.norm(p - (a + t * (b - a))))


def _line_dist(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    e, r = b - a, p - a
    return float(abs(e[0] * r[1] - e[1] * r[0]) / np.linalg.norm(e))


def test_three_legged_and_two_legged_support_on_the_dog() -> None:
    from habitsim.body import center_of_mass

    m = moving(40, 30.0, 0.0)
    pos = m.global_positions()[0]
    com = center_of_mass("dog", pos)[:2]
    lf, rf, lh, rh = pos[m.skeleton.foot_indices, :2]
    # The dog's CoM lies nearer the fore feet: lifting a fore foot tips it over the
    # diagonal LF–RH; lifting a hind foot keeps it inside the triangle LF, RF, LH.
    c = np.ones((40, 4), bool)
    c[0:10, 1] = False  # LF, LH, RH: outside, beyond the diagonal RH–LF
    c[10:20] = [True, False, True, False]  # left feet only: segment LF–LH
    c[20:30, 3] = False  # LF, RF, LH: inside; nearest edge the diagonal RF–LH
    s = gait_statistics(m, c)
    out_tri = -_line_dist(com, rh, lf)
    seg = -_seg_dist(com, lf, lh)
    in_tri = min(_line_dist(com, rf, lh), _line_dist(com, lf, rf), _line_dist(com, lh, lf))
    full = min(
        _line_dist(com, lf, rf),
        _line_dist(com, rf, rh),
        _line_dist(com, rh, lh),
        _line_dist(com, lh, lf),
    )
    assert out_tri < 0 < in_tri
    assert s.stability_margin_min_m == pytest.approx(min(out_tri, seg), abs=1e-12)
    mean = (out_tri + seg + in_tri + full) / 4
    assert s.stability_margin_mean_m == pytest.approx(mean, abs=1e-12)
    assert s.statically_stable_fraction == pytest.approx(2 / 3)


def test_gait_statistics_is_fast() -> None:
    m = moving(180, 30.0, 1.0)
    c = table(180, 15, 6, {"LH": 0.0, "LF": 0.5, "RH": 0.5, "RF": 0.0}, start=1)
    gait_statistics(m, c)
    t0 = time.perf_counter()
    gait_statistics(m, c)
    gait_statistics(m)
    assert time.perf_counter() - t0 < 0.1


def test_peak_froude_is_the_fastest_span() -> None:
    """Constant speed: v²/(g·h); a walk that breaks into a run for one second reads the
    run's speed, not the clip's mean; a turn counts its path, not its chord."""
    h = SP.hip_height
    assert peak_froude(moving(60, 30.0, 2.0)) == pytest.approx(4.0 / (GRAVITY * h), rel=1e-9)
    walk, run = moving(90, 30.0, 0.5), moving(30, 30.0, 4.0)
    root = np.concatenate(
        [
            walk.root_positions,
            run.root_positions[1:] - run.root_positions[0] + walk.root_positions[-1],
        ]
    )
    mixed = Motion("dog", 30.0, root, np.repeat(walk.rotations[:1], len(root), 0))
    assert peak_froude(mixed) == pytest.approx(16.0 / (GRAVITY * h), rel=1e-9)
    assert gait_statistics(mixed).froude < 0.5 * peak_froude(mixed)
    # a circle of radius 0.5 m at 2 m/s: half a second covers 1 m of path
    t = np.arange(61) / 30.0
    circ = moving(61, 30.0, 0.0)
    circ.root_positions[:, 0] += 0.5 * np.cos(4.0 * t)
    circ.root_positions[:, 1] += 0.5 * np.sin(4.0 * t)
    assert peak_froude(circ) == pytest.approx(4.0 / (GRAVITY * h), rel=2e-3)
    assert peak_froude(moving(1, 30.0, 1.0)) == 0.0
    with pytest.raises(InvalidMotionError, match="span_s"):
        peak_froude(mixed, span_s=0.0)
