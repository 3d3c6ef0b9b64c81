"""Transformed copies of a source clip: the dev set as other animals, rigs and recordings.

A second real animal arrives on another rig, at another frame rate, with other
proportions and its own marker placement. ``habitsim bench variants`` (and ``bench real
--variants``) builds such inputs from the clips we have: each :class:`Variant` turns a
parsed BVH file (:class:`habitsim.bvh.BVHData`) into another one, in memory,
deterministically (the noise is seeded), and says how its time axis maps onto the
original's, so its stance labels can be scored against the original clip's.

The variants (:data:`VARIANTS`, in this order):

* ``original``: the clip as it is.
* ``fps24``, ``fps30``, ``fps60``: resampled to 24 / 30 / 60 Hz (joint rotations by
  spherical interpolation, scipy's ``Slerp``; position channels linearly).
* ``slow``, ``fast``: played at 0.8× / 1.25× speed (a slower or quicker animal), then
  resampled back to the clip's own frame rate.
* ``legs-long``, ``legs-short``: every leg below its hip / shoulder joint 1.2× / 0.85× as
  long; the root rises by the change in hip height and its horizontal travel scales
  alike, so planted feet stay planted.
* ``hind-long``: the hind legs alone 1.15× as long, the root raised so that they still
  reach the ground: the fore feet then stand above it (fore toes higher than hind toes).
* ``hind-short``: the hind legs alone 0.87× as long, the root kept: the hind toes stand
  above the ground all clip long, 13 % of their leg higher than the fore toes.
* ``scale-small``: the whole animal and its travel 0.6× (a small dog).
* ``units-m``: the same animal in metres instead of the file's units.
* ``hind-toe-up``, ``hind-toe-down``: the hind toe points (the mapped hind toe joints,
  with everything below them) moved 3 cm up / down, "up" as the toe is held over the
  clip (its median orientation).
* ``hind-foot-long``, ``hind-foot-short``: the hind feet (hock → toe) 1.5× / 0.6× as long.
* ``noise``: measurement jitter, seeded: 0.5° on every rotation channel and 2 mm on the
  root position, independently per frame.
* ``trim``: the first second cut off; ``pad``: the first frame held for one second
  before the clip (a still start).
* ``z-up``: the rig exported z up (the whole clip turned about the file's lateral axis).
* ``renamed``: every joint name under a namespace (``Dog2:b_Hips``), as a rig export
  writes it.

Lengths given in metres (3 cm, 2 mm) are converted with the file's detected units.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from habitsim.errors import HabitsimError

from .targets import TargetCheck, verdict

if TYPE_CHECKING:  # pragma: no cover
    from habitsim.bvh import BVHData

__all__ = [
    "VARIANTS",
    "Variant",
    "VariantError",
    "VariantsOptions",
    "evaluate_targets",
    "make_variant",
    "resample_bvh",
    "run",
    "stance_row",
    "variant_names",
    "variant_sources",
]

#: Target: every variant's stance labels agree with the original's (per-foot F1) …
MIN_STANCE_F1 = 0.9
#: … and every foot's duty factor stays within this of the original's [share of frames].
MAX_DUTY_CHANGE = 0.05
#: Size of the moves given in metres (converted with the file's units) [m].
TOE_SHIFT_M = 0.03
NOISE_ROOT_M = 0.002
NOISE_ROT_DEG = 0.5
#: Seconds trimmed from / padded before a clip's start.
TRIM_S = 1.0


class VariantError(HabitsimError, ValueError):
    """An unknown variant name, or a clip a variant cannot be made of."""


@dataclass(frozen=True)
class _Rig:
    """What the variants need to know of a source rig: its mapped joints and frame."""

    bvh: BVHData
    joints: dict[str, str]  # habitsim joint -> source joint (mapped ones)
    up: np.ndarray  # (3,) the file's up axis
    lateral: np.ndarray  # (3,) the file's left axis
    scale: float  # metres per file unit
    seed: int

    def index(self, habitsim_joint: str) -> int:
        return self.bvh.index(self.joints[habitsim_joint])

    def below(self, j: int) -> list[int]:
        """Every joint below joint ``j`` (End Sites included), not ``j`` itself."""
        kids: dict[int, list[int]] = {}
        for i, p in enumerate(self.bvh.parents):
            kids.setdefault(p, []).append(i)
        out, todo = [], list(kids.get(j, []))
        while todo:
            i = todo.pop()
            out.append(i)
            todo += kids.get(i, [])
        return out


@dataclass(frozen=True)
class Variant:
    """One transformation of a clip.

    Attributes:
        name: the variant's name (``--variants``).
        description: what it does, in a line.
        make: the transformation (the rig, returns the new file).
        to_variant_time: time t [s] of the original → the same instant in the variant.
    """

    name: str
    description: str
    make: Callable[[_Rig], BVHData]
    to_variant_time: Callable[[np.ndarray], np.ndarray] = lambda t: t


# ---------------------------------------------------------------------------- tools


def _with_frames(bvh: BVHData, frames: np.ndarray, **changes: Any) -> BVHData:
    return dataclasses.replace(bvh, frames=np.ascontiguousarray(frames), **changes)


def _euler_order(channels: Sequence[str]) -> str:
    """scipy's intrinsic sequence of a joint's rotation channels (``ZXY``)."""
    return "".join(c[0] for c in channels if c.endswith("rotation"))


def _set_rotations(bvh: BVHData, frames: np.ndarray, j: int, quat_wxyz: np.ndarray) -> None:
    """Write (F, 4) local rotations of joint ``j`` into ``frames`` in its channel order."""
    from scipy.spatial.transform import Rotation

    chans = bvh.channels[j]
    order = _euler_order(chans)
    if len(order) != 3:
        return
    eul = Rotation.from_quat(quat_wxyz[:, [1, 2, 3, 0]]).as_euler(order, degrees=True)
    start = bvh.channel_start[j]
    cols = [start + k for k, c in enumerate(chans) if c.endswith("rotation")]
    frames[:, cols] = eul


def resample_bvh(bvh: BVHData, fps: float, frame_time: float | None = None) -> BVHData:
    """The clip resampled to ``fps`` over its own duration: rotations by spherical
    interpolation (scipy's ``Slerp``), position channels linearly.

    Args:
        bvh: the clip.
        fps: the new frame rate [Hz].
        frame_time: the clip's frame time to assume [s] (default its own; another value
            plays it faster or slower).
    """
    from scipy.spatial.transform import Rotation, Slerp

    dt = float(bvh.frame_time if frame_time is None else frame_time)
    n = bvh.num_frames
    t_old = np.arange(n) * dt
    t_new = np.arange(int(math.floor(t_old[-1] * fps + 1e-9)) + 1) / fps
    frames = np.empty((len(t_new), bvh.num_channels))
    for c in range(bvh.num_channels):  # positions (rotations overwritten below)
        frames[:, c] = np.interp(t_new, t_old, bvh.frames[:, c])
    q = bvh.local_rotations()
    for j in range(bvh.num_joints):
        if len(_euler_order(bvh.channels[j])) != 3:
            continue
        rot = Rotation.from_quat(q[:, j][:, [1, 2, 3, 0]])
        qn = Slerp(t_old, rot)(t_new).as_quat()[:, [3, 0, 1, 2]]
        _set_rotations(bvh, frames, j, qn)
    return _with_frames(bvh, frames, frame_time=1.0 / fps)


def _scale_translations(bvh: BVHData, frames: np.ndarray, joints: Sequence[int], k: float):
    """Scale the local translation (OFFSET and position channels) of ``joints`` by k;
    returns the new offsets."""
    offsets = bvh.offsets.copy()
    starts = bvh.channel_start
    for j in joints:
        offsets[j] *= k
        for i, c in enumerate(bvh.channels[j]):
            if c.endswith("position"):
                frames[:, starts[j] + i] *= k
    return offsets


def _root_columns(bvh: BVHData) -> list[int]:
    """Columns of the root's X, Y, Z position channels (in that order)."""
    ch = bvh.channels[0]
    cols = []
    for axis in ("Xposition", "Yposition", "Zposition"):
        if axis not in ch:
            raise VariantError(f"{bvh.source}: the root has no {axis} channel")
        cols.append(bvh.channel_start[0] + ch.index(axis))
    return cols


