"""glTF 2.0 skinned animations (``.glb`` / ``.gltf``) read as :class:`~habitsim.bvh.BVHData`.

:func:`read_gltf` turns one animation of a skinned glTF model into the same in-memory form
as a parsed BVH file, so :func:`habitsim.bvh_mapping.import_bvh` maps and retargets it
unchanged (``import_bvh(read_gltf("Fox.glb", "Walk"), "dog")``). :func:`list_gltf_animations`
lists a file's animations.

The glTF container (GLB chunks, JSON, external ``.bin`` files and data URIs) is read with
``pygltflib``. pygltflib gives the buffers as bytes but does not decode accessors into
arrays, so accessors (typed, possibly strided views into a buffer) are decoded here with
numpy, with bounds checks that turn a truncated buffer into a :class:`GLTFError`.

Conversion:

* Joints: the joints of the skin the animation drives (most animated joints; the first skin
  on a tie), in depth-first node order from the skin's top joint. If the skin has several
  top joints, their lowest common ancestor node becomes the root; nodes between a joint and
  its nearest joint ancestor are kept as joints so that world positions stay right. Nodes
  above the root (an armature node with a transform, a unit-scale node) are folded into the
  root's channels.
* Every joint gets six channels ``Xposition Yposition Zposition Zrotation Xrotation
  Yrotation``; the position channels hold the glTF local translation (times the uniform
  scale of the ancestors), the rotation channels the local rotation as intrinsic ZXY Euler
  angles in degrees, so :meth:`BVHData.local_translations` / :meth:`BVHData.local_rotations`
  reproduce the glTF local transforms and :meth:`BVHData.fk` the glTF world joint
  positions. OFFSETs are the rest-pose translations (the channels override them).
* Every leaf joint gets an End Site child (``<leaf>_End``) so that the last bone has a tip,
  as in BVH files (the automatic mapping uses End Sites as toe tips and snout): its offset
  is :data:`END_SITE_FRACTION` times the leaf's own bone (its rest translation), in the
  leaf's frame. glTF rigs keep the bone axis constant in every joint frame (Blender's +Y,
  the Fox's +X), so the tip continues the leaf's bone along that axis.
* Scale: uniform joint scale (rest or animated) is applied to the translations below the
  joint. Non-uniform or negative scale on a joint with child joints, or on a node above
  the root, cannot be expressed as rotations and translations and raises
  :class:`GLTFError`; on a leaf joint it moves no joint and is ignored.
* Sampling: uniformly at ``fps`` from the animation's first to its last keyframe time
  (``floor(duration · fps) + 1`` frames); joints without a channel keep their node's rest
  TRS. LINEAR interpolation (spherical for rotations, scipy's ``Slerp``), STEP (the
  previous keyframe) and CUBICSPLINE reduced to its keyframe values (tangents ignored,
  then interpolated linearly) are supported; ``weights`` (morph target) channels are
  ignored.
* Coordinates stay those of the file (glTF: y up; metres by the standard, but many rigs
  are authored in centimetres without a scale node); the importer's
  :func:`~habitsim.bvh_mapping.detect_frame` finds units and up axis.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from .bvh import END_SITE_SUFFIX, BVHData
from .errors import GLTFError
from .gltf_container import GLTFFile as _File
from .gltf_container import GLTFReadOptions
from .rotations import quat_to_euler

__all__ = [
    "END_SITE_FRACTION",
    "GLTFAnimationInfo",
    "GLTFReadOptions",
    "list_gltf_animations",
    "read_gltf",
]

#: Length of a leaf joint's End Site as a fraction of the leaf's own bone [-].
END_SITE_FRACTION = 0.25
#: Rotation channel order written for every joint (intrinsic, degrees).
_ORDER = "ZXY"
_CHANNELS = ("Xposition", "Yposition", "Zposition") + tuple(f"{a}rotation" for a in _ORDER)
#: Relative spread of a scale vector below which it counts as uniform.
_UNIFORM_TOL = 1e-4

_PATH_COMP = {"translation": 3, "rotation": 4, "scale": 3}
_INTERPOLATIONS = ("LINEAR", "STEP", "CUBICSPLINE")


@dataclass(frozen=True)
class GLTFAnimationInfo:
    """One animation of a glTF file.

    Attributes:
        index: position in the file's animation list.
        name: the animation's name (``""`` if it has none).
        duration: last minus first keyframe time [s].
        num_joints: skin joints the animation drives.
        num_channels: animation channels (one per animated node property).
    """

    index: int
    name: str
    duration: float
    num_joints: int
    num_channels: int


# ---------------------------------------------------------------------- container


def _short(items: list[str], limit: int = 12) -> str:
    """Comma-separated, at most ``limit`` items of at most 40 characters each."""
    shown = [s if len(s) <= 40 else s[:37] + "..." for s in items[:limit]]
    more = f" (and {len(items) - limit} more)" if len(items) > limit else ""
    return ", ".join(shown) + more


# ---------------------------------------------------------------------- nodes


def _parents(f: _File) -> list[int]:
    nodes = f.doc.nodes
    par = [-1] * len(nodes)
    for i, n in enumerate(nodes):
        for c in n.children or []:
            if not 0 <= c < len(nodes):
                raise f.error(f"node {i} lists child {c}, which does not exist")
            if par[c] >= 0 or c == i:
                raise f.error(f"node {c} has two parents ({par[c]} and {i}): not a tree")
            par[c] = i
    done = [False] * len(nodes)  # cycle check: each node walked up once
    for i in range(len(nodes)):
        path: dict[int, None] = {}
        j = i
        while j >= 0 and not done[j]:
            if j in path:
                raise f.error(f"the node hierarchy has a cycle through node {j}")
            path[j] = None
            j = par[j]
        for k in path:
            done[k] = True
    return par


def _rest_trs(f: _File, i: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rest translation (3,), rotation xyzw (4,) and scale (3,) of node ``i``."""
    n = f.doc.nodes[i]
    if n.matrix is not None and not np.allclose(n.matrix, np.eye(4).ravel()):
        m = np.asarray(n.matrix, dtype=np.float64).reshape(4, 4).T  # column-major in glTF
        # (16 finite numbers: checked by GLTFFile)
        a = m[:3, :3]
        s = np.linalg.norm(a, axis=0)
        if np.any(s < 1e-12):
            raise f.error(f"node {i} ({n.name}): its matrix has a zero scale")
        if np.linalg.det(a) < 0:
            s[0] = -s[0]
        r = a / s
        if not np.allclose(r.T @ r, np.eye(3), atol=1e-4):
            raise f.error(f"node {i} ({n.name}): its matrix has a shear; only TRS is supported")
        return m[:3, 3].copy(), Rotation.from_matrix(r).as_quat(), s
    t = np.asarray(n.translation if n.translation is not None else [0, 0, 0], dtype=np.float64)
    q = np.asarray(n.rotation if n.rotation is not None else [0, 0, 0, 1], dtype=np.float64)
    s = np.asarray(n.scale if n.scale is not None else [1, 1, 1], dtype=np.float64)
    if t.shape != (3,) or q.shape != (4,) or s.shape != (3,):
        raise f.error(f"node {i} ({n.name}): translation/rotation/scale of the wrong length")
    if np.linalg.norm(q) < 1e-12:
        raise f.error(f"node {i} ({n.name}): zero rotation quaternion")
    return t, q / np.linalg.norm(q), s


