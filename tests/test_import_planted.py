"""Import of foreign rigs: helper chains, per-leg confidence, source stance, planted feet.

The rigs are written here from a synthetic dog walk whose stance is known: the joints get
other names, 6-channel joints, centimetres, z up, an extra root, and rig helpers that a
motion-capture rig carries (a long sided tail helper, armour plates, toe nubs pointing into
the ground, a footstep tracker).
"""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

import habitsim
from habitsim.bvh import BVHData, bvh_text, parse_bvh
from habitsim.bvh_mapping import (
    ImportReport,
    import_bvh,
    is_helper_name,
    load_joint_map,
    read_source,
)
from habitsim.cli import main
from habitsim.errors import SkeletonMappingError
from habitsim.stance.labels import stance_f1, stance_runs
from habitsim.stance.planting import label_source_stance

RENAME = {
    "pelvis": "Hips_jnt",
    "spine1": "SpineA",
    "spine2": "SpineB",
    "spine3": "Chest",
    "neck": "NeckA",
    "head": "Skull",
    "snout": "Nose",
    "tail1": "TailBase",
    "tail2": "TailMid",
    "tail3": "TailTip",
}
for _s, _S in (("l", "L"), ("r", "R")):
    RENAME.update(
        {
            f"{_s}f_scapula": f"{_S}_Collar",
            f"{_s}f_shoulder": f"{_S}_UpperArm",
            f"{_s}f_elbow": f"{_S}_LowerArm",
            f"{_s}f_wrist": f"{_S}_Paw",
            f"{_s}f_toe": f"{_S}_Digits",
            f"{_s}h_ilium": f"{_S}_Ilium",
            f"{_s}h_hip": f"{_S}_Thigh",
            f"{_s}h_knee": f"{_S}_Shin",
            f"{_s}h_hock": f"{_S}_Hock",
            f"{_s}h_toe": f"{_S}_Toes",
        }
    )
CM = 100.0
#: The same rig with its legs named by leg codes and numbers only, as robot rigs name them.
CODED = {
    **{k: v for k, v in RENAME.items() if k[1:3] not in ("f_", "h_")},
    **{
        f"{s}{g}_{seg}": f"{g.upper()}{s.upper()}_{k}"
        for s in "lr"
        for g, segs in (
            ("f", ("scapula", "shoulder", "elbow", "wrist", "toe")),
            ("h", ("ilium", "hip", "knee", "hock", "toe")),
        )
        for k, seg in enumerate(segs)
    },
}