def _ground_and_hips(rig: _Rig, hips: str) -> tuple[float, float]:
    """The ground height (median lowest foot) and the median height of two hip / shoulder
    joints above it, along the file's up axis [file units]."""
    pos = rig.bvh.fk()
    up = pos @ rig.up
    feet = [rig.index(n) for n in ("lf_toe", "rf_toe", "lh_toe", "rh_toe") if n in rig.joints]
    ground = float(np.median(up[:, feet].min(axis=1)))
    pair = [rig.index(f"{s}{hips}") for s in ("l", "r")]
    return ground, float(np.median(up[:, pair].mean(axis=1))) - ground


def _legs(rig: _Rig, pairs: str, k: float, carry: bool, raise_from: str | None) -> BVHData:
    """Legs (``pairs``: ``fh``, ``f``, ``h``) below their hip / shoulder joints scaled by k.

    ``carry``: the root's horizontal travel scales alike; ``raise_from``: the root rises
    by (k − 1) × the median height of that joint pair (``f_shoulder``, ``h_hip``)."""
    bvh = rig.bvh
    frames = bvh.frames.copy()
    joints: list[int] = []
    for g in pairs:
        top = "shoulder" if g == "f" else "hip"
        for s in "lr":
            joints += rig.below(rig.index(f"{s}{g}_{top}"))
    lift = 0.0
    if raise_from is not None:
        _, h = _ground_and_hips(rig, raise_from)
        lift = (k - 1.0) * h
    offsets = _scale_translations(bvh, frames, joints, k)
    cols = _root_columns(bvh)
    root = frames[:, cols]
    if carry:
        flat = root - np.outer(root @ rig.up, rig.up)
        root = root + (k - 1.0) * (flat - flat[:1])
    frames[:, cols] = root + lift * rig.up
    return _with_frames(bvh, frames, offsets=offsets)