def _rest_above(f: _File, above: list[int]) -> tuple[Rotation, np.ndarray, float]:
    """The rest transform of the nodes above the root joint, top first: rotation,
    translation and uniform scale of their product."""
    r_rot, r_pos, r_scale = Rotation.identity(), np.zeros(3), 1.0
    for i in above:
        rt, rq, rs = _rest_trs(f, i)
        r_pos = r_pos + r_rot.apply(rt * r_scale)
        r_rot = r_rot * Rotation.from_quat(rq)
        r_scale *= float(_uniform(f, i, rs[None])[0])
    return r_rot, r_pos, r_scale


def _uniform(f: _File, i: int, s: np.ndarray) -> np.ndarray:
    """(F,) uniform scale from (F, 3) scales of node ``i``, or GLTFError."""
    lo, hi = s.min(axis=1), s.max(axis=1)
    bad = (hi - lo > _UNIFORM_TOL * np.maximum(np.abs(hi), 1e-12)) | (lo <= 0)
    if np.any(bad):
        k = int(np.flatnonzero(bad)[0])
        raise f.error(
            f"node {i} ({f.doc.nodes[i].name}) has non-uniform, zero or negative scale "
            f"{np.round(s[k], 6).tolist()}; only uniform positive scale can be expressed as "
            "joint rotations and translations (apply the scale to the rig before exporting)"
        )
    return s.mean(axis=1)