def _foreign_rig(  # noqa: N803 - the unit factor
    motion, CM: float = CM, rename=RENAME, anonymous: bool = False, nub=(0.05, 0.0, -0.25)
) -> BVHData:
    """The motion as a foreign rig: other names, 6 channels, cm, z up, helpers
    (``anonymous``: every joint, helpers included, named ``J000`` … in file order;
    ``nub``: where the toe nub points from the toe [m])."""
    h = parse_bvh(bvh_text(motion))
    starts = h.channel_start
    f = h.num_frames
    nodes: list[dict] = []  # name, parent name, offset (cm), values (F, 6) or None

    def add(name, parent, offset, values=None):
        nodes.append(
            {"name": name, "parent": parent, "offset": np.asarray(offset, float), "values": values}
        )

    add("Rig_Root", None, [0, 0, 0], np.zeros((f, 6)))
    add("Rig_Footsteps", "Rig_Root", [0, 0, 0], np.zeros((f, 6)))
    for j, name in enumerate(h.names):
        if h.is_end_site[j]:
            parent = h.names[h.parents[j]]
            if parent.endswith("_toe"):  # a toe nub pointing into the ground instead
                add(
                    rename[parent] + "_Nub",
                    rename[parent],
                    np.asarray(nub) * CM,
                    np.zeros((f, 6)),
                )
            else:
                add(rename[parent] + "_End", rename[parent], h.offsets[j] * CM)
            continue
        ch = h.channels[j]
        vals = np.zeros((f, 6))
        cols = {c: starts[j] + k for k, c in enumerate(ch)}
        for k, c in enumerate(("Xposition", "Yposition", "Zposition")):
            vals[:, k] = h.frames[:, cols[c]] * CM if c in cols else h.offsets[j, k] * CM
        for k, c in enumerate(("Zrotation", "Xrotation", "Yrotation")):
            vals[:, 3 + k] = h.frames[:, cols[c]]
        parent = "Rig_Root" if h.parents[j] < 0 else rename[h.names[h.parents[j]]]
        add(rename[name], parent, h.offsets[j] * CM, vals)
        u = CM / 100.0  # helper sizes below are in cm
        if name == "pelvis":  # a sided helper chain longer than a leg
            prev = "Hips_jnt"
            for k in range(1, 6):
                add(f"L_TailHelper0{k}", prev, [-15.0 * u, 3.0 * u, 0.0], np.zeros((f, 6)))
                prev = f"L_TailHelper0{k}"
            add(prev + "_End", prev, [-15.0 * u, 0.0, 0.0])
        if name.endswith("f_shoulder"):
            side = name[0].upper()
            add(f"{side}_Armor01", rename[name], [0.0, 5.0 * u, 5.0 * u], np.zeros((f, 6)))
            add(f"{side}_Armor01_End", f"{side}_Armor01", [0.0, 5.0 * u, 0.0])

    kids: dict[str | None, list[dict]] = {}
    for n in nodes:
        kids.setdefault(n["parent"], []).append(n)
    lines, columns = ["HIERARCHY"], []

    def emit(n, depth):
        pad = "  " * depth
        if n["values"] is None:
            lines.append(f"{pad}End Site")
            lines.append(f"{pad}{{")
            lines.append(f"{pad}  OFFSET " + " ".join(f"{v:.6f}" for v in n["offset"]))
            lines.append(f"{pad}}}")
            return
        lines.append(f"{pad}{'ROOT' if n['parent'] is None else 'JOINT'} {n['name']}")
        lines.append(f"{pad}{{")
        lines.append(f"{pad}  OFFSET " + " ".join(f"{v:.6f}" for v in n["offset"]))
        lines.append(
            f"{pad}  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation"
        )
        columns.append(n["values"])
        for c in kids.get(n["name"], []):
            emit(c, depth + 1)
        lines.append(f"{pad}}}")

    emit(kids[None][0], 0)
    data = np.concatenate(columns, axis=1)
    if anonymous:
        count = iter(range(len(lines)))
        lines = [
            re.sub(r"^(\s*(?:ROOT|JOINT)) .*$", lambda m: f"{m.group(1)} J{next(count):03d}", ln)
            for ln in lines
        ]
    lines += ["MOTION", f"Frames: {f}", f"Frame Time: {1.0 / motion.fps:.8f}"]
    lines += [" ".join(f"{v:.6f}" for v in row) for row in data]
    return parse_bvh("\n".join(lines) + "\n", source="foreign_rig.bvh")


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
    assert any("geometry" in n for n in mapping.notes)
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


def test_source_stance_matches_the_known_footfalls(walk, rig):
    motion, _ = import_bvh(rig, "dog")
    imp = motion.metadata["import"]
    assert imp["contacts"]["method"] == "source foot path"
    assert ImportReport.from_metadata(motion.metadata).to_metadata() == imp  # type: ignore[union-attr]
    # the labels found on the foreign rig's own feet are the walk's own stance
    f1 = stance_f1(motion.contacts, walk.contacts)
    assert np.all(f1 >= 0.85), f1
    assert np.allclose(imp["contacts"]["duty"], motion.contacts.mean(axis=0), atol=1e-3)


