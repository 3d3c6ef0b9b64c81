"""The file's frame: units, up and forward axes, and the conversion to habitsim's frame
(:class:`FrameConversion`, found by :func:`detect_frame`)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from ..bvh import BVHData
from ..errors import SkeletonMappingError
from ..species import Species, load_species
from .chains import _LEG_CHAINS
from .clip_cues import up_scores
from .options import MappingOptions
from .tree import _Tree

#: Known length units of BVH files and their size in metres.
UNIT_SCALES: dict[str, float] = {"m": 1.0, "cm": 0.01, "mm": 0.001, "in": 0.0254}
#: The units the detection chooses among. Inches are given explicitly (``units="in"``):
#: a leg of N inches is a plausible leg in centimetres too, and nothing in a file tells
#: the two apart.
DETECTED_UNITS: tuple[str, ...] = ("m", "cm", "mm")


def _axis_vector(axis: str) -> np.ndarray:
    v = np.zeros(3)
    v["xyz".index(axis[-1])] = -1.0 if axis.startswith("-") else 1.0
    return v


def _axis_name(v: np.ndarray) -> str:
    k = int(np.argmax(np.abs(v)))
    return ("-" if v[k] < 0 else "+") + "xyz"[k]


@dataclass(frozen=True)
class UpEvidence:
    """What decided a file's up axis (:func:`find_up`).

    Attributes:
        axis: the up axis chosen, ``"+y"`` style.
        source: ``"given"`` (by the caller), ``"feet"`` (the feet over the clip),
            ``"rest pose"`` or ``"names"`` (tie-breakers where the clip was unsure).
        margin: the chosen axis's score lead over the best other axis on the clip [leg
            lengths] (0 when given).
        unsure: the clip's evidence was weak (lead below
            :attr:`MappingOptions.up_margin`).
        runner_up: the best other axis on the clip.
        rest_axis: the best axis of the rest pose, None where the rest pose is no
            evidence (not a standing pose, :attr:`MappingOptions.standing_score`, or
            its own lead below the margin).
    """

    axis: str
    source: str = "given"
    margin: float = 0.0
    unsure: bool = False
    runner_up: str | None = None
    rest_axis: str | None = None

    def describe(self) -> str:
        """The evidence in words, for the mapping's notes."""
        if self.source == "given":
            return f"up {self.axis} given"
        if self.unsure:
            text = (
                f"up axis unsure: {self.axis} leads {self.runner_up} by only "
                f"{self.margin:.2f} leg lengths on the feet over the clip; {self.axis} taken "
                f"from the {'feet' if self.source == 'feet' else self.source}; "
                "check it and pass --up if wrong"
            )
        else:
            text = (
                f"up {self.axis} from the feet over the clip (lead {self.margin:.2f} leg "
                f"lengths over {self.runner_up})"
            )
        if self.rest_axis is not None and self.rest_axis != self.axis:
            text += f"; the rest pose suggests {self.rest_axis}"
        elif self.rest_axis == self.axis and self.source != "rest pose":
            text += "; the rest pose agrees"
        return text


def find_up(
    pos: np.ndarray,
    rest: np.ndarray,
    feet: list[int],
    body: list[int],
    leg: float,
    names_axis: str | None = None,
    options: MappingOptions | None = None,
) -> UpEvidence:
    """The up axis from where the feet are over the clip, checked against the rest pose.

    Each signed axis is scored by :func:`~habitsim.bvh_mapping.clip_cues.up_scores`
    (the body above the feet, the feet's low heights on one plane). The best axis wins
    when it leads every other by :attr:`MappingOptions.up_margin`; otherwise, among the
    axes within that margin of the best, the rest pose's best axis, then ``names_axis``
    (the pelvis above the feet the names mapped), then the clip's best is taken, and the
    evidence is marked unsure.

    Args:
        pos: (F, J, 3) joint positions over the clip [file units].
        rest: (1, J, 3) the rest pose.
        feet: the feet's joints (the leg chains' tips).
        body: the joints the legs hang from.
        leg: the leg length [file units].
        names_axis: the tie-breaker from the names, if any.
        options: the mapping's knobs.
    """
    opt = options or MappingOptions()
    scale = max(leg, 1e-9)
    clip = up_scores(pos, feet, body, scale, opt.low_percentile)
    ranked = sorted(clip, key=lambda a: -clip[a])
    best, second = ranked[0], ranked[1]
    margin = clip[best] - clip[second]
    rest_s = up_scores(rest, feet, body, scale, opt.low_percentile)
    r_ranked = sorted(rest_s, key=lambda a: -rest_s[a])
    rest_axis = (
        r_ranked[0]
        if rest_s[r_ranked[0]] >= opt.standing_score
        and rest_s[r_ranked[0]] - rest_s[r_ranked[1]] >= opt.up_margin
        else None
    )
    if margin >= opt.up_margin:
        return UpEvidence(best, "feet", round(margin, 3), False, second, rest_axis)
    near = [a for a in ranked if clip[best] - clip[a] < opt.up_margin]
    if rest_axis in near:
        axis, source = rest_axis, "rest pose"
    elif names_axis in near:
        axis, source = names_axis, "names"
    else:
        axis, source = best, "feet"
    other = next(a for a in ranked if a != axis)
    lead = clip[axis] - clip[other]
    return UpEvidence(axis, source, round(lead, 3), True, other, rest_axis)


