"""``habitsim.retarget.vendor`` and ``habitsim models vendor``: a collision-only single-file
copy of a robot, on a small robot whose meshes the test builds with trimesh."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest
import trimesh

from habitsim.cli import main
from habitsim.retarget.errors import VendorError
from habitsim.retarget.vendor import SHAPES, VendorOptions, vendor_robot

#: Half extents of the trunk's box mesh [m] and the leg capsule's radius and half length.
TRUNK = (0.2, 0.05, 0.03)
LEG = (0.02, 0.1)


def _robot(folder: Path) -> Path:
    """A two-body robot in ``folder/meshes``: a visual mesh and a collision box mesh on the
    trunk (turned by an euler angle), a collision capsule mesh on the leg, a textured
    floor, a licence file beside it."""
    (folder / "meshes").mkdir(parents=True)
    trimesh.creation.box(extents=2 * np.array(TRUNK)).export(folder / "meshes" / "trunk.stl")
    trimesh.creation.capsule(height=2 * LEG[1], radius=LEG[0], count=[16, 16]).export(
        folder / "meshes" / "leg.obj"
    )
    trimesh.creation.icosphere(radius=0.1).export(folder / "meshes" / "shell.stl")
    rgb = np.zeros((4, 4, 3), np.uint8)
    from PIL import Image

    Image.fromarray(rgb).save(folder / "meshes" / "skin.png")
    (folder / "LICENSE").write_text("a licence\n")
    xml = """<mujoco model="tiny">
  <compiler meshdir="meshes" texturedir="meshes"/>
  <asset>
    <mesh name="trunk" file="trunk.stl"/>
    <mesh name="leg" file="leg.obj"/>
    <mesh name="shell" file="shell.stl"/>
    <texture name="skin" type="2d" file="skin.png"/>
    <material name="painted" texture="skin"/>
    <texture name="grid" type="2d" builtin="checker" rgb1="0 0 0" rgb2="1 1 1" width="8"
      height="8"/>
    <material name="floor" texture="grid"/>
  </asset>
  <worldbody>
    <geom name="floor" type="plane" size="1 1 0.1" material="floor"/>
    <body name="trunk" pos="0 0 0.5">
      <freejoint/>
      <geom name="shell" type="mesh" mesh="shell" contype="0" conaffinity="0" group="2"
        material="painted"/>
      <geom name="trunk_col" type="mesh" mesh="trunk" pos="0.05 0 0" euler="0 0 30"/>
      <body name="leg" pos="0.1 0 -0.1">
        <joint name="hip" axis="0 1 0" range="-1 1"/>
        <geom type="mesh" mesh="leg"/>
        <geom name="foot" type="sphere" size="0.02" pos="0 0 -0.12"/>
      </body>
    </body>
  </worldbody>
  <actuator><motor joint="hip" gear="10"/></actuator>
  <keyframe><key name="home" qpos="0 0 0.5 1 0 0 0 0.2"/></keyframe>