# ---------------------------------------------------------------------- animations


def _anim_label(i: int, a) -> str:
    return repr(a.name) if a.name else f"#{i}"


def _times(f: _File, a, i: int) -> tuple[float, float]:
    lo, hi = math.inf, -math.inf
    for s_i, smp in enumerate(a.samplers):
        t = f.accessor(smp.input, f"animation {_anim_label(i, a)} sampler {s_i} input")[:, 0]
        if t.size:
            lo, hi = min(lo, float(t.min())), max(hi, float(t.max()))
    if not math.isfinite(lo):
        raise f.error(f"animation {_anim_label(i, a)} has no keyframes")
    return lo, hi


def _select_animation(f: _File, animation: str | int | None) -> int:
    anims = f.doc.animations
    if not anims:
        raise f.error("no animation in the file; a skinned animation is needed")
    labels = [f"{k}: {_anim_label(k, a)}" for k, a in enumerate(anims)]
    if animation is None:
        return 0
    if isinstance(animation, bool) or not isinstance(animation, int | str):
        raise f.error(f"animation must be a name or an index, got {type(animation).__name__}")
    if isinstance(animation, int):
        if not -len(anims) <= animation < len(anims):
            raise f.error(
                f"animation index {animation} out of range; valid: 0..{len(anims) - 1} "
                f"({_short(labels)})"
            )
        return animation % len(anims)
    hits = [k for k, a in enumerate(anims) if a.name == animation]
    if not hits:
        raise f.error(
            f"unknown animation {animation[:60]!r}; valid: {_short(labels)} (name or index)"
        )
    return hits[0]


def _target_nodes(a) -> set[int]:
    return {
        c.target.node
        for c in a.channels
        if c.target is not None and c.target.node is not None and c.target.path in _PATH_COMP
    }


def list_gltf_animations(
    path: str | Path, options: GLTFReadOptions | None = None
) -> list[GLTFAnimationInfo]:
    """The animations of a glTF / GLB file.

    Args:
        path: the ``.glb`` or ``.gltf`` file.
        options: the reader's limits (None: :class:`GLTFReadOptions` defaults).

    Returns:
        One :class:`GLTFAnimationInfo` per animation, in file order (empty if none).

    Raises:
        GLTFError: missing, unreadable or corrupt file.
    """
    f = _File(path, options)
    joints = {j for s in f.doc.skins for j in (s.joints or [])}
    out = []
    for i, a in enumerate(f.doc.animations):
        lo, hi = _times(f, a, i)
        out.append(
            GLTFAnimationInfo(
                index=i,
                name=a.name or "",
                duration=hi - lo,
                num_joints=len(_target_nodes(a) & joints),
                num_channels=len(a.channels),
            )
        )
    return out