@dataclass(frozen=True)
class FrameConversion:
    """Conversion of file coordinates to habitsim's frame (z up, x forward, metres).

    Attributes:
        scale: size of one file unit [m].
        units: ``"m"``, ``"cm"``, ``"mm"`` or ``"x<scale>"`` for a custom scale.
        up: the file's up axis, ``"+y"`` style.
        forward: the file's forward axis (perpendicular to ``up``).
        matrix: (3, 3) rotation whose rows are the file's forward, left and up axes, so
            habitsim = scale · matrix @ file.
        up_evidence: what decided the up axis (:class:`UpEvidence`).
    """

    scale: float
    units: str
    up: str
    forward: str
    matrix: np.ndarray
    up_evidence: UpEvidence | None = None

    @classmethod
    def from_axes(
        cls,
        scale: float,
        units: str,
        up: str,
        forward: str,
        up_evidence: UpEvidence | None = None,
    ) -> FrameConversion:
        u, f = _axis_vector(up), _axis_vector(forward)
        if abs(float(u @ f)) > 1e-9:
            raise SkeletonMappingError(f"forward axis {forward} is not perpendicular to up {up}")
        left = np.cross(u, f)
        return cls(scale, units, up, forward, np.stack([f, left, u]), up_evidence)

    @property
    def left(self) -> str:
        """The file axis that becomes habitsim's +y (left)."""
        return _axis_name(self.matrix[1])

    def apply(self, points: np.ndarray) -> np.ndarray:
        """Convert points (…, 3) from file units/axes to habitsim's frame [m]."""
        return self.scale * np.asarray(points, dtype=np.float64) @ self.matrix.T

    def describe(self) -> str:
        return (
            f"units {self.units} (x{self.scale:g} to m), up {self.up}, forward {self.forward}, "
            f"left {self.left}"
        )


def _parse_up(up: str) -> str:
    u = str(up).strip().lower()
    if u in ("x", "y", "z"):
        u = "+" + u
    if len(u) != 2 or u[0] not in "+-" or u[1] not in "xyz":
        raise SkeletonMappingError(
            f"unknown up axis {up!r}; valid: x, y, z (optionally signed, e.g. -y)"
        )
    return u


def _parse_units(units: str | float) -> tuple[float, str]:
    if isinstance(units, int | float) and not isinstance(units, bool):
        if not math.isfinite(units) or units <= 0:
            raise SkeletonMappingError(
                f"unit scale must be a positive number of metres, got {units}"
            )
        return float(units), f"x{units:g}"
    u = str(units).strip().lower()
    if u not in UNIT_SCALES:
        raise SkeletonMappingError(f"unknown units {units!r}; valid: {', '.join(UNIT_SCALES)}")
    return UNIT_SCALES[u], u


def _leg_ends(joints: Mapping[str, str | None], bvh: BVHData) -> list[int]:
    out = []
    for chain in _LEG_CHAINS.values():
        src = [s for n in chain if (s := joints.get(n))]
        if src:
            out.append(bvh.index(src[-1]))
    return out


def _leg_roots(joints: Mapping[str, str | None], bvh: BVHData) -> list[int]:
    """The first mapped joint of each leg chain that has one (as :func:`_leg_ends`)."""
    out = []
    for chain in _LEG_CHAINS.values():
        src = [s for n in chain if (s := joints.get(n))]
        if src:
            out.append(bvh.index(src[0]))
    return out


def _forward_joint(joints: Mapping[str, str | None]) -> str | None:
    for n in ("spine3", "spine2", "spine1", "neck", "head", "snout"):
        if joints.get(n):
            return joints[n]
    return None


