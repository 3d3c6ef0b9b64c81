"""habitsim.controllers on a hand-written 12-DoF robot (not built by habitsim) and the dog.

Golden figures measured with mujoco 4.0.0 (see the hold tests for the tolerances).
"""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest

from habitsim.controllers import (
    ControllerError,
    InverseDynamicsFeedforward,
    PDController,
    Reference,
    RootAssist,
    ServoController,
    StabilizedController,
    TrunkStabilizer,
    configure_servos,
    critical_damping,
    distribute_wrench,
    effective_inertia,
    max_stable_kd,
    servo_map,
    stiffness_rule,
)
from habitsim.controllers import stance as stance_mod
from habitsim.controllers.gains import joint_space_inertia

ROBOT_XML = Path(__file__).parent / "data" / "quadruped12.xml"
DOG_SCENE = Path(__file__).resolve().parents[1] / "mjcf_models" / "dog" / "scene_torque.xml"
FEET = ["FL_foot", "FR_foot", "RL_foot", "RR_foot"]
JOINTS = [f"{leg}_{j}" for leg in ("FL", "FR", "RL", "RR") for j in ("hip", "thigh", "calf")]


@pytest.fixture(scope="module")
def robot() -> mujoco.MjModel:
    return mujoco.MjModel.from_xml_path(str(ROBOT_XML))


def home_data(model: mujoco.MjModel) -> mujoco.MjData:
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key("home").id)
    mujoco.mj_forward(model, data)
    return data


def standing_ref(model: mujoco.MjModel, contacts=None) -> Reference:
    q = model.key("home").qpos.copy()
    return Reference(0.0, q, np.zeros(model.nv), np.zeros(model.nv), contacts)


def quat_angle_deg(q1: np.ndarray, q2: np.ndarray) -> float:
    return float(np.degrees(2 * np.arccos(min(1.0, abs(float(np.dot(q1, q2)))))))


def hold(model: mujoco.MjModel, controller, seconds: float) -> dict[str, float]:
    """Run ``controller`` on a standing reference; worst height error and tilt."""
    data = home_data(model)
    ref = standing_ref(model)
    controller.reset(model, data)
    z0, quat0 = ref.qpos[2], ref.qpos[3:7]
    worst_dz, worst_tilt, free_force = 0.0, 0.0, 0.0
    for _ in range(int(round(seconds / model.opt.timestep))):
        data.ctrl[:] = controller.control(model, data, ref)
        mujoco.mj_step(model, data)
        worst_dz = max(worst_dz, abs(data.qpos[2] - z0) / z0)
        worst_tilt = max(worst_tilt, quat_angle_deg(data.qpos[3:7], quat0))
        free_force = max(free_force, float(np.abs(data.qfrc_applied[:6]).max()))
    return {
        "height": data.qpos[2] / z0,
        "worst_dz": worst_dz,
        "tilt": worst_tilt,
        "free_force": free_force,
        "data": data,
    }


def assert_holds(res: dict, height_tol: float = 0.05, tilt_deg: float = 5.0) -> None:
    assert res["worst_dz"] < height_tol, res
    assert res["tilt"] < tilt_deg, res
    assert res["free_force"] == 0.0  # nothing ever pushed the free joint: no assistance


# ---------------------------------------------------------------------------- holding home


def test_explicit_pd_with_gain_rule_holds_home(robot) -> None:
    kp = stiffness_rule(robot, mode="gravity")
    kd = critical_damping(robot, kp)
    assert np.all(kd < max_stable_kd(robot))  # explicit PD inside its stability limit
    ctrl = PDController(robot, kp, kd)
    res = hold(robot, ctrl, 4.0)
    assert_holds(res)
    assert ctrl.assist is None


def test_in_engine_servos_hold_home(robot) -> None:
    model = configure_servos(robot)
    res = hold(model, ServoController(model), 4.0)
    assert_holds(res)


