"""A habitsim motion written back onto a user's own rig (:func:`export_to_rig`), the
inverse of :func:`~habitsim.bvh_mapping.import_bvh`.

The rig (a BVH file or a glTF/GLB skinned model) is mapped exactly as an import maps it
(:func:`~habitsim.bvh_mapping.map_joints`: the automatic mapping or a joint map, units
and up axis detected or given). Then every quantity the import reads off a source is
set from the motion, in the rig's own bone lengths:

* each mapped bone span (a mapped rig joint to the next mapped one along a habitsim
  chain) points along the motion's bone; the rig joint at its top takes the rotation,
  its twist keeping the rig's lateral axis (of its first frame) on the habitsim joint's;
* the hips take the rotation that puts the line from the hips to the chest (the joint the
  import reads the pelvis's heading from) along the motion's pelvis axis;
* the root's travel is the motion's divided by the scale the import finds for this rig
  (:func:`~habitsim.bvh_mapping.retargeting.leg_root_scale`, the one rule both ways: the
  species' hind-leg length over the rig's; without feet to measure, the hip-height ratio
  the import finds, solved so the two agree), in the rig's units and axes, with the rig's
  lowest resting foot on its floor;
* every other joint (ears, toes, tail tips, helpers, joints of unmapped chains) keeps the
  local rotation and translation of the rig's first frame and follows its parent.

What the round trip keeps (``import(export(m, rig))`` against ``m``): the directions of
the mapped bones and the pelvis's heading and pitch are the motion's exactly, the root's
horizontal travel exactly, and its height exactly when the motion's stance toes rest on
the floor (the import stands the body on its toes,
:func:`~habitsim.bvh_mapping.retargeting.root_height_shift`). The import builds the
pelvis without roll and aims a span of several habitsim bones along one line: a pelvis
roll and a bend inside an unmapped span do not come back. See docs/import.md, "Back onto
your rig".
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..bvh import POSITION_CHANNELS, ROTATION_CHANNELS, BVHData
from ..errors import RigExportError
from ..fileio import atomic_write
from ..gltf_export import GLTF_SUFFIXES, add_gltf_animation
from ..motion import Motion
from ..rotations import matrix_to_quat, quat_fix_continuity, quat_to_euler, quat_to_matrix
from ..skeleton import JOINT_NAMES, fk
from ..species import Species, load_species
from ..stance.planting import stance_slip
from .chains import _HEADING, _LEG_CHAINS
from .frame import FrameConversion, _parse_up
from .identity import _habitsim_order, identity_root_scale, is_habitsim_bvh
from .importing import map_joints, read_source
from .options import MappingOptions
from .result import JointMapping
from .retargeting import _driven, _source_feet, _source_stance, leg_root_scale, retarget
from .tree import _Tree

_X, _Y, _Z = np.eye(3)


#: How the rig's root travels (:attr:`RigExportOptions.travel`).
TRAVEL_MODES: tuple[str, ...] = ("round-trip", "feet")


@dataclass(frozen=True)
class RigExportOptions:
    """The knobs of :func:`export_to_rig`.

    Attributes:
        travel: ``"round-trip"``: the root's travel is the motion's divided by the scale
            the import finds for the rig, so importing the result gives the motion back;
            ``"feet"``: then each frame step loses the mean step of the rig's stance toes
            (the motion's stance labels), so the rig's own feet stay put where its
            proportions or its hip height differ from the species' (the round trip then
            travels as far as the rig's legs carry it).
    """

    travel: str = "round-trip"


@dataclass(frozen=True)
class RigExport:
    """A motion on a user's rig.

    Attributes:
        bvh: the rig's hierarchy, channel orders, units and axes, with the motion's frames.
        mapping: the rig's joint mapping and frame conversion.
        root_scale: the factor the import applies to the rig's root travel (the species'
            hind-leg length / the rig's); the rig's travel is the motion's divided by it.
        rig: the rig's file (or the parsed rig's source name).
    """

    bvh: BVHData
    mapping: JointMapping
    root_scale: float
    rig: str
    animation: str | int | None = None

    def text(self) -> str:
        """The BVH file's text."""
        return self.bvh.to_text()

    def write(self, path: str | Path) -> Path:
        """Write the result atomically (nothing is left on a failure): a ``.bvh`` file, or
        for a glTF/GLB rig a ``.glb`` / ``.gltf`` copy of the rig's model with the motion
        added as the animation ``habitsim`` (:func:`habitsim.gltf_export.add_gltf_animation`).

        Raises:
            RigExportError: a glTF output for a rig that is not a glTF file, or another type.
        """
        p = Path(path)
        kind = p.suffix.lower()
        if kind in GLTF_SUFFIXES:
            if Path(self.rig).suffix.lower() not in GLTF_SUFFIXES:
                raise RigExportError(
                    f"{p.name}: a glTF output needs a glTF/GLB rig (the rig is "
                    f"{Path(self.rig).name}); write a .bvh"
                )
            return add_gltf_animation(self.rig, self.bvh, p, animation=self.animation)
        if kind != ".bvh":
            raise RigExportError(
                f"{p.name}: unknown output type; valid: .bvh, or .glb / .gltf for a glTF rig"
            )
        with atomic_write(p, "w") as fh:
            fh.write(self.text())
        return p


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 1e-12, n, 1.0)


