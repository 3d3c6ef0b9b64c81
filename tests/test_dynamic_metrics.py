"""Dynamic and simulated metrics on hand-made cases with known answers (MuJoCo 4.0.0)."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from habitsim.metrics.dynamic import DYNAMIC_KEYS, dynamic_metrics, inverse_dynamics
from habitsim.metrics.simulated import (
    SIMULATED_KEYS,
    contact_f1,
    cost_of_transport,
    root_drift_mm,
    sim_mpjpe_mm,
    simulated_metrics,
)
from habitsim.qpos import load_species_model, qpos_to_motion
from habitsim.sim import SimulationError, build_reference, finite_differences

FPS = 30.0
G = 9.81


@pytest.fixture(scope="module")
def dog():
    return load_species_model("dog")


def _home(model, frames: int = 30) -> np.ndarray:
    return np.tile(model.key_qpos[model.key("home").id], (frames, 1))


def _leg() -> float:
    import habitsim

    return habitsim.load_species("dog").leg_length


# ------------------------------------------------------------------ finite differences
def test_finite_differences_of_a_sine(dog) -> None:
    q = _home(dog, 120)
    t = np.arange(120) / FPS
    a = dog.joint("lh_knee_flex").qposadr[0]
    v = dog.joint("lh_knee_flex").dofadr[0]
    q[:, a] = 1.0 + 0.3 * np.sin(2.0 * t)
    qvel, qacc = finite_differences(dog, q, FPS)
    inner = slice(2, -2)
    # central differences: error O(h²ω³) ≈ 0.3·8/(6·900) ≈ 4e-4
    np.testing.assert_allclose(qvel[inner, v], 0.6 * np.cos(2.0 * t[inner]), atol=1e-3)
    np.testing.assert_allclose(qacc[inner, v], -1.2 * np.sin(2.0 * t[inner]), atol=3e-3)
    others = np.delete(np.arange(dog.nv), v)
    assert np.abs(qvel[:, others]).max() < 1e-12


def test_finite_differences_of_a_free_fall(dog) -> None:
    q = _home(dog, 10)
    t = np.arange(10) / FPS
    q[:, 2] += 1.0 - 0.5 * G * t**2
    _, qacc = finite_differences(dog, q, FPS)
    np.testing.assert_allclose(qacc[:, 2], -G, atol=1e-9)


def test_reference_hits_the_frames(dog) -> None:
    fps = 25.0  # 20 steps of 2 ms per frame: every frame falls on a step
    q = _home(dog, 31)
    t = np.arange(31) / fps
    q[:, 0] = 0.5 * t  # walking forward
    q[:, dog.joint("neck_yaw").qposadr[0]] = 0.2 * np.sin(3 * t)
    yaw = 0.4 * t  # turning: root quaternion about z
    q[:, 3:7] = np.stack([np.cos(yaw / 2), 0 * yaw, 0 * yaw, np.sin(yaw / 2)], axis=1)
    ref = build_reference(dog, q, fps)
    step = int(round(1 / fps / dog.opt.timestep))
    idx = np.arange(0, len(ref.time), step)
    np.testing.assert_allclose(ref.qpos[idx], q[: len(idx)], atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(ref.qpos[:, 3:7], axis=1), 1.0, atol=1e-12)
    # between frames, slerp keeps the constant yaw rate
    mid = step // 2
    yaw_mid = 2 * np.arctan2(ref.qpos[mid, 6], ref.qpos[mid, 3])
    assert yaw_mid == pytest.approx(0.4 * ref.time[mid], abs=1e-9)
    np.testing.assert_allclose(ref.qvel[:, 0], 0.5, atol=1e-9)


def test_nan_reference_is_a_typed_error(dog) -> None:
    q = _home(dog, 5)
    q[2, 9] = np.nan
    with pytest.raises(SimulationError, match="NaN"):
        finite_differences(dog, q, FPS)
    with pytest.raises(SimulationError, match="shape"):
        build_reference(dog, q[:, :-1], FPS)


# ------------------------------------------------------------------ dynamic metrics
def test_floating_body_reads_exactly_one_mg(dog) -> None:
    q = _home(dog)
    q[:, 2] += 1.0  # in the air, still: the motion needs a hand of god carrying m·g
    m = dynamic_metrics(qpos_to_motion(dog, q, "dog", FPS))
    assert set(m) == set(DYNAMIC_KEYS)
    assert m["root_residual_mg"] == pytest.approx(1.0, abs=1e-9)
    assert m["torque_saturation"] == 0.0


def test_still_standing_pose_needs_no_external_force(dog) -> None:
    motion = qpos_to_motion(dog, _home(dog), "dog", FPS)
    m = dynamic_metrics(motion, contacts=np.ones((30, 4), bool))
    assert m["root_residual_mg"] == pytest.approx(0.0, abs=1e-6)
    assert m["root_residual_torque_mgl"] == pytest.approx(0.0, abs=1e-6)
    assert m["torque_saturation"] == 0.0
    # default contacts (detected from toe heights) find the four planted feet too
    assert dynamic_metrics(motion)["root_residual_mg"] == pytest.approx(0.0, abs=1e-6)


def test_ballistic_flight_needs_no_external_force(dog) -> None:
    q = _home(dog, 12)
    t = np.arange(12) / FPS
    q[:, 0] += 2.0 * t
    q[:, 2] += 1.0 + 1.5 * t - 0.5 * G * t**2
    inv = inverse_dynamics(dog, q, FPS, None, _leg())
    assert inv.metrics()["root_residual_mg"] == pytest.approx(0.0, abs=1e-6)


def test_lifted_upward_at_g_reads_two_mg(dog) -> None:
    q = _home(dog, 12)
    t = np.arange(12) / FPS
    q[:, 2] += 1.0 + 0.5 * G * t**2
    inv = inverse_dynamics(dog, q, FPS, None, _leg())
    assert inv.metrics()["root_residual_mg"] == pytest.approx(2.0, rel=1e-6)


def test_labelled_feet_in_mid_air_push_on_nothing(dog) -> None:
    """All four feet labelled in contact, the body held still 0.5 m up: a hand of god."""
    from habitsim.contacts import ground_reach

    labels = np.ones((30, 4), bool)
    up = _home(dog)
    up[:, 2] += 0.5
    inv = inverse_dynamics(dog, up, FPS, labels, _leg())
    assert not inv.contacts.any() and not inv.contact_force.any()
    assert inv.metrics()["root_residual_mg"] == pytest.approx(1.0, abs=1e-9)
    # just within reach the feet still carry the body (the ground bears it)
    near = _home(dog)
    near[:, 2] += 0.9 * ground_reach(_leg())
    inv = inverse_dynamics(dog, near, FPS, labels, _leg())
    assert inv.contacts.all()
    assert inv.metrics()["root_residual_mg"] == pytest.approx(0.0, abs=1e-6)


def test_ground_explains_a_gentle_push_within_friction(dog) -> None:
    """Standing feet planted, trunk accelerating forward at 0.1 g: friction suffices."""
    q = _home(dog, 30)
    t = np.arange(30) / FPS
    q[:, 0] += 0.5 * 0.1 * G * t**2  # (feet slide along: a skating motion, dynamically fine)
    inv = inverse_dynamics(dog, q, FPS, np.ones((30, 4), bool), _leg())
    assert inv.metrics()["root_residual_mg"] < 1e-6
    fz = inv.contact_force[..., 2].sum(axis=1)
    np.testing.assert_allclose(fz, inv.mg, rtol=1e-6)  # the ground carries the weight
    fx = inv.contact_force[..., 0].sum(axis=1)
    np.testing.assert_allclose(fx, 0.1 * inv.mg, rtol=1e-3)


def test_weak_motors_saturate(dog) -> None:
    weak = dog.__copy__()
    weak.actuator_ctrlrange[:] *= 1e-3
    m = dynamic_metrics(qpos_to_motion(dog, _home(dog), "dog", FPS), model=weak)
    assert m["torque_saturation"] == 1.0


# ------------------------------------------------------------------ simulated metrics
def test_simulated_metrics_of_a_perfect_run(dog) -> None:
    q = _home(dog, 31)
    c = np.ones((31, 4), bool)
    m = simulated_metrics(
        dog,
        q,
        q,
        c,
        c,
        leg_length=_leg(),
        survival=1.0,
        fell=False,
        work_j=0.0,
        assist_force_mg=0.0,
        sim_time_s=1.0,
        wall_time_s=0.5,
    )
    assert list(m) == list(SIMULATED_KEYS)
    assert m["sim_mpjpe_mm"] == 0.0 and m["root_drift_mm"] == 0.0
    assert m["contact_f1"] == 1.0 and m["survival"] == 1.0 and m["fell"] is False
    assert math.isnan(m["cost_of_transport"])  # no distance travelled
    assert m["realtime_factor"] == 2.0


def test_mpjpe_and_drift_of_a_shifted_run(dog) -> None:
    ref = _home(dog, 10)
    sim = ref.copy()
    sim[:, 0] += 0.003  # every joint 3 mm forward
    assert sim_mpjpe_mm(dog, sim, ref) == pytest.approx(3.0, abs=1e-9)
    assert root_drift_mm(dog, sim, ref) == pytest.approx(3.0, abs=1e-9)
    # only the frames that were simulated count (a run that fell after 4 frames)
    assert sim_mpjpe_mm(dog, sim[:4], ref) == pytest.approx(3.0, abs=1e-9)


def test_contact_f1_by_hand() -> None:
    ref = np.array([[1, 1, 0, 0], [1, 0, 0, 1]], bool)
    sim = np.array([[1, 0, 0, 0], [1, 0, 1, 1]], bool)
    # TP = 3, FP = 1, FN = 1 → F1 = 6 / 8
    assert contact_f1(sim, ref) == pytest.approx(0.75)
    assert contact_f1(np.zeros((3, 4), bool), np.zeros((3, 4), bool)) == 1.0


def test_cost_of_transport_by_hand(dog) -> None:
    q = _home(dog, 11)
    q[:, 0] += np.linspace(0.0, 2.0, 11)  # 2 m travelled
    mg = mujoco.mj_getTotalmass(dog) * G
    assert cost_of_transport(dog, q, work_j=mg, leg_length=_leg()) == pytest.approx(0.5)


def test_the_ground_force_split_is_unique_and_continuous() -> None:
    """Standing still on four feet needs no joint beyond its motor, and a change of 1e-9
    in the pose moves no joint torque by more than 0.1 % of the smallest limit: of the many
    splits of the ground force over the stance feet the least-norm one is taken."""
    from habitsim.gaits import generate
    from habitsim.metrics.dynamic import inverse_dynamics
    from habitsim.qpos import motion_to_qpos, species_model

    for species, action, seed in (("horse", "idle", 1), ("cat", "walk", 1)):
        m = generate(species, action, seed=seed, duration_s=2.0)
        model = species_model(species)
        q = motion_to_qpos(m, model).qpos
        leg = m.species_info.leg_length
        inv = inverse_dynamics(model, q, m.fps, m.contacts, leg)
        assert inv.metrics()["torque_saturation"] == 0.0, species
        nudged = q + 1e-9 * np.random.default_rng(0).standard_normal(q.shape)
        again = inverse_dynamics(model, nudged, m.fps, m.contacts, leg)
        assert np.abs(again.joint_torque - inv.joint_torque).max() < 1e-3 * inv.torque_limit.min()