def test_pd_with_inverse_dynamics_feedforward_holds_home(robot) -> None:
    kp = stiffness_rule(robot, mode="torque")
    kd = critical_damping(robot, kp)
    ctrl = PDController(robot, kp, kd, feedforward=InverseDynamicsFeedforward(robot))
    assert_holds(hold(robot, ctrl, 4.0))


@pytest.mark.slow
def test_pd_with_trunk_stabiliser_holds_home_better(robot) -> None:
    kp = stiffness_rule(robot)
    kd = critical_damping(robot, kp)
    plain = hold(robot, PDController(robot, kp, kd), 3.0)
    ctrl = StabilizedController(PDController(robot, kp, kd), TrunkStabilizer(robot, FEET))
    res = hold(robot, ctrl, 3.0)
    assert_holds(res, height_tol=0.02)
    assert abs(res["height"] - 1) < abs(plain["height"] - 1)  # it carries the weight
    stats = ctrl.stats.to_dict()
    assert stats["failures"] == 0 and stats["calls"] == 1500
    assert stats["stance_mean_time_ms"] > 0


@pytest.mark.slow
def test_servo_with_feedforward_and_stabiliser_reports_effort(robot) -> None:
    model = configure_servos(robot)
    base = ServoController(model, feedforward=InverseDynamicsFeedforward(model))
    ctrl = StabilizedController(base, TrunkStabilizer(model, FEET))
    res = hold(model, ctrl, 3.0)
    assert_holds(res, height_tol=0.02)
    assert ctrl.stats.extra["ff_mean_abs_Nm"] > 0.1
    # feed-forward went to the joint dofs only and stayed within the motor limits
    data = res["data"]
    smap = servo_map(model)
    np.testing.assert_array_equal(data.qfrc_applied[:6], 0.0)
    total = base.joint_torques(model, data)
    assert np.all(np.abs(total) <= smap.torque_limit + 1.0)  # +1 N·m: one-step prediction


def test_pid_servos_from_spec_hold_home(robot) -> None:
    spec = mujoco.MjSpec.from_file(str(ROBOT_XML))
    model = configure_servos(spec, kind="pid", ki=200.0, imax=10.0)
    assert model.na == 12
    assert set(servo_map(model).kind) == {"pid"}
    res = hold(model, ServoController(model), 3.0)
    assert_holds(res)
    position = configure_servos(robot)
    plain = hold(position, ServoController(position), 3.0)
    assert abs(res["height"] - 1) < 0.01 < abs(plain["height"] - 1)  # integral removes the sag


@pytest.mark.slow
def test_dog_servos_with_stabiliser_hold_home() -> None:
    dog = mujoco.MjModel.from_xml_path(str(DOG_SCENE))  # plain MuJoCo loading
    model = configure_servos(dog)
    feet = ["lf_foot", "rf_foot", "lh_foot", "rh_foot"]
    ctrl = StabilizedController(ServoController(model), TrunkStabilizer(model, feet))
    res = hold(model, ctrl, 3.0)
    assert_holds(res)
    assert ctrl.stats.failures == 0


# ------------------------------------------------------------------------------- servos


def test_configure_servos_copies_and_keeps_torque_limits(robot) -> None:
    before = {
        k: getattr(robot, k).copy()
        for k in (
            "actuator_gainprm",
            "actuator_biasprm",
            "actuator_gear",
            "actuator_ctrlrange",
            "actuator_forcerange",
            "actuator_forcelimited",
            "actuator_biastype",
        )
    }
    model = configure_servos(robot, dampratio=1.0)
    for k, v in before.items():
        np.testing.assert_array_equal(getattr(robot, k), v, err_msg=k)  # input untouched
    assert model is not robot
    smap = servo_map(model)
    limit = np.abs(robot.actuator_ctrlrange[:, 1])  # motors: gear 1, symmetric
    np.testing.assert_allclose(smap.torque_limit, limit)
    np.testing.assert_array_equal(model.actuator_forcelimited, 1)
    jids = [robot.joint(n).id for n in smap.names]
    np.testing.assert_allclose(model.actuator_ctrlrange, robot.jnt_range[jids])
    np.testing.assert_allclose(smap.kp, limit / 0.15)  # default rule τmax / 0.15 rad
    m_ii = np.diag(joint_space_inertia(robot))[smap.dof_adr]
    np.testing.assert_allclose(smap.kv, 2 * np.sqrt(smap.kp * m_ii))
    # a servo far from its target saturates exactly at the motor's limit
    data = home_data(model)
    data.ctrl[:] = model.actuator_ctrlrange[:, 1]
    mujoco.mj_forward(model, data)
    assert np.all(np.abs(data.actuator_force) <= limit + 1e-9)
    assert np.isclose(np.abs(data.actuator_force).max(), limit.max())