def _frame(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Rotation matrices (…, 3, 3) whose columns are unit ``x``, ``y`` made orthogonal to
    it, and their cross product (a perpendicular stands in for a ``y`` along ``x``)."""
    x, y = np.broadcast_arrays(_unit(np.asarray(x, float)), np.asarray(y, float))
    y = y - np.sum(y * x, axis=-1, keepdims=True) * x
    n = np.linalg.norm(y, axis=-1, keepdims=True)
    alt = np.where(np.abs(x[..., 2:3]) < 0.9, np.cross(_Z, x), np.cross(x, _X))
    y = np.where(n > 1e-6, y, alt)
    y = _unit(y)
    return np.stack([x, y, np.cross(x, y)], axis=-1)


def _spans(j2s: Mapping[str, str]) -> dict[tuple[str, str], list[tuple[str, str]]]:
    """The mapped spans the import aims bones along: (top, bottom) habitsim joints, each
    with the habitsim bones (joint, child) aimed along it."""
    out: dict[tuple[str, str], list[tuple[str, str]]] = {}
    for name, child, chain, i in _driven():
        a = next((chain[k] for k in range(i, -1, -1) if chain[k] in j2s), None)
        b = next((chain[k] for k in range(i + 1, len(chain)) if chain[k] in j2s), None)
        if a is not None and b is not None:
            out.setdefault((a, b), []).append((name, child))
    return out


def check_rig(mapping: JointMapping, where: str) -> None:
    """Raise :class:`RigExportError` unless the mapping animates the trunk and each leg.

    A leg needs two mapped joints along it (a span the motion's bone can be aimed along);
    the trunk needs the pelvis and a spine, neck or head joint (the pelvis's heading).
    """
    j2s = mapping.mapped()
    spans = _spans(j2s)
    fix = (
        "map it with a joint-map file (--map, for transfer --rig-map; "
        "'habitsim data inspect-bvh RIG' prints one to "
        "edit), or give a rig with that chain"
    )
    if not any(n in j2s for n in _HEADING):
        raise RigExportError(
            f"{where}: no spine, neck or head joint is mapped, so the rig's pelvis cannot "
            f"take the motion's heading; {fix}"
        )
    for prefix, chain in _LEG_CHAINS.items():
        if not any(a in chain and b in chain for a, b in spans):
            found = [f"{n} <- {j2s[n]}" for n in chain if n in j2s] or ["nothing"]
            raise RigExportError(
                f"{where}: the {prefix} leg is not animatable (mapped: {', '.join(found)}; "
                f"it needs two mapped joints along {' > '.join(chain)}); {fix}"
            )


def _path(parents: tuple[int, ...], top: int, bottom: int) -> list[int] | None:
    """Joints from ``top`` (excluded) down to ``bottom`` (included), None if ``bottom``
    does not hang below ``top``."""
    out = []
    j = bottom
    while j != top:
        if j < 0:
            return None
        out.append(j)
        j = parents[j]
    return out[::-1]


def export_to_rig(
    motion: Motion,
    rig: str | Path | BVHData,
    joint_map: str | Path | Mapping[str, str] | None = None,
    units: str | float | None = None,
    up: str | None = None,
    animation: str | int | None = None,
    options: MappingOptions | None = None,
    export: RigExportOptions | None = None,
) -> RigExport:
    """Write a habitsim motion onto a rig the mapping can map (see the module docstring).

    Args:
        motion: the habitsim motion (any species).
        rig: the rig: a ``.bvh``, ``.glb`` or ``.gltf`` file, or a parsed
            :class:`~habitsim.bvh.BVHData`; its first frame is the pose its unmapped
            joints keep.
        joint_map, units, up, options: how to map the rig, as for
            :func:`~habitsim.bvh_mapping.import_bvh`.
        animation: glTF/GLB rig: the animation whose first frame is the reference pose.
        export: how the root travels (:class:`RigExportOptions`; default: the round trip).

    Returns:
        The :class:`RigExport` (its :meth:`~RigExport.write` writes the BVH file).

    Raises:
        RigExportError: the mapping leaves a leg or the trunk unanimated, a joint that must
            turn lacks rotation channels, or no joint can carry the root's travel.
        SkeletonMappingError, BVHParseError, GLTFError: an unmappable or unreadable rig.
    """
    export = export or RigExportOptions()
    if export.travel not in TRAVEL_MODES:
        raise RigExportError(f"unknown travel {export.travel!r}; valid: {', '.join(TRAVEL_MODES)}")
    src = rig if isinstance(rig, BVHData) else read_source(rig, animation=animation)
    sp = load_species(motion.species)
    plain = (units is None or (isinstance(units, str) and units.lower() == "m")) and (
        up is None or _parse_up(up) == "+z"
    )
    if joint_map is None and plain and is_habitsim_bvh(src):
        return _identity_export(motion, src, sp)
    mapping = map_joints(src, sp, joint_map=joint_map, units=units, up=up, options=options)
    check_rig(mapping, Path(src.source).name)
    solver = _Solver(motion, src, mapping)
    assert mapping.frame is not None  # map_joints always sets it
    # The import's root scale: the legs' ratio, a constant of the rig (the same function
    # both ways); a rig without feet to measure gets the scale the import finds for it.
    probe = solver.bvh(1.0, 0.0)
    rig_pos = mapping.frame.apply(probe.fk())
    feet = _source_feet(
        probe,
        _Tree(probe),
        mapping.mapped(),
        rig_pos,
        JointMapping(dict(mapping.joints), mapping.method, mapping.frame),
    )
    by_legs = feet is not None
    scale = leg_root_scale(sp, feet[2]) if feet is not None else _root_scale(solver, mapping, sp)
    out = solver.bvh(scale, 0.0)
    # The rig's lowest resting foot on its floor (the import reads heights from it).
    rig_pos = mapping.frame.apply(out.fk())
    st = _source_stance(out.fps, feet, rig_pos)
    lift = 0.0 if st is None else -st[0].ground
    out = solver.bvh(scale, lift)
    if export.travel == "feet":
        contacts = motion.contacts if motion.contacts is not None else motion.detect_contacts()
        j2s = mapping.mapped()
        toes = [  # each leg's lowest mapped joint
            out.index(next(j2s[n] for n in reversed(_LEG_CHAINS[p]) if n in j2s))
            for p in ("lf", "rf", "lh", "rh")
        ]
        pos = mapping.frame.apply(out.fk()[:, toes])
        step = np.zeros((motion.num_frames, 2))
        step[1:] = np.cumsum(stance_slip(pos[..., :2], contacts), axis=0)
        out = solver.bvh(scale, lift, step)
    elif not by_legs:
        out = _centred(solver, out, scale, lift, lambda b: _import_scale(b, mapping, sp))
    return RigExport(out, mapping, scale, src.source, animation)


def _import_scale(bvh: BVHData, mapping: JointMapping, sp: Species) -> float:
    """The root scale the import finds for ``bvh`` (retargeted without planting)."""
    probe = JointMapping(dict(mapping.joints), mapping.method, mapping.frame)
    retarget(bvh, probe, sp, plant=False)
    return probe.root_scale


def _centred(solver: _Solver, out: BVHData, scale: float, lift: float, k: Callable) -> BVHData:
    """Where the import's root scale ``k`` of the result still differs from ``scale`` (the
    stance it finds jumps there), shift the travel so the import's error is centred on the
    clip's horizontal extent instead of growing from the origin (a shift does not change
    the stance the import finds, so ``k`` stays)."""
    k_out = k(out)
    if abs(k_out - scale) <= 1e-9 * scale:
        return out
    root = solver.root_m[:, :2]
    mid = 0.5 * (root.min(axis=0) + root.max(axis=0))
    shift = mid * (1.0 / k_out - 1.0 / scale)
    moved = solver.bvh(scale, lift, np.broadcast_to(-shift, root.shape))
    return moved if abs(k(moved) - k_out) <= 1e-9 * scale else out


def _identity_export(motion: Motion, rig: BVHData, sp: Species) -> RigExport:
    """A habitsim file as the rig: the import copies its rotations and root translation
    (the root scaled when its offsets are not the species'), so the motion's go in."""
    keep = _habitsim_order(rig)
    assert keep is not None
    scale = identity_root_scale(rig, sp)
    frames = np.broadcast_to(rig.frames[0], (motion.num_frames, rig.num_channels)).copy()
    starts = rig.channel_start
    for h, j in enumerate(keep):
        chans = rig.channels[j]
        rots = [c for c in chans if c in ROTATION_CHANNELS]
        if len(rots) != 3:
            raise RigExportError(
                f"{Path(rig.source).name}: joint {rig.names[j]!r} has channels "
                f"{' '.join(chans) or '(none)'}; a habitsim rig needs three rotation channels"
            )
        euler = np.degrees(quat_to_euler(motion.rotations[:, h], "".join(c[0] for c in rots)))
        for k, c in enumerate(rots):
            frames[:, starts[j] + chans.index(c)] = euler[:, k]
    root = keep[0]
    if not all(c in rig.channels[root] for c in POSITION_CHANNELS):
        raise RigExportError(
            f"{Path(rig.source).name}: the root {rig.names[root]!r} has no Xposition "
            "Yposition Zposition channels to carry the motion's travel"
        )
    for k, c in enumerate(POSITION_CHANNELS):
        frames[:, starts[root] + rig.channels[root].index(c)] = motion.root_positions[:, k] / scale
    out = BVHData(
        rig.names,
        rig.parents,
        rig.offsets,
        rig.channels,
        rig.is_end_site,
        1.0 / motion.fps,
        frames,
        rig.source,
    )
    frame = FrameConversion.from_axes(1.0, "m", "+z", "+x")
    mapping = JointMapping({n: n for n in JOINT_NAMES}, "identity", frame, scale)
    return RigExport(out, mapping, scale, rig.source)


def _root_scale(solver: _Solver, mapping: JointMapping, sp: Species) -> float:
    """The travel scale ``c`` at which the import finds root scale ``k(c) = c`` for the
    rig: fixed-point passes (``k`` hardly depends on ``c``), then, where the stance the
    import finds on the rig's feet changes with ``c`` and ``k`` jumps across ``c``, a
    bisection onto the jump (the ``c`` with the smallest ``|k(c) - c|`` is kept)."""

    def k(c: float) -> float:
        return _import_scale(solver.bvh(c, 0.0), mapping, sp)

    seen: dict[float, float] = {}
    c = 1.0
    for _ in range(6):
        seen[c] = k(c)
        if abs(seen[c] - c) <= 1e-9 * c:
            return c
        c = seen[c]
    below = [x for x, y in seen.items() if y > x]
    above = [x for x, y in seen.items() if y < x]
    if below and above:
        lo, hi = max(below), min(above)
        for _ in range(30):
            if hi - lo <= 1e-9 * hi:
                break
            mid = 0.5 * (lo + hi)
            seen[mid] = k(mid)
            lo, hi = (mid, hi) if seen[mid] > mid else (lo, mid)
    return min(seen, key=lambda x: abs(seen[x] - x))


class _Solver:
    """The rig's rotations for a motion, in habitsim's axes and metres; :meth:`bvh` puts
    them into the rig's channels."""

    def __init__(self, motion: Motion, rig: BVHData, mapping: JointMapping):
        assert mapping.frame is not None
        self.rig, self.motion = rig, motion
        fr = mapping.frame
        m, s = fr.matrix, fr.scale
        self.m, self.s = m, s
        j2s = mapping.mapped()
        idx = {h: rig.index(n) for h, n in j2s.items()}
        par = rig.parents
        n_j = rig.num_joints
        # The rig's first frame, in habitsim's axes and metres.
        loc0 = m @ quat_to_matrix(rig.local_rotations()[0]) @ m.T  # (J, 3, 3)
        tr0 = s * rig.local_translations()[0] @ m.T  # (J, 3)
        g0 = np.empty((n_j, 3, 3))
        p0 = np.empty((n_j, 3))
        for j, p in enumerate(par):
            g0[j] = loc0[j] if p < 0 else g0[p] @ loc0[j]
            p0[j] = tr0[j] if p < 0 else p0[p] + g0[p] @ tr0[j]
        self.loc0, self.tr0 = loc0, tr0
        fwd = next(n for n in _HEADING if n in j2s)
        ahead = p0[idx[fwd]] - p0[idx["pelvis"]]
        ahead[2] = 0.0
        side0 = np.cross(_Z, _unit(ahead) if np.linalg.norm(ahead) > 1e-9 else _X)

        # The motion's global frames.
        pos, rot = fk(motion.skeleton, motion.root_positions, motion.rotations, True)
        self.n_f = motion.num_frames
        glob = np.empty((self.n_f, n_j, 3, 3))
        solved = np.zeros(n_j, bool)
        jn = {n: i for i, n in enumerate(JOINT_NAMES)}
        for (a, b), bones in _spans(j2s).items():
            if a == "pelvis":
                continue  # the pelvis's rotation follows its heading (below)
            ra, rb = idx[a], idx[b]
            if _path(par, ra, rb) is None:
                continue
            d = _unit(np.sum([_unit(pos[:, jn[c]] - pos[:, jn[j]]) for j, c in bones], axis=0))
            v = g0[ra].T @ (p0[rb] - p0[ra])
            if np.linalg.norm(v) < 1e-9:
                continue  # a zero-length span has no direction to aim
            ref = _frame(v, g0[ra].T @ side0)
            glob[:, ra] = _frame(d, rot[:, jn[a]] @ _Y) @ ref.T
            solved[ra] = True

        # The pelvis: the line from the hips to the forward joint along the pelvis's axis.
        rh, rf = idx["pelvis"], idx[fwd]
        path = _path(par, rh, rf) or [rf]
        m0 = next((j for j in path if solved[j]), rf)
        u = g0[rh].T @ (p0[m0] - p0[rh])
        w = np.zeros((self.n_f, 3))
        if m0 != rf:
            g_prev, p_prev = glob[:, m0], np.zeros((self.n_f, 3))
            for j in path[path.index(m0) + 1 :]:
                p_prev = p_prev + g_prev @ tr0[j]
                g_prev = glob[:, j] if solved[j] else g_prev @ loc0[j]
            w = p_prev
        x_m = rot[:, 0, :, 0]
        xw = np.sum(x_m * w, axis=-1, keepdims=True)
        lam = xw + np.sqrt(np.maximum(xw**2 - np.sum(w * w, -1, keepdims=True) + u @ u, 0.0))
        t = _unit(lam * x_m - w)
        glob[:, rh] = _frame(t, rot[:, 0] @ _Y) @ _frame(u, g0[rh].T @ side0).T
        solved[rh] = True

        self.glob, self.solved = glob, solved
        self._propagate()
        if (
            all(n in j2s for n in ("spine3", "lf_shoulder", "rf_shoulder"))
            and solved[idx["spine3"]]
        ):
            self._chest_twist(idx, rot[:, jn["spine3"]] @ _Y)
        self.hips = rh
        self.root_m = motion.root_positions
        # The joint that carries the travel: the hips if they have position channels.
        full = [all(c in rig.channels[j] for c in POSITION_CHANNELS) for j in range(n_j)]
        if full[rh]:
            self.carrier = rh
        elif full[0]:
            self.carrier = 0
        else:
            raise RigExportError(
                f"{Path(rig.source).name}: neither the root {rig.names[0]!r} nor the hips "
                f"{rig.names[rh]!r} has Xposition Yposition Zposition channels to carry the "
                "motion's travel; give a rig whose root has position channels"
            )
        for j in range(n_j):
            if solved[j] and sum(c in ROTATION_CHANNELS for c in rig.channels[j]) < 3:
                raise RigExportError(
                    f"{Path(rig.source).name}: joint {rig.names[j]!r} must turn freely but "
                    f"has channels {' '.join(rig.channels[j]) or '(none)'}; give a rig whose "
                    "mapped joints have three rotation channels"
                )

    def _propagate(self) -> None:
        """Every joint not solved keeps its first frame's local rotation."""
        for j, p in enumerate(self.rig.parents):
            if not self.solved[j]:
                self.glob[:, j] = self.loc0[j] if p < 0 else self.glob[:, p] @ self.loc0[j]

    def _rel(self, top: int, bottom: int) -> np.ndarray:
        """(F, 3) from joint ``top`` to joint ``bottom`` below it [m]."""
        out = np.zeros((self.n_f, 3))
        for j in _path(self.rig.parents, top, bottom) or []:
            out += self.glob[:, self.rig.parents[j]] @ self.tr0[j]
        return out

    def _chest_twist(self, idx: Mapping[str, int], lateral: np.ndarray, passes: int = 12) -> None:
        """Turn the chest about its bone until the rig's shoulder line, the lateral axis
        the import gives the chest, lies along the motion's chest ``lateral`` (F, 3): a
        secant search per frame on the angle between the two."""
        from scipy.spatial.transform import Rotation

        c = idx["spine3"]
        base = self.glob[:, c].copy()
        d = _unit(self._rel(c, idx["neck"]) if "neck" in idx else base[:, :, 0])
        b = _unit(lateral - np.sum(lateral * d, -1, keepdims=True) * d)

        def miss(theta: np.ndarray) -> np.ndarray:
            self.glob[:, c] = Rotation.from_rotvec(d * theta[:, None]).as_matrix() @ base
            self._propagate()
            side = self._rel(c, idx["lf_shoulder"]) - self._rel(c, idx["rf_shoulder"])
            a = side - np.sum(side * d, -1, keepdims=True) * d
            return np.arctan2(np.sum(np.cross(a, b) * d, -1), np.sum(a * b, -1))

        t0 = np.zeros(self.n_f)
        f0 = miss(t0)
        t1 = f0.copy()
        for _ in range(passes):
            f1 = miss(t1)
            if np.abs(f1).max() < 1e-12:
                break
            slope = np.where(
                np.abs(f1 - f0) > 1e-15, (t1 - t0) / np.where(f1 == f0, 1.0, f1 - f0), -1.0
            )
            t0, f0, t1 = t1, f1, t1 - f1 * np.clip(slope, -10.0, -0.1)
        miss(t1)

    def bvh(self, scale: float, lift: float, back: np.ndarray | None = None) -> BVHData:
        """The rig's frames with the root's travel divided by ``scale``, lifted by
        ``lift`` [m] and moved back horizontally by ``back`` ((F, 2) [m], if given)."""
        rig, glob, tr0 = self.rig, self.glob, self.tr0
        par, n_f = rig.parents, self.n_f
        target = self.root_m / scale
        target[:, 2] += lift
        if back is not None:
            target[:, :2] -= back
        # Positions of the hips' parent chain (the travel's carrier and above).
        pos = np.empty((n_f, rig.num_joints, 3))
        chain = [self.hips]
        while par[chain[-1]] >= 0:
            chain.append(par[chain[-1]])
        trans = np.broadcast_to(tr0, (n_f, *tr0.shape)).copy()
        for j in chain[::-1]:
            p = par[j]
            pos[:, j] = (
                trans[:, j]
                if p < 0
                else pos[:, p] + np.einsum("fab,fb->fa", glob[:, p], trans[:, j])
            )
        shift = target - pos[:, self.hips]
        carrier = self.carrier
        if par[carrier] < 0:
            trans[:, carrier] += shift
        else:
            trans[:, carrier] += np.einsum("fba,fb->fa", glob[:, par[carrier]], shift)
        local = np.empty_like(glob)
        for j, p in enumerate(par):
            local[:, j] = glob[:, j] if p < 0 else np.swapaxes(glob[:, p], -1, -2) @ glob[:, j]
        m = self.m
        local_f = m.T @ local @ m
        trans_f = trans @ m / self.s
        quat = quat_fix_continuity(matrix_to_quat(local_f), axis=0)
        frames0 = rig.frames[0]
        frames = np.broadcast_to(frames0, (n_f, frames0.shape[0])).copy()
        for j, (chans, start) in enumerate(zip(rig.channels, rig.channel_start, strict=True)):
            rots = [c for c in chans if c in ROTATION_CHANNELS]
            if len(rots) == 3:
                order = "".join(c[0] for c in rots)
                euler = np.degrees(quat_to_euler(quat[:, j], order))
                for k, c in enumerate(rots):
                    frames[:, start + chans.index(c)] = euler[:, k]
            if j == carrier:
                for k, ch in enumerate(POSITION_CHANNELS):
                    frames[:, start + chans.index(ch)] = trans_f[:, j, k]
        return BVHData(
            rig.names,
            rig.parents,
            rig.offsets,
            rig.channels,
            rig.is_end_site,
            1.0 / self.motion.fps,
            frames,
            rig.source,
        )


@dataclass(frozen=True)
class RoundTrip:
    """``import(export(m, rig))`` against ``m`` on the joints the rig maps.

    Attributes:
        joints: the habitsim joints the rig maps.
        error: (F, J) distance of each mapped joint from the motion's [m].
        height_offset: the median vertical difference of the joints [m]: what the
            import's root height (the body stood on its lowest toes) adds when the
            motion's stance toes hover or sink.
        pose_error: (F, J) the distances with ``height_offset`` removed [m].
        quarter_turns: the import's turn of the clip about the up axis, in quarter turns
            (it takes the forward axis from the first frame's heading); undone before
            measuring.
    """

    joints: tuple[str, ...]
    error: np.ndarray
    height_offset: float
    pose_error: np.ndarray
    quarter_turns: int

    def summary(self) -> dict[str, float]:
        """Max and median of :attr:`error` and :attr:`pose_error` [mm], the height offset
        [mm] and the quarter turns."""
        return {
            "max_mm": float(self.error.max() * 1e3),
            "median_mm": float(np.median(self.error) * 1e3),
            "pose_max_mm": float(self.pose_error.max() * 1e3),
            "pose_median_mm": float(np.median(self.pose_error) * 1e3),
            "height_offset_mm": self.height_offset * 1e3,
            "quarter_turns": self.quarter_turns,
        }


def round_trip(
    export: RigExport,
    motion: Motion,
    joint_map: str | Path | Mapping[str, str] | None = None,
    units: str | float | None = None,
    up: str | None = None,
    plant: bool = False,
) -> RoundTrip:
    """Import an export back (its BVH text, parsed) and measure it against the motion.

    Args:
        export: what :func:`export_to_rig` returned for ``motion``.
        motion: the exported motion.
        joint_map, units, up: the mapping arguments the export was given.
        plant: plant the legs on import (the import's default; False measures the
            mapping alone, as planting re-solves the legs onto footholds).
    """
    from ..bvh import parse_bvh
    from .importing import import_bvh

    back = parse_bvh(export.text(), source=Path(export.rig).name)
    again, mapping = import_bvh(
        back, motion.species, joint_map=joint_map, units=units, up=up, plant=plant
    )
    turn = np.eye(3)  # re-import -> motion axes (an identity import keeps habitsim's)
    if mapping.frame is not None and export.mapping.frame is not None:
        turn = export.mapping.frame.matrix @ mapping.frame.matrix.T
    joints = tuple(n for n in JOINT_NAMES if n in export.mapping.mapped())
    jx = [JOINT_NAMES.index(n) for n in joints]
    got = again.global_positions()[:, jx] @ turn.T
    diff = got - motion.global_positions()[:, jx]
    offset = float(np.median(diff[..., 2]))
    pose = diff.copy()
    pose[..., 2] -= offset
    yaw = np.degrees(np.arctan2(turn[1, 0], turn[0, 0]))
    return RoundTrip(
        joints,
        np.linalg.norm(diff, axis=-1),
        offset,
        np.linalg.norm(pose, axis=-1),
        int(round(yaw / 90.0)) % 4,
    )
