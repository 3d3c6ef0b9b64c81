"""glTF / GLB skinned animations read as BVH data (habitsim.gltf)."""

from __future__ import annotations

import json
import math
import struct
from importlib import resources
from pathlib import Path

import numpy as np
import pygltflib
import pytest
from scipy.spatial.transform import Rotation

from habitsim.bvh_mapping import import_bvh
from habitsim.errors import GLTFError, HabitsimError
from habitsim.gltf import END_SITE_FRACTION, GLTFReadOptions, list_gltf_animations, read_gltf

FOX = Path(str(resources.files("habitsim.examples") / "Fox.glb"))


# ---------------------------------------------------------------------- a tiny rig


def _rz(deg: float) -> list[float]:
    return Rotation.from_euler("z", deg, degrees=True).as_quat().tolist()  # xyzw


def _tiny(
    tmp_path: Path,
    *,
    skin: bool = True,
    animations: bool = True,
    armature_scale: tuple[float, float, float] = (2.0, 2.0, 2.0),
    name: str = "chain.glb",
) -> Path:
    """A 3-joint chain under an armature node, three animations.

    Armature: translation (1, 0, 0), rotation 90° about z, scale 2. Joints j0 (at the
    armature origin) → j1 → j2, bones of length 1 along local +y. Animations:

    * ``bend``: j1 rotates about z 0° → 90° → 0° at t = 0, 1, 2 (LINEAR) and j0 moves
      along z from 0 to 1 over t = 0..2 (LINEAR).
    * ``step``: j1 rotates about z, 0° at t = 0 and 90° at t = 1 (STEP).
    * ``cubic``: as ``bend``'s rotation, CUBICSPLINE with large (ignored) tangents.
    """
    blob = bytearray()
    views: list[pygltflib.BufferView] = []
    accs: list[pygltflib.Accessor] = []

    def add(arr: np.ndarray, kind: str) -> int:
        data = np.asarray(arr, dtype="<f4").tobytes()
        views.append(pygltflib.BufferView(buffer=0, byteOffset=len(blob), byteLength=len(data)))
        blob.extend(data)
        ncomp = {"SCALAR": 1, "VEC3": 3, "VEC4": 4}[kind]
        a = np.asarray(arr, dtype=np.float64).reshape(-1, ncomp)
        accs.append(
            pygltflib.Accessor(
                bufferView=len(views) - 1,
                componentType=pygltflib.FLOAT,
                count=a.shape[0],
                type=kind,
                min=a.min(axis=0).tolist() if kind == "SCALAR" else None,
                max=a.max(axis=0).tolist() if kind == "SCALAR" else None,
            )
        )
        return len(accs) - 1

    nodes = [
        pygltflib.Node(
            name="Armature",
            translation=[1.0, 0.0, 0.0],
            rotation=_rz(90.0),
            scale=list(armature_scale),
            children=[1],
        ),
        pygltflib.Node(name="j0", children=[2]),
        pygltflib.Node(name="j1", translation=[0.0, 1.0, 0.0], children=[3]),
        pygltflib.Node(name="j2", translation=[0.0, 1.0, 0.0]),
    ]
    anims = []
    if animations:
        t3 = add([0.0, 1.0, 2.0], "SCALAR")
        rot = add([_rz(0.0), _rz(90.0), _rz(0.0)], "VEC4")
        t2 = add([0.0, 2.0], "SCALAR")
        tr = add([[0.0, 0.0, 0.0], [0.0, 0.0, 1.0]], "VEC3")
        anims.append(
            pygltflib.Animation(
                name="bend",
                samplers=[
                    pygltflib.AnimationSampler(input=t3, output=rot, interpolation="LINEAR"),
                    pygltflib.AnimationSampler(input=t2, output=tr, interpolation="LINEAR"),
                ],
                channels=[
                    pygltflib.AnimationChannel(
                        sampler=0, target=pygltflib.AnimationChannelTarget(node=2, path="rotation")
                    ),
                    pygltflib.AnimationChannel(
                        sampler=1,
                        target=pygltflib.AnimationChannelTarget(node=1, path="translation"),
                    ),
                ],
            )
        )
        ts = add([0.0, 1.0], "SCALAR")
        rs = add([_rz(0.0), _rz(90.0)], "VEC4")
        anims.append(
            pygltflib.Animation(
                name="step",
                samplers=[pygltflib.AnimationSampler(input=ts, output=rs, interpolation="STEP")],
                channels=[
                    pygltflib.AnimationChannel(
                        sampler=0, target=pygltflib.AnimationChannelTarget(node=2, path="rotation")
                    )
                ],
            )
        )
        junk = [5.0, -3.0, 7.0, 2.0]
        cub = add([junk, _rz(0.0), junk, junk, _rz(90.0), junk, junk, _rz(0.0), junk], "VEC4")
        anims.append(
            pygltflib.Animation(
                name="cubic",
                samplers=[
                    pygltflib.AnimationSampler(input=t3, output=cub, interpolation="CUBICSPLINE")
                ],
                channels=[
                    pygltflib.AnimationChannel(
                        sampler=0, target=pygltflib.AnimationChannelTarget(node=2, path="rotation")
                    )
                ],
            )
        )
    if not blob:
        blob.extend(b"\0\0\0\0")
    g = pygltflib.GLTF2(
        scene=0,
        scenes=[pygltflib.Scene(nodes=[0])],
        nodes=nodes,
        skins=[pygltflib.Skin(joints=[1, 2, 3])] if skin else [],
        animations=anims,
        accessors=accs,
        bufferViews=views,
        buffers=[pygltflib.Buffer(byteLength=len(blob))],
    )
    g.set_binary_blob(bytes(blob))
    out = tmp_path / name
    g.save_binary(str(out))
    return out


