"""BVH reading, writing, automatic mapping and retargeting (habitsim.bvh, habitsim.bvh_mapping)."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from habitsim import species_names
from habitsim.bvh import BVHData, parse_bvh, read_bvh, write_bvh
from habitsim.bvh_mapping import (
    auto_map,
    detect_frame,
    import_bvh,
    load_joint_map,
    name_cues,
)
from habitsim.cli import main
from habitsim.errors import BVHParseError, HabitsimError, SkeletonMappingError
from habitsim.motion import Motion
from habitsim.rotations import quat_angle, quat_from_axis_angle, quat_normalize, quat_to_euler
from habitsim.skeleton import JOINT_NAMES, get_skeleton
from habitsim.species import load_species

DATA = Path(__file__).parent / "data"
DOG = DATA / "dog_mocap_cm_yup.bvh"

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


def _two_species() -> list[str]:
    names = species_names()
    assert "dog" in names
    others = [n for n in names if n != "dog"]
    return ["dog"] + others[:1]


def _random_motion(species: str, t: int = 6, seed: int = 0) -> Motion:
    rng = np.random.default_rng(seed)
    skel = get_skeleton(species)
    root, q0 = skel.standing_pose()
    axes = rng.normal(size=(t, skel.num_joints, 3))
    ang = rng.uniform(-0.6, 0.6, size=(t, skel.num_joints))
    from habitsim.rotations import quat_mul

    q = quat_mul(q0[None], quat_from_axis_angle(axes, ang))
    # include a near gimbal-lock rotation for the ZXY order (X = 90 deg) on one joint
    q[2, 3] = quat_from_axis_angle(np.array([1.0, 0.0, 0.0]), math.pi / 2)
    rp = root[None] + np.cumsum(rng.normal(scale=0.02, size=(t, 3)), axis=0)
    return Motion(species, 30.0, rp, quat_normalize(q))


# ---------------------------------------------------------------------- reader


def test_parse_dog_file_structure():
    d = read_bvh(DOG)
    assert d.names[:5] == ("Hips", "Spine", "Spine1", "Neck", "Head")
    assert d.num_joints == 23 + 6  # 23 joints + 6 End Sites (head, tail, 4 feet)
    assert sum(d.is_end_site) == 6
    assert d.names[d.parents[d.index("LeftHand_End")]] == "LeftHand"
    assert d.channels[0] == (
        "Xposition",
        "Yposition",
        "Zposition",
        "Zrotation",
        "Xrotation",
        "Yrotation",
    )
    assert d.channels[d.index("LeftArm")] == ("Zrotation", "Xrotation", "Yrotation")
    assert d.frames.shape == (5, 6 + 22 * 3)
    assert d.fps == 30.0
    np.testing.assert_allclose(d.offsets[d.index("LeftUpLeg")], [7, -4, -3])
    np.testing.assert_allclose(d.root_translation()[0], [0, 54, 0])


def test_fk_two_joint_by_hand():
    # Root at (1, 2, 3) rotated R = Rz(90) Rx(90) (channels Zrotation Xrotation); child offset
    # (0, 10, 0): Rx(90) turns it to (0, 0, 10), Rz(90) leaves that -> child at (1, 2, 13).
    # End Site (0, 0, 5) in the child's frame (child rotation 0): Rx(90) -> (0, -5, 0),
    # Rz(90) -> (5, 0, 0) -> (6, 2, 13).
    text = """HIERARCHY
ROOT A
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT B
  {
    OFFSET 0 10 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0 0 5
    }
  }
}
MOTION
Frames: 1
Frame Time: 0.01
1 2 3 90 90 0 0 0 0
"""
    d = parse_bvh(text)
    pos = d.fk()
    np.testing.assert_allclose(pos[0], [[1, 2, 3], [1, 2, 13], [6, 2, 13]], atol=1e-12)
    assert d.fps == 100.0


def _elem(axis: str, deg: float) -> np.ndarray:
    a = math.radians(deg)
    c, s = math.cos(a), math.sin(a)
    return {
        "X": np.array([[1, 0, 0], [0, c, -s], [0, s, c]]),
        "Y": np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]),
        "Z": np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]),
    }[axis]


def _one_joint_bvh(order: str, angles_deg) -> str:
    chans = " ".join(f"{a}rotation" for a in order)
    vals = " ".join(f"{v:.12g}" for v in angles_deg)
    return f"""HIERARCHY