def test_configure_servos_geared_general_actuator() -> None:
    xml = """<mujoco><compiler angle="radian"/><worldbody><body>
      <joint name="j" axis="0 1 0" range="-1 1"/>
      <geom size=".05" pos="0 0 -.3" mass="2"/></body></worldbody><actuator>
      <general joint="j" gear="3" gainprm="2" ctrlrange="-1.5 1.5"/></actuator></mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    servo = configure_servos(model, kp=50.0)
    smap = servo_map(servo)
    np.testing.assert_allclose(smap.torque_limit, [3 * 2 * 1.5])  # gear · gain · ctrl
    np.testing.assert_allclose(smap.kp, [50.0])
    # holds an angle against gravity with the small static error kp predicts
    ctrl = ServoController(servo)
    data = mujoco.MjData(servo)
    ref = Reference(0.0, np.array([0.4]), np.zeros(1), np.zeros(1))
    for _ in range(2000):
        data.ctrl[:] = ctrl.control(servo, data, ref)
        mujoco.mj_step(servo, data)
    sag = 2 * 9.81 * 0.3 * np.sin(data.qpos[0]) / 50.0
    assert data.qpos[0] == pytest.approx(0.4 - sag, abs=2e-3)


def _swing_tracking_error(servo: mujoco.MjModel, velocity_lead: bool) -> float:
    """RMS error [rad] of a servo following a 2 Hz, ±0.6 rad swing for 2 s."""
    ctrl = ServoController(servo, velocity_lead=velocity_lead)
    data = mujoco.MjData(servo)
    w, amp, dt = 2 * np.pi * 2.0, 0.6, servo.opt.timestep
    data.qvel[0] = amp * w
    err = []
    for k in range(int(2.0 / dt)):
        t = k * dt
        ref = Reference(
            t,
            np.array([amp * np.sin(w * t)]),
            np.array([amp * w * np.cos(w * t)]),
            np.array([-amp * w * w * np.sin(w * t)]),
        )
        data.ctrl[:] = ctrl.control(servo, data, ref)
        mujoco.mj_step(servo, data)
        err.append(data.qpos[0] - amp * np.sin(w * (t + dt)))
    return float(np.sqrt(np.mean(np.square(err[len(err) // 4 :]))))


def test_servo_velocity_lead_damps_the_velocity_error_not_the_motion() -> None:
    xml = """<mujoco><compiler angle="radian"/>
      <option timestep="0.002" integrator="implicitfast"/><worldbody><body>
      <joint name="j" axis="0 1 0" range="-1.5 1.5"/>
      <geom type="capsule" fromto="0 0 0 0 0 -.4" size=".04" mass="3"/></body></worldbody>
      <actuator><motor joint="j" ctrlrange="-200 200"/></actuator></mujoco>"""
    servo = configure_servos(mujoco.MjModel.from_xml_string(xml), kp=300.0, dampratio=1.0)
    smap = servo_map(servo)
    q, qd = np.array([0.2]), np.array([1.5])
    # the law: q_target = q_ref + kv/kp · q̇_ref, so kp·(q_target − q) − kv·q̇ is a PD
    # on the position AND velocity errors
    np.testing.assert_allclose(smap.position_targets(q, qd), 0.2 + smap.kv / smap.kp * 1.5)
    np.testing.assert_allclose(smap.position_targets(q), [0.2])
    with_lead = _swing_tracking_error(servo, True)
    without = _swing_tracking_error(servo, False)
    # a position servo's D term on −q̇ alone brakes the swing: it lags by a large phase
    assert with_lead < 0.35 * without, (with_lead, without)
    assert with_lead < 0.05  # what is left is the inertia and gravity the servo resists


# --------------------------------------------------------------------------- PD clipping


def test_pd_torques_clipped_to_actuator_limits(robot) -> None:
    ctrl = PDController(robot, kp=1e4, kd=0.0)
    data = home_data(robot)
    ref = standing_ref(robot)
    q = ref.qpos.copy()
    q[7:] += np.where(np.arange(12) % 2 == 0, 1.0, -1.0)  # huge errors both ways
    u = ctrl.control(robot, data, Reference(0.0, q, ref.qvel, ref.qacc))
    limit = robot.actuator_ctrlrange[:, 1]
    np.testing.assert_allclose(np.abs(u), limit)
    np.testing.assert_allclose(np.sign(u), np.where(np.arange(12) % 2 == 0, 1.0, -1.0))
    np.testing.assert_allclose(np.abs(ctrl.last_torque), limit)


def test_pd_uses_general_actuator_gain() -> None:
    xml = """<mujoco><worldbody><body><joint name="j" axis="0 1 0"/><geom size=".1" mass="1"/>
      </body></worldbody><actuator><general joint="j" gear="2" gainprm="5" ctrlrange="-1 1"/>
      </actuator></mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    ctrl = PDController(model, kp=10.0, kd=0.0)
    data = mujoco.MjData(model)
    u = ctrl.control(model, data, Reference(0.0, np.array([0.3]), np.zeros(1), np.zeros(1)))
    assert u[0] == pytest.approx(3.0 / 10.0)  # 3 N·m / (gear 2 · gain 5)
    mujoco.mj_forward(model, data)
    data.ctrl[:] = u
    mujoco.mj_forward(model, data)
    assert data.qfrc_actuator[0] == pytest.approx(3.0)


