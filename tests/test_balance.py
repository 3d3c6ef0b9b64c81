"""Stance-force QP and balance controller (issue [6/6]): math on hand-made stance sets,
physics on the hand-written 12-DoF robot and the dog (mujoco 4.0.0).

No test ever adds a force to help the robot: the only ``xfrc_applied`` is the lateral
push of the recovery test (the DISTURBANCE), and root assistance stays off.
"""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest
from helpers import run_cli

from habitsim.controllers import (
    BalanceController,
    ControllerError,
    MPCController,
    Reference,
    StanceQP,
)
from habitsim.controllers.balance import BalanceConfig, wrench_matrix
from habitsim.controllers.swing import LegSet

ROBOT_XML = Path(__file__).parent / "data" / "quadruped12.xml"
MU = 0.6


@pytest.fixture(scope="module")
def robot() -> mujoco.MjModel:
    return mujoco.MjModel.from_xml_path(str(ROBOT_XML))


@pytest.fixture(scope="module")
def qp4() -> StanceQP:
    return StanceQP(4, "daqp")


FEET_R = np.array(
    [[0.19, 0.13, -0.28], [0.19, -0.13, -0.28], [-0.19, 0.13, -0.28], [-0.19, -0.13, -0.28]]
)  # foot − CoM [m]
SCALE = np.array([1.0, 1.0, 1.0, 4.0, 4.0, 4.0])