ROOT R
{{
\tOFFSET 0 0 0
\tCHANNELS 6 Xposition Yposition Zposition {chans}
\tJOINT C
\t{{
\t\tOFFSET 1 0 0
\t\tCHANNELS 3 {chans}
\t\tEnd Site
\t\t{{
\t\t\tOFFSET 0 1 0
\t\t}}
\t}}
}}
MOTION
Frames: 1
Frame Time: 0.02
0 0 0 0 0 0 {vals}
"""


ORDERS = ["XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"]


@pytest.mark.parametrize("order", ORDERS)
def test_every_channel_order_reads_the_known_rotation(order):
    from habitsim.rotations import quat_to_matrix

    # 1) channel values (a, b, c) in this order mean R = R_a · R_b · R_c (matrices on paper)
    vals = (25.0, -40.0, 70.0)
    d = parse_bvh(_one_joint_bvh(order, vals))
    expected = _elem(order[0], vals[0]) @ _elem(order[1], vals[1]) @ _elem(order[2], vals[2])
    np.testing.assert_allclose(quat_to_matrix(d.local_rotations()[0, 1]), expected, atol=1e-12)
    # 2) a known quaternion written as Euler angles in this order reads back to itself
    q = quat_from_axis_angle(np.array([1.0, 2.0, 3.0]), math.radians(70))
    ang = np.degrees(quat_to_euler(q, order))
    d = parse_bvh(_one_joint_bvh(order, ang))
    assert quat_angle(d.local_rotations()[0, 1], q) < 1e-9


def test_lenient_whitespace_crlf_tabs_and_odd_channels():
    base = DOG.read_text()
    messy = (
        base.replace("\n", "\r\n").replace("OFFSET", "OFFSET \t ").replace("Frames: 5", "Frames:5")
    )
    messy = messy.replace("Frame Time: 0.0333333", "Frame Time:   0.0333333  ") + "\r\n\r\n"
    a, b = parse_bvh(base), parse_bvh(messy)
    assert a.names == b.names
    np.testing.assert_array_equal(a.frames, b.frames)
    np.testing.assert_array_equal(a.offsets, b.offsets)
    # 3-channel root without position channels, 6-channel non-root joint, 2-channel joint
    text = """HIERARCHY