# ----------------------------------------------------------------------- wrench QP / VMC


def square_feet(z: float = 0.0) -> np.ndarray:
    return np.array([[0.2, 0.12, z], [0.2, -0.12, z], [-0.2, 0.12, z], [-0.2, -0.12, z]])


def test_qp_reproduces_feasible_wrench() -> None:
    com = np.array([0.01, 0.0, 0.3])
    wanted = np.array([5.0, -3.0, 190.0, 2.0, -4.0, 1.0])
    f, ok = distribute_wrench(square_feet(), com, wanted, mu=0.8)
    assert ok
    achieved = np.concatenate([f.sum(0), np.cross(square_feet() - com, f).sum(0)])
    np.testing.assert_allclose(achieved, wanted, atol=0.05)
    assert np.all(f[:, 2] >= -1e-9)


def test_qp_respects_friction_pyramid() -> None:
    mu = 0.5
    com = np.array([0.0, 0.0, 0.3])
    wanted = np.array([150.0, 40.0, 190.0, 0.0, 0.0, 0.0])  # |F_t| > μ·F_n: infeasible
    f, ok = distribute_wrench(square_feet(), com, wanted, mu=mu, fz_max=100.0)
    assert ok
    assert np.all(f[:, 2] >= -1e-9) and np.all(f[:, 2] <= 100.0 + 1e-6)
    assert np.all(np.abs(f[:, 0]) <= mu * f[:, 2] + 1e-6)
    assert np.all(np.abs(f[:, 1]) <= mu * f[:, 2] + 1e-6)
    assert f[:, 0].sum() == pytest.approx(mu * f[:, 2].sum(), rel=1e-3)  # pushed to the edge