def _chain_world(t: float, theta_deg: float) -> np.ndarray:
    """Closed-form world positions (3, 3) of j0, j1, j2 of the tiny rig."""
    z = t / 2.0  # j0 translation along z (the armature's rotation about z keeps it)
    j0 = np.array([1.0, 0.0, 2.0 * z])
    j1 = j0 + 2.0 * np.array([-1.0, 0.0, 0.0])  # 2 · Rz(90°) · (0, 1, 0)
    th = math.radians(theta_deg)
    j2 = j1 + 2.0 * np.array([-math.cos(th), -math.sin(th), 0.0])  # 2 · Rz(90° + θ) · (0, 1, 0)
    return np.stack([j0, j1, j2])


def test_tiny_chain_matches_closed_form(tmp_path):
    d = read_gltf(_tiny(tmp_path), "bend", fps=4.0)
    assert d.names == ("j0", "j1", "j2", "j2_End")
    assert d.parents == (-1, 0, 1, 2)
    assert d.is_end_site == (False, False, False, True)
    assert d.num_frames == 9  # 2 s at 4 fps, both ends included
    assert d.fps == 4.0
    pos = d.fk()
    for k in range(d.num_frames):
        t = k / 4.0
        theta = 90.0 * (t if t <= 1.0 else 2.0 - t)  # slerp about one axis: linear in angle
        np.testing.assert_allclose(pos[k, :3], _chain_world(t, theta), atol=1e-6)
    # The End Site continues j2's bone (local +y) by END_SITE_FRACTION of its length (2 m).
    np.testing.assert_allclose(d.offsets[3], [0.0, 2.0 * END_SITE_FRACTION, 0.0], atol=1e-9)
    tip = pos[4, 2] + (pos[4, 2] - pos[4, 1]) * END_SITE_FRACTION
    np.testing.assert_allclose(pos[4, 3], tip, atol=1e-6)


def test_tiny_chain_keyframe_values_and_step(tmp_path):
    path = _tiny(tmp_path)
    bend = read_gltf(path, "bend", fps=4.0)
    q = bend.local_rotations()  # wxyz
    half = math.sqrt(0.5)
    np.testing.assert_allclose(np.abs(q[4, 1]), [half, 0.0, 0.0, half], atol=1e-6)  # t = 1
    np.testing.assert_allclose(np.abs(q[0, 1]), [1.0, 0.0, 0.0, 0.0], atol=1e-6)
    np.testing.assert_allclose(bend.local_translations()[8, 0], [1.0, 0.0, 2.0], atol=1e-6)

    step = read_gltf(path, "step", fps=4.0)
    assert step.num_frames == 5
    pos = step.fk()
    for k in range(5):
        theta = 0.0 if k < 4 else 90.0  # STEP holds 0° until the key at t = 1
        np.testing.assert_allclose(pos[k, :3], _chain_world(0.0, theta), atol=1e-6)


def test_cubicspline_reduces_to_keyframe_values(tmp_path):
    d = read_gltf(_tiny(tmp_path), "cubic", fps=4.0)
    pos = d.fk()
    for k in range(d.num_frames):
        t = k / 4.0
        theta = 90.0 * (t if t <= 1.0 else 2.0 - t)
        np.testing.assert_allclose(pos[k, :3], _chain_world(0.0, theta), atol=1e-6)


