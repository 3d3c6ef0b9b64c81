"""Every per-clip metric of docs/metrics.md against motions made to fool it.

One synthetic dog walk (:func:`habitsim.gaits.generate`, with its planned stance labels)
and five fakes of it, as docs/metrics.md's "Adversarial cases" describes them:

* floating: the whole walk lifted 0.05 m or 0.5 m, labels kept;
* sliding: the root dragged forward 0.5 L/s faster than the feet step (stance feet skate);
* sunk: the whole walk lowered 0.02 m into the floor;
* teleport: the root jumps 0.5 m forward between two frames;
* fast: the same frames played at 3 × the frame rate.

Each test checks that its metric moves the documented way, or stays where the document
says it is blind.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pytest

from habitsim.gait_stats import gait_statistics
from habitsim.gaits import generate
from habitsim.metrics.biomech import biomech_metrics
from habitsim.metrics.dynamic import dynamic_metrics
from habitsim.metrics.kinematic import kinematic_metrics
from habitsim.motion import Motion

LIFTS_M = (0.05, 0.5)
SINK_M = 0.02
SLIDE_PER_LEG = 0.5  # extra root speed [hind-leg lengths per second]
TELEPORT_M = 0.5
SPEED_UP = 3.0
CASES = ("walk", "float05", "float50", "slide", "sunk", "teleport", "fast")
FAKES = CASES[1:]


def _remade(m: Motion, root: np.ndarray | None = None, fps: float | None = None) -> Motion:
    return Motion(
        m.species,
        m.fps if fps is None else fps,
        m.root_positions if root is None else root,
        m.rotations,
        m.contacts,
        dict(m.metadata),
    )


def _lifted(m: Motion, dz: float) -> Motion:
    root = m.root_positions.copy()
    root[:, 2] += dz
    return _remade(m, root)


def _sliding(m: Motion) -> Motion:
    root = m.root_positions.copy()
    root[:, 0] += SLIDE_PER_LEG * m.species_info.leg_length * np.arange(m.num_frames) / m.fps
    return _remade(m, root)


def _teleported(m: Motion) -> Motion:
    root = m.root_positions.copy()
    root[m.num_frames // 2 :, 0] += TELEPORT_M
    return _remade(m, root)


def fakes(m: Motion) -> dict[str, Motion]:
    """The walk and its five fakes, by case name (:data:`CASES`)."""
    return {
        "walk": m,
        "float05": _lifted(m, LIFTS_M[0]),
        "float50": _lifted(m, LIFTS_M[1]),
        "slide": _sliding(m),
        "sunk": _lifted(m, -SINK_M),
        "teleport": _teleported(m),
        "fast": _remade(m, fps=SPEED_UP * m.fps),
    }


@pytest.fixture(scope="module")
def cases() -> dict[str, Motion]:
    return fakes(generate("dog", "walk", seed=0, duration_s=2.0))


def _table(cases: dict[str, Motion], f: Callable[[Motion], dict]) -> dict[str, dict]:
    return {name: f(m) for name, m in cases.items()}


@pytest.fixture(scope="module")
def kin(cases):
    return _table(cases, kinematic_metrics)


@pytest.fixture(scope="module")
def dyn(cases):
    return _table(cases, dynamic_metrics)


@pytest.fixture(scope="module")
def tracked(cases):
    """Tracking with root assistance (the servo controller): every run survives."""
    from habitsim.sim import track

    return _table(cases, lambda m: track(m, assist=True).metrics)


# ----------------------------------------------------------------------------- kinematic


def test_floating_reads_its_height_on_float(kin) -> None:
    assert kin["walk"]["float_mm"] == 0.0
    for case, lift in zip(("float05", "float50"), LIFTS_M, strict=True):
        assert kin[case]["float_mm"] == pytest.approx(1000 * lift, abs=1.0)
    for case in ("slide", "sunk", "teleport", "fast"):
        assert kin[case]["float_mm"] == 0.0


def test_sunk_reads_its_depth_on_penetration(kin) -> None:
    assert kin["walk"]["penetration_mm"] < 1e-6
    assert kin["sunk"]["penetration_mm"] == pytest.approx(1000 * SINK_M, abs=0.5)
    for case in ("float05", "float50", "slide", "teleport", "fast"):
        assert kin[case]["penetration_mm"] < 1e-6


def test_sliding_and_teleport_raise_skating(cases, kin) -> None:
    walk = cases["walk"]
    slide_mm = 1000 * SLIDE_PER_LEG * walk.species_info.leg_length / walk.fps  # per frame
    assert kin["walk"]["skate_mm"] < 0.1 and kin["walk"]["skate_ratio"] == 0.0
    assert kin["slide"]["skate_mm"] > 0.9 * slide_mm
    assert kin["slide"]["skate_ratio"] > 0.9
    assert kin["teleport"]["skate_mm"] > 100 * kin["walk"]["skate_mm"]
    # sunk: swing toes pass below the contact height and count as sliding contacts
    assert kin["sunk"]["skate_ratio"] > 0.3


def test_floating_hides_skating_but_not_itself(kin) -> None:
    """In the air no toe is below the contact height: nothing skates, float_mm reads it."""
    for case in ("float05", "float50"):
        assert kin[case]["skate_mm"] == 0.0 and kin[case]["skate_ratio"] == 0.0
        assert kin[case]["float_per_leg"] > 0.05


def test_teleport_and_fast_raise_jerk(kin) -> None:
    walk = kin["walk"]["jerk"]
    assert kin["teleport"]["jerk"] > 3 * walk
    assert kin["fast"]["jerk"] == pytest.approx(SPEED_UP**3 * walk, rel=1e-9)
    for case in ("float05", "float50", "slide", "sunk"):
        assert kin[case]["jerk"] == pytest.approx(walk, rel=1e-9)


@pytest.mark.parametrize("case", FAKES)
def test_skeleton_metrics_are_blind_to_the_fakes(kin, case: str) -> None:
    """Bone lengths and joint limits see the poses, which no fake changes."""
    assert kin[case]["bone_length_error_mm"] < 1e-6
    assert kin[case]["joint_limit_violation_rad"] == kin["walk"]["joint_limit_violation_rad"]


# ----------------------------------------------------------------------------- dynamic


@pytest.mark.parametrize("case", ["float05", "float50"])
def test_floating_walk_needs_its_weight_from_outside(dyn, case: str) -> None:
    """Labelled stance feet in mid-air push on nothing (the outside tester's case)."""
    assert dyn["walk"]["root_residual_mg"] < 0.05
    assert dyn[case]["root_residual_mg"] == pytest.approx(1.0, abs=0.05)
    assert dyn[case]["root_residual_torque_mgl"] > 10 * dyn["walk"]["root_residual_torque_mgl"]


def test_sunk_and_sliding_walks_read_as_the_walk(dyn) -> None:
    """A sunk foot still pushes (penetration's business); a constant drag needs no force."""
    for case in ("sunk", "slide"):
        for key, value in dyn["walk"].items():
            assert dyn[case][key] == pytest.approx(value, rel=1e-6, abs=1e-9)


def test_teleport_and_fast_need_a_hand_of_god(dyn) -> None:
    walk = dyn["walk"]
    for case in ("teleport", "fast"):
        assert dyn[case]["root_residual_mg"] > 10 * walk["root_residual_mg"]
        assert dyn[case]["root_residual_torque_mgl"] > 10 * walk["root_residual_torque_mgl"]
    assert dyn["fast"]["torque_saturation"] > 0.5 > walk["torque_saturation"]


# ----------------------------------------------------------------------------- gait


@pytest.mark.parametrize("case", ["float05", "float50"])
def test_floating_walk_has_no_support(cases, case: str) -> None:
    """The stance labels of a lifted walk stand on nothing: no stability margin."""
    walk = gait_statistics(cases["walk"])
    assert math.isfinite(walk.stability_margin_min_m)
    assert walk.statically_stable_fraction > 0.5
    up = gait_statistics(cases[case])
    assert math.isnan(up.stability_margin_min_m) and math.isnan(up.stability_margin_mean_m)
    assert math.isnan(up.statically_stable_fraction)
    assert up.duty_factor == walk.duty_factor  # the footfall timing is the labels'


def test_fast_walk_leaves_the_walk(cases) -> None:
    walk, fast = gait_statistics(cases["walk"]), gait_statistics(cases["fast"])
    assert fast.froude == pytest.approx(SPEED_UP**2 * walk.froude, rel=1e-6)
    assert fast.stride_frequency_hz == pytest.approx(SPEED_UP * walk.stride_frequency_hz)
    b_walk, b_fast = biomech_metrics(cases["walk"]), biomech_metrics(cases["fast"])
    assert b_fast.froude_error > 1.0 and b_fast.score > b_walk.score + 2.0


def test_biomech_sees_floating_and_sliding_on_the_geometry(cases) -> None:
    """With contacts from the geometry (the benchmark's way) a floating or skating walk
    has no steps; with its labels a floating walk keeps the walk's footfalls."""
    walk = biomech_metrics(cases["walk"], use_labels=False).score
    for case in ("float05", "float50", "slide"):
        assert biomech_metrics(cases[case], use_labels=False).score > walk + 5.0
    assert biomech_metrics(cases["float50"]).score == biomech_metrics(cases["walk"]).score
    assert biomech_metrics(cases["teleport"]).score > biomech_metrics(cases["walk"]).score


# ----------------------------------------------------------------------------- simulated


def test_tracking_fakes_needs_more_assistance(tracked) -> None:
    walk = tracked["walk"]
    assert walk["survival"] == 1.0
    for case in FAKES:
        assert tracked[case]["assist_force_mg"] > walk["assist_force_mg"] + 0.1, case
        assert tracked[case]["sim_mpjpe_mm"] > walk["sim_mpjpe_mm"] + 2.0, case
    for case in ("float05", "float50", "teleport", "fast"):
        assert tracked[case]["assist_force_mg"] > walk["assist_force_mg"] + 0.3, case


def test_tracking_fakes_moves_contacts_drift_and_cost(tracked) -> None:
    walk = tracked["walk"]
    for case in ("float05", "float50"):  # the simulated feet never reach the labels' floor
        assert tracked[case]["contact_f1"] < 0.5
    for case in ("slide", "fast"):
        assert tracked[case]["contact_f1"] < walk["contact_f1"] - 0.1
        assert tracked[case]["root_drift_mm"] > 3 * walk["root_drift_mm"]
    assert tracked["fast"]["cost_of_transport"] > 2 * walk["cost_of_transport"]


@pytest.mark.parametrize("case", ["float05", "float50"])
def test_floating_reference_falls_without_assistance(cases, case: str) -> None:
    from habitsim.sim import track

    walk = track(cases["walk"], controller="mpc").metrics
    assert walk["survival"] == 1.0 and walk["fell"] is False
    up = track(cases[case], controller="mpc").metrics
    assert up["fell"] is True and up["survival"] < 0.5


# ----------------------------------------------------------------------------- distribution


@pytest.fixture(scope="module")
def walk_sets():
    """Eight dog walks and each fake of them: features and predictions of the evaluator."""
    from habitsim.evaluation.evaluator import load_evaluator

    ev = load_evaluator()
    walks = [generate("dog", "walk", seed=s, duration_s=2.0) for s in range(8)]
    sets = {name: [fakes(w)[name] for w in walks] for name in CASES}
    return sets, {name: ev.predict(ms) for name, ms in sets.items()}


def test_evaluator_metrics_are_blind_to_height(walk_sets) -> None:
    """Features are local rotations and velocities: lifting or sinking changes nothing;
    MPJPE (global positions) reads the offset."""
    from habitsim.evaluation.distribution import fid, mpjpe_mm

    sets, pred = walk_sets
    real = pred["walk"]
    for case, dz in (("float05", LIFTS_M[0]), ("float50", LIFTS_M[1]), ("sunk", SINK_M)):
        np.testing.assert_allclose(pred[case].features, real.features, atol=1e-5)
        assert abs(fid(pred[case].features, real.features)) < 1e-4
        assert pred[case].species == real.species and pred[case].actions == real.actions
        for a, b in zip(sets[case], sets["walk"], strict=True):
            assert mpjpe_mm(a, b) == pytest.approx(1000 * dz, rel=1e-9)


def test_evaluator_metrics_see_motion_changes(walk_sets) -> None:
    from habitsim.evaluation.distribution import diversity, fid, mpjpe_mm, one_nna

    sets, pred = walk_sets
    real = pred["walk"].features
    for case in ("slide", "teleport", "fast"):
        assert fid(pred[case].features, real) > 1.0, case
        assert diversity(pred[case].features) > 1.3 * diversity(real), case
    assert one_nna(pred["fast"].features, real) == 1.0
    walked = np.mean([a == "walk" for a in pred["fast"].actions])
    assert walked < 0.5  # 3 × faster is no walk any more: action accuracy falls
    assert all(s == "dog" for s in pred["fast"].species)  # habit accuracy does not
    # MPJPE compares frame by frame: the same frames played faster read 0
    for a, b in zip(sets["fast"], sets["walk"], strict=True):
        assert mpjpe_mm(a, b) == pytest.approx(0.0, abs=1e-9)