def test_planted_feet_on_the_ground(rig):
    motion, _ = import_bvh(rig, "cat")  # another size: the legs are re-solved for the cat
    leg = motion.species_info.leg_length
    toes = motion.foot_positions()[..., 2]
    c = motion.contacts
    assert toes.min() >= -1e-6  # no toe under the ground
    assert np.all(np.abs(toes[c]) <= 0.01 * leg)  # stance toes within 1 % of leg length
    # stance feet stay put: horizontal slide within a stance run
    feet = motion.foot_positions()[..., :2]
    slide = np.linalg.norm(np.diff(feet, axis=0), axis=-1)[c[1:] & c[:-1]]
    assert slide.max() <= 0.005 * leg
    # the metric's contacts on the imported clip agree with the source's labels
    f1 = np.asarray(motion.metadata["import"]["contact_f1"])
    assert np.all(f1 >= 0.85), f1


def test_inches_given_explicitly(walk, rig):
    inch = _foreign_rig(walk, CM=100.0 / 2.54)
    m_in, map_in = import_bvh(inch, "dog", units="in")
    m_cm, _ = import_bvh(rig, "dog")
    assert map_in.frame.units == "in" and map_in.frame.scale == 0.0254
    np.testing.assert_allclose(m_in.global_positions(), m_cm.global_positions(), atol=1e-5)
    np.testing.assert_array_equal(m_in.contacts, m_cm.contacts)


def test_unplanted_import_hovers_or_sinks(rig):
    # The reason planting exists: bone directions alone put a cat's toes off the ground.
    motion, _ = import_bvh(rig, "cat", plant=False)
    leg = motion.species_info.leg_length
    toes = motion.foot_positions()[..., 2]
    assert np.abs(np.median(toes[motion.contacts])) > 0.01 * leg or toes.min() < -0.01 * leg


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


def test_label_source_stance_floor_and_hold():
    # One foot: planted at a 3 cm marker height, lifted 10 cm in the middle; another held
    # still in the air for the whole clip never counts as stance.
    fps, leg, t = 60.0, 0.6, 120
    x = np.linspace(0.0, 1.2, t)
    pts = []
    z = np.full(t, 0.03)
    z[40:80] += 0.1 * np.sin(np.linspace(0, np.pi, 40))
    xf = np.where(np.arange(t) < 40, 0.2, np.where(np.arange(t) >= 80, 0.7, x))
    pts.append(np.stack([xf, np.zeros(t), z], -1)[:, None])
    pts.append(np.stack([x * 0 + 0.3, np.zeros(t), np.full(t, 0.2)], -1)[:, None])
    pts.append(np.stack([x * 0, np.zeros(t), np.full(t, 0.03)], -1)[:, None])
    pts.append(np.stack([x * 0, np.zeros(t), np.full(t, 0.03)], -1)[:, None])
    st = label_source_stance(pts, fps, leg)
    assert st.contacts[:35, 0].all() and st.contacts[85:, 0].all()
    assert not st.contacts[45:75, 0].any()
    assert not st.contacts[:, 1].any()  # held in the air: 17 cm above the lowest floor
    assert st.contacts[:, 2].all() and st.contacts[:, 3].all()


def test_label_source_stance_follows_a_floor_that_steps_down():
    # Four feet walking (stride 0.5 s, duty 0.6, 6 cm swings) on a capture floor that is
    # 2 cm lower after 2 s (a mat's edge, a sloping floor): every stance frame on either
    # side is found, also the ones just before the step, where a floor window much
    # longer than a stride would already reach the lower floor.
    fps, leg, t = 60.0, 0.6, 240
    tt = np.arange(t) / fps
    floor = np.where(tt < 2.0, 0.03, 0.01)
    ph = (tt % 0.5) / 0.5
    stance = ph < 0.6
    sw = np.clip((ph - 0.6) / 0.4, 0, 1)
    z = floor + np.where(stance, 0.0, 0.06 * np.sin(np.pi * sw))
    x = np.floor(tt / 0.5) * 0.5 + np.where(stance, 0.0, 0.5 * (3 * sw**2 - 2 * sw**3))
    pts = [np.stack([x + o, np.zeros(t), z], -1)[:, None] for o in (0.0, 0.1, 0.2, 0.3)]
    st = label_source_stance(pts, fps, leg)
    for k in range(4):
        assert st.contacts[stance, k].mean() >= 0.99
        assert not st.contacts[(sw > 0.2) & (sw < 0.8), k].any()  # swings stay swings


