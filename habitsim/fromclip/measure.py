"""What a clip's rig shows of the animal's body (:func:`measure_rig`): segment lengths of
the legs, spine, neck, head and tail, the standing inclination of each leg segment, the
hip and shoulder heights on the stance frames, and the carriage of neck, head and tail.

The rig is mapped onto the habitsim chains by the importer's own mapping
(:func:`habitsim.bvh_mapping.map_joints`: legs, spine, neck, tail, units, up axis).
A segment is the distance between two mapped joints summed over the rig's bones between
them, as posed in each frame (so animated translations and glTF node scales count), the
median over the frames. A span whose middle joint is not mapped (a leg without a
collarbone joint, say) is measured whole and split later by a catalog species'
proportions (:mod:`habitsim.fromclip.draft`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..bvh import BVHData
from ..bvh_mapping import JointMapping, map_joints
from ..errors import ClipMeasureError
from .options import FromClipOptions

__all__ = ["LEG_SEGMENTS", "RigMeasure", "measure_rig"]

#: The leg segments of each limb in chain order, with the habitsim joints that bound them.
LEG_SEGMENTS: dict[str, tuple[tuple[str, str, str], ...]] = {
    "fore": (
        ("girdle", "scapula", "shoulder"),
        ("upper", "shoulder", "elbow"),
        ("lower", "elbow", "wrist"),
        ("foot", "wrist", "toe"),
    ),
    "hind": (
        ("girdle", "ilium", "hip"),
        ("upper", "hip", "knee"),
        ("lower", "knee", "hock"),
        ("foot", "hock", "toe"),
    ),
}
_SIDES = {"fore": ("lf", "rf"), "hind": ("lh", "rh")}
_TOP = {"fore": "shoulder", "hind": "hip"}


@dataclass(frozen=True)
class Span:
    """A measured stretch of one limb between two mapped joints.

    Attributes:
        segments: the segments it covers, in chain order (e.g. ``("upper", "lower")``).
        length: its length [m] (mean of the left and right legs).
        inclination: its standing inclination from the downward vertical [rad],
            positive = distal end ahead.
        measured: False where it ends at a tip a glTF reader made up (an End Site a
            fixed share of the last bone long): its length is then no measurement.
    """

    segments: tuple[str, ...]
    length: float
    inclination: float
    measured: bool = True


@dataclass(frozen=True)
class RigMeasure:
    """The body a clip shows.

    Attributes:
        source: the clip file's name.
        mapping: the joint mapping used (its frame: units, up axis).
        frames: the clip's frame count; fps its rate [Hz].
        spans: per limb (``fore``, ``hind``), the measured spans top to toe.
        trunk: pelvis to withers along the rig's spine [m].
        trunk_width_fore, trunk_width_hind: left-right distance of the shoulder /
            hip joints [m] (None: not measured).
        neck, head, tail: lengths [m] (None: the rig has no such chain).
        hip_height, shoulder_height: median height of the hip / shoulder joints over the
            ground on the frames that leg stands [m].
        neck_elevation, head_pitch, tail_carriage: median carriage [rad] (elevation
            above the horizontal, positive = up; None: not measured).
        stance_frames: per leg (``lf``…), frames it stands.
        measured: every measured length by name [m] (for the report).
    """

    source: str
    mapping: JointMapping
    frames: int
    fps: float
    spans: dict[str, tuple[Span, ...]]
    trunk: float
    trunk_width_fore: float | None
    trunk_width_hind: float | None
    neck: float | None
    head: float | None
    tail: float | None
    hip_height: float
    shoulder_height: float
    neck_elevation: float | None
    head_pitch: float | None
    tail_carriage: float | None
    stance_frames: dict[str, int]
    measured: dict[str, float] = field(default_factory=dict)

    def leg_length(self, limb: str) -> float:
        """Top (shoulder / hip) joint to toe of ``limb`` [m] (girdle left out)."""
        return sum(s.length for s in self.spans[limb] if "girdle" not in s.segments)


def _path(parents: tuple[int, ...], a: int, b: int) -> list[int] | None:
    """Joints from ``b`` up to (not including) ``a`` when ``b`` descends from ``a``."""
    out, j = [], b
    while j >= 0 and j != a:
        out.append(j)
        j = parents[j]
    return out if j == a else None


def _lengths(pos: np.ndarray, parents: tuple[int, ...], a: int, b: int) -> np.ndarray:
    """(F,) length of the rig's bones from joint ``a`` to ``b`` per frame [m]."""
    path = _path(parents, a, b)
    if path is None:  # not one chain: the straight distance
        return np.asarray(np.linalg.norm(pos[:, b] - pos[:, a], axis=-1))
    return np.sum([np.linalg.norm(pos[:, j] - pos[:, parents[j]], axis=-1) for j in path], axis=0)


