"""A habitsim motion back onto a user's rig (habitsim.bvh_mapping.export)."""

from __future__ import annotations

import numpy as np
import pytest
from foreign_rig import CODED, _foreign_rig
from helpers import DOG, run_cli

import habitsim
from habitsim.bvh import read_bvh
from habitsim.bvh_mapping import import_bvh
from habitsim.bvh_mapping.export import export_to_rig, round_trip
from habitsim.errors import HabitsimError, RigExportError
from habitsim.skeleton import JOINT_NAMES


@pytest.fixture(scope="module")
def rig():
    return _foreign_rig(habitsim.generate("dog", "walk", seed=3, duration_s=2.0))


@pytest.fixture(scope="module")
def trot():
    return habitsim.generate("dog", "trot", seed=1, duration_s=2.0)


def test_round_trip_of_an_imported_clip_within_a_millimetre(rig):
    motion, _ = import_bvh(rig, "dog", plant=False)
    rt = round_trip(export_to_rig(motion, rig), motion)
    assert len(rt.joints) == len(JOINT_NAMES)
    assert rt.error.max() <= 1e-3
    assert rt.quarter_turns == 0


@pytest.mark.parametrize("names", ["named", "coded", "anonymous"])
def test_round_trip_of_another_motion_keeps_the_pose(rig, trot, names):
    walk = habitsim.generate("dog", "walk", seed=3, duration_s=2.0)
    src = {
        "named": rig,
        "coded": _foreign_rig(walk, rename=CODED),
        "anonymous": _foreign_rig(walk, anonymous=True),
    }[names]
    ex = export_to_rig(trot, src)
    rt = round_trip(ex, trot)
    # every mapped joint where the motion has it, up to the import's root height rule;
    # the anonymous rig's head maps onto the snout joint, whose End Site has no length:
    # no direction for the head's bone, so the import keeps the head's standing pose
    keep = [k for k, n in enumerate(rt.joints) if names != "anonymous" or n != "snout"]
    assert rt.pose_error[:, keep].max() <= 1e-3
    assert abs(rt.height_offset) < 0.1 * load_leg()
    # the root's horizontal travel is the motion's over the import's scale
    hips = ex.bvh.names.index(ex.mapping.joints["pelvis"])
    travel = ex.mapping.frame.apply(ex.bvh.fk()[:, hips]) * ex.root_scale
    moved = trot.root_positions[-1, :2] - trot.root_positions[0, :2]
    assert np.allclose(travel[-1, :2] - travel[0, :2], moved, atol=1e-4)


def load_leg() -> float:
    return habitsim.load_species("dog").leg_length


def test_unmapped_joints_and_offsets_are_kept(rig, trot):
    ex = export_to_rig(trot, rig)
    out = ex.bvh
    assert out.names == rig.names and out.channels == rig.channels
    assert np.array_equal(out.offsets, rig.offsets)
    mapped = set(ex.mapping.mapped().values())
    helpers = [n for n in rig.names if "Helper" in n or "Armor" in n]
    assert helpers and not mapped & set(helpers)
    q_out, q_rig = out.local_rotations(), rig.local_rotations()
    for n in helpers:
        j = rig.index(n)
        if rig.is_end_site[j]:
            continue
        dots = np.abs(np.sum(q_out[:, j] * q_rig[0, j], axis=-1))
        assert dots.min() > 1 - 1e-9, n
    # the mapped legs do move
    knee = rig.index(ex.mapping.joints["lh_knee"])
    assert np.ptp(q_out[:, knee, 2]) > 0.05


def test_units_and_up_axis_of_a_cm_y_up_rig_are_kept(trot):
    src = read_bvh(DOG)
    ex = export_to_rig(trot, src)
    assert (ex.mapping.frame.units, ex.mapping.frame.up) == ("cm", "+y")
    hips = src.index(ex.mapping.joints["pelvis"])
    pos = ex.bvh.fk()[:, hips]  # file units and axes
    height_cm = trot.root_positions[:, 2] * 100.0 / ex.root_scale
    assert np.ptp(pos[:, 1] - height_cm) < 0.01  # y is up, in centimetres
    rt = round_trip(ex, trot)
    assert rt.pose_error.max() <= 1e-3


def test_a_rig_without_a_leg_is_refused(rig, trot, tmp_path, capsys):
    joints = {h: s for h, s in import_bvh(rig, "dog", plant=False)[1].mapped().items()}
    for n in ("lf_scapula", "lf_shoulder", "lf_elbow", "lf_wrist"):
        joints.pop(n, None)
    with pytest.raises(RigExportError, match="lf leg") as ei:
        export_to_rig(trot, rig, joint_map=joints)
    assert isinstance(ei.value, HabitsimError) and "--map" in str(ei.value)
    # through the command: nothing written
    rig_file = tmp_path / "rig.bvh"
    rig_file.write_text(rig.to_text())
    motion = tmp_path / "trot.npz"
    trot.save(motion)
    jm = tmp_path / "map.json"
    import json

    jm.write_text(json.dumps({"map": joints}))
    out = tmp_path / "out.bvh"
    code, err = run_cli(
        ["data", "export-bvh", motion, "--out", out, "--rig", rig_file, "--map", jm], capsys
    )
    assert code != 0 and "lf leg" in err and not out.exists()


