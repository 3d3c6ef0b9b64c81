"""Convex single-rigid-body MPC (issue [6/6]): the model, the QP, and locomotion on the
hand-written 12-DoF robot and the dog (mujoco 4.0.0). No external force anywhere."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest
from scipy.linalg import expm

from habitsim.controllers import (
    CONTROLLER_NAMES,
    CONTROLLERS,
    BalanceController,
    ControllerError,
    ConvexMPC,
    MPCController,
    MPCWeights,
    PDController,
    Reference,
    make_controller,
    plan_from_qpos,
)
from habitsim.controllers.mpc import NX, srb_matrices
from habitsim.controllers.swing import SWING

ROBOT_XML = Path(__file__).parent / "data" / "quadruped12.xml"
MASS, DT, MU = 19.5, 0.03, 0.6
INERTIA = np.diag([0.12, 0.35, 0.4])
FEET = np.array([[0.19, 0.13, 0.0], [0.19, -0.13, 0.0], [-0.19, 0.13, 0.0], [-0.19, -0.13, 0.0]])


@pytest.fixture(scope="module")
def robot() -> mujoco.MjModel:
    return mujoco.MjModel.from_xml_path(str(ROBOT_XML))


def problem(n: int = 10, seed: int = 0):
    """A trotting horizon: diagonal pairs alternate every 3 steps, the state starts tilted
    and moving, the reference walks forward and turns."""
    rng = np.random.default_rng(seed)
    x0 = np.r_[0.05, -0.04, 0.3, 0.0, 0.0, 0.28, 0.2, -0.1, 0.3, 0.1, -0.05, 0.05, 9.81]
    xref = np.zeros((n, NX))
    for k in range(n):
        t = DT * (k + 1)
        xref[k] = np.r_[0, 0, 0.3 + 0.5 * t, 0.4 * t, 0, 0.28, 0, 0, 0.5, 0.4, 0, 0, 9.81]
    yaw = xref[:, 2].copy()
    r = np.array(
        [FEET + rng.normal(0, 0.01, FEET.shape) - [0.4 * DT * k, 0, 0.28] for k in range(n)]
    )
    contacts = np.ones((n, 4), dtype=bool)
    for k in range(n):
        if (k // 3) % 2:
            contacts[k, [0, 3]] = False
        else:
            contacts[k, [1, 2]] = False
    return x0, xref, r, yaw, contacts


def test_discretisation_is_exact() -> None:
    """x_{k+1} = A_d x_k + B_d u_k equals the matrix exponential of the continuous model."""
    r = FEET - [0.0, 0.0, 0.28]
    ad, bd = srb_matrices(0.7, np.linalg.inv(INERTIA), r, MASS, DT)
    c, s = np.cos(0.7), np.sin(0.7)
    rz = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
    a = np.zeros((NX, NX))
    a[0:3, 6:9] = rz.T
    a[3:6, 9:12] = np.eye(3)
    a[11, 12] = -1.0
    b = bd.copy()
    b[:] = 0.0
    iw = rz @ np.linalg.inv(INERTIA) @ rz.T
    for i, ri in enumerate(r):
        skew = np.array([[0, -ri[2], ri[1]], [ri[2], 0, -ri[0]], [-ri[1], ri[0], 0]])
        b[6:9, 3 * i : 3 * i + 3] = iw @ skew
        b[9:12, 3 * i : 3 * i + 3] = np.eye(3) / MASS
    big = np.zeros((NX + 12, NX + 12))
    big[:NX, :NX], big[:NX, NX:] = a, b
    e = expm(big * DT)
    np.testing.assert_allclose(ad, e[:NX, :NX], atol=1e-12)
    np.testing.assert_allclose(bd, e[:NX, NX:], atol=1e-12)


@pytest.mark.parametrize("solver", ["osqp", "proxqp"])
def test_prediction_matches_forward_simulation(solver: str) -> None:
    """The MPC's predicted states are a forward simulation of its own model under its own
    forces: the numpy roll-out of the discrete model and a fine-step integration of the
    continuous one (forces held over each step) give the same states."""
    n = 10
    x0, xref, r, yaw, contacts = problem(n)
    q, rw = MPCWeights().scaled(MASS, 0.27, 9.81)
    mpc = ConvexMPC(n, 4, solver, tolerance=1e-6)
    sol = mpc.solve(
        x0,
        xref,
        r,
        yaw,
        INERTIA,
        contacts,
        mass=MASS,
        dt=DT,
        mu=MU,
        fz_max=2.0 * MASS * 9.81,
        q=q,
        rw=rw,
    )
    assert sol.ok
    pred = ConvexMPC.predict(x0, sol.forces, r, yaw, INERTIA, mass=MASS, dt=DT)
    np.testing.assert_allclose(sol.states, pred, atol=2e-4)
    # fine-step semi-implicit Euler of the continuous model
    x = x0.copy()
    sub = 400
    h = DT / sub
    iinv = np.linalg.inv(INERTIA)
    for k in range(n):
        c, s = np.cos(yaw[k]), np.sin(yaw[k])
        rz = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
        f = sol.forces[k]
        wd = rz @ iinv @ rz.T @ np.cross(r[k], f).sum(axis=0)
        vd = f.sum(axis=0) / MASS - [0, 0, x[12]]
        for _ in range(sub):
            x[0:3] += h * (rz.T @ (x[6:9] + 0.5 * h * wd))
            x[3:6] += h * (x[9:12] + 0.5 * h * vd)
            x[6:9] += h * wd
            x[9:12] += h * vd
        np.testing.assert_allclose(x, pred[k], atol=1e-9)


def test_mpc_forces_follow_schedule_friction_and_bounds() -> None:
    n = 10
    x0, xref, r, yaw, contacts = problem(n, seed=1)
    q, rw = MPCWeights().scaled(MASS, 0.27, 9.81)
    fz_max = 1.2 * MASS * 9.81
    sol = ConvexMPC(n, 4).solve(
        x0, xref, r, yaw, INERTIA, contacts, mass=MASS, dt=DT, mu=MU, fz_max=fz_max, q=q, rw=rw
    )
    assert sol.ok
    f = sol.forces
    assert np.all(f[~contacts] == 0.0)
    assert np.all(f[..., 2] >= 0.0) and np.all(f[..., 2] <= fz_max + 1e-9)
    assert np.all(np.abs(f[..., :2]) <= MU * f[..., 2:3] + 1e-9)


def test_mpc_standing_equilibrium() -> None:
    """At rest on the reference, the planned forces carry the weight with no net torque."""
    n = 8
    x = np.r_[0, 0, 0, 0, 0, 0.28, 0, 0, 0, 0, 0, 0, 9.81]
    r = np.tile(FEET - [0, 0, 0.28], (n, 1, 1))
    q, rw = MPCWeights().scaled(MASS, 0.27, 9.81)
    sol = ConvexMPC(n, 4, tolerance=1e-6).solve(
        x,
        np.tile(x, (n, 1)),
        r,
        np.zeros(n),
        INERTIA,
        np.ones((n, 4), bool),
        mass=MASS,
        dt=DT,
        mu=MU,
        fz_max=MASS * 9.81,
        q=q,
        rw=rw,
    )
    f0 = sol.forces[0]
    np.testing.assert_allclose(f0.sum(axis=0), [0, 0, MASS * 9.81], atol=0.01 * MASS * 9.81)
    np.testing.assert_allclose(np.cross(r[0], f0).sum(axis=0), 0.0, atol=0.05)
    # the force penalty lets the end of the horizon sag by a few mm (R ‖u‖², not ‖u − mg‖²)
    np.testing.assert_allclose(sol.states[:, 3:6], np.tile([0, 0, 0.28], (n, 1)), atol=5e-3)


# --------------------------------------------------------------------------- robot
def trot_in_place(
    model: mujoco.MjModel,
    seconds: float = 3.0,
    fps: float = 100.0,
    stride_hz: float = 2.0,
    duty: float = 0.6,
    lift: float = 0.3,
):
    """Diagonal pairs (FL+RR, FR+RL) step in place: a swing leg bends thigh +d, calf −2d
    (its foot rises straight under the hip). Standing for the first 0.5 s."""
    q0 = model.key("home").qpos.copy()
    t = np.arange(int(seconds * fps)) / fps
    q = np.tile(q0, (len(t), 1))
    contacts = np.ones((len(t), 4), dtype=bool)
    for leg, offset in ((0, 0.0), (3, 0.0), (1, 0.5), (2, 0.5)):
        phase = (t * stride_hz - offset) % 1.0
        swing = (phase >= duty) & (t >= 0.5)
        d = lift * np.sin(np.pi * np.where(swing, (phase - duty) / (1 - duty), 0.0))
        q[:, 7 + 3 * leg + 1] += d
        q[:, 7 + 3 * leg + 2] -= 2 * d
        contacts[:, leg] = ~swing
    return q, fps, contacts


def follow(model, ctl, qpos, fps, contacts):
    """Track a clip (reference linearly interpolated, velocities by finite differences)."""
    dt = model.opt.timestep
    n = int(round((len(qpos) - 1) / fps / dt))
    vel = np.zeros((len(qpos), model.nv))
    for k in range(len(qpos) - 1):
        mujoco.mj_differentiatePos(model, vel[k], 1.0 / fps, qpos[k], qpos[k + 1])
    data = mujoco.MjData(model)
    data.qpos[:] = qpos[0]
    mujoco.mj_forward(model, data)
    ctl.set_plan(qpos, fps, contacts)
    ctl.reset(model, data)
    zero = np.zeros(model.nv)
    log = {"q": [], "touch": [], "sched": []}
    for i in range(n):
        s = i * dt * fps
        k = min(int(s), len(qpos) - 2)
        a = s - k
        q = qpos[k].copy()
        mujoco.mj_integratePos(model, q, vel[k], a / fps)
        kc = min(int(s + 0.5), len(qpos) - 1)
        ref = Reference(i * dt, q, vel[k], zero, contacts[kc])
        data.ctrl[:] = ctl.control(model, data, ref)
        mujoco.mj_step(model, data)
        log["q"].append(data.qpos.copy())
        log["touch"].append(ctl.legs.touching(data))
        log["sched"].append(contacts[kc])
    return {k: np.array(v) for k, v in log.items()}


@pytest.mark.slow
def test_robot_trots_in_place_under_mpc(robot: mujoco.MjModel) -> None:
    qpos, fps, contacts = trot_in_place(robot)
    ctl = MPCController(robot)
    log = follow(robot, ctl, qpos, fps, contacts)
    q, touch, sched = log["q"], log["touch"], log["sched"]
    z0 = robot.key("home").qpos[2]
    assert np.abs(q[:, 2] - z0).max() < 0.025  # the trunk neither sinks nor bounces
    assert np.linalg.norm(q[-1, :2] - qpos[0, :2]) < 0.05  # in place
    tilt = np.degrees(2 * np.arccos(np.clip(np.abs(q[:, 3]), 0, 1)))
    assert tilt.max() < 8.0
    late = touch[int(0.6 / robot.opt.timestep) :]
    # every foot really steps: it leaves the ground ≥ 4 times, about as long as planned
    for f in range(4):
        lifts = np.count_nonzero(late[1:, f] < late[:-1, f])
        assert lifts >= 4, f"foot {f} lifted {lifts} times"
    share = late.mean(axis=0)
    np.testing.assert_allclose(
        share, sched[int(0.6 / robot.opt.timestep) :].mean(axis=0), atol=0.15
    )
    st = ctl.stats.to_dict()
    assert st["mpc_solves"] >= 80 and st["mpc_failures"] == 0
    assert st["mpc_horizon_steps"] * st["mpc_dt_s"] >= 0.5 - 1e-9  # ≥ one stride


@pytest.mark.slow
def test_robot_trots_in_place_under_balance(robot: mujoco.MjModel) -> None:
    qpos, fps, contacts = trot_in_place(robot)
    log = follow(robot, BalanceController(robot), qpos, fps, contacts)
    z0 = robot.key("home").qpos[2]
    assert np.abs(log["q"][:, 2] - z0).max() < 0.025
    assert np.linalg.norm(log["q"][-1, :2] - qpos[0, :2]) < 0.05


@pytest.mark.slow
@pytest.mark.parametrize(
    ("action", "seed", "max_mpjpe_per_leg", "min_solves"),
    [("walk", 2, 0.10, 80), ("trot", 0, 0.12, 80)],
)
def test_dog_mpc_unassisted(
    action: str, seed: int, max_mpjpe_per_leg: float, min_solves: int
) -> None:
    """The issue's cases: a dog's walk and (flying) trot under the MPC, no external force."""
    from habitsim.gaits import generate
    from habitsim.qpos import load_species_model, motion_to_qpos
    from habitsim.sim import track

    dog = load_species_model("dog")
    motion = generate("dog", action, seed=seed, duration_s=3.0)
    ctl = make_controller(
        "mpc",
        dog,
        "dog",
        qpos=motion_to_qpos(motion, dog).qpos,
        fps=motion.fps,
        contacts=motion.contacts,
    )
    res = track(motion, controller=ctl, model=dog)
    assert res.survival == 1.0, res.fall_reason
    assert res.metrics["assist_force_mg"] == 0.0
    assert res.metrics["sim_mpjpe_per_leg"] < max_mpjpe_per_leg
    st = res.controller_stats
    assert st["mpc_failures"] == 0 and st["mpc_solves"] >= min_solves


# --------------------------------------------------------------------------- API
def test_make_controller(robot: mujoco.MjModel) -> None:
    assert CONTROLLER_NAMES == CONTROLLERS and {"pd", "balance", "mpc"} <= set(CONTROLLERS)
    assert isinstance(make_controller("pd", robot), PDController)
    ctl = make_controller("balance", robot)
    assert isinstance(ctl, BalanceController) and ctl.plan is None
    qpos, fps, contacts = trot_in_place(robot, seconds=1.0)
    ctl = make_controller("mpc", robot, qpos=qpos, fps=fps, contacts=contacts, rate_hz=40.0)
    assert isinstance(ctl, MPCController) and ctl.plan is not None
    assert ctl.dt_mpc == pytest.approx(1 / 40) and ctl.steps * ctl.dt_mpc >= 0.5 - 1e-9
    with pytest.raises(ControllerError, match="valid: balance, mpc, pd, servo"):
        make_controller("lqr", robot)
    with pytest.raises(ControllerError, match="unknown balance option"):
        make_controller("balance", robot, stiffness=3.0)
    with pytest.raises(ControllerError, match="unknown pd option"):
        make_controller("pd", robot, mu=0.5)
    dog_scaled = make_controller("balance", robot, "dog")
    assert dog_scaled.config.leg_length == pytest.approx(0.61)


def test_plan_contact_schedule(robot: mujoco.MjModel) -> None:
    qpos, fps, contacts = trot_in_place(robot, seconds=2.0)
    plan = plan_from_qpos(robot, qpos, fps, contacts)
    assert plan.stride_s == pytest.approx(0.5, abs=0.02)
    s = plan.sample(0.5 + 0.25 * 0.5)  # FL swings from t=0.8 … first swing of FR at 0.55
    assert not s.contacts[1] and s.contacts[0]
    assert 0.0 < s.phase[1] < 1.0 and np.isnan(s.phase[0])
    assert s.t_liftoff[1] < s.t < s.t_touchdown[1]
    np.testing.assert_allclose(s.foothold[1], plan.feet[plan.frame(s.t_touchdown[1]), 1], atol=1e-9)
    # the default contact rule (foot heights) finds the same schedule
    auto = plan_from_qpos(robot, qpos, fps)
    assert np.mean(auto.contacts == contacts) > 0.9
    assert SWING == 1


# --------------------------------------------------------------------------- trot fixes
def test_plan_schedule_between_frames(robot: mujoco.MjModel) -> None:
    """The reference is interpolated between frames: a foot labelled swing at frame k−1 and
    stance at k lands at frame k, one labelled stance at k and swing at k+1 leaves right
    after frame k. Between frames a foot is in stance only if both frames are stance."""
    qpos, fps, contacts = trot_in_place(robot, seconds=2.0, fps=20.0)
    plan = plan_from_qpos(robot, qpos, fps, contacts)
    foot = 1
    c = contacts[:, foot]
    td = next(k for k in range(1, len(c)) if c[k] and not c[k - 1])  # first touch-down
    lo = next(k for k in range(td, len(c)) if not c[k])  # next first swing frame
    mid = (td - 0.5) / fps
    assert not plan.contacts_at(np.array([mid]))[0, foot]
    assert not plan.sample(mid).contacts[foot]
    assert plan.sample(td / fps).contacts[foot]
    assert plan.contacts_at(np.array([(lo - 1) / fps]))[0, foot]
    after = (lo - 0.5) / fps
    s = plan.sample(after)
    assert not s.contacts[foot] and not plan.contacts_at(np.array([after]))[0, foot]
    # the swing runs from the last stance frame to the next stance frame
    assert s.t_liftoff[foot] == pytest.approx((lo - 1) / fps)
    nxt = next(k for k in range(lo, len(c)) if c[k])
    assert s.t_touchdown[foot] == pytest.approx(nxt / fps)
    assert 0.0 < s.phase[foot] < 0.5
    np.testing.assert_allclose(s.foothold[foot], plan.feet[nxt, foot], atol=1e-12)


def test_foothold_follows_the_body(robot: mujoco.MjModel) -> None:
    """Raibert: the foothold moves with the body (relative to the hip), plus a bounded
    stepping feedback that makes position and velocity errors decay."""
    ctl = BalanceController(robot)
    sw, cfg = ctl.swing, ctl.config
    com_ref, v0 = np.array([1.0, 2.0, 0.3]), np.zeros(3)
    e = np.array([0.01, -0.005, 0.0])
    d = sw.correction(com_ref + e, v0, com_ref, v0, 0.3, 9.81)
    np.testing.assert_allclose(d, (1.0 + cfg.capture_pos_gain) * e, atol=1e-12)
    big = np.array([0.0, 1.0, 0.0])  # far off: follows fully, feedback saturated
    d = sw.correction(com_ref + big, v0, com_ref, v0, 0.3, 9.81)
    np.testing.assert_allclose(d, big + [0.0, cfg.capture_max, 0.0], atol=1e-12)
    dv = np.array([0.1, 0.0, 0.0])  # a velocity error: step onto its capture point
    d = sw.correction(com_ref, dv, com_ref, v0, 0.3, 9.81)
    np.testing.assert_allclose(d, cfg.capture_gain * dv * np.sqrt(0.3 / 9.81), atol=1e-12)


def test_foothold_feedback_bounded_per_axis(robot: mujoco.MjModel) -> None:
    """The stepping feedback is bounded forward and sideways separately (along the
    heading): a saturated forward error leaves the sideways feedback intact."""
    sw = BalanceController(robot).swing
    m, w = sw.capture_max, np.sqrt(0.3 / 9.81)
    com_ref = np.array([1.0, 2.0, 0.3])
    for yaw in (0.0, 0.7):
        h, n = np.array([np.cos(yaw), np.sin(yaw), 0.0]), np.array([-np.sin(yaw), np.cos(yaw), 0.0])
        v_ref = 2.0 * h  # moving along the heading
        dv = 10.0 * m / w * h + 0.3 * m / w * n  # forward error saturates, sideways not
        d = sw.correction(com_ref, v_ref + dv, com_ref, v_ref, 0.3, 9.81, yaw)
        np.testing.assert_allclose(d, m * h + sw.capture_gain * 0.3 * m * n, atol=1e-9)
        # without heading or reference speed: per world axis
        d = sw.correction(com_ref, dv, com_ref, np.zeros(3), 0.3, 9.81)
        assert abs(d[0]) <= m + 1e-12 and abs(d[1]) <= m + 1e-12


def test_joint_damping_is_compensated(robot: mujoco.MjModel) -> None:
    """The joints' own viscous damping is added to the torques (else a fast stance leg
    brakes the trunk and a swing leg lags its path)."""
    from habitsim.controllers.swing import STANCE

    plain = mujoco.MjModel.from_xml_path(str(ROBOT_XML))
    plain.dof_damping[:] = 0.0
    rng = np.random.default_rng(3)
    out = []
    for m in (robot, plain):
        ctl = BalanceController(m)
        data = mujoco.MjData(m)
        data.qpos[:] = m.key("home").qpos
        data.qvel[:] = rng.normal(size=m.nv) if not out else out[0][1]
        mujoco.mj_forward(m, data)
        ctl.reset(m, data)
        nf, n = ctl.legs.n_feet, len(ctl.joint_names)
        ref = Reference(0.1, data.qpos.copy(), data.qvel.copy(), np.zeros(m.nv), None)
        tau, _ = ctl._other_torques(
            m, data, ref, np.zeros((nf, 3, n + 1)), np.zeros((nf, 3)), np.full(nf, STANCE)
        )
        out.append((tau, data.qvel.copy(), ctl._dof))
    (tau_d, qvel, dof), (tau_p, _, _) = out
    np.testing.assert_allclose(tau_d - tau_p, robot.dof_damping[dof] * qvel[dof], atol=1e-9)
    assert np.abs(tau_d - tau_p).max() > 0.0


def test_mpc_uses_the_centroidal_angular_velocity() -> None:
    """The MPC's ω is the whole body's I_c⁻¹ h_c (what the ground forces change); the
    balance PD keeps the trunk body's own rate (the rate of its orientation error)."""
    from habitsim.qpos import load_species_model

    dog = load_species_model("dog")
    data = mujoco.MjData(dog)
    data.qpos[:] = dog.qpos0
    data.qpos[2] += 0.5
    data.qvel[:] = np.random.default_rng(0).normal(size=dog.nv)
    mujoco.mj_forward(dog, data)
    mpc, bal = MPCController(dog, leg_length=0.61), BalanceController(dog, leg_length=0.61)
    for c in (mpc, bal):
        c.reset(dog, data)
    _, _, rot, w_mpc = mpc._trunk_state(dog, data)
    _, _, _, w_bal = bal._trunk_state(dog, data)
    tr = mpc.legs.trunk
    np.testing.assert_allclose(
        w_mpc, np.linalg.solve(mpc._inertia, data.subtree_angmom[tr]), atol=1e-9
    )
    da = mpc.legs.dadr
    np.testing.assert_allclose(w_bal, rot @ data.qvel[da + 3 : da + 6], atol=1e-12)
    assert np.linalg.norm(w_mpc - w_bal) > 0.1  # the legs and spine move: they differ


