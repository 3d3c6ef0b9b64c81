"""Mapping a source skeleton onto a species (habitsim.bvh_mapping): name cues, the automatic
map, units and axes detection, joint-map files, helper joints of foreign rigs, retargeting."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
from foreign_rig import CODED, RENAME, _foreign_rig
from helpers import DOG, _dog_text

import habitsim
from habitsim.bvh import BVHData, parse_bvh, read_bvh
from habitsim.bvh_mapping import (
    MappingNote,
    MappingOptions,
    auto_map,
    detect_frame,
    import_bvh,
    is_helper_name,
    load_joint_map,
    name_cues,
    read_source,
)
from habitsim.errors import SkeletonMappingError
from habitsim.rotations import quat_angle
from habitsim.skeleton import JOINT_NAMES, get_skeleton
from habitsim.species import load_species
from habitsim.stance.labels import stance_f1

EXPECTED_DOG_MAP = {
    "pelvis": "Hips",
    "spine1": "Spine",
    "spine2": None,
    "spine3": "Spine1",
    "neck": "Neck",
    "head": "Head",
    "snout": "Head_End",
    "tail1": "Tail",
    "tail2": "Tail1",
    "tail3": "Tail1_End",
    "lf_scapula": "LeftShoulder",
    "lf_shoulder": "LeftArm",
    "lf_elbow": "LeftForeArm",
    "lf_wrist": "LeftHand",
    "lf_toe": "LeftHand_End",
    "rf_scapula": "RightShoulder",
    "rf_shoulder": "RightArm",
    "rf_elbow": "RightForeArm",
    "rf_wrist": "RightHand",
    "rf_toe": "RightHand_End",
    "lh_ilium": None,
    "lh_hip": "LeftUpLeg",
    "lh_knee": "LeftLeg",
    "lh_hock": "LeftFoot",
    "lh_toe": "LeftToeBase",
    "rh_ilium": None,
    "rh_hip": "RightUpLeg",
    "rh_knee": "RightLeg",
    "rh_hock": "RightFoot",
    "rh_toe": "RightToeBase",
}


# (habitsim joint, next mapped habitsim joint along its chain) for bones driven by a
# non-root joint: their direction must follow the source.
BONE_PAIRS = [
    ("spine1", "spine3"),
    ("spine3", "neck"),
    ("neck", "head"),
    ("head", "snout"),
    ("tail1", "tail2"),
    ("tail2", "tail3"),
] + [
    (f"{s}{limb}_{a}", f"{s}{limb}_{b}")
    for s in "lr"
    for limb, segs in (
        ("f", ("scapula", "shoulder", "elbow", "wrist", "toe")),
        ("h", ("hip", "knee", "hock", "toe")),
    )
    for a, b in zip(segs[:-1], segs[1:], strict=True)
]


def test_name_cues():
    assert name_cues("LeftUpLeg") == ("l", "upleg")
    assert name_cues("RightForeArm") == ("r", "forearm")
    assert name_cues("L_Thigh") == ("l", "thigh")
    assert name_cues("hand.R") == ("r", "hand")
    assert name_cues("Bip01_L_Foot") == ("l", "bip01foot")
    assert name_cues("LHand") == ("l", "hand")
    assert name_cues("Spine1") == (None, "spine1")
    assert name_cues("LowerLeg")[0] is None


def test_auto_mapping_of_dog_mocap_joint_by_joint():
    d = read_bvh(DOG)
    m = auto_map(d)
    assert set(m) == set(JOINT_NAMES)
    for k, v in EXPECTED_DOG_MAP.items():
        assert m[k] == v, f"{k}: {m[k]} != {v}"


def test_units_and_axes_detection_with_hand_fk():
    d = read_bvh(DOG)
    fr = detect_frame(d, auto_map(d), species="dog")
    assert (fr.units, fr.scale, fr.up, fr.forward, fr.left) == ("cm", 0.01, "+y", "+z", "+x")
    pos = fr.apply(d.fk())  # habitsim frame, metres
    # Frame 0: no rotations, Hips at (0, 54, 0) cm. By hand (file x, y, z in cm):
    # LeftHand_End = Hips + Spine(0,2,15) + Spine1(0,0,20) + LeftShoulder(6,-2,2)
    #   + LeftArm(0,-15,-3) + LeftForeArm(0,-18,2) + LeftHand(0,-18,0) + End(0,-3,3) = (6, 0, 39)
    # -> habitsim (forward = file z, left = file x, up = file y) = (0.39, 0.06, 0.0) m.
    np.testing.assert_allclose(pos[0, d.index("LeftHand_End")], [0.39, 0.06, 0.0], atol=1e-12)
    # Head_End = (0,54,0)+(0,2,15)+(0,0,20)+(0,5,10)+(0,12,8)+(0,-3,18) = (0, 70, 71)
    np.testing.assert_allclose(pos[0, d.index("Head_End")], [0.71, 0.0, 0.70], atol=1e-12)
    # RightToeBase = (0,54,0)+(-7,-4,-3)+(0,-20,4)+(0,-20,-6)+(0,-10,2) = (-7, 0, -3)
    np.testing.assert_allclose(pos[0, d.index("RightToeBase")], [-0.03, -0.07, 0.0], atol=1e-12)
    # Frame 1 root position channels (1.5, 54 + 0.5 sin 1, 8) cm
    np.testing.assert_allclose(pos[1, 0], [0.08, 0.015, 0.54 + 0.005 * math.sin(1)], atol=1e-6)


def test_explicit_units_and_up_override():
    d = read_bvh(DOG)
    fr = detect_frame(d, auto_map(d), units="m", up="y")
    assert fr.scale == 1.0 and fr.up == "+y"
    with pytest.raises(SkeletonMappingError, match="unknown units"):
        detect_frame(d, auto_map(d), units="furlong")
    with pytest.raises(SkeletonMappingError, match="unknown up axis"):
        detect_frame(d, auto_map(d), up="w")


def _to_zup_metres(d: BVHData) -> BVHData:
    """The same clip re-expressed z-up in metres: p' = (x, -z, y) / 100 (a +90 deg turn about x).

    Under that change of basis a rotation about x stays about x, about y becomes about z and
    about z becomes about -y, so channels are relabelled (order kept) and Z angles negated.
    """
    relabel = {
        "Xrotation": "Xrotation",
        "Yrotation": "Zrotation",
        "Zrotation": "Yrotation",
        "Xposition": "Xposition",
        "Yposition": "Zposition",
        "Zposition": "Yposition",
    }
    off = np.stack([d.offsets[:, 0], -d.offsets[:, 2], d.offsets[:, 1]], axis=1) / 100.0
    frames = d.frames.copy()
    starts = d.channel_start
    chans = []
    for j, ch in enumerate(d.channels):
        chans.append(tuple(relabel[c] for c in ch))
        for k, c in enumerate(ch):
            col = starts[j] + k
            if c == "Zrotation":
                frames[:, col] = -d.frames[:, col]
            elif c == "Zposition":
                frames[:, col] = -d.frames[:, col] / 100.0
            elif c.endswith("position"):
                frames[:, col] = d.frames[:, col] / 100.0
    return dataclasses.replace(d, offsets=off, channels=tuple(chans), frames=frames)


def test_zup_metres_file_gives_the_same_motion(tmp_path):
    d = read_bvh(DOG)
    z = _to_zup_metres(d)
    p = tmp_path / "dog_zup_m.bvh"
    p.write_text(z.to_text())
    # sanity: the conversion really is the same physical motion
    np.testing.assert_allclose(
        read_bvh(p).fk()[:, :, [0, 2, 1]] * [1, 1, -1] * 100, d.fk(), atol=1e-5
    )
    m_y, map_y = import_bvh(DOG, "dog")
    m_z, map_z = import_bvh(p, "dog")
    assert (map_z.frame.units, map_z.frame.up, map_z.frame.forward) == ("m", "+z", "-y")
    assert map_z.mapped() == map_y.mapped()
    np.testing.assert_allclose(m_z.global_positions(), m_y.global_positions(), atol=1e-6)


def test_retargeted_bone_directions_match_source():
    # Without planting the legs keep the source's bone directions (the first stage).
    d = read_bvh(DOG)
    motion, mapping = import_bvh(DOG, "dog", plant=False)
    src = mapping.frame.apply(d.fk())
    dst = motion.global_positions()
    idx = {n: i for i, n in enumerate(JOINT_NAMES)}
    for f in range(motion.num_frames):
        for a, b in BONE_PAIRS:
            vs = src[f, d.index(mapping.joints[b])] - src[f, d.index(mapping.joints[a])]
            vd = dst[f, idx[b]] - dst[f, idx[a]]
            cos = vs @ vd / np.linalg.norm(vs) / np.linalg.norm(vd)
            assert cos > 0.999, (f, a, b, cos)
    # pelvis heading follows hips -> chest (Spine1) projected: first frame faces +x
    from habitsim.rotations import quat_to_matrix

    x_axis = quat_to_matrix(motion.rotations[:, 0])[:, :, 0]
    chest = src[:, d.index("Spine1")] - src[:, d.index("Hips")]
    chest /= np.linalg.norm(chest, axis=1, keepdims=True)
    assert np.all(np.sum(x_axis * chest, axis=1) > 0.999)
    # root translation: horizontal displacement = source displacement x root_scale
    k = mapping.root_scale
    sp = load_species("dog")
    assert 0.7 * sp.hip_height / 0.5 < k < 1.3 * sp.hip_height / 0.5  # source hip height ~0.5 m
    np.testing.assert_allclose(
        motion.root_positions[1:, :2] - motion.root_positions[0, :2],
        k * (src[1:, 0, :2] - src[0, 0, :2]),
        atol=1e-12,
    )
    assert motion.fps == 30.0
    assert motion.metadata["mapping"]["units"] == "cm"


def test_unnamed_sides_are_found_by_geometry(tmp_path):
    # Left -> Port, Right -> Starboard: no side cue in the names; left = +x in this file.
    text = _dog_text().replace("Left", "Port").replace("Right", "Starboard")
    p = tmp_path / "port.bvh"
    p.write_text(text)
    motion, mapping = import_bvh(p, "dog")
    expected = {
        k: (v.replace("Left", "Port").replace("Right", "Starboard") if v else None)
        for k, v in EXPECTED_DOG_MAP.items()
    }
    assert mapping.joints == expected
    assert MappingNote.GEOMETRIC_SIDES in mapping.note_codes


def test_unmappable_three_joint_chain():
    text = """HIERARCHY
