"""BVH reading, writing, automatic mapping and retargeting (habitsim.bvh, habitsim.bvh_mapping)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers import DOG, _dog_text

from habitsim import species_names
from habitsim.bvh import parse_bvh, read_bvh, write_bvh
from habitsim.bvh_mapping import (
    import_bvh,
)
from habitsim.cli import main
from habitsim.errors import BVHParseError, HabitsimError
from habitsim.motion import Motion
from habitsim.rotations import quat_angle, quat_from_axis_angle, quat_normalize, quat_to_euler
from habitsim.skeleton import get_skeleton


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