def _sample(f: _File, a, ai: int, ch_i: int, path: str, t: np.ndarray) -> np.ndarray:
    """(F, k) values of one animation channel at times ``t`` (rotation as xyzw)."""
    ch = a.channels[ch_i]
    what = f"animation {_anim_label(ai, a)} channel {ch_i} ({path})"
    if not 0 <= ch.sampler < len(a.samplers):
        raise f.error(f"{what}: sampler {ch.sampler} does not exist")
    smp = a.samplers[ch.sampler]
    interp = (smp.interpolation or "LINEAR").upper()
    if interp not in _INTERPOLATIONS:
        raise f.error(f"{what}: unknown interpolation {interp!r}; valid: {_INTERPOLATIONS}")
    times = f.accessor(smp.input, what + " input")[:, 0]
    vals = f.accessor(smp.output, what + " output")
    k = _PATH_COMP[path]
    n = times.size
    if n == 0:
        raise f.error(f"{what}: no keyframes")
    if vals.shape[1] != k:
        raise f.error(f"{what}: output has {vals.shape[1]} components, expected {k}")
    if interp == "CUBICSPLINE":
        if vals.shape[0] != 3 * n:
            raise f.error(f"{what}: CUBICSPLINE needs 3 x {n} outputs, found {vals.shape[0]}")
        vals = vals.reshape(n, 3, k)[:, 1]  # (in-tangent, value, out-tangent): keep the value
        interp = "LINEAR"
    elif vals.shape[0] != n:
        raise f.error(f"{what}: {vals.shape[0]} outputs for {n} keyframe times")
    if n > 1 and np.any(np.diff(times) <= 0):
        raise f.error(f"{what}: keyframe times are not strictly increasing")
    if path == "rotation":
        norm = np.linalg.norm(vals, axis=1, keepdims=True)
        if np.any(norm < 1e-12):
            raise f.error(f"{what}: zero rotation quaternion")
        vals = vals / norm
    if n == 1:
        return np.repeat(vals, t.size, axis=0)
    if interp == "STEP":
        idx = np.clip(np.searchsorted(times, t, side="right") - 1, 0, n - 1)
        return vals[idx]
    tc = np.clip(t, times[0], times[-1])
    if path == "rotation":
        return Slerp(times, Rotation.from_quat(vals))(tc).as_quat()
    return np.stack([np.interp(tc, times, vals[:, c]) for c in range(k)], axis=1)


# ---------------------------------------------------------------------- reading


def _joint_set(f: _File, skin_i: int, par: list[int]) -> tuple[int, list[int]]:
    """Root node and the node set (skin joints plus the nodes linking them to the root)."""
    skin = f.doc.skins[skin_i]
    joints = list(dict.fromkeys(skin.joints or []))
    if not joints:
        raise f.error(f"skin {skin_i} has no joints")
    n_nodes = len(f.doc.nodes)
    bad = [j for j in joints if not 0 <= j < n_nodes]
    if bad:
        raise f.error(f"skin {skin_i} lists joints {bad[:5]} that are not nodes")

    # The nodes on a path from a skin joint to the top, each walked once.
    marked: set[int] = set()
    kids: dict[int, list[int]] = {}
    for j in joints:
        c = j
        while c >= 0 and c not in marked:
            marked.add(c)
            if par[c] >= 0:
                kids.setdefault(par[c], []).append(c)
            c = par[c]
    tops = [c for c in marked if par[c] < 0]
    if len(tops) != 1:
        raise f.error(
            f"skin {skin_i}: its joints have no common ancestor node (several separate "
            "skeletons); cannot make one hierarchy"
        )
    # Their lowest common ancestor: down from the top while the path does not branch.
    root, jset = tops[0], set(joints)
    while root not in jset and len(kids.get(root, [])) == 1:
        root = kids[root][0]
    c, above = par[root], set()
    while c >= 0:
        above.add(c)
        c = par[c]
    keep = marked - above
    return root, sorted(keep)


def _joint_names(f: _File, order: list[int]) -> list[str]:
    names, seen = [], set()
    for i in order:
        raw = f.doc.nodes[i].name or f"node{i}"
        name = re.sub(r"\s+", "_", raw.strip()) or f"node{i}"
        if name in seen:
            name = f"{name}_{i}"
        seen.add(name)
        names.append(name)
    return names