@pytest.mark.slow
def test_mpc_solves_again_on_contact_change(robot: mujoco.MjModel) -> None:
    qpos, fps, contacts = trot_in_place(robot, seconds=1.5)
    counts = {}
    for flag in (True, False):
        ctl = MPCController(robot, resolve_on_contact=flag)
        follow(robot, ctl, qpos, fps, contacts)
        counts[flag] = ctl.stats.to_dict()["mpc_solves"]
    periodic = int(np.ceil((len(qpos) - 1) / fps * 30.0))
    assert abs(counts[False] - periodic) <= 1
    assert counts[True] >= counts[False] + 4  # the trot's lift-offs and touch-downs


def test_mpc_integral_action_on_forward_lag(robot: mujoco.MjModel) -> None:
    ctl = MPCController(robot, integral_rate=2.0, integral_max=0.1)
    ctl.integral[:] = 0.0
    heading = 0.5
    h = np.array([np.cos(heading), np.sin(heading)])
    side = np.array([-h[1], h[0]])
    com = np.zeros(3)
    ref = np.zeros(3)
    ref[:2] = 0.02 * h + 0.05 * side  # ahead of the CoM and to its side
    ctl._integrate(0.0, False, com, ref, heading)  # first call: starts the clock
    assert np.all(ctl.integral == 0.0)
    ctl._integrate(0.1, False, com, ref, heading)
    # only the forward lag is integrated: k_i · dt · e_fwd along the heading
    np.testing.assert_allclose(ctl.integral, 2.0 * 0.1 * 0.02 * h, atol=1e-12)
    for k in range(2, 200):  # bounded by integral_max leg lengths
        ctl._integrate(0.1 * k, False, com, ref, heading)
    assert np.linalg.norm(ctl.integral) == pytest.approx(0.1 * ctl.config.leg_length)
    ctl._integrate(30.0, True, com, ref, heading)  # holding: no integration, clock stops
    assert ctl._t_int is None
    with pytest.raises(ControllerError):
        MPCController(robot, integral_rate=-1.0)