def in_cone(f: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Random forces (k, 3) strictly inside the friction pyramid."""
    fz = rng.uniform(20.0, 80.0, len(f))
    return np.stack(
        [rng.uniform(-0.8, 0.8, len(f)) * MU * fz, rng.uniform(-0.8, 0.8, len(f)) * MU * fz, fz],
        axis=1,
    )


@pytest.mark.parametrize("stance", [(1, 1, 1, 1), (1, 1, 1, 0), (1, 0, 0, 1), (0, 1, 1, 0)])
def test_qp_reproduces_a_wanted_wrench(qp4: StanceQP, stance) -> None:
    st = np.array(stance, dtype=bool)
    rng = np.random.default_rng(sum(stance) + 7 * stance[0])
    f_true = np.zeros((4, 3))
    f_true[st] = in_cone(f_true[st], rng)
    wrench = wrench_matrix(FEET_R) @ f_true.ravel()
    f, ok = qp4.solve(
        FEET_R,
        wrench,
        st,
        mu=MU,
        fz_min=0.0,
        fz_max=500.0,
        row_scale=SCALE,
        smooth=0.0,
        regularization=1e-9,
    )
    assert ok
    np.testing.assert_allclose(wrench_matrix(FEET_R) @ f.ravel(), wrench, atol=1e-3)
    assert np.all(f[~st] == 0.0)  # swing feet carry no force
    assert np.all(np.abs(f[:, :2]) <= MU * f[:, 2:3] + 1e-6)


def test_qp_respects_friction_and_bounds(qp4: StanceQP) -> None:
    mg = 200.0
    wrench = np.array([2.0 * MU * mg, -0.5 * MU * mg, mg, 0.0, 0.0, 0.0])  # too much shear
    st = np.array([1, 1, 1, 0], dtype=bool)
    f, ok = qp4.solve(FEET_R, wrench, st, mu=MU, fz_min=5.0, fz_max=90.0, row_scale=SCALE)
    assert ok
    fs = f[st]
    assert np.all(np.abs(fs[:, 0]) <= MU * fs[:, 2] + 1e-6)
    assert np.all(np.abs(fs[:, 1]) <= MU * fs[:, 2] + 1e-6)
    assert np.all(fs[:, 2] >= 5.0 - 1e-6) and np.all(fs[:, 2] <= 90.0 + 1e-6)
    assert np.all(f[~st] == 0.0)
    # the shear saturates the pyramid: |Σ f_x| reaches μ Σ f_z
    assert abs(fs[:, 0].sum()) == pytest.approx(MU * fs[:, 2].sum(), rel=1e-3)


def test_qp_keeps_joint_torques_within_bounds() -> None:
    rng = np.random.default_rng(3)
    qp = StanceQP(4, "daqp", n_joints=5)
    jac = rng.normal(0.0, 0.2, (4, 3, 5))
    wrench = np.array([0.0, 0.0, 250.0, 0.0, 0.0, 0.0])
    st = np.ones(4, dtype=bool)
    free, _ = qp.solve(
        FEET_R,
        wrench,
        st,
        mu=MU,
        fz_min=0.0,
        fz_max=400.0,
        row_scale=SCALE,
        jac=jac,
        tau_lo=np.full(5, -1e4),
        tau_hi=np.full(5, 1e4),
    )
    tau_free = -np.einsum("fkn,fk->n", jac, free)
    lim = 0.5 * np.abs(tau_free).max()
    f, ok = qp.solve(
        FEET_R,
        wrench,
        st,
        mu=MU,
        fz_min=0.0,
        fz_max=400.0,
        row_scale=SCALE,
        jac=jac,
        tau_lo=np.full(5, -lim),
        tau_hi=np.full(5, lim),
    )
    assert ok
    tau = -np.einsum("fkn,fk->n", jac, f)
    assert np.all(np.abs(tau) <= lim + 1e-6)


def test_qp_solvers_agree() -> None:
    wrench = np.array([10.0, -5.0, 180.0, 2.0, -3.0, 0.5])
    st = np.array([1, 1, 0, 1], dtype=bool)
    out = []
    for solver in ("daqp", "qpoases"):
        f, ok = StanceQP(4, solver).solve(
            FEET_R, wrench, st, mu=MU, fz_min=0.0, fz_max=400.0, row_scale=SCALE
        )
        assert ok
        out.append(f)
    np.testing.assert_allclose(out[0], out[1], atol=1e-4)
    with pytest.raises(ControllerError, match="available"):
        StanceQP(4, "nosuchsolver")


# --------------------------------------------------------------------------- physics
def home(model: mujoco.MjModel) -> np.ndarray:
    return model.key("home").qpos.copy()


def stand(
    model: mujoco.MjModel,
    ctl,
    seconds: float,
    *,
    drop: float = 0.0,
    push_mg: float = 0.0,
    push_at: float = 0.5,
    push_s: float = 0.1,
):
    """Hold the home pose; optional drop height [m] and a lateral push (the disturbance:
    ``xfrc_applied`` on the trunk for ``push_s`` seconds, push_mg · m·g newtons)."""
    q0 = home(model)
    nf = ctl.legs.n_feet
    ctl.set_plan(np.tile(q0, (3, 1)), 1.0, np.ones((3, nf), dtype=bool))
    data = mujoco.MjData(model)
    data.qpos[:] = q0
    data.qpos[2] += drop
    mujoco.mj_forward(model, data)
    ctl.reset(model, data)
    zero = np.zeros(model.nv)
    trunk = ctl.legs.trunk
    weight = mujoco.mj_getTotalmass(model) * float(np.linalg.norm(model.opt.gravity))
    log = {"z": [], "tilt": [], "xy": [], "fz": []}
    dt = model.opt.timestep
    for i in range(int(round(seconds / dt))):
        t = i * dt
        data.xfrc_applied[trunk] = 0.0
        if push_mg and push_at <= t < push_at + push_s:
            data.xfrc_applied[trunk, 1] = push_mg * weight
        data.ctrl[:] = ctl.control(model, data, Reference(t, q0, zero, zero, np.ones(nf, bool)))
        mujoco.mj_step(model, data)
        up = data.xmat[trunk].reshape(3, 3)[2, 2]
        log["z"].append(data.qpos[2])
        log["tilt"].append(np.degrees(np.arccos(np.clip(up, -1.0, 1.0))))
        log["xy"].append(data.qpos[:2] - q0[:2])
        log["fz"].append(ctl.last_forces[:, 2].sum())
    data.xfrc_applied[:] = 0.0
    return {k: np.array(v) for k, v in log.items()}, weight


def test_standing_forces_sum_to_weight(robot: mujoco.MjModel) -> None:
    ctl = BalanceController(robot)
    log, weight = stand(robot, ctl, 1.0)
    assert abs(log["fz"][-100:].mean() - weight) < 0.02 * weight
    assert abs(log["z"][-1] - home(robot)[2]) < 0.005
    assert log["tilt"][-1] < 1.0
    f = ctl.last_forces
    assert np.all(f[:, 2] > 0.1 * weight / 4)  # every foot carries load
    np.testing.assert_allclose(f[:, :2].sum(axis=0), 0.0, atol=0.02 * weight)
    assert ctl.stats.to_dict()["qp_failures"] == 0


def test_jt_sign_a_pushing_leg_lifts_the_trunk(robot: mujoco.MjModel) -> None:
    """τ = −Jᵀ f with an upward ground force f extends the stance legs: the trunk rises
    (and without it the trunk sinks)."""
    legs = LegSet(robot)
    weight = mujoco.mj_getTotalmass(robot) * 9.81

    def rise(push: float) -> float:
        data = mujoco.MjData(robot)
        data.qpos[:] = home(robot)
        mujoco.mj_forward(robot, data)
        z0 = data.qpos[2]
        for _ in range(40):
            p = legs.positions(data)
            jac = legs.jacobians(robot, data, p)[:, :, legs.jmap.dof_adr]
            f = np.tile([0.0, 0.0, push * weight / 4], (4, 1))
            tau = -np.einsum("fkn,fk->n", jac, f) + data.qfrc_bias[legs.jmap.dof_adr]
            data.ctrl[legs.jmap.ctrl_index] = tau / legs.jmap.torque_per_ctrl
            mujoco.mj_step(robot, data)
        return float(data.qpos[2] - z0)

    assert rise(1.6) > 0.005
    assert rise(0.0) < -0.005


@pytest.mark.parametrize("kind", ["balance", "mpc"])
def test_dropped_robot_lands_and_stands(robot: mujoco.MjModel, kind: str) -> None:
    ctl = (BalanceController if kind == "balance" else MPCController)(robot)
    log, weight = stand(robot, ctl, 1.5, drop=0.06)
    assert log["z"].max() > home(robot)[2] + 0.05  # it really fell from above
    assert abs(log["z"][-1] - home(robot)[2]) < 0.01
    assert log["tilt"].max() < 10.0
    assert np.linalg.norm(log["xy"][-1]) < 0.03
    assert abs(log["fz"][-100:].mean() - weight) < 0.05 * weight


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["balance", "mpc"])
def test_recovers_from_a_lateral_push(robot: mujoco.MjModel, kind: str) -> None:
    ctl = (BalanceController if kind == "balance" else MPCController)(robot)
    log, _ = stand(robot, ctl, 2.0, push_mg=0.5)  # Δv ≈ 0.5 m/s sideways
    i_push = int(0.6 / robot.opt.timestep)
    assert np.abs(log["xy"][i_push:, 1]).max() > 0.005  # the push moved it
    assert log["tilt"].max() < 15.0
    assert abs(log["z"][-1] - home(robot)[2]) < 0.01
    assert np.linalg.norm(log["xy"][-1]) < 0.05
    assert log["tilt"][-1] < 2.0


@pytest.mark.slow
def test_dog_recovers_from_a_lateral_push() -> None:
    from habitsim.qpos import load_species_model

    dog = load_species_model("dog")
    ctl = BalanceController(dog, leg_length=0.61)
    log, _ = stand(dog, ctl, 2.0, push_mg=0.3)
    assert log["tilt"].max() < 30.0
    assert log["tilt"][-1] < 5.0
    assert abs(log["z"][-1] - home(dog)[2]) < 0.03


def test_config_scales_with_the_body() -> None:
    small = BalanceConfig.scaled(2.0, 0.2)
    mid = BalanceConfig.scaled(100.0, 1.0)
    big = BalanceConfig.scaled(3500.0, 1.8)
    assert big.fz_max / small.fz_max == pytest.approx(1750.0)
    assert big.capture_max / small.capture_max == pytest.approx(9.0)
    # same dimensionless trunk stiffness ω² L / g, up to the frequency cap
    assert mid.trunk_omega**2 * 1.0 == pytest.approx(big.trunk_omega**2 * 1.8)
    assert small.trunk_omega == small.rot_omega == 10.0  # the default cap
    assert BalanceConfig.scaled(2.0, 0.2, omega_cap=5.0).trunk_omega == 5.0
    with pytest.raises(ControllerError, match="unknown balance option"):
        BalanceConfig.scaled(10.0, 0.5, frobnicate=1.0)
    with pytest.raises(ControllerError, match="must be"):
        BalanceConfig.scaled(-1.0, 0.5)


def test_controller_rejects_bad_models() -> None:
    no_free = mujoco.MjModel.from_xml_string(
        "<mujoco><worldbody><body><joint type='hinge'/><geom size='.1' name='f'/></body>"
        "</worldbody><actuator><motor joint='' /></actuator></mujoco>".replace(
            "<motor joint='' />", ""
        )
    )
    with pytest.raises(ControllerError):
        BalanceController(no_free, ["f"])
    robot = mujoco.MjModel.from_xml_path(str(ROBOT_XML))
    with pytest.raises(ControllerError, match="not a site, geom or body"):
        BalanceController(robot, ["FL_foot", "nope", "RL_foot", "RR_foot"])


@pytest.mark.slow
def test_dog_walk_balance_unassisted() -> None:
    """A species model follows a synthetic walk with the balance controller alone."""
    from habitsim.gaits import generate
    from habitsim.qpos import load_species_model, motion_to_qpos
    from habitsim.sim import track

    dog = load_species_model("dog")
    motion = generate("dog", "walk", seed=1, duration_s=3.0)
    ctl = BalanceController(dog, leg_length=0.61)
    ctl.set_plan(motion_to_qpos(motion, dog).qpos, motion.fps, motion.contacts)
    res = track(motion, controller=ctl, model=dog)
    assert res.survival == 1.0, res.fall_reason
    assert res.metrics["assist_force_mg"] == 0.0
    assert res.metrics["sim_mpjpe_per_leg"] < 0.1


def test_contact_tracker_tells_a_landing_from_a_scuff() -> None:
    """A swing foot touching the ground counts as an early touch-down only late in its
    swing and near its swing target; a touch at mid-swing, or far behind the path, is a
    scuff and the foot keeps swinging (planted half a step short, it would carry the body
    on a support polygon the plan never had)."""
    from habitsim.controllers.swing import STANCE, SWING, ContactTracker

    sched = np.array([False, True])
    touch = np.array([True, True])
    tr = ContactTracker(2)
    assert tr.update(0.0, sched, touch, np.array([0.6, np.nan]))[0] == SWING  # mid-swing
    tr = ContactTracker(2)
    near = np.array([False, True])
    assert tr.update(0.0, sched, touch, np.array([0.9, np.nan]), near)[0] == SWING  # far
    assert tr.update(0.0, sched, touch, np.array([0.9, np.nan]), ~near)[0] == STANCE
    assert tr.events["early_touchdown"] == 1
    cfg = BalanceConfig.scaled(25.0, 0.6)
    assert cfg.early_phase == 0.75 and cfg.early_reach == pytest.approx(0.06)


def test_track_balance_far_below_the_floor(tmp_path: Path, capsys) -> None:
    """A cat 100 km under the floor held by the balance controller: the stance QP's
    least-squares fallback met a matrix singular in floating point (LinAlgError)."""
    from habitsim.motion import Motion
    from habitsim.skeleton import get_skeleton

    root, rot = get_skeleton("cat").standing_pose()
    rp = np.repeat(root[None], 7, axis=0)
    rp[:, 2] = -1e5
    q = np.zeros((7, rot.shape[0], 4))
    q[..., 0] = 1.0
    contacts = np.array(
        [[0, 0, 1, 1], [1, 1, 1, 1], [1, 0, 0, 0], [1, 0, 1, 0], [0, 0, 1, 1], [0, 0, 1, 1]]
        + [[0, 0, 0, 1]],
        dtype=bool,
    )
    src = tmp_path / "cat.npz"
    Motion("cat", 30.0, rp, q, contacts, {"action": "trot"}).save(src)
    argv = ["track", src, "--controller", "balance", "--out", tmp_path / "o.npz"]
    code, err = run_cli([*argv, "--settle", "0.3", "--control-hz", "1", "--assist", "root"], capsys)
    assert code in (0, 1) or (code == 2 and err.startswith("error: ")), err