def test_label_source_stance_of_a_fast_gait_whose_paws_roll():
    # A run at 4 m/s (stride 0.4 s, duty 0.3): on the ground the paw's lowest point rolls
    # forward at 1 m/s (a quarter of the body's speed, far above the 0.18 m/s rest speed
    # of a 0.6 m leg), in swing it lifts 8 cm and catches up. Each stance is found by the
    # speed relative to the body; by the absolute rest speed alone, none is.
    fps, leg, t, v = 120.0, 0.6, 480, 4.0
    tt = np.arange(t) / fps
    feet = []
    stance_all = []
    for k, phase in enumerate((0.0, 0.1, 0.5, 0.6)):
        ph = (tt / 0.4 + phase) % 1.0
        stance = ph < 0.3
        sw = np.clip((ph - 0.3) / 0.7, 0, 1)
        # forward speed: v/4 in stance, and the rest of the stride's travel in swing
        speed = np.where(stance, v / 4, (v - 0.3 * v / 4) / 0.7 * 2 * np.sin(np.pi * sw) ** 2)
        x = np.cumsum(speed) / fps + 0.3 * k
        z = 0.02 + np.where(stance, 0.0, 0.08 * np.sin(np.pi * sw))
        feet.append(np.stack([x, np.zeros(t), z], -1)[:, None])
        stance_all.append(stance)
    st = label_source_stance(feet, fps, leg)
    for k in range(4):
        assert st.contacts[stance_all[k], k].mean() >= 0.8, k
        mid = ~stance_all[k] & (np.abs(((tt / 0.4 + (0.0, 0.1, 0.5, 0.6)[k]) % 1.0) - 0.65) < 0.2)
        assert not st.contacts[mid, k].any()
    assert label_source_stance(feet, fps, leg, speed_per_body=0.0).contacts.mean() < 0.05


def test_cli_inspect_and_import_with_warning(rig, tmp_path, capsys):
    p = tmp_path / "rig.bvh"
    p.write_text(rig.to_text())
    assert main(["data", "inspect-bvh", str(p)]) == 0
    out = capsys.readouterr().out
    assert "L_TailHelper01  (15.3) [helper]" in out
    assert "L_Thigh" in out and "-> lh_hip" in out
    assert '"extends": "auto"' in out
    m = tmp_path / "m.json"
    m.write_text(
        json.dumps(
            {
                "extends": "auto",
                "map": {
                    "lh_hip": "L_TailHelper01",
                    "lh_knee": "L_TailHelper02",
                    "lh_hock": "L_TailHelper03",
                    "lh_toe": "L_TailHelper04",
                },
            }
        )
    )
    out_npz = tmp_path / "o.npz"
    rc = main(
        ["data", "import-bvh", str(p), "--species", "dog", "--out", str(out_npz), "--map", str(m)]
    )
    assert rc == 0 and out_npz.is_file()
    err = capsys.readouterr().err
    assert "warning: lh leg" in err
    back = habitsim.load_motion(out_npz)
    assert back.contacts is not None and back.metadata["import"]["warnings"]


