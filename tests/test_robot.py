"""The controllers on a robot habitsim did not build: MuJoCo Menagerie's Unitree Go1.

The Go1 (tests/robots/unitree_go1, collision primitives only) has position servos and
names its feet ``FL``, ``FR``, ``RL``, ``RR``; docs/controllers.md's robot section must run on it as
written, and ``habitsim.sim.track`` must simulate it with fall detection and metrics.
"""

from __future__ import annotations

import re
from pathlib import Path

import mujoco
import numpy as np
import pytest

from habitsim.controllers import ControllerError, Reference, configure_servos, make_controller
from habitsim.controllers.base import actuated_joints
from habitsim.controllers.robot import ServoTorque, foot_geoms, torque_model
from habitsim.retarget import trot
from habitsim.sim import FallDetector, SimulationError, track

GO1 = Path(__file__).parent / "robots" / "unitree_go1"
FEET = ["FL", "FR", "RL", "RR"]


@pytest.fixture(scope="module")
def go1() -> mujoco.MjModel:
    return mujoco.MjModel.from_xml_path(str(GO1 / "scene.xml"))


def _home(model: mujoco.MjModel) -> mujoco.MjData:
    d = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, d, 0)
    mujoco.mj_forward(model, d)
    return d


def test_vendored_model_is_menagerie_go1_without_meshes(go1):
    assert "BSD 3-Clause" in (GO1 / "LICENSE").read_text()
    assert go1.nmesh == 0 and not any(go1.geom_type == mujoco.mjtGeom.mjGEOM_MESH)
    assert go1.nu == 12 and go1.nkey == 1 and go1.key(0).name == "home"
    assert abs(mujoco.mj_getTotalmass(go1) - 12.74) < 0.05  # menagerie's inertials
    for f in FEET:
        g = go1.geom(f)
        assert g.type[0] == mujoco.mjtGeom.mjGEOM_SPHERE and go1.site(f).id >= 0
    # every actuator is a position servo, as menagerie ships it
    assert all(actuated_joints(go1).biased)


def test_readme_robot_section_runs_as_written_on_go1(go1):
    """The README snippet, with the Go1's own foot names, then its loop standing 2 s
    under ``balance`` on the robot's own position servos (no conversion by the user)."""
    model = go1
    servo_model = configure_servos(model, kp=None, dampratio=1.0)  # PD inside the engine
    ctl = make_controller("balance", model, feet=["FL", "FR", "RL", "RR"])
    assert servo_model.nu == model.nu and ctl.legs.feet == tuple(FEET)
    d = _home(model)
    ctl.reset(model, d)
    z = np.zeros(model.nv)
    ref = Reference(0.0, d.qpos.copy(), z, z, np.ones(4, bool))
    z0 = float(d.qpos[2])
    for _ in range(int(2.0 / model.opt.timestep)):
        d.ctrl[:] = ctl.control(model, d, ref)
        mujoco.mj_step(model, d)
    assert abs(d.qpos[2] - z0) < 0.01 * z0
    assert np.allclose(d.qpos[7:], ref.qpos[7:], atol=0.05)
    # the servos stayed within their control ranges (targets, not torques)
    assert np.all(d.ctrl >= model.actuator_ctrlrange[:, 0] - 1e-9)
    assert np.all(d.ctrl <= model.actuator_ctrlrange[:, 1] + 1e-9)
    # without the targets the servos hold home only by their stiffness: the torques the
    # controller asked for are what the servos gave
    assert np.allclose(ctl.last_torque, d.qfrc_actuator[6:], atol=0.5)


def test_servo_torque_inverts_the_position_law(go1):
    d = _home(go1)
    rng = np.random.default_rng(3)
    d.qvel[6:] = rng.normal(0.0, 1.0, go1.nv - 6)
    jm = actuated_joints(go1)
    st = ServoTorque(go1, jm)
    tau = rng.uniform(-10.0, 10.0, len(jm.names))
    tau[2] = 200.0  # beyond the knee's 35.55 N·m: clipped, and reported so
    ctrl, given = st.controls(d, tau)
    d.ctrl[jm.ctrl_index] = ctrl
    mujoco.mj_forward(go1, d)
    assert np.allclose(d.qfrc_actuator[jm.dof_adr], given, atol=1e-9)
    assert np.allclose(given[3:], tau[3:]) and given[2] == pytest.approx(35.55)