ROOT A
{
 OFFSET 0 0 0
 CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
 JOINT B
 {
  OFFSET 0 1 0
  CHANNELS 3 Zrotation Xrotation Yrotation
  JOINT C
  {
   OFFSET 0 1 0
   CHANNELS 3 Zrotation Xrotation Yrotation
   End Site
   {
    OFFSET 0 1 0
   }
  }
 }
}
MOTION
Frames: 1
Frame Time: 0.04
0 0 0 0 0 0 0 0 0 0 0 0
"""
    with pytest.raises(
        SkeletonMappingError, match=r"found 0 left and 0 right leg chains.*need 4 legs"
    ):
        import_bvh(parse_bvh(text), "dog")


def test_explicit_map_toml(tmp_path):
    toml = tmp_path / "map.toml"
    body = "\n".join(f'{k} = "{v}"' for k, v in EXPECTED_DOG_MAP.items() if v)
    toml.write_text('units = "cm"\nup = "y"\n[map]\n' + body + "\n")
    spec = load_joint_map(toml)
    assert spec["units"] == "cm" and spec["map"]["lf_wrist"] == "LeftHand"
    m_map, mapping = import_bvh(DOG, "dog", joint_map=toml)
    m_auto, _ = import_bvh(DOG, "dog")
    assert mapping.method.startswith("map file")
    np.testing.assert_allclose(m_map.global_positions(), m_auto.global_positions(), atol=1e-12)
    # a partial map works too: unmapped joints keep the standing pose
    part, pm = import_bvh(
        DOG,
        "dog",
        joint_map={
            "pelvis": "Hips",
            "spine3": "Spine1",
            "lh_hip": "LeftUpLeg",
            "lh_toe": "LeftToeBase",
            "rh_hip": "RightUpLeg",
            "rh_toe": "RightToeBase",
        },
    )
    stand = get_skeleton("dog").standing_pose()[1]
    assert (
        quat_angle(
            part.rotations[0, JOINT_NAMES.index("lf_elbow")], stand[JOINT_NAMES.index("lf_elbow")]
        )
        < 1e-9
    )


@pytest.mark.parametrize(
    "content, fragment",
    [
        (
            '[map]\npelvis = "Hips"\nfront_paw = "LeftHand"\n',
            "unknown habitsim joints ['front_paw']; valid: pelvis",
        ),
        ('[map]\npelvis = "Hips"\nlf_wrist = "LeftPaw"\n', "source joints ['LeftPaw'] are not in"),
        ('[map]\nlf_wrist = "LeftHand"\n', "must map pelvis"),
        ('[map]\npelvis = "Hips"\nspine1 = "Hips"\n', "mapped to both"),
        ("[map]\npelvis = 3\n", "must be a source joint name"),
        ('pelvis = "Hips"\n', "unknown keys"),
        ("[map\n", "cannot read joint-map TOML"),
    ],
)
def test_bad_map_toml(tmp_path, content, fragment):
    toml = tmp_path / "bad.toml"
    toml.write_text(content)
    with pytest.raises(SkeletonMappingError) as ei:
        import_bvh(DOG, "dog", joint_map=toml)
    assert fragment in str(ei.value)


@pytest.fixture(scope="module")
def walk():
    return habitsim.generate("dog", "walk", seed=3, duration_s=3.0)


@pytest.fixture(scope="module")
def rig(walk):
    return _foreign_rig(walk)


def test_helper_names():
    for n in (
        "Dog_LeftTail001",
        "Bip01_L_Toe0Nub",
        "Bip01_Footsteps",
        "Dog_LeftArmor002",
        "LeftLegIKTarget",
        "forearm_twist.L",
        "L_TailHelper01",
    ):
        assert is_helper_name(n), n
    for n in ("b_LeftLegUpper", "LeftUpLeg", "L_Toes", "b__LeftFinger", "RightAnkle", "Hips"):
        assert not is_helper_name(n), n


def test_foreign_rig_maps_legs_not_helpers(rig):
    motion, mapping = import_bvh(rig, "dog")
    j = mapping.joints
    assert (mapping.frame.units, mapping.frame.up) == ("cm", "+z")
    assert j["pelvis"] == "Hips_jnt"
    assert [j[f"lh_{s}"] for s in ("ilium", "hip", "knee", "hock", "toe")] == [
        "L_Ilium",
        "L_Thigh",
        "L_Shin",
        "L_Hock",
        "L_Toes",
    ]
    assert [j[f"rf_{s}"] for s in ("scapula", "shoulder", "elbow", "wrist", "toe")] == [
        "R_Collar",
        "R_UpperArm",
        "R_LowerArm",
        "R_Paw",
        "R_Digits",
    ]
    assert not any(v and ("Helper" in v or "Nub" in v or "Armor" in v) for v in j.values())
    assert set(mapping.confidence) == {"lf", "rf", "lh", "rh"}
    assert min(mapping.confidence.values()) >= 0.67 and mapping.warnings == []


def test_leg_codes_and_numbers_map_like_names(walk, rig):
    """``FL_1`` / ``HR_3`` names (side and girdle in a code, the bone only a number) map
    onto the same joints as the named rig: the codes give side and girdle, and the short
    first bone of a chain makes its first joint the girdle's."""
    _, named = import_bvh(rig, "dog")
    _, coded = import_bvh(_foreign_rig(walk, rename=CODED), "dog")
    back = {v: k for k, v in CODED.items()}
    assert {k: back.get(v, v) for k, v in coded.joints.items() if v} == {
        k: {v: k2 for k2, v in RENAME.items()}.get(v, v) for k, v in named.joints.items() if v
    }
    assert coded.joints["lf_scapula"] == "FL_0" and coded.joints["rh_toe"] == "HR_4"
    assert min(coded.confidence.values()) >= 0.67