def _whole(rig: _Rig, k: float) -> BVHData:
    """Every length (offsets, position channels) times k."""
    bvh = rig.bvh
    frames = bvh.frames.copy()
    offsets = _scale_translations(bvh, frames, range(bvh.num_joints), k)
    return _with_frames(bvh, frames, offsets=offsets)


def _median_up_local(rig: _Rig, j: int) -> np.ndarray:
    """The file's up axis in joint ``j``'s local frame as the joint is held over the clip
    (its median global orientation), unit length."""
    _, glob = rig.bvh.fk(return_rotations=True)
    v = np.einsum("fba,b->fa", glob[:, j], rig.up)  # R^T up, per frame
    m = np.median(v, axis=0)
    return m / max(float(np.linalg.norm(m)), 1e-12)


def _hind_toe_shift(rig: _Rig, metres: float) -> BVHData:
    """The mapped hind toes (with all below them) moved ``metres`` up as they are held."""
    bvh = rig.bvh
    frames = bvh.frames.copy()
    offsets = bvh.offsets.copy()
    starts = bvh.channel_start
    for s in "lr":
        toe = rig.index(f"{s}h_toe")
        parent = bvh.parents[toe]
        d = _median_up_local(rig, parent) * metres / rig.scale
        offsets[toe] += d
        for i, c in enumerate(bvh.channels[toe]):
            if c.endswith("position"):
                frames[:, starts[toe] + i] += d["XYZ".index(c[0])]
    return _with_frames(bvh, frames, offsets=offsets)


def _hind_foot(rig: _Rig, k: float) -> BVHData:
    """The hind feet (the mapped toe's translation from the hock) times k."""
    bvh = rig.bvh
    frames = bvh.frames.copy()
    offsets = _scale_translations(bvh, frames, [rig.index(f"{s}h_toe") for s in "lr"], k)
    return _with_frames(bvh, frames, offsets=offsets)


def _noise(rig: _Rig) -> BVHData:
    """Seeded jitter on every rotation channel and the root position."""
    bvh = rig.bvh
    rng = np.random.default_rng(rig.seed)
    frames = bvh.frames.copy()
    rot = [
        bvh.channel_start[j] + i
        for j, ch in enumerate(bvh.channels)
        for i, c in enumerate(ch)
        if c.endswith("rotation")
    ]
    frames[:, rot] += rng.normal(0.0, NOISE_ROT_DEG, (bvh.num_frames, len(rot)))
    cols = _root_columns(bvh)
    frames[:, cols] += rng.normal(0.0, NOISE_ROOT_M / rig.scale, (bvh.num_frames, 3))
    return _with_frames(bvh, frames)


def _trim(rig: _Rig) -> BVHData:
    n = int(round(TRIM_S / rig.bvh.frame_time))
    if rig.bvh.num_frames <= n + 1:
        raise VariantError(f"{rig.bvh.source}: too short to trim {TRIM_S:g} s")
    return _with_frames(rig.bvh, rig.bvh.frames[n:])


def _pad(rig: _Rig) -> BVHData:
    n = int(round(TRIM_S / rig.bvh.frame_time))
    return _with_frames(
        rig.bvh, np.concatenate([np.repeat(rig.bvh.frames[:1], n, 0), rig.bvh.frames])
    )