def test_animation_selection_by_name_and_index(tmp_path):
    path = _tiny(tmp_path)
    by_name = read_gltf(path, "step", fps=10.0)
    by_index = read_gltf(path, 1, fps=10.0)
    np.testing.assert_array_equal(by_name.frames, by_index.frames)
    assert by_name.num_frames == 11
    first = read_gltf(path, fps=10.0)
    assert first.num_frames == 21  # "bend" (2 s) is the first animation
    np.testing.assert_array_equal(first.frames, read_gltf(path, "bend", fps=10.0).frames)
    assert read_gltf(path, -1, fps=10.0).num_frames == read_gltf(path, "cubic", fps=10.0).num_frames
    infos = list_gltf_animations(path)
    assert [(a.index, a.name, a.num_joints, a.num_channels) for a in infos] == [
        (0, "bend", 2, 2),
        (1, "step", 1, 1),
        (2, "cubic", 1, 1),
    ]
    assert [a.duration for a in infos] == pytest.approx([2.0, 1.0, 2.0])


def test_gltf_with_data_uri_buffer(tmp_path):
    glb = _tiny(tmp_path)
    g = pygltflib.GLTF2().load(str(glb))
    g.convert_buffers(pygltflib.BufferFormat.DATAURI)
    out = tmp_path / "chain.gltf"
    g.save_json(str(out))
    np.testing.assert_allclose(
        read_gltf(out, "bend", fps=4.0).fk(), read_gltf(glb, "bend", fps=4.0).fk(), atol=1e-12
    )


# ---------------------------------------------------------------------- errors


def _err(path, *args, **kw) -> str:
    with pytest.raises(GLTFError) as ei:
        read_gltf(path, *args, **kw)
    assert isinstance(ei.value, HabitsimError) and isinstance(ei.value, ValueError)
    msg = str(ei.value)
    assert len(msg) < 400
    return msg


def test_errors(tmp_path):
    assert "no such glTF file" in _err(tmp_path / "missing.glb")
    assert "no skin" in _err(_tiny(tmp_path, skin=False, name="noskin.glb"))
    assert "no animation" in _err(_tiny(tmp_path, animations=False, name="noanim.glb"))
    path = _tiny(tmp_path)
    msg = _err(path, "Gallop")
    assert "'Gallop'" in msg and "'bend'" in msg and "'step'" in msg and "'cubic'" in msg
    assert "0..2" in _err(path, 3)
    assert "fps" in _err(path, fps=0.0)

    raw = path.read_bytes()
    short = tmp_path / "short.glb"
    short.write_bytes(raw[: len(raw) - 40])  # BIN chunk cut: accessors run past the end
    assert "truncated" in _err(short)
    g = pygltflib.GLTF2().load(str(path))
    g.accessors[1].count += 100  # the rotation keys of "bend" now run past their bufferView
    over = tmp_path / "over.glb"
    g.save_binary(str(over))
    msg = _err(over, "bend")
    assert "accessor 1" in msg and "truncated or corrupt" in msg
    garbage = tmp_path / "garbage.glb"
    garbage.write_bytes(b"glTF" + b"\xff" * 7)
    assert "not a readable GLB" in _err(garbage)
    text = tmp_path / "broken.gltf"
    text.write_text("{ not json")
    assert "not a readable glTF JSON" in _err(text)

    skew = _tiny(tmp_path, armature_scale=(1.0, 2.0, 1.0), name="skew.glb")
    assert "non-uniform" in _err(skew) and "Armature" in _err(skew)
    with pytest.raises(GLTFError, match="no such glTF file"):
        list_gltf_animations(tmp_path / "missing.glb")


# ---------------------------------------------------------------------- the Fox