def test_anonymous_rig_finds_legs_by_mirrored_chains(walk, rig):
    """Every joint named ``J000`` …: the legs are the chains that mirror each other bone by
    bone, although unnamed armour plates branch off them, and the sided tail helper (a
    chain longer than a leg, beside the hind legs, with no mirror) is not one. The toe
    nub pointing into the ground, a bone longer than the toe's own, is neither the toe
    nor a foot point, so the stance is the named rig's."""
    anon = _foreign_rig(walk, anonymous=True)
    named_motion, named = import_bvh(rig, "dog")
    motion, mapping = import_bvh(anon, "dog")
    by_index = dict(zip(rig.names, anon.names, strict=True))
    for leg in ("lf", "rf", "lh", "rh"):
        segs = (
            ("scapula", "shoulder", "elbow", "wrist", "toe")
            if leg[1] == "f"
            else (
                "hip",
                "knee",
                "hock",
                "toe",
            )
        )
        for seg in segs:
            k = f"{leg}_{seg}"
            assert mapping.joints[k] == by_index[named.joints[k]], k
    tail = {by_index[n] for n in rig.names if "TailHelper" in n}
    assert not tail & set(mapping.joints.values())
    assert MappingNote.GEOMETRIC_SIDES in mapping.note_codes
    assert named_motion.contacts is not None and motion.contacts is not None
    assert min(stance_f1(motion.contacts, named_motion.contacts)) >= 0.95
    # a nub pointing ahead (as a 3ds Max biped's finger nub does) is no foot point either
    ahead = _foreign_rig(walk, anonymous=True, nub=(0.25, 0.0, 0.0))
    motion, mapping = import_bvh(ahead, "dog")
    assert mapping.joints["lf_toe"] == by_index[named.joints["lf_toe"]]
    nubs = {by_index[n] for n in rig.names if n.endswith("_Nub")}
    points = motion.metadata["import"]["contacts"]["foot_points"]
    assert len(points) == 4 and all(p and not nubs & set(p) for p in points)
    assert motion.contacts is not None
    assert min(stance_f1(motion.contacts, named_motion.contacts)) >= 0.95