def detect_frame(
    bvh: BVHData,
    joints: Mapping[str, str | None],
    units: str | float | None = None,
    up: str | None = None,
    species: str | Species | None = None,
    options: MappingOptions | None = None,
) -> FrameConversion:
    """Units, up and forward axis of a BVH file, as a conversion to habitsim's frame.

    * units: explicit, else the candidate (m, cm, mm) that makes the source's hind-leg
      length (hip joint to toe along the bones) a plausible animal leg (0.02–4 m); if
      several or none are plausible, the one closest (in log scale) to the species' leg
      length (default: 0.5 m).
    * up: explicit, else from where the feet (most distal mapped leg joints) are over
      the whole clip, checked against the rest pose (:func:`find_up`); the direction
      from the feet to the hips (what the names mapped) breaks a tie.
    * forward: the coordinate axis perpendicular to up closest to the hips → chest
      direction in the first frame (rest pose as a fallback).

    Args:
        bvh: the source file.
        joints: habitsim → source mapping (at least ``pelvis``; legs and a spine/neck/
            head joint unless ``up`` is given and forward can be found).
        units: ``"m"``, ``"cm"``, ``"mm"``, a scale in metres per unit, or None to detect.
        up: ``"y"``, ``"z"``, ``"-y"``… or None to detect.
        species: target species (for unit detection).
        options: the mapping's knobs (the up axis's margin).

    Returns:
        The :class:`FrameConversion`.

    Raises:
        SkeletonMappingError: unknown units / axis names, or too few mapped joints to
            detect what was not given.
    """
    hips_name = joints.get("pelvis")
    if not hips_name:
        raise SkeletonMappingError("cannot detect the file's frame without a pelvis (hips) joint")
    hips = bvh.index(hips_name)
    t = _Tree(bvh)
    pos = bvh.fk()
    rest = bvh.fk(rest=True)
    feet = _leg_ends(joints, bvh)

    # Units.
    if units is not None:
        scale, uname = _parse_units(units)
    else:
        leg = None
        target = 0.5
        sp = load_species(species) if species is not None else None
        for a, b, fore in (
            ("lh_hip", "lh_toe", False),
            ("rh_hip", "rh_toe", False),
            ("lf_shoulder", "lf_toe", True),
            ("rf_shoulder", "rf_toe", True),
            ("lh_hip", "lh_hock", False),
            ("lf_shoulder", "lf_wrist", True),
        ):
            ja, jb = joints.get(a), joints.get(b)
            if ja and jb:
                leg = t.path_length(bvh.index(ja), bvh.index(jb))
                if sp is not None:
                    target = sp.fore_leg_length if fore else sp.hind_leg_length
                    if b.endswith(("hock", "wrist")):
                        seg = sp.segments
                        target -= seg["fore_foot"] if fore else seg["hind_foot"]
                break
        if leg is None or leg <= 0:
            ext = pos[0].max(axis=0) - pos[0].min(axis=0)
            leg = float(ext.max()) / 2.0
        if not (math.isfinite(leg) and leg > 0):
            raise SkeletonMappingError(
                "cannot detect the file's units: the skeleton has no size (every joint at "
                "the same place in the first frame); pass units='m', 'cm' or 'mm' (--units)"
            )
        plausible = [u for u in DETECTED_UNITS if 0.02 <= leg * UNIT_SCALES[u] <= 4.0]
        if len(plausible) == 1:
            uname = plausible[0]
        else:
            uname = min(DETECTED_UNITS, key=lambda u: abs(math.log(leg * UNIT_SCALES[u] / target)))
        scale = UNIT_SCALES[uname]

    # Up.
    if up is not None:
        up_ax = _parse_up(up)
        evidence = UpEvidence(up_ax)
    else:
        if not feet:
            raise SkeletonMappingError(
                "cannot detect the up axis: no leg joints are mapped; pass up='y' or 'z' (--up)"
            )
        v = (pos[:, hips] - pos[:, feet].mean(axis=1)).mean(axis=0)
        if np.linalg.norm(v) < 1e-9:
            v = rest[0, hips] - rest[0, feet].mean(axis=0)
        names_axis = _axis_name(v) if np.linalg.norm(v) >= 1e-9 else None
        roots = _leg_roots(joints, bvh)
        leg_len = float(np.mean([t.path_length(r, f) for r, f in zip(roots, feet, strict=True)]))
        if leg_len <= 0:
            raise SkeletonMappingError(
                "cannot detect the up axis: no mapped leg reaches from its hip or shoulder "
                "to a lower joint (a leg needs at least two mapped joints); map them, or pass "
                "up='y' or 'z' (--up)"
            )
        evidence = find_up(pos, rest, feet, roots, leg_len, names_axis, options)
        up_ax = evidence.axis
    u_vec = _axis_vector(up_ax)

    # Forward.
    fwd_vec = None
    fname = _forward_joint(joints)
    cands: list[np.ndarray] = []
    if fname:
        c = bvh.index(fname)
        cands += [pos[0, c] - pos[0, hips], rest[0, c] - rest[0, hips]]
    tail = joints.get("tail1") or joints.get("tail2")
    if tail:
        c = bvh.index(tail)
        cands += [pos[0, hips] - pos[0, c]]
    for v in cands:
        h = v - (v @ u_vec) * u_vec
        if np.linalg.norm(h) > 1e-6 * max(1.0, float(np.linalg.norm(v))):
            fwd_vec = h
            break
    if fwd_vec is None:
        raise SkeletonMappingError(
            "cannot detect the forward axis: map a spine, neck or head joint ahead of the pelvis"
        )
    fwd_vec = fwd_vec.copy()
    fwd_vec[int(np.argmax(np.abs(u_vec)))] = 0.0
    return FrameConversion.from_axes(scale, uname, up_ax, _axis_name(fwd_vec), evidence)