def test_torque_model_keeps_the_servos_strength(go1):
    tm = torque_model(go1)
    jm = actuated_joints(tm)
    assert not jm.biased.any()
    assert np.allclose(jm.torque_limit, actuated_joints(go1).torque_limit)
    assert np.allclose(tm.actuator_ctrlrange, go1.actuator_forcerange)
    assert not go1.actuator_biastype[0] == mujoco.mjtBias.mjBIAS_NONE  # input untouched
    assert np.all(tm.key_ctrl == 0.0)


def test_torque_model_takes_the_joints_actuator_force_range(tmp_path):
    """Menagerie's Spot limits its servos by the joints' actuatorfrcrange, not by the
    actuators' forcerange: the torque motors get that strength; with neither, no motor
    can be made and the error names both ways."""
    xml = (GO1 / "go1.xml").read_text()
    no_force = re.sub(r' forcerange="[^"]*"', "", xml)
    joint_limited = no_force.replace(
        '<joint axis="0 1 0" damping="2"',
        '<joint axis="0 1 0" actuatorfrcrange="-30 30" damping="2"',
    ).replace(
        '<joint axis="1 0 0" damping="1"',
        '<joint axis="1 0 0" actuatorfrcrange="-20 20" damping="1"',
    )
    (tmp_path / "go1.xml").write_text(joint_limited)
    model = mujoco.MjModel.from_xml_path(str(tmp_path / "go1.xml"))
    assert not model.actuator_forcelimited.any() and model.jnt_actfrclimited[1:].all()
    tm = torque_model(model)
    hi = tm.actuator_ctrlrange[:, 1]
    assert np.allclose(hi, [20, 30, 30] * 4)
    assert np.allclose(actuated_joints(model).force_hi, hi)
    (tmp_path / "go1.xml").write_text(no_force)
    with pytest.raises(ControllerError, match="forcerange=.*actuatorfrcrange="):
        torque_model(mujoco.MjModel.from_xml_path(str(tmp_path / "go1.xml")))


def test_unknown_feet_are_typed_errors_listing_the_names(go1):
    with pytest.raises(ControllerError, match="named geoms: .*FL"):
        make_controller("mpc", go1, feet=["FL_foot", "FR_foot", "RL_foot", "RR_foot"])
    clip = trot(go1, FEET, duration_s=0.2)
    with pytest.raises(SimulationError, match="feet=\\[...\\]"):
        track(clip.trajectory(), model=go1, controller="mpc")  # habitsim's names
    with pytest.raises(SimulationError, match="not a site, geom or body"):
        track(clip.trajectory(), model=go1, feet=["FL", "FR", "RL", "toe"], controller="mpc")


def test_foot_geoms_by_site_or_body_find_the_foot_sphere(go1):
    spheres = foot_geoms(go1, FEET)
    assert [go1.geom(g).name for g in spheres] == FEET
    by_body = foot_geoms(go1, ["FL_calf", "FR_calf", "RL_calf", "RR_calf"])
    assert np.array_equal(by_body, spheres)  # the lowest geom, not the shank capsules


def test_fall_rule_on_the_robot(go1):
    ref = np.tile(_home(go1).qpos, (10, 1))
    det = FallDetector(go1, ref, 50.0, leg_length=0.265, feet=FEET)
    d = _home(go1)
    assert det.check(1, d) is None
    d.qpos[2] = 0.1
    mujoco.mj_forward(go1, d)
    assert "trunk height" in det.check(1, d)
    d = _home(go1)
    d.qpos[3:7] = (np.cos(np.pi / 4), np.sin(np.pi / 4), 0.0, 0.0)  # rolled 90°
    mujoco.mj_forward(go1, d)
    assert "tilt" in det.check(1, d)