def _rig_nodes(f: _File, ai: int) -> tuple[list[int], int, list[int], list[int], set[int]]:
    """The nodes :func:`read_gltf` makes joints of for animation ``ai``: every node's
    parent, the root, the joints in depth-first order (children in node order), the nodes
    above the root (top first) and the joint set."""
    doc = f.doc
    targets = _target_nodes(doc.animations[ai])
    skin_i = max(
        range(len(doc.skins)), key=lambda s: (len(targets & set(doc.skins[s].joints or [])), -s)
    )
    par = _parents(f)
    root, keep = _joint_set(f, skin_i, par)
    keep_set = set(keep)
    order: list[int] = []
    stack = [root]
    while stack:
        j = stack.pop()
        order.append(j)
        kids = [c for c in (doc.nodes[j].children or []) if c in keep_set]
        stack.extend(reversed(kids))
    above = []
    j = par[root]
    while j >= 0:
        above.append(j)
        j = par[j]
    above.reverse()
    return par, root, order, above, keep_set


def read_gltf(
    path: str | Path,
    animation: str | int | None = None,
    fps: float = 30.0,
    options: GLTFReadOptions | None = None,
) -> BVHData:
    """Read one skinned animation of a glTF 2.0 file as BVH data (see the module docstring).

    Args:
        path: the ``.glb`` or ``.gltf`` file (a ``.gltf`` with its ``.bin`` / images
            beside it, or with data URIs).
        animation: the animation's name or index; None = the first one. See
            :func:`list_gltf_animations`.
        fps: sampling rate [Hz] (> 0).
        options: the reader's limits (None: :class:`GLTFReadOptions` defaults).

    Returns:
        :class:`~habitsim.bvh.BVHData` in the file's units and axes, six channels per
        joint, End Sites on leaf joints, ``source`` = the path.

    Raises:
        GLTFError: missing / unreadable / corrupt file, truncated buffer, no skin, no
            animation, unknown animation name or index (the message lists the valid ones),
            non-uniform scale on a joint with children, invalid ``fps``, a field of the
            wrong type or out of range, a buffer URI outside the file's folder, a clip
            whose frames × sampled nodes exceed ``options.max_samples``.
    """
    if isinstance(fps, bool) or not isinstance(fps, int | float) or not math.isfinite(fps):
        raise GLTFError(f"fps must be a positive number, got {fps!r}")
    if fps <= 0:
        raise GLTFError(f"fps must be a positive number, got {fps!r}")
    opt = options or GLTFReadOptions()
    f = _File(path, opt)
    doc = f.doc
    if not doc.skins:
        raise f.error("no skin in the file: read_gltf needs a skinned (rigged) model with joints")
    ai = _select_animation(f, animation)
    anim = doc.animations[ai]
    par, root, order, above, keep_set = _rig_nodes(f, ai)

    # Sample every node that matters.
    lo, hi = _times(f, anim, ai)
    span = (hi - lo) * fps  # frames - 1, bounded before anything is allocated
    n_nodes = len(order) + len(above)
    if not span + 1 <= opt.max_samples / n_nodes:
        raise f.error(
            f"animation {_anim_label(ai, anim)} lasts {hi - lo:.6g} s: {span + 1:.6g} frames at "
            f"{fps:g} Hz x {n_nodes} nodes; valid: at most {opt.max_samples} samples "
            "(GLTFReadOptions.max_samples; a lower fps or a shorter clip)"
        )
    n_frames = int(math.floor(span + 1e-6)) + 1
    t = lo + np.arange(n_frames) / fps
    trs: dict[int, list[np.ndarray]] = {}
    for i in order + above:
        rt, rq, rs = _rest_trs(f, i)
        trs[i] = [
            np.tile(rt, (n_frames, 1)),
            np.tile(rq, (n_frames, 1)),
            np.tile(rs, (n_frames, 1)),
        ]
    for ci, ch in enumerate(anim.channels):
        tgt = ch.target
        if tgt is None or tgt.node not in trs or tgt.path not in _PATH_COMP:
            continue
        slot = ("translation", "rotation", "scale").index(tgt.path)
        trs[tgt.node][slot] = _sample(f, anim, ai, ci, tgt.path, t)

    # Nodes above the root: world rotation, uniform scale and position.
    rot_a = Rotation.identity(n_frames)
    pos_a = np.zeros((n_frames, 3))
    scale_a = np.ones(n_frames)
    for i in above:
        tt, qq, ss = trs[i]
        pos_a = pos_a + rot_a.apply(tt * scale_a[:, None])
        rot_a = rot_a * Rotation.from_quat(qq)
        scale_a = scale_a * _uniform(f, i, ss)

    # Channels of the joints.
    idx = {n: k for k, n in enumerate(order)}
    n_j = len(order)
    trans = np.empty((n_frames, n_j, 3))
    quat = np.empty((n_frames, n_j, 4))  # xyzw
    cum = np.empty((n_frames, n_j))  # uniform scale applied to the joint's children
    has_kids = {par[i] for i in order if i != root}
    for k, i in enumerate(order):
        tt, qq, ss = trs[i]
        s = _uniform(f, i, ss) if i in has_kids else np.ones(n_frames)
        if i == root:
            trans[:, k] = pos_a + rot_a.apply(tt * scale_a[:, None])
            quat[:, k] = (rot_a * Rotation.from_quat(qq)).as_quat()
            cum[:, k] = scale_a * s
        else:
            p = idx[par[i]]
            trans[:, k] = tt * cum[:, p, None]
            quat[:, k] = qq
            cum[:, k] = cum[:, p] * s

    # Rest offsets (rest TRS of every node; the channels override them).
    rest_off = np.empty((n_j, 3))
    rest_cum = np.empty(n_j)
    r_rot, r_pos, r_scale = _rest_above(f, above)
    for k, i in enumerate(order):
        rt, _, rs = _rest_trs(f, i)
        s0 = float(_uniform(f, i, rs[None])[0]) if i in has_kids else 1.0
        if i == root:
            rest_off[k] = r_pos + r_rot.apply(rt * r_scale)
            rest_cum[k] = r_scale * s0
        else:
            p = idx[par[i]]
            rest_off[k] = rt * rest_cum[p]
            rest_cum[k] = rest_cum[p] * s0

    euler = np.degrees(quat_to_euler(quat[..., [3, 0, 1, 2]], _ORDER))  # (F, J, 3)
    node_names = _joint_names(f, order)

    # Assemble joints (depth-first) with End Sites after leaf joints.
    names: list[str] = []
    parents: list[int] = []
    offsets: list[np.ndarray] = []
    channels: list[tuple[str, ...]] = []
    end: list[bool] = []
    cols: list[np.ndarray] = []
    out_idx: dict[int, int] = {}
    taken = set(node_names)
    for k, i in enumerate(order):
        out_idx[i] = len(names)
        names.append(node_names[k])
        parents.append(-1 if i == root else out_idx[par[i]])
        offsets.append(rest_off[k])
        channels.append(_CHANNELS)
        end.append(False)
        cols += [trans[:, k], euler[:, k]]
        is_leaf = not any(c in keep_set for c in (doc.nodes[i].children or []))
        if is_leaf and i != root and np.linalg.norm(rest_off[k]) > 0:
            tip, n = node_names[k] + END_SITE_SUFFIX, 2
            while tip in taken:
                tip, n = f"{node_names[k]}{END_SITE_SUFFIX}{n}", n + 1
            taken.add(tip)
            names.append(tip)
            parents.append(out_idx[i])
            offsets.append(END_SITE_FRACTION * rest_off[k])
            channels.append(())
            end.append(True)
    frames = np.concatenate(cols, axis=1)
    offsets_arr = np.asarray(offsets, dtype=np.float64).reshape(-1, 3)
    if not (np.all(np.isfinite(frames)) and np.all(np.isfinite(offsets_arr))):
        raise f.error(
            "the rig's transforms overflow (a translation or scale too large for float64); "
            "valid: finite joint positions"
        )
    return BVHData(
        names=tuple(names),
        parents=tuple(parents),
        offsets=offsets_arr,
        channels=tuple(channels),
        is_end_site=tuple(end),
        frame_time=1.0 / float(fps),
        frames=frames,
        source=f.source,
    )