</mujoco>
"""
    (folder / "tiny.xml").write_text(xml)
    return folder / "tiny.xml"


def test_the_copy_is_one_file_with_fitted_primitives(tmp_path):
    src = _robot(tmp_path / "src")
    rep = vendor_robot(src, tmp_path / "out")
    assert rep.out == tmp_path / "out" / "tiny.xml"
    text = rep.out.read_text()
    assert "file=" not in text and "<mesh" not in text  # no other file, no mesh
    assert rep.licence is not None and rep.licence.read_text() == "a licence\n"
    original = mujoco.MjModel.from_xml_path(str(src))
    copy = mujoco.MjModel.from_xml_string(text)  # compiles with nothing beside it
    assert rep.dropped == ["shell"]
    assert mujoco.mj_name2id(copy, mujoco.mjtObj.mjOBJ_GEOM, "shell") < 0
    assert not np.any(copy.geom_type == mujoco.mjtGeom.mjGEOM_MESH)
    # the box mesh became a box of its extents, where it was; the leg a capsule
    box = copy.geom("trunk_col")
    assert box.type[0] == mujoco.mjtGeom.mjGEOM_BOX
    np.testing.assert_allclose(np.sort(box.size), np.sort(TRUNK), rtol=1e-4)
    np.testing.assert_allclose(box.pos, original.geom("trunk_col").pos, atol=1e-6)
    leg = int(np.flatnonzero(copy.geom_bodyid == copy.body("leg").id)[0])
    assert copy.geom_type[leg] == mujoco.mjtGeom.mjGEOM_CAPSULE
    np.testing.assert_allclose(copy.geom_size[leg, :2], LEG, rtol=0.05)
    # same bodies, joints, mass, inertia, keyframe, actuators
    assert (copy.nbody, copy.njnt, copy.nu, copy.nkey) == (
        original.nbody,
        original.njnt,
        original.nu,
        original.nkey,
    )
    np.testing.assert_allclose(copy.body_mass, original.body_mass, rtol=1e-5)
    np.testing.assert_allclose(copy.body_inertia, original.body_inertia, rtol=1e-5)
    np.testing.assert_allclose(copy.key_qpos, original.key_qpos)
    # the foot sphere and the floor are kept as they are
    assert copy.geom("foot").size[0] == pytest.approx(0.02)
    assert "texture skin" in rep.assets_removed and "texture grid" not in rep.assets_removed


def test_a_chosen_shape_is_used_for_every_mesh(tmp_path):
    src = _robot(tmp_path / "src")
    rep = vendor_robot(src, tmp_path / "out", VendorOptions(shape="sphere"))
    assert {kind for _, kind, _ in rep.fitted} == {"sphere"}
    assert len(rep.fitted) == 2


def test_visual_mesh_files_are_not_needed(tmp_path):
    """A robot downloaded without its visual mesh files is vendored the same (the bodies
    whose inertia came from their geoms say so); a missing collision mesh file is a typed
    error."""
    src = _robot(tmp_path / "src")
    (src.parent / "meshes" / "shell.stl").unlink()
    rep = vendor_robot(src, tmp_path / "out")
    assert rep.dropped == ["shell"] and len(rep.fitted) == 2
    assert rep.inertia_without_visuals == ["trunk", "leg"]
    mujoco.MjModel.from_xml_path(str(rep.out))
    (src.parent / "meshes" / "trunk.stl").unlink()
    with pytest.raises(VendorError):
        vendor_robot(src, tmp_path / "out2")


def test_bad_input_is_a_typed_error(tmp_path):
    with pytest.raises(VendorError):
        vendor_robot(tmp_path / "missing.xml", tmp_path / "out")
    with pytest.raises(VendorError):
        VendorOptions(shape="cone")
    with pytest.raises(VendorError):
        VendorOptions(fit_scale=0.0)
    src = _robot(tmp_path / "src")
    with pytest.raises(VendorError):  # would overwrite the input
        vendor_robot(src, src.parent)
    (tmp_path / "broken.xml").write_text("<mujoco><worldbody><geom/></worldbody>")
    with pytest.raises(VendorError):
        vendor_robot(tmp_path / "broken.xml", tmp_path / "out")


def test_cli_models_vendor(tmp_path, capsys):
    from habitsim.cli import build_parser

    src = _robot(tmp_path / "src")
    out = tmp_path / "out"
    assert main(["models", "vendor", str(src), "--out", str(out)]) == 0
    assert (out / "tiny.xml").is_file() and (out / "LICENSE").is_file()
    assert "1 visual mesh geoms dropped, 2 collision meshes replaced" in capsys.readouterr().out
    bad = tmp_path / "bad"
    assert main(["models", "vendor", str(src), "--out", str(bad), "--fit-scale", "-1"]) == 2
    assert not bad.exists()
    for shape in SHAPES:  # the command offers every shape the library fits
        ns = build_parser().parse_args(
            ["models", "vendor", "r.xml", "--out", "o", "--shape", shape]
        )
        assert ns.shape == shape


def test_an_unreadable_collision_mesh_is_fitted_to_a_visual_mesh_of_its_body(tmp_path, capsys):
    """The trunk's collision mesh file is gone but its visual shell (a sphere of radius
    0.1) reads: the trunk's primitive is fitted to the shell, and the command says so."""
    src = _robot(tmp_path / "src")
    (src.parent / "meshes" / "trunk.stl").unlink()
    rep = vendor_robot(src, tmp_path / "out")
    assert rep.stand_ins == [("trunk_col", "shell")]
    copy = mujoco.MjModel.from_xml_path(str(rep.out))
    g = copy.geom("trunk_col")
    assert g.type[0] != mujoco.mjtGeom.mjGEOM_MESH
    assert max(g.size) == pytest.approx(0.1, rel=0.05)  # the shell's size, not the box's
    np.testing.assert_allclose(g.pos, 0.0, atol=1e-6)  # where the shell is
    assert main(["models", "vendor", str(src), "--out", str(tmp_path / "cli")]) == 0
    assert "trunk_col: its collision mesh cannot be read" in capsys.readouterr().out