def test_cli_inspect_takes_units_and_up(walk, tmp_path, capsys):
    """An inches file is read as centimetres unless told (nothing in a file tells them
    apart); inspect-bvh takes ``--units`` / ``--up`` as import-bvh does and sizes the rig
    as the import would."""
    p = tmp_path / "inch.bvh"
    p.write_text(_foreign_rig(walk, CM=100.0 / 2.54).to_text())
    assert main(["data", "inspect-bvh", str(p), "--units", "in", "--up", "z"]) == 0
    told = capsys.readouterr().out
    assert "units in (x0.0254 to m), up +z" in told
    _, mapping = import_bvh(p, "dog", units="in")
    assert f"root scale {mapping.root_scale:.4g}" in told
    assert main(["data", "inspect-bvh", str(p)]) == 0
    assert "units cm" in capsys.readouterr().out


def test_bench_real_import_options_reach_the_importer(rig, tmp_path):
    """``bench real --map / --units / --up`` are the importer's, for every clip."""
    from habitsim.evaluation.bench.real import read_clip

    clip = tmp_path / "rig.bvh"
    clip.write_text(rig.to_text())
    found = read_clip(clip, "dog").metadata["mapping"]
    assert (found["units"], found["up"]) == ("cm", "+z")
    told = read_clip(clip, "dog", units="in", up="z").metadata["mapping"]
    assert told["units"] == "in"
    m = tmp_path / "map.json"
    m.write_text(json.dumps({"extends": "auto", "map": {"tail3": None}}))
    assert read_clip(clip, "dog", joint_map=m).metadata["mapping"]["joints"].get("tail3") is None
    assert found["joints"]["tail3"] is not None


def test_plant_motion_plants_own_feet_and_lifts_swing():
    from habitsim.motion import Motion
    from habitsim.stance.planting import leg_pose_angles, plant_motion

    m = habitsim.generate("cat", "trot", seed=1, duration_s=2.0)
    leg = m.species_info.leg_length
    # the legs' own angles re-solve the motion exactly
    g, i = leg_pose_angles(m)
    from habitsim.ik import pose_from_targets

    p = pose_from_targets("cat", m.root_positions, m.rotations, m.foot_positions(), g, i)
    np.testing.assert_allclose(p.reach_error, 0.0, atol=1e-9)
    # hovering feet (the whole body 3 % of a leg too high) and a swing floor of 3 %
    up = m.root_positions.copy()
    up[:, 2] += 0.03 * leg
    hover = Motion("cat", m.fps, up, m.rotations, m.contacts)
    floor = np.where(m.contacts, np.nan, 0.03 * leg)
    out, rep = plant_motion(hover, m.contacts, floor)
    toes = out.foot_positions()[..., 2]
    assert np.all(np.abs(toes[m.contacts]) <= 0.002 * leg)
    assert toes.min() >= -1e-9
    # swing toes reach the floor wherever the leg can reach its target at all
    reach = rep.reach_error[~m.contacts] < 1e-6
    assert reach.mean() > 0.8
    assert np.all(toes[~m.contacts][reach] >= 0.03 * leg - 1e-6)
    feet = out.foot_positions()[..., :2]
    both = m.contacts[1:] & m.contacts[:-1]
    assert np.linalg.norm(np.diff(feet, axis=0), axis=-1)[both].max() <= 0.002 * leg


def test_stance_driven_root_measures_how_far_the_legs_carry_the_body():
    from habitsim.motion import Motion
    from habitsim.stance.planting import stance_driven_root

    m = habitsim.generate("dog", "walk", seed=2, duration_s=2.0)  # no flight phase
    assert m.contacts.any(axis=1).all()
    # feet that rest: the legs carry the whole travel, the path is unchanged
    same, ratio = stance_driven_root(m, m.contacts)
    assert ratio == pytest.approx(1.0, abs=0.03)
    np.testing.assert_allclose(same.root_positions, m.root_positions, atol=0.03 * 0.5)
    # the same legs with the body sliding twice as far: the stance legs carry half of it,
    # and held still they put the body back on the legs' own path
    fast = m.root_positions.copy()
    fast[:, :2] = fast[0, :2] + 2.0 * (fast[:, :2] - fast[0, :2])
    slide = Motion("dog", m.fps, fast, m.rotations, m.contacts)
    back, ratio = stance_driven_root(slide, m.contacts)
    assert ratio == pytest.approx(0.5, abs=0.03)
    np.testing.assert_array_equal(back.root_positions[:, 2], fast[:, 2])
    # the global joint positions at hand give the same path, and must match the motion
    held, ratio_g = stance_driven_root(slide, m.contacts, slide.global_positions())
    np.testing.assert_array_equal(held.root_positions, back.root_positions)
    assert ratio_g == ratio
    with pytest.raises(habitsim.errors.InvalidMotionError, match="contacts must have shape"):
        stance_driven_root(m, m.contacts[:-1])
    with pytest.raises(habitsim.errors.InvalidMotionError, match="glob must have shape"):
        stance_driven_root(m, m.contacts, m.global_positions()[:-1])


