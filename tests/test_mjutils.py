"""The shared MuJoCo lookups (habitsim.mjutils) on a catalog model and on a foreign robot.

The catalog dog names its feet ``lf_foot`` … (sphere geoms); MuJoCo Menagerie's Unitree
Go1 (tests/robots/unitree_go1) names them ``FL``, ``FR``, ``RL``, ``RR`` (a geom and a
site each), its trunk ``trunk`` and its keyframe ``home``.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import mujoco
import numpy as np
import pytest

from habitsim import mjutils
from habitsim.errors import SimulationError
from habitsim.qpos import species_model
from habitsim.species import load_species

GO1 = Path(__file__).parent / "robots" / "unitree_go1"
GO1_FEET = ("FL", "FR", "RL", "RR")


@pytest.fixture(scope="module")
def dog() -> mujoco.MjModel:
    return species_model("dog")


@pytest.fixture(scope="module")
def go1() -> mujoco.MjModel:
    return mujoco.MjModel.from_xml_path(str(GO1 / "scene.xml"))


def _no_free_joint() -> mujoco.MjModel:
    return mujoco.MjModel.from_xml_string(
        '<mujoco><worldbody><body name="b"><joint name="h" axis="0 1 0"/>'
        '<geom name="g" size=".1"/></body></worldbody></mujoco>'
    )


def test_free_joint_lookups(dog, go1) -> None:
    for model, trunk in ((dog, None), (go1, "trunk")):
        free = mjutils.free_joints(model)
        assert len(free) == 1 and mjutils.free_joint(model) == free[0]
        body = mjutils.free_body(model)
        assert body == int(model.jnt_bodyid[free[0]]) and body > 0
        if trunk is not None:
            assert model.body(body).name == trunk
        assert mjutils.body_free_joint(model, body) == free[0]
        assert mjutils.body_free_joint(model, body + 1) == -1  # a leg body: hinge
        dofs = mjutils.free_dofs(model)
        a = int(model.jnt_dofadr[free[0]])
        np.testing.assert_array_equal(dofs, np.arange(a, a + 6))
    bare = _no_free_joint()
    assert mjutils.free_joints(bare) == [] and mjutils.free_joint(bare) == -1
    assert mjutils.free_body(bare) == -1 and mjutils.free_dofs(bare).size == 0
    assert mjutils.body_free_joint(bare, -1) == -1


def test_home_qpos_is_the_home_keyframe_else_qpos0(dog, go1) -> None:
    for model in (dog, go1):
        kid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_KEY, "home")
        assert kid >= 0
        np.testing.assert_array_equal(mjutils.home_qpos(model), model.key_qpos[kid])
        np.testing.assert_array_equal(mjutils.home_qpos(model, 0), model.key_qpos[0])
        np.testing.assert_array_equal(mjutils.home_qpos(model, "nosuchkey"), model.qpos0)
    assert mjutils.home_qpos(go1)[2] == pytest.approx(0.27)
    home = mjutils.home_qpos(go1)
    home[0] = 99.0  # a copy, not a view of the model
    assert go1.key_qpos[0, 0] != 99.0
    bare = _no_free_joint()
    np.testing.assert_array_equal(mjutils.home_qpos(bare), bare.qpos0)


def test_feet_by_name_and_by_ground_contact(dog, go1) -> None:
    assert mjutils.known_feet(dog) == mjutils.HABITSIM_FEET
    assert mjutils.known_feet(go1) == GO1_FEET
    assert mjutils.known_feet(_no_free_joint()) is None
    found = mjutils.find_feet(dog)  # the foot spheres, and the toe capsules beside them
    assert set(mjutils.HABITSIM_FEET) <= set(found)
    assert all(n in mjutils.HABITSIM_FEET or n.endswith("_toe_col") for n in found)
    found = mjutils.find_feet(go1)  # the foot spheres (and unnamed calf geoms near them)
    assert set(GO1_FEET) <= set(found)
    assert all(n in GO1_FEET or n.startswith("#") for n in found)


def test_points_resolve_site_before_geom_before_body(go1) -> None:
    pts = mjutils.resolve_points(go1, ["FL", "trunk", "#0"])
    assert pts[0] == ("site", mujoco.mj_name2id(go1, mujoco.mjtObj.mjOBJ_SITE, "FL"))
    assert pts[1] == ("body", mujoco.mj_name2id(go1, mujoco.mjtObj.mjOBJ_BODY, "trunk"))
    assert pts[2] == ("geom", 0)
    d = mujoco.MjData(go1)
    d.qpos[:] = mjutils.home_qpos(go1)
    mujoco.mj_kinematics(go1, d)
    calf = mujoco.mj_name2id(go1, mujoco.mjtObj.mjOBJ_BODY, "FL_calf")
    assert mjutils.point_body(go1, *pts[0]) == calf
    assert mjutils.point_body(go1, *pts[1]) == pts[1][1]
    np.testing.assert_allclose(mjutils.point_pos(d, *pts[0]), d.site_xpos[pts[0][1]])
    np.testing.assert_allclose(mjutils.point_pos(d, *pts[1]), d.xpos[pts[1][1]])
    with pytest.raises(mjutils.ModelLookupError, match="named sites: .*FL"):
        mjutils.resolve_points(go1, ["nose"])


def test_foot_geoms_of_a_catalog_model_and_of_a_robot(dog, go1) -> None:
    ids = mjutils.foot_geoms(dog)
    assert [dog.geom(int(g)).name for g in ids] == list(mjutils.HABITSIM_FEET)
    robot = mjutils.foot_geoms(go1, GO1_FEET)
    assert [go1.geom(int(g)).name for g in robot] == list(GO1_FEET)  # colliding geoms
    # a body names its lowest colliding geom at home: the foot sphere of the calf
    calves = mjutils.foot_geoms(go1, ["FL_calf", "FR_calf", "RL_calf", "RR_calf"])
    np.testing.assert_array_equal(calves, robot)
    with pytest.raises(SimulationError, match="no foot geom 'lf_foot'"):
        mjutils.foot_geoms(go1)


def test_lowest_z_and_foot_soles_touch_the_ground_at_home(dog, go1) -> None:
    for model, names in ((dog, None), (go1, GO1_FEET)):
        feet = mjutils.foot_geoms(model, names)
        home = mjutils.home_qpos(model)
        soles = mjutils.foot_soles(model, np.stack([home, home]), feet)
        assert soles.shape == (2, 4, 3)
        d = mujoco.MjData(model)
        d.qpos[:] = home
        mujoco.mj_kinematics(model, d)
        low = mjutils.lowest_z(model, feet, d.geom_xpos[feet], d.geom_xmat[feet])
        np.testing.assert_allclose(soles[0, :, 2], low, atol=1e-9)  # spheres: exact
        assert np.all(np.abs(low) < 0.025)  # (the Go1's home keyframe sinks them 1.8 cm)


def test_leg_length_rule(dog, go1) -> None:
    # trunk height above the mean foot point at home, close to the catalog's leg length
    sp = load_species("dog")
    assert mjutils.leg_length(dog) == pytest.approx(sp.leg_length, rel=0.1)
    d = mujoco.MjData(go1)
    d.qpos[:] = mjutils.home_qpos(go1)
    mujoco.mj_kinematics(go1, d)
    feet_z = np.mean([d.site_xpos[go1.site(n).id][2] for n in GO1_FEET])
    expected = d.xpos[mjutils.free_body(go1), 2] - feet_z
    assert mjutils.leg_length(go1) == pytest.approx(expected)
    assert mjutils.leg_length(go1, GO1_FEET) == pytest.approx(expected)
    assert 0.2 < expected < 0.3
    with pytest.raises(mjutils.ModelLookupError, match="no free joint"):
        mjutils.leg_length(_no_free_joint())


def test_mjutils_is_light() -> None:
    code = (
        "import sys, habitsim.mjutils\n"
        "print(sorted(m for m in ('torch', 'roma', 'casadi', 'habitsim.controllers') "
        "if m in sys.modules))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd="/"
    )
    assert out.stdout.strip() == "[]"