ROOT R
{
 OFFSET 5 0 0
 CHANNELS 3 Yrotation Xrotation Zrotation
 JOINT C
 {
  OFFSET 0 1 0
  CHANNELS 6 Zrotation Xposition Yposition Zposition Xrotation Yrotation
  JOINT D
  {
   OFFSET 0 0 2
   CHANNELS 2 Xrotation Zrotation
   End Site
   {
    OFFSET 1 0 0
   }
  }
 }
}
MOTION
Frames: 1
Frame Time: 0.5
0 0 0  0 3 4 5 0 0  0 90
"""
    d = parse_bvh(text)
    pos = d.fk()[0]
    # root stays at its OFFSET; C's position channels replace its offset: (5,0,0)+(3,4,5);
    # D at C + (0,0,2); D's Zrotation 90 turns its End Site (1,0,0) to (0,1,0).
    np.testing.assert_allclose(pos, [[5, 0, 0], [8, 4, 5], [8, 4, 7], [8, 5, 7]], atol=1e-12)


def test_to_text_round_trip():
    d = read_bvh(DOG)
    e = parse_bvh(d.to_text())
    assert e.names == d.names and e.parents == d.parents and e.channels == d.channels
    np.testing.assert_allclose(e.frames, d.frames)
    np.testing.assert_allclose(e.offsets, d.offsets)


# ---------------------------------------------------------------------- reader errors


def _dog_text() -> str:
    return DOG.read_text()


@pytest.mark.parametrize(
    "mutate, fragment",
    [
        (lambda t: t[: len(t) // 3], "unexpected end of the HIERARCHY"),  # cut in the hierarchy
        (lambda t: t[: len(t) - 200], "truncated"),  # short last frame line
        (lambda t: t.rsplit("\n", 3)[0] + "\n", "declares 5 frames but holds 3"),  # missing frames
        (
            lambda t: t.replace(
                "CHANNELS 3 Zrotation Xrotation Yrotation", "CHANNELS 3 Zrotation Xrotation", 1
            ),
            "declares 3 channels but lists 2",
        ),
        (lambda t: t.replace("CHANNELS 3 Zrotation", "CHANNELS 7 Zrotation", 1), "7 channels"),
        (
            lambda t: t.replace(
                "CHANNELS 3 Zrotation Xrotation Yrotation",
                "CHANNELS 3 Zrotation Xrotation Wrotation",
                1,
            ),
            "unknown channel 'Wrotation'",
        ),
        (lambda t: t.replace("54.4546", "abc"), "'abc' is not a number"),
        (lambda t: t.replace("54.4546", "nan"), "non-finite value 'nan'"),
        (lambda t: t.replace("54.4546", "inf"), "non-finite"),
        (lambda t: t.replace("OFFSET 0.00 2.00 15.00", "OFFSET 0.00 x 15.00"), "is not a number"),
        (lambda t: t.split("MOTION")[0], "no MOTION section"),
        (
            lambda t: t.replace("Frame Time: 0.0333333", "Frame Time: 0"),
            "frame time must be positive",
        ),
        (lambda t: t.replace("Frames: 5", "Frames: five"), "not an integer"),
        (lambda t: t.replace("Frames: 5\n", ""), "expected 'Frames: N'"),
        (lambda t: "", "empty file"),
        (lambda t: t.replace("HIERARCHY", "HIERARCHIE"), "expected 'HIERARCHY'"),
    ],
)
def test_malformed_bvh_raises_typed_error_with_line(tmp_path, mutate, fragment):
    p = tmp_path / "bad.bvh"
    p.write_text(mutate(_dog_text()))
    with pytest.raises(BVHParseError) as ei:
        read_bvh(p)
    msg = str(ei.value)
    assert fragment in msg
    assert isinstance(ei.value, HabitsimError)
    if fragment != "empty file":
        assert f"{p}:" in msg  # file:line prefix


def test_wrong_value_count_names_the_line():
    lines = _dog_text().splitlines()
    i = next(k for k, ln in enumerate(lines) if ln.startswith("Frame Time")) + 2  # 2nd frame line
    lines[i] = lines[i] + " 1.0"
    with pytest.raises(
        BVHParseError, match=rf"<string>:{i + 1}: frame line holds 73 values .* 72 channels"
    ):
        parse_bvh("\n".join(lines))


def test_non_strict_keeps_complete_frames():
    cut = _dog_text()[:-200]
    with pytest.warns(UserWarning, match="truncated"):
        d = parse_bvh(cut, strict=False)
    assert d.num_frames == 4


def test_missing_file():
    with pytest.raises(BVHParseError, match="no such BVH file"):
        read_bvh("/nonexistent/x.bvh")


# ---------------------------------------------------------------------- mapping


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
    assert any("geometry" in n for n in mapping.notes)


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


# ---------------------------------------------------------------------- writer / round trip


@pytest.mark.parametrize("species", _two_species())
def test_export_import_round_trip(tmp_path, species):
    m = _random_motion(species)
    p = write_bvh(m, tmp_path / f"{species}.bvh")
    back, mapping = import_bvh(p, species)
    assert mapping.method == "identity"
    assert back.species == species and back.fps == m.fps and back.num_frames == m.num_frames
    assert np.abs(back.global_positions() - m.global_positions()).max() < 1e-5
    assert quat_angle(back.rotations, m.rotations).max() < 1e-6
    text = p.read_text()
    assert text.startswith("HIERARCHY\nROOT pelvis")
    assert "CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation" in text


@pytest.mark.parametrize("order", ORDERS)
def test_export_every_order_round_trip(tmp_path, order):
    m = _random_motion("dog", t=3, seed=1)
    back, _ = import_bvh(write_bvh(m, tmp_path / "o.bvh", order=order), "dog")
    assert np.abs(back.global_positions() - m.global_positions()).max() < 1e-5


def test_export_bad_order_writes_nothing(tmp_path):
    m = _random_motion("dog", t=3)
    with pytest.raises(HabitsimError, match="rotation order"):
        write_bvh(m, tmp_path / "x.bvh", order="XXY")
    assert list(tmp_path.iterdir()) == []


# ---------------------------------------------------------------------- CLI


def test_cli_import_prints_mapping_and_writes(tmp_path, capsys):
    out = tmp_path / "dog.npz"
    rc = main(["data", "import-bvh", str(DOG), "--species", "dog", "--out", str(out)])
    assert rc == 0 and out.is_file()
    text = capsys.readouterr().out
    assert "lf_wrist    <- LeftHand" in text
    assert "lh_ilium    <- (unmapped: standing pose)" in text
    assert "units cm" in text and "5 frames" in text
    # export it back and re-import as identity
    bvh_out = tmp_path / "back.bvh"
    assert main(["data", "export-bvh", str(out), "--out", str(bvh_out)]) == 0
    assert (
        main(
            [
                "data",
                "import-bvh",
                str(bvh_out),
                "--species",
                "dog",
                "--out",
                str(tmp_path / "b.npz"),
            ]
        )
        == 0
    )
    assert "joint mapping (identity)" in capsys.readouterr().out


def test_cli_unknown_species(tmp_path, capsys):
    out = tmp_path / "o.npz"
    rc = main(["data", "import-bvh", str(DOG), "--species", "unicorn", "--out", str(out)])
    assert rc == 2
    err = capsys.readouterr().err
    assert "unknown species 'unicorn'" in err and "dog" in err
    assert not out.exists()


@pytest.mark.parametrize("kind", ["truncated", "unmappable", "badmap"])
def test_cli_failed_import_leaves_no_output(tmp_path, capsys, kind):
    out = tmp_path / "o.npz"
    bvh = tmp_path / "in.bvh"
    args = ["data", "import-bvh", str(bvh), "--species", "dog", "--out", str(out)]
    if kind == "truncated":
        bvh.write_text(_dog_text()[:-200])
    elif kind == "unmappable":
        bvh.write_text(_dog_text().replace("Left", "Port").replace("RightUpLeg", "Tail9"))
    else:
        bvh.write_text(_dog_text())
        (tmp_path / "m.toml").write_text('[map]\npelvis = "Nope"\n')
        args += ["--map", str(tmp_path / "m.toml")]
    rc = main(args)
    assert rc == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ")
    assert not out.exists()
    assert [
        f.name for f in tmp_path.iterdir() if f.suffix == ".npz" or f.name.endswith(".tmp")
    ] == []