def test_centred_footholds_hold_the_sweep_under_the_joint_and_reach_further():
    from habitsim.motion import Motion
    from habitsim.skeleton import JOINT_NAMES
    from habitsim.stance.planting import FOOT_ANCHORS, plant_motion, stance_reach_shortfall

    m = habitsim.generate("dog", "walk", seed=2, duration_s=2.0)
    leg = m.species_info.leg_length
    c = m.contacts

    def sliding(k):  # the same legs, the body travelling k times as far: feet slide
        fast = m.root_positions.copy()
        fast[:, :2] = fast[0, :2] + k * (fast[:, :2] - fast[0, :2])
        return Motion("dog", m.fps, fast, m.rotations, c)

    slide = sliding(1.3)
    out, rep = plant_motion(slide, c, centre=True)
    toes = out.foot_positions()
    anchors = slide.global_positions()[:, [JOINT_NAMES.index(n) for n in FOOT_ANCHORS]]
    checked = 0
    for k, runs in enumerate(stance_runs(c)):
        for a, b in runs:
            travel = anchors[b - 1, k, :2] - anchors[a, k, :2]
            if np.linalg.norm(travel) < 0.2 * leg or a == 0 or b == len(c):
                continue  # short or cut runs blend towards the toe path's median
            u = travel / np.linalg.norm(travel)
            hold = toes[a:b, k, :2].mean(axis=0)
            mid = 0.5 * (anchors[a, k, :2] + anchors[b - 1, k, :2])
            assert abs((hold - mid) @ u) <= 0.01 * leg  # centred along the travel
            assert np.ptp(toes[a:b, k, :2], axis=0).max() <= 0.01 * leg  # and held
            checked += 1
    assert checked >= 6
    for k in (1.3, 1.6, 2.0):
        s = sliding(k)
        med = plant_motion(s, c)[1].reach_error[c].max()
        cen = plant_motion(s, c, centre=True)[1].reach_error[c].max()
        assert cen <= med + 1e-9, k
    # the reach test without IK: nothing out of reach for the clip's own stance, and a
    # shortfall beyond the limit whenever the IK cannot hold the footholds either
    assert stance_reach_shortfall(m, c) == 0.0
    for k in (1.6, 3.0):
        s = sliding(k)
        short = stance_reach_shortfall(s, c, max_drop=0.1 * leg)
        _, rep = plant_motion(s, c)
        assert short > 0.05 * leg
        assert rep.reach_error.max() > 0.05 * leg or rep.pelvis_drop.max() > 0.1 * leg
    with pytest.raises(habitsim.errors.InvalidMotionError, match="contacts must have shape"):
        stance_reach_shortfall(m, c[:-1])


