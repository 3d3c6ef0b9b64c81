"""A motion added to a copy of a user's glTF / GLB model as a new animation
(:func:`add_gltf_animation`), the writing side of :func:`habitsim.gltf.read_gltf`.

The motion comes in the form :func:`~habitsim.gltf.read_gltf` reads the model in (the
joints of the same skin, in the same order, in the file's units and axes, as
:func:`habitsim.bvh_mapping.export_to_rig` writes it). Each joint node gets a rotation and
a translation channel (LINEAR, one key per frame, float32); the nodes above the root keep
their rest transform, and the root's channels are expressed below it. Everything else in
the file (meshes, skins, materials, the other animations) is kept as it is; the new data
is appended to the binary buffer of a ``.glb``, or added as an embedded buffer of a
``.gltf`` whose buffers are all embedded in the copy.
"""

from __future__ import annotations

import base64
from pathlib import Path

import numpy as np
import pygltflib
from scipy.spatial.transform import Rotation

from .bvh import BVHData
from .errors import GLTFError
from .fileio import atomic_path
from .gltf import (
    _joint_names,
    _rest_above,
    _rest_trs,
    _rig_nodes,
    _select_animation,
    _uniform,
)
from .gltf_container import GLTFFile as _File

__all__ = ["add_gltf_animation", "GLTF_SUFFIXES"]

#: The file types :func:`add_gltf_animation` writes.
GLTF_SUFFIXES: tuple[str, ...] = (".glb", ".gltf")
_DATA_URI = "data:application/octet-stream;base64,"


def _node_channels(f: _File, ai: int, motion: BVHData) -> list[tuple[int, np.ndarray, np.ndarray]]:
    """(node, translations (F, 3), rotations xyzw (F, 4)) of every joint node."""
    par, root, order, above, _ = _rig_nodes(f, ai)
    names = _joint_names(f, order)
    joints = [n for n, end in zip(motion.names, motion.is_end_site, strict=True) if not end]
    if joints != names:
        raise GLTFError(
            f"{f.source}: the motion's joints are not the model's skin joints "
            f"({len(joints)} against {len(names)}); write it with the rig it was exported on"
        )
    r_rot, r_pos, r_scale = _rest_above(f, above)
    has_kids = {par[i] for i in order if i != root}
    cum: dict[int, float] = {}
    q = motion.local_rotations()  # (F, J, 4) wxyz
    t = motion.local_translations()
    out = []
    for i, name in zip(order, names, strict=True):
        b = motion.index(name)
        _, _, rs = _rest_trs(f, i)
        s0 = float(_uniform(f, i, rs[None])[0]) if i in has_kids else 1.0
        rot = Rotation.from_quat(q[:, b][:, [1, 2, 3, 0]])
        if i == root:
            inv = r_rot.inv()
            trans = inv.apply(t[:, b] - r_pos) / r_scale
            quat = (inv * rot).as_quat()
            cum[i] = r_scale * s0
        else:
            trans = t[:, b] / cum[par[i]]
            quat = rot.as_quat()
            cum[i] = cum[par[i]] * s0
        out.append((i, trans, quat))
    return out


def add_gltf_animation(
    rig: str | Path,
    motion: BVHData,
    out: str | Path,
    animation: str | int | None = None,
    name: str = "habitsim",
) -> Path:
    """Write a copy of the model ``rig`` with ``motion`` added as a new animation.

    Args:
        rig: the user's ``.glb`` / ``.gltf`` model.
        motion: the motion in the model's hierarchy (what
            :func:`~habitsim.bvh_mapping.export_to_rig` returns for this rig, as ``.bvh``).
        out: the copy to write (``.glb`` or ``.gltf``), atomically.
        animation: the animation the rig was read with (it picks the skin).
        name: the new animation's name (a number is added if the model has one so named).

    Returns:
        The written path.

    Raises:
        GLTFError: an unreadable model, a motion of other joints, an unknown output type.
    """
    dest = Path(out)
    kind = dest.suffix.lower()
    if kind not in GLTF_SUFFIXES:
        raise GLTFError(f"{dest.name}: a glTF copy ends in {' or '.join(GLTF_SUFFIXES)}")
    f = _File(rig)
    doc = f.doc
    ai = _select_animation(f, animation)
    channels = _node_channels(f, ai, motion)
    n_f = motion.num_frames
    times = (np.arange(n_f) * motion.frame_time).astype(np.float32)
    arrays: list[tuple[np.ndarray, str]] = [(times, "SCALAR")]
    for _, trans, quat in channels:
        arrays += [(trans.astype(np.float32), "VEC3"), (quat.astype(np.float32), "VEC4")]
    if kind == ".glb" and len(doc.buffers) <= 1 and not (doc.buffers and doc.buffers[0].uri):
        blob = bytearray(doc.binary_blob() or b"")
        buffer = 0
        if not doc.buffers:
            doc.buffers.append(pygltflib.Buffer(byteLength=0))
    else:
        f.data_uri_buffers()  # external files read within the folder check, not by pygltflib
        doc.convert_buffers(pygltflib.BufferFormat.DATAURI)
        blob, buffer = bytearray(), len(doc.buffers)
    first = len(doc.accessors)
    for k, (arr, kind_acc) in enumerate(arrays):
        blob += b"\0" * (-len(blob) % 4)
        offset = len(blob)
        blob += arr.tobytes()
        doc.bufferViews.append(
            pygltflib.BufferView(buffer=buffer, byteOffset=offset, byteLength=arr.nbytes)
        )
        acc = pygltflib.Accessor(
            bufferView=len(doc.bufferViews) - 1,
            componentType=pygltflib.FLOAT,
            count=len(arr),
            type=kind_acc,
        )
        if k == 0:
            acc.min, acc.max = [float(times.min())], [float(times.max())]
        doc.accessors.append(acc)
    samplers, targets = [], []
    for k, (node, _, _) in enumerate(channels):
        for m, path in enumerate(("translation", "rotation")):
            samplers.append(pygltflib.AnimationSampler(input=first, output=first + 1 + 2 * k + m))
            targets.append(
                pygltflib.AnimationChannel(
                    sampler=len(samplers) - 1,
                    target=pygltflib.AnimationChannelTarget(node=node, path=path),
                )
            )
    taken = {a.name for a in doc.animations}
    label, n = name, 2
    while label in taken:
        label, n = f"{name}_{n}", n + 1
    doc.animations.append(pygltflib.Animation(name=label, samplers=samplers, channels=targets))
    if buffer == 0 and kind == ".glb":
        doc.set_binary_blob(bytes(blob))
        doc.buffers[0].byteLength = len(blob)
    else:
        doc.buffers.append(pygltflib.Buffer(byteLength=len(blob)))
        doc.buffers[-1].uri = _DATA_URI + base64.b64encode(bytes(blob)).decode("ascii")
        if kind == ".glb":
            doc.convert_buffers(pygltflib.BufferFormat.BINARYBLOB)
    with atomic_path(dest, suffix=kind) as tmp:
        if kind == ".glb":
            doc.save_binary(tmp)
        else:
            doc.save_json(tmp)
    return dest
