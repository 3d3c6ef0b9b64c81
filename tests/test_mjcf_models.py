"""Contract test over every shipped species model (menagerie style)."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

import habitsim
from habitsim.mjcf_models.builder import build_spec, hinge_joints, model_path, scene_path
from habitsim.skeleton import JOINT_NAMES, get_skeleton

SPECIES = habitsim.species_names()


@pytest.fixture(scope="module", params=SPECIES)
def loaded(request):
    name = request.param
    path = scene_path(name)
    assert path.is_file(), f"{path} missing: run `habitsim models build`"
    model = mujoco.MjModel.from_xml_path(str(path))  # plain MuJoCo, no habitsim code
    return name, model


def test_compiles_with_conventions(loaded) -> None:
    name, m = loaded
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
    for kind, count in ((mujoco.mjtObj.mjOBJ_BODY, m.nbody), (mujoco.mjtObj.mjOBJ_GEOM, m.ngeom),
                        (mujoco.mjtObj.mjOBJ_SITE, m.nsite), (mujoco.mjtObj.mjOBJ_JOINT, m.njnt)):
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


def test_home_matches_skeleton_fk(loaded) -> None:
    name, m = loaded
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


def test_random_controls_no_warnings(loaded) -> None:
    name, m = loaded
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, m.key("home").id)
    rng = np.random.default_rng(0)
    lo, hi = m.actuator_ctrlrange[:, 0], m.actuator_ctrlrange[:, 1]
    for _ in range(int(1.0 / m.opt.timestep)):
        d.ctrl[:] = rng.uniform(lo, hi) * 0.3
        mujoco.mj_step(m, d)
    assert all(w.number == 0 for w in d.warning), [w.number for w in d.warning]
    assert np.all(np.isfinite(d.qpos))


def test_shipped_files_are_current(loaded, tmp_path) -> None:
    """The committed XML equals what the builder makes from the catalog now."""
    name, _ = loaded
    fresh = build_spec(name, mesh_dir="assets")
    fresh.modelfiledir = str(model_path(name).parent)
    assert fresh.to_xml() == model_path(name).read_text(encoding="utf-8")