def _z_up(rig: _Rig) -> BVHData:
    """The clip turned so that the file's up axis becomes +z (about the lateral axis)."""
    from scipy.spatial.transform import Rotation

    bvh = rig.bvh
    up = rig.up
    z = np.array([0.0, 0.0, 1.0])
    if abs(float(up @ z)) > 1 - 1e-9:
        rot = Rotation.identity() if up @ z > 0 else Rotation.from_rotvec(np.pi * rig.lateral)
    else:
        axis = np.cross(up, z)
        rot = Rotation.from_rotvec(axis / np.linalg.norm(axis) * np.arccos(float(up @ z)))
    frames = bvh.frames.copy()
    cols = _root_columns(bvh)
    frames[:, cols] = rot.apply(frames[:, cols])
    offsets = bvh.offsets.copy()
    offsets[0] = rot.apply(offsets[0])
    q = bvh.local_rotations()[:, 0]
    r0 = rot * Rotation.from_quat(q[:, [1, 2, 3, 0]])
    _set_rotations(bvh, frames, 0, r0.as_quat()[:, [3, 0, 1, 2]])
    return _with_frames(bvh, frames, offsets=offsets)


def _renamed(rig: _Rig) -> BVHData:
    names = tuple(f"Dog2:{n}" for n in rig.bvh.names)
    return dataclasses.replace(rig.bvh, names=names)


def _fps(rate: float) -> Callable[[_Rig], BVHData]:
    return lambda rig: resample_bvh(rig.bvh, rate)


def _speed(k: float) -> Callable[[_Rig], BVHData]:
    return lambda rig: resample_bvh(rig.bvh, rig.bvh.fps, rig.bvh.frame_time / k)


def _shifted(seconds: float) -> Callable[[np.ndarray], np.ndarray]:
    return lambda t: t + seconds


def _stretched(k: float) -> Callable[[np.ndarray], np.ndarray]:
    return lambda t: t / k


#: Every variant, by name (see the module docstring).
VARIANTS: dict[str, Variant] = {
    v.name: v
    for v in (
        Variant("original", "the clip as it is", lambda rig: rig.bvh),
        Variant("fps24", "resampled to 24 Hz", _fps(24.0)),
        Variant("fps30", "resampled to 30 Hz", _fps(30.0)),
        Variant("fps60", "resampled to 60 Hz", _fps(60.0)),
        Variant("slow", "played at 0.8× speed", _speed(0.8), _stretched(0.8)),
        Variant("fast", "played at 1.25× speed", _speed(1.25), _stretched(1.25)),
        Variant(
            "legs-long",
            "legs 1.2× as long, root raised and travel scaled",
            lambda rig: _legs(rig, "fh", 1.2, True, "h_hip"),
        ),
        Variant(
            "legs-short",
            "legs 0.85× as long, root lowered and travel scaled",
            lambda rig: _legs(rig, "fh", 0.85, True, "h_hip"),
        ),
        Variant(
            "hind-long",
            "hind legs 1.15× as long, root raised (fore toes above the ground)",
            lambda rig: _legs(rig, "h", 1.15, False, "h_hip"),
        ),
        Variant(
            "hind-short",
            "hind legs 0.87× as long, root kept (hind toes above the ground)",
            lambda rig: _legs(rig, "h", 0.87, False, None),
        ),
        Variant(
            "scale-small", "the whole animal and its travel 0.6×", lambda rig: _whole(rig, 0.6)
        ),
        Variant(
            "units-m",
            "written in metres",
            lambda rig: _whole(rig, rig.scale),
        ),
        Variant(
            "hind-toe-up",
            f"hind toe points {100 * TOE_SHIFT_M:g} cm higher",
            lambda rig: _hind_toe_shift(rig, TOE_SHIFT_M),
        ),
        Variant(
            "hind-toe-down",
            f"hind toe points {100 * TOE_SHIFT_M:g} cm lower",
            lambda rig: _hind_toe_shift(rig, -TOE_SHIFT_M),
        ),
        Variant("hind-foot-long", "hind feet 1.5× as long", lambda rig: _hind_foot(rig, 1.5)),
        Variant("hind-foot-short", "hind feet 0.6× as long", lambda rig: _hind_foot(rig, 0.6)),
        Variant(
            "noise",
            f"jitter: {NOISE_ROT_DEG:g}° per rotation channel, "
            f"{1000 * NOISE_ROOT_M:g} mm on the root (seeded)",
            _noise,
        ),
        Variant("trim", f"the first {TRIM_S:g} s cut off", _trim, _shifted(-TRIM_S)),
        Variant(
            "pad", f"the first frame held {TRIM_S:g} s before the clip", _pad, _shifted(TRIM_S)
        ),
        Variant("z-up", "turned to z up", _z_up),
        Variant("renamed", "joint names under a namespace (Dog2:…)", _renamed),
    )
}