@pytest.mark.slow
@pytest.mark.parametrize("speed", [0.0, 0.5])
def test_go1_trots_under_mpc_through_track(go1, speed):
    """Trot in place and forward (shortened from the example's 10 s), no assistance:
    the robot keeps up with the reference, the metrics are those of any species."""
    clip = trot(go1, FEET, speed=speed, duration_s=3.0)
    assert clip.metadata["ik_residual_max_m"] < 1e-4
    res = track(clip.trajectory(), model=go1, feet=FEET, contacts=clip.contacts, controller="mpc")
    assert not res.failed and res.survival == 1.0
    assert res.assist["assist_force_mg"] == 0.0
    assert res.contacts.shape == (len(clip.qpos), 4)
    m = res.metrics
    assert m["sim_mpjpe_mm"] < 15.0 and m["contact_f1"] > 0.8
    assert m["root_drift_mm"] < 50.0
    travelled = res.qpos[-1, 0] - res.qpos[0, 0]
    assert travelled == pytest.approx(clip.qpos[-1, 0] - clip.qpos[0, 0], abs=0.1)
    # simulated with torque motors of the servos' strength (the given model is kept)
    assert not actuated_joints(res.model).biased.any()
    assert res.controller_stats["mpc_failures"] == 0


def _docs_section_code() -> list[str]:
    text = (Path(__file__).parents[1] / "docs" / "controllers.md").read_text()
    sec = text.split("## On your own robot", 1)[1].split("\n## ", 1)[0]
    return [b.split("\n", 1)[1] for b in sec.split("```")[1::2] if b.startswith("python")]


@pytest.mark.slow
def test_readme_robot_code_runs_as_written(monkeypatch, capsys):
    """docs/controllers.md's "On your own robot" code blocks, verbatim, from the repository
    root."""
    monkeypatch.chdir(Path(__file__).parents[1])
    blocks = _docs_section_code()
    assert len(blocks) == 2 and 'feet=["FL", "FR", "RL", "RR"]' in blocks[0]
    scope: dict = {}
    for code in blocks:
        exec(compile(code, "controllers.md", "exec"), scope)  # noqa: S102 - our own docs
    res = scope["res"]
    assert res.survival == 1.0 and res.qpos[-1, 0] > 4.0  # 10 s at 0.5 m/s
    survival, mpjpe, _ = capsys.readouterr().out.split()
    assert float(survival) == 1.0 and float(mpjpe) < 15.0


@pytest.mark.slow
def test_robot_trot_example(capsys):
    from habitsim.examples.robot_trot import main, run

    rows = run(duration_s=2.5, speed=0.6)  # 0.5 s standing, 1 s ramp: 0.9 m
    assert [r["case"] for r in rows] == ["stand", "trot in place", "trot 0.6 m/s"]
    assert all(r["survival"] == 1.0 and r["fall_reason"] is None for r in rows)
    assert abs(rows[1]["distance_m"]) < 0.05 and rows[2]["distance_m"] > 0.8
    assert all(r["mpc_median_ms"] < 20.0 for r in rows)
    assert main(["--duration", "0.5", "--feet", "FL,FR,RL,toe"]) == 2
    assert "unknown foot name(s) 'toe'" in capsys.readouterr().err
    # without --feet: ANYmal C's unnamed foot spheres are found from its shank bodies
    anymal = GO1.parent / "anybotics_anymal_c" / "scene.xml"
    assert main(["--robot", str(anymal), "--duration", "0.5"]) == 0
    assert "trot in place" in capsys.readouterr().out


def test_menagerie_unitree_foot_names_are_found_by_default(go1):
    assert make_controller("mpc", go1).legs.feet == tuple(FEET)


@pytest.mark.slow
def test_mpc_trots_the_robot_on_its_own_servos(go1):
    """The user's own loop on the unconverted robot: mpc's torques reach the joints as
    servo targets, every step, and the Go1 trots forward."""
    from habitsim.sim import build_reference

    clip = trot(go1, FEET, speed=0.5, duration_s=2.5)
    ctl = make_controller(
        "mpc", go1, feet=FEET, qpos=clip.qpos, fps=clip.fps, contacts=clip.contacts
    )
    ref = build_reference(go1, clip.qpos, clip.fps)
    d = mujoco.MjData(go1)
    d.qpos[:] = clip.qpos[0]
    mujoco.mj_forward(go1, d)
    ctl.reset(go1, d)
    for i, t in enumerate(ref.time):
        k = min(int(t * clip.fps + 0.5), len(clip.contacts) - 1)
        r = Reference(float(t), ref.qpos[i], ref.qvel[i], ref.qacc[i], clip.contacts[k])
        d.ctrl[:] = ctl.control(go1, d, r)
        mujoco.mj_step(go1, d)
    assert np.linalg.norm(d.qpos[:3] - ref.qpos[-1, :3]) < 0.05
    assert d.xmat[1, 8] > 0.99  # trunk upright
    assert ctl.stats.failures == 0