def test_mirror_tolerance_is_a_mapping_option(walk):
    """The mirrored-chain tolerance reaches the automatic mapping through
    ``MappingOptions``: with none (a negative share) no unnamed chains pair, so an
    anonymous rig has no legs."""
    anon = _foreign_rig(walk, anonymous=True)
    assert auto_map(anon, MappingOptions())["lf_toe"] is not None
    with pytest.raises(SkeletonMappingError, match="symmetric unnamed chains"):
        import_bvh(anon, "dog", options=MappingOptions(mirror_bone_tolerance=-1.0))


def test_inches_given_explicitly(walk, rig):
    inch = _foreign_rig(walk, CM=100.0 / 2.54)
    m_in, map_in = import_bvh(inch, "dog", units="in")
    m_cm, _ = import_bvh(rig, "dog")
    assert map_in.frame.units == "in" and map_in.frame.scale == 0.0254
    np.testing.assert_allclose(m_in.global_positions(), m_cm.global_positions(), atol=1e-5)
    np.testing.assert_array_equal(m_in.contacts, m_cm.contacts)


def test_map_file_overrides_joints_and_warns(rig, tmp_path):
    bad = {
        "extends": "auto",
        "map": {
            "lh_hip": "L_TailHelper01",
            "lh_knee": "L_TailHelper02",
            "lh_hock": "L_TailHelper03",
            "lh_toe": "L_TailHelper04",
            "lh_ilium": None,
        },
    }
    p = tmp_path / "map.json"
    p.write_text(json.dumps(bad))
    spec = load_joint_map(p)
    assert spec["extends"] == "auto" and spec["map"]["lh_ilium"] is None
    motion, mapping = import_bvh(rig, "dog", joint_map=p)
    assert mapping.joints["lh_hip"] == "L_TailHelper01"
    assert mapping.joints["rh_hip"] == "R_Thigh"  # the rest still comes from the auto map
    assert mapping.joints["lh_ilium"] is None
    assert mapping.confidence["lh"] < 0.67
    assert any(w.startswith("lh leg") for w in mapping.warnings)
    assert motion.metadata["import"]["warnings"] == mapping.warnings