def variant_names(names: Sequence[str] | None = None) -> list[str]:
    """The variants named (all of them when None or ``["all"]``), checked.

    Raises:
        VariantError: an unknown name (lists the known ones).
    """
    if not names or list(names) == ["all"]:
        return list(VARIANTS)
    bad = [n for n in names if n not in VARIANTS]
    if bad:
        raise VariantError(
            f"unknown variant(s) {', '.join(bad)}; valid: {', '.join(VARIANTS)} or all"
        )
    return list(dict.fromkeys(names))


def _rig(bvh: BVHData, seed: int) -> _Rig:
    from habitsim.bvh_mapping import auto_map, detect_frame

    joints = {k: v for k, v in auto_map(bvh).items() if v is not None}
    frame = detect_frame(bvh, joints)
    up, lateral = frame.matrix[2], frame.matrix[1]
    return _Rig(bvh, joints, up, lateral, float(frame.scale), int(seed))


def make_variant(bvh: BVHData, name: str, seed: int = 0) -> BVHData:
    """The variant ``name`` of a parsed clip (see the module docstring).

    Raises:
        VariantError: an unknown name, a clip the variant cannot be made of.
        SkeletonMappingError: a rig the automatic mapping cannot map (the variants that
            move legs need to know them).
    """
    (name,) = variant_names([name])
    out = VARIANTS[name].make(_rig(bvh, seed))
    return dataclasses.replace(out, source=f"{Path(bvh.source).stem}~{name}.bvh")


def variant_sources(
    files: Sequence[Path], names: Sequence[str], seed: int = 0, notes: list[str] | None = None
) -> list[tuple[str, BVHData]]:
    """The variants of every clip, as ``(name, parsed file)`` pairs named
    ``<clip>~<variant>.bvh``, clip by clip (for ``bench real --variants``). A clip that
    cannot be read or mapped, or a variant that cannot be made of it, is left out with a
    note in ``notes``.

    Raises:
        VariantError: an unknown variant name.
    """
    from habitsim.bvh_mapping import read_source

    wanted = variant_names(names)
    out = []
    for f in files:
        try:
            bvh = read_source(f)
            rig = _rig(bvh, seed)
        except HabitsimError as e:
            if notes is not None:
                notes.append(f"{Path(f).name}: no variants, {e}")
            continue
        for name in wanted:
            label = f"{Path(f).stem}~{name}.bvh"
            try:
                v = VARIANTS[name].make(rig)
            except HabitsimError as e:
                if notes is not None:
                    notes.append(f"{label}: skipped, {e}")
                continue
            out.append((label, dataclasses.replace(v, source=label)))
    return out


# ---------------------------------------------------------------------------- figures


@dataclass(frozen=True)
class VariantsOptions:
    """What a ``bench variants`` run does.

    Attributes:
        data: folder of BVH clips.
        clips: the clips' file names or stems to take (empty: every BVH clip).
        variants: the variants (empty: all).
        species: the skeleton the clips are imported onto.
        seed: seed of the noisy variants.
    """

    data: str | Path
    clips: tuple[str, ...] = ()
    variants: tuple[str, ...] = ()
    species: str = "dog"
    seed: int = 0