def _fox_world(path: Path, anim_name: str) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """World joint positions at every keyframe from the node matrices, by node name."""
    g = pygltflib.GLTF2().load(str(path))
    blob = g.binary_blob()

    def acc(i: int) -> np.ndarray:
        a = g.accessors[i]
        v = g.bufferViews[a.bufferView]
        n = {"SCALAR": 1, "VEC3": 3, "VEC4": 4}[a.type]
        off = (v.byteOffset or 0) + (a.byteOffset or 0)
        return np.frombuffer(blob, "<f4", a.count * n, off).reshape(a.count, n).astype(float)

    anim = next(a for a in g.animations if a.name == anim_name)
    times = acc(anim.samplers[0].input)[:, 0]
    nt = len(times)
    t_all = np.zeros((len(g.nodes), nt, 3))
    q_all = np.tile([0.0, 0.0, 0.0, 1.0], (len(g.nodes), nt, 1))
    for i, n in enumerate(g.nodes):
        if n.translation:
            t_all[i] = n.translation
        if n.rotation:
            q_all[i] = n.rotation
    for ch in anim.channels:
        smp = anim.samplers[ch.sampler]
        assert np.allclose(acc(smp.input)[:, 0], times)  # the Fox keys all channels alike
        (t_all if ch.target.path == "translation" else q_all)[ch.target.node] = acc(smp.output)
    parent = {c: i for i, n in enumerate(g.nodes) for c in n.children or []}
    world: dict[int, np.ndarray] = {}

    def mat(i: int) -> np.ndarray:
        if i not in world:
            m = np.tile(np.eye(4), (nt, 1, 1))
            m[:, :3, :3] = Rotation.from_quat(q_all[i]).as_matrix()
            m[:, :3, 3] = t_all[i]
            world[i] = mat(parent[i]) @ m if i in parent else m
        return world[i]

    return {g.nodes[j].name: mat(j)[:, :3, 3] for j in g.skins[0].joints}, times


def test_fox_fk_matches_node_matrices():
    for anim in ("Survey", "Walk"):
        d = read_gltf(FOX, anim, fps=24.0)  # the Fox is keyed at 24 fps
        world, times = _fox_world(FOX, anim)
        assert d.num_frames == len(times)
        pos = d.fk()
        joints = [n for n, e in zip(d.names, d.is_end_site, strict=True) if not e]
        assert sorted(joints) == sorted(world)
        for name in joints:
            np.testing.assert_allclose(pos[:, d.index(name)], world[name], atol=1e-3)


def test_fox_animations_and_sampling():
    infos = list_gltf_animations(FOX)
    assert [a.name for a in infos] == ["Survey", "Walk", "Run"]
    assert [a.duration for a in infos] == pytest.approx([41 / 12, 17 / 24, 139 / 120], abs=1e-5)
    assert all(a.num_joints == 20 for a in infos)
    walk = read_gltf(FOX, "Walk")
    assert walk.num_frames == 22  # floor(0.7083 s · 30) + 1
    assert walk.source == str(FOX)
    assert walk.num_joints == 24 + 6  # 24 skin joints + 6 End Sites
    assert all(len(c) == 6 for c, e in zip(walk.channels, walk.is_end_site, strict=True) if not e)


FOX_LEGS = {
    "lf_shoulder": "b_LeftUpperArm_09",
    "lf_elbow": "b_LeftForeArm_010",
    "lf_wrist": "b_LeftHand_011",
    "lf_toe": "b_LeftHand_011_End",
    "rf_shoulder": "b_RightUpperArm_06",
    "rf_elbow": "b_RightForeArm_07",
    "rf_wrist": "b_RightHand_08",
    "rf_toe": "b_RightHand_08_End",
    "lh_hip": "b_LeftLeg01_015",
    "lh_knee": "b_LeftLeg02_016",
    "lh_hock": "b_LeftFoot01_017",
    "lh_toe": "b_LeftFoot02_018",
    "rh_hip": "b_RightLeg01_019",
    "rh_knee": "b_RightLeg02_020",
    "rh_hock": "b_RightFoot01_021",
    "rh_toe": "b_RightFoot02_022",
    "pelvis": "b_Hip_01",
    "head": "b_Head_05",
    "tail1": "b_Tail01_012",
}


def test_fox_walk_imports_onto_the_dog():
    motion, mapping = import_bvh(read_gltf(FOX, "Walk"), "dog")
    print(mapping)
    for k, v in FOX_LEGS.items():
        assert mapping.joints[k] == v, k
    # The Fox is authored in centimetre-sized units without a scale node.
    assert mapping.frame.units == "cm" and mapping.frame.up == "+y"
    assert motion.num_frames == 22 and motion.fps == 30.0
    assert np.all(np.isfinite(motion.rotations))