def test_qp_with_a_tilted_normal_is_the_rotated_flat_problem() -> None:
    from habitsim.controllers.stance_qp import ground_frame

    com = np.array([0.01, 0.0, 0.3])
    wanted = np.array([60.0, -3.0, 190.0, 2.0, -4.0, 1.0])
    flat, ok_flat = distribute_wrench(square_feet(), com, wanted, mu=0.5, fz_max=80.0)
    up = np.array([0.3, -0.2, 1.0]) / np.linalg.norm([0.3, -0.2, 1.0])
    rot = ground_frame(up)
    np.testing.assert_allclose(rot @ rot.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(rot) == pytest.approx(1.0) and np.allclose(rot[2], up)
    tilted, ok = distribute_wrench(
        (square_feet() - com) @ rot + com,
        com,
        np.concatenate([wanted[:3] @ rot, wanted[3:] @ rot]),
        mu=0.5,
        fz_max=80.0,
        up=up,
    )
    assert ok and ok_flat
    np.testing.assert_allclose(tilted, flat @ rot, atol=1e-6)


def test_one_stance_qp_for_stabiliser_balance_and_mpc() -> None:
    from habitsim.controllers import balance, mpc, stance_qp

    assert stance_mod.StanceQP is balance.StanceQP is stance_qp.StanceQP
    assert stance_mod.distribute_wrench is stance_qp.distribute_wrench
    assert issubclass(mpc.MPCController, balance.BalanceController)


def test_qp_failure_falls_back_and_is_counted(robot, monkeypatch) -> None:
    monkeypatch.setattr(
        stance_mod.StanceQP,
        "_evaluate",
        lambda self: (np.full(3 * self.n, np.nan), np.zeros_like(self._out[2])),
    )
    stab = TrunkStabilizer(robot, FEET, mu=0.5)
    data = home_data(robot)
    ref = standing_ref(robot)
    q = ref.qpos.copy()
    q[0] += 0.5  # asks for a large forward force
    stab.torques(robot, data, Reference(0.0, q, ref.qvel, ref.qacc))
    assert stab.stats.failures == 1 and stab.stats.notes
    f = stab.last_forces
    assert np.all(f[:, 2] >= 0) and np.all(np.abs(f[:, :2]) <= 0.5 * f[:, 2:3] + 1e-9)


def test_standing_stance_forces_sum_to_weight(robot) -> None:
    stab = TrunkStabilizer(robot, FEET)
    data = home_data(robot)
    stab.torques(robot, data, standing_ref(robot))
    weight = robot.body_subtreemass[1] * 9.81
    np.testing.assert_allclose(stab.last_forces.sum(0), [0, 0, weight], atol=1e-3 * weight)
    np.testing.assert_allclose(stab.last_forces[:, 2], weight / 4, rtol=0.05)  # symmetric robot
    # in simulation the real contact forces then carry the weight too
    kp = stiffness_rule(robot)
    res = hold(
        robot,
        StabilizedController(
            PDController(robot, kp, critical_damping(robot, kp)), TrunkStabilizer(robot, FEET)
        ),
        1.5,
    )
    data = res["data"]
    normal = sum(_contact_world(robot, data, i)[2] for i in range(data.ncon))
    assert normal == pytest.approx(weight, rel=0.02)


def _contact_world(model, data, i) -> np.ndarray:
    """World-frame force of contact ``i`` on its second geom (the robot's foot)."""
    f6 = np.zeros(6)
    mujoco.mj_contactForce(model, data, i, f6)
    return data.contact[i].frame.reshape(3, 3).T @ f6[:3]


def test_stance_torque_sign_pushing_legs_lift_trunk(robot) -> None:
    stab = TrunkStabilizer(robot, FEET)
    data = home_data(robot)
    ref = standing_ref(robot)
    tau = stab.torques(robot, data, ref)
    # instantaneous: with the stance torques the trunk accelerates less downward than
    # with no torques, and the OPPOSITE sign (legs pulling the feet up) makes it fall faster
    acc = {}
    for label, sign in (("none", 0.0), ("stance", 1.0), ("flipped", -1.0)):
        d = home_data(robot)
        d.ctrl[:] = sign * tau
        mujoco.mj_forward(robot, d)
        acc[label] = d.qacc[2]
    assert acc["flipped"] < acc["none"] < acc["stance"]
    # over time: a reference 3 cm higher makes the stabiliser alone lift the trunk
    q = ref.qpos.copy()
    q[2] += 0.03
    high = Reference(0.0, q, ref.qvel, ref.qacc)
    ctrl = StabilizedController(PDController(robot, 0.0, 0.0), TrunkStabilizer(robot, FEET))
    for _ in range(400):
        data.ctrl[:] = ctrl.control(robot, data, high)
        mujoco.mj_step(robot, data)
    assert data.qpos[2] > ref.qpos[2] + 0.01


def test_stance_subset_from_reference_contacts(robot) -> None:
    stab = TrunkStabilizer(robot, FEET)
    data = home_data(robot)
    ref = standing_ref(robot, contacts=np.array([True, False, False, True]))  # diagonal pair
    tau = stab.torques(robot, data, ref)
    np.testing.assert_array_equal(stab.last_forces[[1, 2]], 0.0)
    swing = [stab.joint_names.index(n) for n in ("FR_hip", "FR_thigh", "FR_calf", "RL_calf")]
    np.testing.assert_array_equal(tau[swing], 0.0)
    with pytest.raises(ControllerError, match="4 feet"):
        stab.torques(robot, data, standing_ref(robot, contacts=np.ones(3, bool)))


# ---------------------------------------------------------------------- feed-forward


def test_inverse_dynamics_feedforward_static(robot) -> None:
    flags = robot.opt.disableflags
    ff = InverseDynamicsFeedforward(robot)
    assert robot.opt.disableflags == flags  # contacts disabled on a private copy only
    data = home_data(robot)
    ref = standing_ref(robot)
    tau = ff(robot, data, ref)
    weight = robot.body_subtreemass[1] * 9.81
    np.testing.assert_allclose(ff.residual_root_wrench[:3], [0, 0, weight], rtol=1e-6, atol=1e-6)
    # static, no contacts: joint torques are the gravity torques of qfrc_bias (minus passive)
    np.testing.assert_allclose(tau, data.qfrc_bias[6:], atol=1e-9)
    assert ff.joint_names == tuple(JOINTS)
    inc = InverseDynamicsFeedforward(robot, contacts="include")
    assert np.all(np.isfinite(inc(robot, data, ref)))


# ------------------------------------------------------------------------- root assist


def test_root_assist_off_by_default_everywhere(robot) -> None:
    kp = stiffness_rule(robot)
    servo = configure_servos(robot)
    ctrls = [
        PDController(robot, kp, critical_damping(robot, kp)),
        PDController(robot, kp, 1.0, feedforward=InverseDynamicsFeedforward(robot)),
        StabilizedController(PDController(robot, kp, 1.0), TrunkStabilizer(robot, FEET)),
    ]
    for c in ctrls:
        assert c.assist is None
        assert hold(robot, c, 0.2)["free_force"] == 0.0
    for c in (
        ServoController(servo),
        StabilizedController(ServoController(servo), TrunkStabilizer(servo, FEET)),
    ):
        assert c.assist is None
        assert hold(servo, c, 0.2)["free_force"] == 0.0


def test_root_assist_holds_unactuated_body_and_reports_it() -> None:
    xml = """<mujoco><option timestep="0.002"/><worldbody><body name="box" pos="0 0 1">
      <freejoint/><geom type="box" size=".1 .1 .1" mass="3"/></body></worldbody></mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    assist = RootAssist(model)
    ref = Reference(0.0, model.qpos0.copy(), np.zeros(6), np.zeros(6))
    for _ in range(1000):  # 2 s
        assist.apply(model, data, ref)
        mujoco.mj_step(model, data)
    rep = assist.report(data)
    assert rep["assist_on"] is True
    assert rep["assist_force_mg"] == pytest.approx(1.0, rel=0.05)
    assert rep["assist_impulse_Ns"] == pytest.approx(3 * 9.81 * 2.0, rel=0.05)
    assert abs(data.qpos[2] - 1.0) < 0.02  # held (sag g/ω² ≈ 1 cm)


def test_root_assist_damping_moves_into_the_model() -> None:
    """damped_model: a copy whose free dofs carry kd; apply then writes the PD without its
    damping term, records the whole PD, and a falling box is held as before."""
    xml = """<mujoco><option timestep="0.002" integrator="implicitfast"/><worldbody>
      <body name="box" pos="0 0 1"><freejoint/><geom type="box" size=".1 .1 .1" mass="3"/>
      </body></worldbody></mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    assist = RootAssist(model, kp=(300.0, 2.0), kd=(60.0, 0.5))
    damped = assist.damped_model(model)
    np.testing.assert_array_equal(model.dof_damping, 0.0)  # the given model is unchanged
    np.testing.assert_allclose(damped.dof_damping, [60.0] * 3 + [0.5] * 3)
    data = mujoco.MjData(damped)
    data.qvel[:] = [0.1, -0.2, 0.3, 0.4, -0.5, 0.6]
    ref = Reference(0.0, damped.qpos0.copy(), np.zeros(6), np.zeros(6))
    w = assist.apply(damped, data, ref)
    np.testing.assert_allclose(w[:3], -60.0 * data.qvel[:3])  # at the reference pose
    np.testing.assert_allclose(w[3:], -0.5 * data.qvel[3:])
    np.testing.assert_allclose(data.qfrc_applied[:6], 0.0, atol=1e-12)  # the model damps
    plain = mujoco.MjData(model)  # on the undamped model the whole wrench is written
    plain.qvel[:] = data.qvel
    np.testing.assert_allclose(assist.apply(model, plain, ref), w)
    np.testing.assert_allclose(plain.qfrc_applied[:6], w)
    data = mujoco.MjData(damped)
    for _ in range(1000):  # 2 s
        assist.apply(damped, data, ref)
        mujoco.mj_step(damped, data)
    assert assist.report(data)["assist_force_mg"] == pytest.approx(1.0, rel=0.05)
    assert data.qpos[2] == pytest.approx(1.0 - 3 * 9.81 / 300.0, abs=1e-3)  # sag m·g/kp
    rk4 = mujoco.MjModel.from_xml_string(xml.replace("implicitfast", "RK4"))
    with pytest.raises(ControllerError, match="RK4"):
        RootAssist(rk4).damped_model(rk4)


def test_root_assist_in_a_controller_is_measured(robot) -> None:
    kp = stiffness_rule(robot)
    assist = RootAssist(robot)
    ctrl = PDController(robot, kp, critical_damping(robot, kp), assist=assist)
    res = hold(robot, ctrl, 1.0)
    assert res["free_force"] > 0  # it did push, and ...
    rep = assist.report(res["data"])
    assert rep["assist_calls"] == 500 and rep["assist_force_mg"] > 0  # ... it is on record
    ctrl.reset(robot, res["data"])
    assert assist.report()["assist_calls"] == 0
    np.testing.assert_array_equal(res["data"].qfrc_applied[:6], 0.0)


# --------------------------------------------------------------------------- gain rules


def test_gain_rules_on_a_pendulum() -> None:
    xml = """<mujoco><worldbody><body><joint name="j" axis="0 1 0" armature="0.01"/>
      <geom type="sphere" size=".01" pos=".5 0 0" mass="2"/></body></worldbody>
      <actuator><motor joint="j" ctrlrange="-30 30"/></actuator></mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    inertia = 2 * 0.5**2 + 2 * 0.4 * 0.01**2 + 0.01  # point + sphere + armature
    assert effective_inertia(model)[0] == pytest.approx(inertia, rel=1e-6)
    kp = stiffness_rule(model, mode="gravity", deflection=0.1)
    assert kp[0] == pytest.approx(2 * 9.81 * 0.5 / 0.1, rel=1e-6)
    assert stiffness_rule(model, mode="torque")[0] == pytest.approx(30 / 0.15)
    assert stiffness_rule(model, mode="inertia", frequency_hz=2.0)[0] == pytest.approx(
        inertia * (4 * np.pi) ** 2
    )
    assert critical_damping(model, 100.0, ratio=0.5)[0] == pytest.approx(np.sqrt(100 * inertia))
    kd_max = max_stable_kd(model, 0.002, margin=1.0)[0]
    assert kd_max == pytest.approx(2 * inertia / 0.002, rel=1e-3)


# --------------------------------------------------------------------------- bad inputs


def test_unknown_joint_lists_valid_names(robot) -> None:
    with pytest.raises(ControllerError, match="FL_hip") as err:
        PDController(robot, 1.0, 0.1, joints=["FL_hipp"])
    assert "FL_hipp" in str(err.value) and "RR_calf" in str(err.value)
    with pytest.raises(ControllerError, match="valid"):
        configure_servos(robot, joints=["knee"])
    with pytest.raises(ControllerError, match="FL_foot"):
        TrunkStabilizer(robot, ["FL_toe"])


def test_bad_gains_and_kinds(robot) -> None:
    with pytest.raises(ControllerError, match="non-negative"):
        PDController(robot, -1.0, 0.1)
    with pytest.raises(ControllerError, match="non-negative"):
        PDController(robot, 1.0, np.full(12, -0.1))
    with pytest.raises(ControllerError):
        PDController(robot, np.ones(5), 0.1)
    with pytest.raises(ControllerError, match="kp"):
        configure_servos(robot, kp=-5.0)
    with pytest.raises(ControllerError, match="dampratio"):
        configure_servos(robot, dampratio=-1.0)
    with pytest.raises(ControllerError, match="kind"):
        configure_servos(robot, kind="velocity")
    with pytest.raises(ControllerError, match="MjSpec"):
        configure_servos(robot, kind="pid")
    with pytest.raises(ControllerError, match="kp"):
        critical_damping(robot, -1.0)
    with pytest.raises(ControllerError, match="mode"):
        stiffness_rule(robot, mode="magic")
    with pytest.raises(ControllerError, match="mu"):
        TrunkStabilizer(robot, FEET, mu=-0.1)
    with pytest.raises(ControllerError, match="kp"):
        RootAssist(robot, kp=-1.0)
    with pytest.raises(ControllerError, match="ServoController"):
        PDController(configure_servos(robot), 1.0, 0.1)
    with pytest.raises(ControllerError, match="configure_servos"):
        ServoController(robot)


def test_nan_or_misshaped_reference_rejected(robot) -> None:
    ctrl = PDController(robot, 10.0, 0.1)
    data = home_data(robot)
    ref = standing_ref(robot)
    q = ref.qpos.copy()
    q[8] = np.nan
    with pytest.raises(ControllerError, match="not finite"):
        ctrl.control(robot, data, Reference(0.0, q, ref.qvel, ref.qacc))
    with pytest.raises(ControllerError, match="shape"):
        ctrl.control(robot, data, Reference(0.0, ref.qpos[:-1], ref.qvel, ref.qacc))
    servo = configure_servos(robot)
    with pytest.raises(ControllerError, match="not finite"):
        ServoController(servo).control(
            servo, home_data(servo), Reference(0.0, ref.qpos, ref.qvel * np.nan, ref.qacc)
        )


def test_swing_reexports_the_legs_plan_and_contact_state_modules() -> None:
    from habitsim.controllers import contact_state, legs, plan, swing

    assert swing.LegSet is legs.LegSet and swing.default_feet is legs.default_feet
    assert swing.model_leg_length is legs.model_leg_length
    assert swing.MotionPlan is plan.MotionPlan and swing.plan_from_qpos is plan.plan_from_qpos
    assert swing.rpy_from_matrix is plan.rpy_from_matrix
    assert swing.ContactTracker is contact_state.ContactTracker
    assert (swing.STANCE, swing.SWING, swing.SEEK) == (0, 1, 2)
    assert set(swing.__all__) <= set(dir(swing))