def _on_original_frames(
    contacts: np.ndarray, fps: float, times: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Labels (T, F) of a clip at ``fps`` sampled at ``times`` [s] (nearest frame), and
    the mask of the times inside the clip."""
    j = np.rint(times * fps).astype(int)
    ok = (j >= 0) & (j < contacts.shape[0])
    out = np.zeros((len(times), contacts.shape[1]), bool)
    out[ok] = contacts[j[ok]]
    return out, ok


def stance_row(
    original: Any, variant: Any, name: str, seconds: float | None = None
) -> dict[str, Any]:
    """The stance figures of one imported variant against the imported original.

    Args:
        original, variant: the imported motions (with stance labels).
        name: the variant's name (its time map).
        seconds: the time the import took [s].

    Returns:
        A row: ``variant``, ``fps``, ``frames``, ``duty`` (per foot LF, RF, LH, RH),
        ``duty_fore`` / ``duty_hind`` (means), ``under_two`` (share of frames with fewer
        than two feet down), ``f1`` (per foot, over the instants both clips hold),
        ``duty_change`` (largest per-foot change of the duty factor over those instants).
    """
    from habitsim.stance.labels import stance_f1

    c0 = np.asarray(original.contacts, bool)
    cv = np.asarray(variant.contacts, bool)
    t0 = np.arange(c0.shape[0]) / original.fps
    lab, ok = _on_original_frames(cv, variant.fps, VARIANTS[name].to_variant_time(t0))
    f1 = stance_f1(lab[ok], c0[ok])
    change = np.abs(lab[ok].mean(axis=0) - c0[ok].mean(axis=0))
    duty = cv.mean(axis=0)
    return {
        "variant": name,
        "fps": float(variant.fps),
        "frames": int(cv.shape[0]),
        "duty": [round(float(d), 4) for d in duty],
        "duty_fore": float(duty[:2].mean()),
        "duty_hind": float(duty[2:].mean()),
        "under_two": float((cv.sum(axis=1) < 2).mean()),
        "f1": [round(float(x), 4) for x in f1],
        "duty_change": float(change.max()),
        "time_import_s": seconds,
    }


def _clip_files(options: VariantsOptions) -> list[Path]:
    d = Path(options.data)
    if not d.is_dir():
        raise VariantError(f"--data {d}: not a folder")
    files = sorted(p for p in d.iterdir() if p.suffix.lower() == ".bvh")
    if options.clips:
        want = set(options.clips)
        files = [p for p in files if p.name in want or p.stem in want]
    if not files:
        raise VariantError(
            f"--data {d}: no BVH clip"
            + (f" named {', '.join(options.clips)}" if options.clips else "")
        )
    return files


def run(
    options: VariantsOptions, on_row: Callable[[dict[str, Any]], None] | None = None
) -> list[dict[str, Any]]:
    """Import every clip and every variant of it; one :func:`stance_row` per pair (with
    ``clip``), or ``status = "error"`` and ``note`` where a variant fails.

    Raises:
        VariantError: bad options, no clip.
    """
    import time

    from habitsim.bvh import read_bvh
    from habitsim.bvh_mapping import import_bvh

    names = variant_names(options.variants)
    rows = []
    for f in _clip_files(options):
        bvh = read_bvh(f)
        original, _ = import_bvh(bvh, options.species)
        for name in names:
            t = time.perf_counter()
            row: dict[str, Any]
            try:
                v = make_variant(bvh, name, options.seed)
                motion, _ = import_bvh(v, options.species)
                row = {"clip": f.stem, "status": "ok", "note": ""}
                row.update(stance_row(original, motion, name, time.perf_counter() - t))
            except HabitsimError as e:
                row = {"clip": f.stem, "variant": name, "status": "error", "note": str(e)}
            rows.append(row)
            if on_row is not None:
                on_row(row)
    return rows


def evaluate_targets(rows: Sequence[dict[str, Any]]) -> list[TargetCheck]:
    """The targets: every variant imports, its stance F1 against the original ≥
    :data:`MIN_STANCE_F1` on every foot, and no foot's duty factor moves more than
    :data:`MAX_DUTY_CHANGE`."""
    ok = [r for r in rows if r.get("status") == "ok"]
    n = len(rows)
    good_f1 = [r for r in ok if min(r["f1"]) >= MIN_STANCE_F1]
    good_duty = [r for r in ok if r["duty_change"] <= MAX_DUTY_CHANGE]
    worst_f1 = min((min(r["f1"]) for r in ok), default=None)
    worst_duty = max((r["duty_change"] for r in ok), default=None)
    return [
        TargetCheck(
            "variants imported",
            len(ok) / n if n else None,
            f"{len(ok)} of {n}",
            "all",
            verdict(len(ok) == n if n else None),
        ),
        TargetCheck(
            "stance F1 against the original, every foot",
            worst_f1,
            "-" if worst_f1 is None else f"{len(good_f1)} of {len(ok)} (worst {worst_f1:.3f})",
            f"≥ {MIN_STANCE_F1} on all",
            verdict(None if not ok else len(good_f1) == len(ok)),
        ),
        TargetCheck(
            "duty factor change, every foot",
            worst_duty,
            "-"
            if worst_duty is None
            else f"{len(good_duty)} of {len(ok)} (worst {worst_duty:.3f})",
            f"≤ {MAX_DUTY_CHANGE} on all",
            verdict(None if not ok else len(good_duty) == len(ok)),
        ),
    ]