def test_free_stance_runs_keep_their_own_toe_path_and_the_reach_test_skips_them():
    from habitsim.motion import Motion
    from habitsim.stance.planting import plant_motion, stance_run_shortfall

    m = habitsim.generate("dog", "walk", seed=2, duration_s=2.0)
    leg = m.species_info.leg_length
    c = m.contacts
    fast = m.root_positions.copy()
    fast[:, :2] = fast[0, :2] + 1.3 * (fast[:, :2] - fast[0, :2])  # feet slide in stance
    slide = Motion("dog", m.fps, fast, m.rotations, c)
    runs = stance_runs(c)[0]
    a, b = next((a, b) for a, b in runs if a > 0 and b < len(c))  # an inner LF run
    free = np.zeros_like(c)
    free[a + 1, 0] = True  # one frame marks the whole run
    out, _ = plant_motion(slide, c, centre=True, free=free)
    held, _ = plant_motion(slide, c, centre=True)
    toes, raw = out.foot_positions(), slide.foot_positions()
    # the free run follows the sliding toe path; held, it stays put
    np.testing.assert_allclose(toes[a:b, 0, :2], raw[a:b, 0, :2], atol=0.01 * leg)
    assert np.ptp(raw[a:b, 0, :2], axis=0).max() > 0.05 * leg
    assert np.ptp(held.foot_positions()[a:b, 0, :2], axis=0).max() <= 0.01 * leg
    # the other runs are held as before
    other = c.copy()
    other[a:b, 0] = False
    np.testing.assert_allclose(toes[other], held.foot_positions()[other], atol=0.01 * leg)
    # the per-frame reach test: zero off stance and on free runs
    k = 3.0
    far = m.root_positions.copy()
    far[:, :2] = far[0, :2] + k * (far[:, :2] - far[0, :2])
    s = Motion("dog", m.fps, far, m.rotations, c)
    short = stance_run_shortfall(s, c, centre=True)
    assert short.shape == c.shape and (short[~c] == 0).all() and short.max() > 0.05 * leg
    mask = np.zeros_like(c)
    mask[:, 0] = c[:, 0]
    assert (stance_run_shortfall(s, c, True, 0.0, mask)[:, 0] == 0).all()
    with pytest.raises(habitsim.errors.InvalidMotionError, match="free must have shape"):
        plant_motion(slide, c, free=free[:-1])
    # joint positions handed in give the same planting; a wrong shape is refused
    glob = slide.global_positions()
    again, rep = plant_motion(slide, c, centre=True, free=free, glob=glob)
    np.testing.assert_array_equal(again.rotations, out.rotations)
    np.testing.assert_array_equal(again.root_positions, out.root_positions)
    # the report's stance heights and lowest toe are the planted motion's own
    z = out.foot_positions()[..., 2]
    med = [np.median(z[c[:, k], k]) for k in range(4)]
    np.testing.assert_allclose(rep.stance_toe_height, med, atol=1e-12)
    assert rep.min_toe_height == pytest.approx(z.min(), abs=1e-12)
    with pytest.raises(habitsim.errors.InvalidMotionError, match="glob must have shape"):
        plant_motion(slide, c, glob=glob[:, :-1])


def test_pelvis_lowering_is_a_slow_carriage_not_a_dip_per_stance():
    from habitsim.motion import Motion
    from habitsim.stance.planting import DROP_SMOOTH_S, plant_motion

    m = habitsim.generate("dog", "walk", seed=2, duration_s=3.0)
    leg = m.species_info.leg_length
    fast = m.root_positions.copy()
    fast[:, :2] = fast[0, :2] + 1.6 * (fast[:, :2] - fast[0, :2])  # strides out of reach
    s = Motion("dog", m.fps, fast, m.rotations, m.contacts)
    _, rep = plant_motion(s, m.contacts)
    drop = rep.pelvis_drop
    assert drop.max() > 0.02 * leg  # the pelvis does come down
    # no dip per stance: over one stride (about 0.6 s) the lowering changes by a small
    # share of its depth, and its frame-to-frame rate stays that of a slow sink
    rate = np.abs(np.diff(drop)) * m.fps
    assert rate.max() <= drop.max() / DROP_SMOOTH_S
    mid = drop[len(drop) // 4 : -len(drop) // 4]
    assert np.ptp(mid) <= 0.5 * drop.max()