def _elevation(d: np.ndarray, fwd: np.ndarray) -> np.ndarray:
    """(F,) elevation above the horizontal [rad] of vectors ``d`` (F, 3) in the sagittal
    plane of the heading ``fwd`` (F, 3)."""
    return np.arctan2(d[:, 2], np.sum(d * fwd, axis=-1))


def measure_rig(
    bvh: BVHData,
    joint_map: str | Path | Mapping[str, str] | None = None,
    units: str | float | None = None,
    up: str | None = None,
    options: FromClipOptions | None = None,
) -> RigMeasure:
    """Measure the body a motion-capture clip shows.

    Args:
        bvh: the clip (a BVH file or a glTF animation read by
            :func:`habitsim.bvh_mapping.read_source`).
        joint_map, units, up: as :func:`habitsim.bvh_mapping.map_joints` takes them.
        options: the knobs (:class:`FromClipOptions`).

    Returns:
        The :class:`RigMeasure`.

    Raises:
        ClipMeasureError: ``code`` ``"short"`` (fewer than ``min_frames`` frames or
            ``min_duration_s`` seconds), ``"legs"`` (a leg without its top joint, its toe
            and a joint between them mapped), ``"body"`` (no spine, neck or head joint
            ahead of the hips, or a zero-length segment).
        SkeletonMappingError: from the mapping.
    """
    o = options or FromClipOptions()
    duration = bvh.num_frames / bvh.fps
    if bvh.num_frames < o.min_frames or duration < o.min_duration_s:
        raise ClipMeasureError(
            "short",
            f"{bvh.source}: {bvh.num_frames} frames ({duration:.2f} s) are too few to show a "
            f"stride; a clip needs at least {o.min_frames} frames and {o.min_duration_s:g} s "
            "of the animal walking or standing",
        )
    mapping = map_joints(bvh, None, joint_map=joint_map, units=units, up=up)
    j2s = mapping.mapped()
    missing = []
    for limb, sides in _SIDES.items():
        for side in sides:
            have = [
                j
                for j in ("scapula", "ilium", _TOP[limb], "elbow", "knee", "wrist", "hock")
                if f"{side}_{j}" in j2s
            ]
            if f"{side}_{_TOP[limb]}" not in j2s or f"{side}_toe" not in j2s or len(have) < 2:
                missing.append(side)
    if missing:
        raise ClipMeasureError(
            "legs",
            f"{bvh.source}: the legs {', '.join(missing)} were not found (each leg needs its "
            "shoulder or hip, a joint below it and its toe mapped; found: "
            f"{', '.join(sorted(j2s)) or 'nothing'}); name the joints with a --map file "
            "(see 'habitsim data inspect-bvh')",
        )
    assert mapping.frame is not None
    pos = mapping.frame.apply(bvh.fk())  # (F, J, 3) metres, z up, x forward
    par = bvh.parents
    made_up = Path(bvh.source).suffix.lower() in (".glb", ".gltf")  # End Sites are made up

    def real(name: str) -> bool:
        return not (made_up and bvh.is_end_site[bvh.index(j2s[name])])

    def idx(name: str) -> int:
        return bvh.index(j2s[name])

    withers = next((n for n in ("spine3", "spine2", "spine1", "neck", "head") if n in j2s), None)
    if withers is None:
        raise ClipMeasureError(
            "body",
            f"{bvh.source}: no spine, neck or head joint ahead of the hips is mapped; map "
            "spine3 (the withers) with a --map file",
        )
    hips = pos[:, idx("pelvis")]
    fwd = pos[:, idx(withers)] - hips
    fwd[:, 2] = 0.0
    norm = np.linalg.norm(fwd, axis=-1, keepdims=True)
    fwd = np.where(norm > 1e-9, fwd / np.maximum(norm, 1e-12), np.array([1.0, 0.0, 0.0]))
    left = np.cross(np.array([0.0, 0.0, 1.0]), fwd)

    toes = {s: pos[:, idx(f"{s}_toe")] for sides in _SIDES.values() for s in sides}
    ground = float(np.percentile([t[:, 2] for t in toes.values()], o.ground_percentile))
    hind_len = float(np.median(np.linalg.norm(hips - toes["lh"], axis=-1)))  # a first scale
    stand = {
        s: (t[:, 2] - ground) < o.stance_height_share * max(hind_len, 1e-6) for s, t in toes.items()
    }
    stand = {s: (m if m.any() else np.ones_like(m)) for s, m in stand.items()}

    spans: dict[str, tuple[Span, ...]] = {}
    measured: dict[str, float] = {}
    for limb, segs in LEG_SEGMENTS.items():
        chain = [segs[0][1], *(s[2] for s in segs)]  # girdle root … toe
        per_side: list[list[tuple[tuple[str, ...], float, float, bool]]] = []
        for side in _SIDES[limb]:
            joints = [j for j in chain if f"{side}_{j}" in j2s]
            rows = []
            for a, b in zip(joints[:-1], joints[1:], strict=True):
                ia, ib = idx(f"{side}_{a}"), idx(f"{side}_{b}")
                cover = tuple(
                    s[0]
                    for s in segs
                    if chain.index(s[1]) >= chain.index(a) and chain.index(s[2]) <= chain.index(b)
                )
                length = float(np.median(_lengths(pos, par, ia, ib)))
                d = pos[:, ib] - pos[:, ia]
                incl = np.arctan2(np.sum(d * fwd, axis=-1), -d[:, 2])[stand[side]]
                rows.append((cover, length, float(np.median(incl)), real(f"{side}_{b}")))
            per_side.append(rows)
        if [r[0] for r in per_side[0]] != [r[0] for r in per_side[1]]:
            # left and right mapped differently: keep the side with more joints
            per_side = [max(per_side, key=len)] * 2
        spans[limb] = tuple(
            Span(a[0], 0.5 * (a[1] + b[1]), 0.5 * (a[2] + b[2]), a[3] and b[3])
            for a, b in zip(per_side[0], per_side[1], strict=True)
        )
        for sp in spans[limb]:
            if sp.measured:
                measured[f"{limb}_{'+'.join(sp.segments)}"] = sp.length
    for limb, sp_list in spans.items():
        bad = [s for s in sp_list if s.length <= 1e-6]
        if bad:
            raise ClipMeasureError(
                "body",
                f"{bvh.source}: the {limb} leg's {'+'.join(bad[0].segments)} has zero length; "
                "map joints that are apart (--map)",
            )

    def height(side: str, joint: str) -> float:
        return float(np.median(pos[stand[side], idx(f"{side}_{joint}"), 2]) - ground)

    hip_h = 0.5 * (height("lh", "hip") + height("rh", "hip"))
    sh_h = 0.5 * (height("lf", "shoulder") + height("rf", "shoulder"))

    def width(a: str, b: str) -> float | None:
        if a not in j2s or b not in j2s:
            return None
        w = float(np.median(np.abs(np.sum((pos[:, idx(a)] - pos[:, idx(b)]) * left, axis=-1))))
        return w if w > 1e-6 else None

    # the withers: spine3, else the joint the fore legs hang from
    fore_top = next(j for j in ("lf_scapula", "lf_shoulder") if j in j2s)
    end = idx("spine3") if "spine3" in j2s else par[idx(fore_top)]
    trunk = float(np.median(_lengths(pos, par, idx("pelvis"), end)))
    if trunk <= 1e-6:
        raise ClipMeasureError(
            "body",
            f"{bvh.source}: the hips and the withers coincide (no spine between the fore and "
            "hind legs); map pelvis and spine3 to joints apart (--map)",
        )
    neck = head = tail = None
    neck_el = head_p = tail_c = None
    if "head" in j2s:
        neck = float(np.median(_lengths(pos, par, end, idx("head"))))
        neck_el = float(np.median(_elevation(pos[:, idx("head")] - pos[:, end], fwd)))
        if "snout" in j2s and real("snout"):
            head = float(np.median(_lengths(pos, par, idx("head"), idx("snout"))))
            head_p = float(np.median(_elevation(pos[:, idx("snout")] - pos[:, idx("head")], fwd)))
    tail_top = next((n for n in ("tail1", "tail2") if n in j2s), None)
    tail_end = next((n for n in ("tail3", "tail2") if n in j2s and n != tail_top and real(n)), None)
    if tail_top and tail_end:
        factor = 1.0 if (tail_top, tail_end) == ("tail1", "tail3") else 2.0
        tail = factor * float(np.median(_lengths(pos, par, idx(tail_top), idx(tail_end))))
        back = pos[:, idx(tail_end)] - pos[:, idx(tail_top)]
        tail_c = float(np.median(np.arctan2(back[:, 2], -np.sum(back * fwd, axis=-1))))
    for k, v in (("trunk", trunk), ("neck", neck), ("head", head), ("tail", tail)):
        if v is not None and v > 1e-6:
            measured[k] = v
    return RigMeasure(
        source=bvh.source,
        mapping=mapping,
        frames=bvh.num_frames,
        fps=bvh.fps,
        spans=spans,
        trunk=trunk,
        trunk_width_fore=width("lf_shoulder", "rf_shoulder"),
        trunk_width_hind=width("lh_hip", "rh_hip"),
        neck=neck if neck and neck > 1e-6 else None,
        head=head if head and head > 1e-6 else None,
        tail=tail if tail and tail > 1e-6 else None,
        hip_height=hip_h,
        shoulder_height=sh_h,
        neck_elevation=neck_el,
        head_pitch=head_p,
        tail_carriage=tail_c,
        stance_frames={s: int(m.sum()) for s, m in stand.items()},
        measured=measured,
    )
