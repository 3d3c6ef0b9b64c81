"""Contract test over every shipped species model (menagerie style): ``scene.xml`` /
``<species>.xml`` stand in plain MuJoCo, ``scene_torque.xml`` / ``<species>_torque.xml``
are the torque models habitsim's controllers drive."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

import habitsim
from habitsim.cli import main
from habitsim.mjcf_models.builder import (
    PREVIEW_SIZE,
    ModelBuildError,
    build_spec,
    hinge_joints,
    model_path,
    position_spec,
    preview_path,
    scene_path,
    to_position_actuators,
    torque_model_path,
    torque_scene_path,
    write_model,
)
from habitsim.qpos import load_species_model
from habitsim.skeleton import JOINT_NAMES, get_skeleton

SPECIES = habitsim.species_names()


@pytest.fixture(scope="module", params=SPECIES)
def models(request):
    """(species, ``scene.xml``, ``scene_torque.xml``) compiled by plain MuJoCo, no
    habitsim code."""
    name = request.param
    paths = (scene_path(name), torque_scene_path(name))
    for path in paths:
        assert path.is_file(), f"{path} missing: run `habitsim models build`"
    return (name, *(mujoco.MjModel.from_xml_path(str(path)) for path in paths))


def test_compiles_with_conventions(models) -> None:
    name, standing, torque = models
    for m in (standing, torque):
        _check_conventions(name, m)


def _check_conventions(name: str, m: mujoco.MjModel) -> None:
    sp = habitsim.load_species(name)
    assert m.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    assert m.opt.timestep <= 0.002
    assert m.body_mass.sum() == pytest.approx(sp.mass_kg, rel=1e-4)
    assert m.joint("root").type == mujoco.mjtJoint.mjJNT_FREE
    names = {m.joint(i).name for i in range(m.njnt)}
    assert names == {"root"} | {h.name for h in hinge_joints()}
    assert {m.actuator(i).name for i in range(m.nu)} == {h.name for h in hinge_joints()}
    for leg in ("lf", "rf", "lh", "rh"):
        assert m.geom(f"{leg}_foot").type == mujoco.mjtGeom.mjGEOM_SPHERE
        assert m.sensor(f"{leg}_touch").type == mujoco.mjtSensor.mjSENS_TOUCH
    for kind, count in (
        (mujoco.mjtObj.mjOBJ_BODY, m.nbody),
        (mujoco.mjtObj.mjOBJ_GEOM, m.ngeom),
        (mujoco.mjtObj.mjOBJ_SITE, m.nsite),
        (mujoco.mjtObj.mjOBJ_JOINT, m.njnt),
    ):
        for i in range(1 if kind == mujoco.mjtObj.mjOBJ_BODY else 0, count):
            assert mujoco.mj_id2name(m, kind, i), f"unnamed {kind} {i} in {name}"
    # visual geoms never collide
    vis = m.geom_group == 2
    assert vis.any() and np.all(m.geom_contype[vis] == 0) and np.all(m.geom_conaffinity[vis] == 0)
    # joint ranges hold the home pose
    key = m.key("home")
    for h in hinge_joints():
        j = m.joint(h.name)
        q = key.qpos[j.qposadr[0]]
        assert j.range[0] - 1e-9 <= q <= j.range[1] + 1e-9, h.name


def test_home_matches_skeleton_fk(models) -> None:
    name, m, _ = models
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, m.key("home").id)
    mujoco.mj_forward(m, d)
    sk = get_skeleton(name)
    pos = sk.fk(*sk.standing_pose())
    for j, joint in enumerate(JOINT_NAMES):
        bid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, joint)
        x = d.xpos[bid] if bid >= 0 else d.site(joint).xpos
        np.testing.assert_allclose(x, pos[j], atol=1e-5, err_msg=joint)
    # feet touch the floor in the home pose; no collision geom lies below it
    for leg in ("lf", "rf", "lh", "rh"):
        g = m.geom(f"{leg}_foot")
        assert d.geom_xpos[g.id][2] - g.size[0] == pytest.approx(0.0, abs=1e-4), leg
    for c in d.contact[: d.ncon]:
        assert c.dist > -1e-4, (m.geom(c.geom1).name, m.geom(c.geom2).name, c.dist)


def test_random_torques_no_warnings(models) -> None:
    name, _, m = models
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, m.key("home").id)
    rng = np.random.default_rng(0)
    lo, hi = m.actuator_ctrlrange[:, 0], m.actuator_ctrlrange[:, 1]
    for _ in range(int(1.0 / m.opt.timestep)):
        d.ctrl[:] = rng.uniform(lo, hi) * 0.3
        mujoco.mj_step(m, d)
    assert all(w.number == 0 for w in d.warning), [w.number for w in d.warning]
    assert np.all(np.isfinite(d.qpos))


def test_shipped_torque_model_is_current(models) -> None:
    """The committed torque XML equals what the builder makes from the catalog now."""
    name, _, _ = models
    fresh = build_spec(name, mesh_dir="assets")
    fresh.modelfiledir = str(torque_model_path(name).parent)
    assert fresh.to_xml() == torque_model_path(name).read_text(encoding="utf-8")


def test_controllers_load_the_torque_model(models) -> None:
    """What habitsim tracks with is ``scene_torque.xml``: torque motors, no servo."""
    name, _, t = models
    m = load_species_model(name)
    assert m.nu == t.nu == len(hinge_joints())
    assert np.all(m.actuator_gaintype == mujoco.mjtGain.mjGAIN_FIXED)
    assert np.all(m.actuator_biastype == mujoco.mjtBias.mjBIAS_NONE)
    for field in ("actuator_gainprm", "actuator_ctrlrange", "body_mass", "key_qpos"):
        np.testing.assert_array_equal(getattr(m, field), getattr(t, field), err_msg=field)


# ---------------------------------------------------------------- the standing model
#: Seconds ``scene.xml`` must stand on ``home`` in plain MuJoCo.
STAND_S = 3.0
#: Lowest pelvis height while standing, as a share of its ``home`` height.
STAND_HEIGHT_SHARE = 0.95


def test_scene_stands_on_home(models) -> None:
    """Plain MuJoCo: load ``scene.xml``, reset to ``home`` (its actuators' ctrl = the home
    joint angles), step 3 s; the animal stays up, within a few % of its home height."""
    name, m, _ = models
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, m.key("home").id)
    held = d.qpos[m.jnt_qposadr[m.actuator_trnid[:, 0]]]
    np.testing.assert_array_equal(d.ctrl, held)  # every actuator holds its home angle
    pelvis = m.body("pelvis").id
    mujoco.mj_forward(m, d)
    z0 = d.xpos[pelvis][2]
    lowest = highest = z0
    for _ in range(int(round(STAND_S / m.opt.timestep))):
        mujoco.mj_step(m, d)
        lowest = min(lowest, d.xpos[pelvis][2])
        highest = max(highest, d.xpos[pelvis][2])
    assert all(w.number == 0 for w in d.warning), {
        mujoco.mjtWarning(i).name: w.number for i, w in enumerate(d.warning) if w.number
    }
    assert lowest >= STAND_HEIGHT_SHARE * z0, f"{name}: pelvis {z0:.3f} -> {lowest:.3f} m"
    assert highest <= (2.0 - STAND_HEIGHT_SHARE) * z0, f"{name}: pelvis rose to {highest:.3f}"
    assert np.linalg.norm(d.qvel[:3]) < 0.05 * z0, f"{name} still moving after {STAND_S} s"
    # upright: the pelvis' z axis within 20° of vertical
    assert d.xmat[pelvis].reshape(3, 3)[2, 2] > np.cos(np.radians(20.0))


def test_standing_model_is_the_torque_model_with_servos(models) -> None:
    """Honest physics: same bodies, masses, feet, gravity and limits; no welds, only the
    actuators differ (position, force-limited by the motors' torque limits)."""
    name, m, t = models
    assert m.neq == 0 and m.nmocap == 0
    np.testing.assert_allclose(m.opt.gravity, t.opt.gravity)
    assert m.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    assert m.opt.timestep == t.opt.timestep
    for field in (
        "body_mass",
        "body_inertia",
        "geom_size",
        "geom_friction",
        "jnt_range",
        "dof_damping",
        "dof_armature",
        "key_qpos",
    ):
        np.testing.assert_array_equal(getattr(m, field), getattr(t, field), err_msg=field)
    assert m.nu == t.nu
    for i in range(m.nu):
        a, b = m.actuator(i), t.actuator(i)
        assert a.name == b.name and a.trnid[0] == b.trnid[0]
        assert m.actuator_biastype[i] == mujoco.mjtBias.mjBIAS_AFFINE  # position servo
        kp = a.gainprm[0]
        assert kp > 0 and a.biasprm[1] == pytest.approx(-kp) and a.biasprm[2] < 0  # damped
        np.testing.assert_allclose(a.forcerange, b.ctrlrange)
        np.testing.assert_allclose(a.ctrlrange, m.jnt_range[a.trnid[0]])
    # home's ctrl is home's joint angles
    key = m.key("home")
    np.testing.assert_allclose(key.ctrl, key.qpos[m.jnt_qposadr[m.actuator_trnid[:, 0]]])


def test_shipped_standing_model_is_current(models) -> None:
    """The committed ``<species>.xml`` equals what the builder makes from the catalog now,
    and each scene includes its own model."""
    name, _, _ = models
    fresh = position_spec(name, mesh_dir="assets")
    fresh.modelfiledir = str(model_path(name).parent)
    assert fresh.to_xml() == model_path(name).read_text(encoding="utf-8")
    for scene, model in ((scene_path, model_path), (torque_scene_path, torque_model_path)):
        include = f'<include file="{model(name).name}"/>'
        assert include in scene(name).read_text(encoding="utf-8"), scene(name)


def test_preview_png(models) -> None:
    name, _, _ = models
    from PIL import Image

    with Image.open(preview_path(name)) as im:
        assert im.size == PREVIEW_SIZE, name
    assert preview_path(name).stat().st_size < 100_000


def test_to_position_actuators_refuses_what_it_cannot_convert() -> None:
    spec = build_spec("cat")
    spec.actuators[0].set_to_position(kp=10.0)  # already a servo: not a torque motor
    with pytest.raises(ModelBuildError, match="torque motor"):
        to_position_actuators(spec)
    with pytest.raises(ModelBuildError, match="keyframe"):
        to_position_actuators(build_spec("cat"), keyframe="crouch")


def test_write_model_writes_the_standing_scene_and_the_torque_scene(tmp_path) -> None:
    """``scene.xml`` is the standing model, ``scene_torque.xml`` the torque one; nothing
    else is written beside README, preview and meshes."""
    scene = write_model("cat", tmp_path)
    assert scene == scene_path("cat", tmp_path)
    names = {p.name for p in (tmp_path / "cat").iterdir()}
    written = {"cat.xml", "scene.xml", "cat_torque.xml", "scene_torque.xml", "README.md"}
    assert names == written | {"assets"}
    m = mujoco.MjModel.from_xml_path(str(scene))
    t = mujoco.MjModel.from_xml_path(str(torque_scene_path("cat", tmp_path)))
    assert np.all(m.actuator_biastype == mujoco.mjtBias.mjBIAS_AFFINE)
    assert np.all(t.actuator_biastype == mujoco.mjtBias.mjBIAS_NONE)
    assert len(m.key("home").ctrl) == m.nu


@pytest.mark.parametrize(
    ("flags", "path"),
    [
        ([], model_path),
        (["--scene"], scene_path),
        (["--torque"], torque_model_path),
        (["--scene", "--torque"], torque_scene_path),
    ],
)
def test_models_path_command(capsys, flags, path) -> None:
    assert main(["models", "path", "cat", *flags]) == 0
    assert capsys.readouterr().out.strip() == str(path("cat"))