def test_export_bvh_rig_command_writes_the_rigs_joints(rig, trot, tmp_path, capsys):
    rig_file = tmp_path / "rig.bvh"
    rig_file.write_text(rig.to_text())
    motion = tmp_path / "trot.npz"
    trot.save(motion)
    out = tmp_path / "out.bvh"
    code, _ = run_cli(["data", "export-bvh", motion, "--out", out, "--rig", rig_file], capsys)
    assert code == 0
    back = read_bvh(out)
    assert back.names == rig.names and back.num_frames == trot.num_frames
    assert back.fps == pytest.approx(trot.fps)
    # rig options without a rig are an error
    code, err = run_cli(["data", "export-bvh", motion, "--out", out, "--up", "y"], capsys)
    assert code != 0 and "--rig" in err


def _stance_slide(ex, motion) -> float:
    """Median horizontal travel of the rig's toes over the motion's stance runs [m]."""
    from habitsim.stance.labels import stance_runs

    pos = ex.mapping.frame.apply(ex.bvh.fk())
    toes = [ex.bvh.index(ex.mapping.joints[f"{p}_toe"]) for p in ("lf", "rf", "lh", "rh")]
    runs = stance_runs(motion.detect_contacts())
    out = [
        np.linalg.norm(pos[b - 1, toes[k], :2] - pos[a, toes[k], :2])
        for k, segs in enumerate(runs)
        for a, b in segs
        if b - a >= 3
    ]
    return float(np.median(out))


def test_feet_travel_keeps_a_rig_of_other_proportions_on_its_feet(trot):
    from habitsim.bvh_mapping.export import RigExportOptions

    horse = _foreign_rig(habitsim.generate("horse", "walk", seed=2, duration_s=1.0))
    walk = habitsim.generate("dog", "walk", seed=4, duration_s=2.0)
    trip = export_to_rig(walk, horse)
    feet = export_to_rig(walk, horse, export=RigExportOptions(travel="feet"))
    assert _stance_slide(feet, walk) < 0.8 * _stance_slide(trip, walk)
    # the pose is the same either way; only the root's horizontal path differs
    assert np.allclose(feet.bvh.local_rotations()[:, 3:], trip.bvh.local_rotations()[:, 3:])
    with pytest.raises(RigExportError, match="travel"):
        export_to_rig(walk, horse, export=RigExportOptions(travel="skate"))


def test_fox_gltf_rig_round_trip_and_glb_copy(tmp_path):
    from importlib import resources

    import pygltflib

    from habitsim.gltf import list_gltf_animations, read_gltf

    fox = resources.files("habitsim.examples") / "Fox.glb"
    own, _ = import_bvh(read_gltf(fox, "Walk"), "dog", plant=False)
    ex = export_to_rig(own, fox, animation="Walk")
    assert round_trip(ex, own).error.max() <= 1e-3
    out = ex.write(tmp_path / "fox_habitsim.glb")
    names = [a.name for a in list_gltf_animations(out)]
    assert names == ["Survey", "Walk", "Run", "habitsim"]
    back = read_gltf(out, "habitsim", fps=own.fps)
    assert back.names == ex.bvh.names
    np.testing.assert_allclose(back.fk(), ex.bvh.fk(), atol=1e-3)  # float32 keys, cm
    a, b = pygltflib.GLTF2().load(str(fox)), pygltflib.GLTF2().load(str(out))
    assert len(a.meshes) == len(b.meshes) and len(a.skins) == len(b.skins)
    # a glTF output needs a glTF rig
    with pytest.raises(RigExportError, match="glTF"):
        export_to_rig(own, read_bvh(DOG)).write(tmp_path / "x.glb")


def test_habitsim_rig_of_another_species_round_trips(trot, tmp_path):
    from habitsim.bvh import write_bvh

    horse = tmp_path / "horse.bvh"
    write_bvh(habitsim.generate("horse", "walk", seed=1, duration_s=1.0), horse)
    ex = export_to_rig(trot, horse)
    assert ex.mapping.method == "identity" and ex.root_scale != 1.0
    assert round_trip(ex, trot).error.max() <= 1e-3


@pytest.mark.slow  # the transfer stage's imports and planting: tens of seconds
def test_transfer_onto_a_rig_in_one_step(trot, tmp_path, capsys):
    motion = tmp_path / "trot.npz"
    trot.save(motion)
    cat_rig = _foreign_rig(habitsim.generate("cat", "walk", seed=1, duration_s=1.0))
    rig = tmp_path / "cat_rig.bvh"
    rig.write_text(cat_rig.to_text())
    out = tmp_path / "out"
    out.mkdir()
    argv = ["transfer", motion, "--to", "cat", "--method", "direct", "--out", out / "cat.npz"]
    code, _ = run_cli([*argv, "--bvh", out / "cat.bvh", "--rig", rig], capsys)
    assert code == 0
    assert read_bvh(out / "cat.bvh").names == cat_rig.names
    # a rig map that leaves the fore legs out: refused, nothing written
    bad = tmp_path / "bad.json"
    bad.write_text('{"map": {"pelvis": "Hips_jnt", "spine3": "Chest", "lh_hip": "L_Thigh"}}')
    code, err = run_cli(
        [*argv[:-1], out / "b.npz", "--bvh", out / "b.bvh", "--rig", rig, "--rig-map", bad],
        capsys,
    )
    assert code == 2 and "leg needs at least two mapped joints" in err
    assert sorted(p.name for p in out.iterdir()) == ["cat.bvh", "cat.npz"]