@pytest.mark.parametrize(
    "content, fragment",
    [
        ('{"map": {"paw": "L_Paw"}}', "unknown habitsim joints ['paw']"),
        ('{"extends": "manual", "map": {"pelvis": "Hips_jnt"}}', "unknown extends"),
        ('{"map": {"pelvis": 3}}', "must be a source joint name"),
        ('{"map": {"pelvis": "Hips_jnt"}, "scale": 2}', "unknown keys ['scale']"),
        ("[1, 2]", "must be a table/object"),
        ("{oops", "cannot read joint-map JSON"),
        ('{"extends": "auto", "map": {"lh_hip": "NoSuchJoint"}}', "source joints ['NoSuchJoint']"),
    ],
)
def test_bad_json_map(rig, tmp_path, content, fragment):
    p = tmp_path / "bad.json"
    p.write_text(content)
    with pytest.raises(SkeletonMappingError) as ei:
        import_bvh(rig, "dog", joint_map=p)
    assert fragment in str(ei.value)
    assert len(str(ei.value)) < 2000


def test_unknown_source_type(tmp_path):
    p = tmp_path / "clip.fbx"
    p.write_text("x")
    with pytest.raises(SkeletonMappingError, match=r"valid: \.bvh, \.glb, \.gltf"):
        read_source(p)


@pytest.mark.parametrize(
    "name, content",
    [
        ("deep.json", '{"map": ' + "[" * 100_000 + "]" * 100_000 + "}"),
        ("deep.toml", "map = " + "[" * 5_000 + "]" * 5_000 + "\n"),
        ("big.json", '{"map": {"pelvis": ' + "9" * 5_000 + "}}"),
    ],
)
def test_map_file_out_of_bounds_is_typed(tmp_path, name, content):
    p = tmp_path / name
    p.write_text(content)
    with pytest.raises(SkeletonMappingError):
        load_joint_map(p)


def test_zero_size_skeleton_is_typed(walk):
    from foreign_rig import blender_rig

    rig = blender_rig(walk.slice(0, 10))
    flat = dataclasses.replace(
        rig, offsets=np.zeros_like(rig.offsets), frames=np.zeros_like(rig.frames)
    )
    with pytest.raises(SkeletonMappingError):
        import_bvh(flat, "dog")
    with pytest.raises(SkeletonMappingError):  # math.log(0) of the unit guess before
        detect_frame(flat, {"pelvis": flat.names[0]})