def test_fox_under_a_scale_node_is_in_metres(tmp_path):
    g = pygltflib.GLTF2().load(str(FOX))
    g.nodes[0].scale = [0.01, 0.01, 0.01]  # the "root" node above the skin's top joint
    scaled = tmp_path / "fox_m.glb"
    g.save_binary(str(scaled))
    d_m = read_gltf(scaled, "Walk")
    np.testing.assert_allclose(d_m.fk(), 0.01 * read_gltf(FOX, "Walk").fk(), atol=1e-9)
    _, mapping = import_bvh(d_m, "dog")
    assert mapping.frame.units == "m" and mapping.frame.up == "+y"
    assert mapping.joints["lh_hip"] == "b_LeftLeg01_015"


# ---------------------------------------------------------------------- hostile files


def _doc_and_blob(tmp_path: Path) -> tuple[dict, bytes]:
    """The tiny rig's JSON document (a dict) and its BIN chunk."""
    g = pygltflib.GLTF2.load_binary(_tiny(tmp_path, name="src.glb"))
    return json.loads(g.to_json()), bytes(g.binary_blob())


def _glb(path: Path, doc: dict, blob: bytes) -> Path:
    """Write ``doc`` and ``blob`` as a GLB file (the container written by hand, so the
    document may break every rule)."""
    js = json.dumps(doc).encode()
    js += b" " * (-len(js) % 4)
    blob += b"\0" * (-len(blob) % 4)
    body = struct.pack("<I4s", len(js), b"JSON") + js + struct.pack("<I4s", len(blob), b"BIN\0")
    body += blob
    path.write_bytes(struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body)
    return path


@pytest.mark.parametrize(
    "where, key, value",
    [
        ("bufferViews", "buffer", None),  # a null buffer
        ("buffers", "byteLength", None),  # a null byteLength
        ("accessors", "byteOffset", -8),  # a negative offset passed the bounds check
        ("accessors", "count", -1),  # a negative count
        ("accessors", "componentType", 5130),  # a double: not a glTF component type
        ("bufferViews", "byteStride", -4),
        ("nodes", "matrix", [1.0, 0.0, 0.0]),  # a matrix of the wrong length
        ("nodes", "children", ["j1"]),
    ],
)
def test_hostile_fields_are_typed_errors(tmp_path, where, key, value):
    doc, blob = _doc_and_blob(tmp_path)
    doc[where][0][key] = value
    msg = _err(_glb(tmp_path / "bad.glb", doc, blob), "bend")
    assert f"{where}[0].{key}" in msg
    assert "j1'" not in msg  # a string of the file is never quoted


def test_huge_key_time_refused_before_resampling(tmp_path):
    doc, blob = _doc_and_blob(tmp_path)
    times = bytearray(blob)
    struct.pack_into("<f", times, 8, 1e9)  # the third key of "bend" at 1e9 s
    with pytest.raises(GLTFError, match="max_samples"):
        read_gltf(_glb(tmp_path / "long.glb", doc, bytes(times)), "bend")
    # the limit is an option: the tiny clip itself (61 frames x 4 nodes) is over 100
    with pytest.raises(GLTFError, match="max_samples"):
        read_gltf(_tiny(tmp_path), "bend", options=GLTFReadOptions(max_samples=100))


def _gltf_with_uri(folder: Path, blob: bytes, uri: str) -> Path:
    g = pygltflib.GLTF2.load_binary(_tiny(folder.parent, name="uri_src.glb"))
    doc = json.loads(g.to_json())
    doc["buffers"] = [{"uri": uri, "byteLength": len(blob)}]
    folder.mkdir(exist_ok=True)
    p = folder / "rig.gltf"
    p.write_text(json.dumps(doc))
    return p


def test_buffer_uris_stay_inside_the_folder(tmp_path):
    _, blob = _doc_and_blob(tmp_path)
    secret = tmp_path / "secret.bin"
    secret.write_bytes(blob)
    rig = tmp_path / "rig"
    (rig / "data.bin").parent.mkdir()
    (rig / "data.bin").write_bytes(blob)
    read_gltf(_gltf_with_uri(rig, blob, "data.bin"), "bend")  # beside the file: read
    (rig / "link.bin").symlink_to(secret)
    for uri in ("../secret.bin", str(secret), "%2E%2E/secret.bin", "link.bin", "file:///x"):
        msg = _err(_gltf_with_uri(rig, blob, uri), "bend")
        assert "refused" in msg and str(len(blob)) not in msg


def test_zero_scale_refused(tmp_path):
    assert "scale" in _err(_tiny(tmp_path, armature_scale=(0.0, 0.0, 0.0)), "bend")