def test_drawable_shows_collision_geoms_only_for_drawing(go1):
    from habitsim.render import render_available, render_frames
    from habitsim.retarget import drawable

    vis = drawable(go1)
    robot = go1.geom_bodyid != 0  # the floor is drawn anyway
    assert (go1.geom_group[robot] == 3).all() and (vis.geom_group[robot] == 0).all()
    assert np.array_equal(vis.geom_size, go1.geom_size)
    assert np.array_equal(vis.geom_contype, go1.geom_contype)
    if render_available():
        frames = render_frames(vis, _home(go1).qpos[None], camera="tracking", width=160, height=120)
        hidden = render_frames(go1, _home(go1).qpos[None], camera="tracking", width=160, height=120)
        assert np.abs(frames.astype(int) - hidden).sum() > 0  # the robot is drawn


def test_track_on_a_robot_refuses_what_does_not_fit(go1):
    from habitsim.gaits import generate

    walk = generate("dog", "walk", seed=1, duration_s=1.0)
    with pytest.raises(SimulationError, match="retarget it first"):
        track(walk, model=go1, feet=FEET, controller="mpc")
    clip = trot(go1, FEET, duration_s=0.5)
    with pytest.raises(SimulationError, match=r"contacts must have shape \(51, 4\)"):
        track(clip.trajectory(), model=go1, feet=FEET, contacts=clip.contacts[:, :3])
    with pytest.raises(SimulationError, match="pass the robot as model="):
        track(clip.trajectory(), species="dog", feet=FEET)


def test_trot_example_measures_distance_along_the_trunks_forward_axis():
    """ANYmal C's trunk frame faces −x at home: walking forward is walking along −x."""
    from habitsim.examples.robot_trot import _forward_distance

    q = np.zeros((2, 7))
    q[:, 3:7] = [0.0, 0.0, 0.0, 1.0]  # yawed half a turn
    q[1, 0] = -1.5
    assert _forward_distance(q) == pytest.approx(1.5)
    q[:, 3:7] = [1.0, 0.0, 0.0, 0.0]
    assert _forward_distance(q) == pytest.approx(-1.5)
    shifted = np.hstack([np.zeros((2, 2)), q])  # the free joint after two other joints
    assert _forward_distance(shifted, 2) == pytest.approx(-1.5)


def test_balance_reports_legs_working_at_their_torque_limit(go1):
    """The stance QP keeps its torques inside the limits, so a robot too weak for its
    weight shows in ``torque_at_limit_share``, not in ``torque_clipped_share``: the Go1
    standing 1 s on its own motors needs them a few percent of the ticks at most, and
    with every motor cut to 12 % of its strength (the knee 4.3 N·m, standing needs
    5.1) most of the ticks."""
    shares = []
    for scale in (1.0, 0.12):
        model = torque_model(go1)
        model.actuator_ctrlrange[:] *= scale
        ctl = make_controller("balance", model, feet=FEET)
        d = _home(model)
        ctl.reset(model, d)
        z = np.zeros(model.nv)
        ref = Reference(0.0, d.qpos.copy(), z, z, np.ones(4, bool))
        for _ in range(int(1.0 / model.opt.timestep)):
            d.ctrl[:] = ctl.control(model, d, ref)
            mujoco.mj_step(model, d)
        st = ctl.stats.to_dict()
        assert 0.0 <= st["torque_clipped_share"] <= 1.0
        shares.append(st["torque_at_limit_share"])
    assert shares[0] < 0.05 and shares[1] > 0.5
