"""Map a BVH skeleton onto a species' habitsim skeleton and retarget its motion.

Pipeline of :func:`import_bvh`:

1. Read the file (:func:`habitsim.bvh.read_bvh`).
2. A file written by :func:`habitsim.bvh.write_bvh` (joint names and hierarchy identical to
   the habitsim skeleton) is imported as an *identity* mapping: rotations and root
   translation are copied, no retargeting.
3. Otherwise find the joint mapping, either from an explicit joint-map TOML
   (:func:`load_joint_map`) or automatically from names and hierarchy
   (:func:`auto_map`): the four legs (left/right name cues, fore/hind from name cues and
   from where they hang: legs hanging from the hips are hind legs, legs hanging from the
   chest are fore legs; unnamed symmetric chains are accepted too and sided by geometry),
   the hips (where the hind legs hang), the spine chain from the hips to the chest (where
   the fore legs hang), neck and head beyond the chest, and the tail from the hips.
4. Detect the file's frame (:func:`detect_frame`): units (cm / m / mm, from the hind-leg
   length against the species'), up axis (from the feet toward the hips, averaged over the
   clip) and forward axis (from the hips toward the chest in the first frame, snapped to
   a coordinate axis), giving a proper rotation to habitsim's frame (z up, x forward, y left).
5. Retarget (:func:`retarget`): the source's global joint positions are converted to
   habitsim's frame; the pelvis takes the source hips' frame (heading along hips → chest,
   up from the world up); then, root to leaf, every habitsim joint that drives a bone of
   its chain gets the shortest-arc rotation that points that bone along the world
   direction between the corresponding mapped source joints. Joints whose bone has no
   mapped counterpart keep the species' standing pose; end points get identity. The root
   translation is scaled by species hip height / source hip height (heights above the
   source's ground, estimated as the median lowest foot height).

The retargeted rotations are general quaternions (no hinge projection; that is done
downstream).
"""

from __future__ import annotations

import json
import math
import re
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .bvh import BVHData, read_bvh
from .errors import SkeletonMappingError
from .motion import Motion
from .rotations import matrix_to_quat, quat_fix_continuity, quat_identity, quat_to_matrix
from .skeleton import JOINT_NAMES, PARENTS, get_skeleton
from .species import Species, load_species
from .stance.labels import stance_f1
from .stance.planting import (
    FOOT_ANCHORS,
    SourceStance,
    label_source_stance,
    plant_legs,
    smooth_path,
)

__all__ = [
    "UNIT_SCALES",
    "FrameConversion",
    "JointMapping",
    "name_cues",
    "auto_map",
    "load_joint_map",
    "validate_joint_map",
    "detect_frame",
    "is_habitsim_bvh",
    "retarget",
    "import_bvh",
    "read_source",
    "SOURCE_SUFFIXES",
    "CONFIDENCE_CHECKS",
    "CONFIDENCE_WARN",
    "is_helper_name",
    "describe_hierarchy",
]

#: The checks behind a leg's mapping confidence (each scores 0, 0.5 or 1; the mean counts).
CONFIDENCE_CHECKS = (
    "names: the chain's joint names say fore / hind as the leg it was mapped to (0.5: no "
    "cue; 1 for a hand-made map)",
    "symmetry: its left/right partner has the same number of joints and a length within "
    "10 % (0.5: within 25 %)",
    "ground: the foot rests on the ground (floor within 10 % of leg length of the lowest "
    "foot's) and has stance frames",
)
#: Legs whose confidence is below this are reported as warnings.
CONFIDENCE_WARN = 0.67

#: Known length units of BVH files and their size in metres.
UNIT_SCALES: dict[str, float] = {"m": 1.0, "cm": 0.01, "mm": 0.001, "in": 0.0254}
#: The units the detection chooses among. Inches are given explicitly (``units="in"``):
#: a leg of N inches is a plausible leg in centimetres too, and nothing in a file tells
#: the two apart.
DETECTED_UNITS: tuple[str, ...] = ("m", "cm", "mm")

_FORE_SEGS = ("scapula", "shoulder", "elbow", "wrist", "toe")
_HIND_SEGS = ("ilium", "hip", "knee", "hock", "toe")
_AXIAL = ("pelvis", "spine1", "spine2", "spine3", "neck", "head", "snout")
_TAIL = ("pelvis", "tail1", "tail2", "tail3")
_LEG_CHAINS = {
    f"{s}{l}": tuple(f"{s}{l}_{seg}" for seg in (_FORE_SEGS if l == "f" else _HIND_SEGS))
    for s in ("l", "r")
    for l in ("f", "h")  # noqa: E741
}
_END_POINTS = ("snout", "tail3", "lf_toe", "rf_toe", "lh_toe", "rh_toe")
_IDX = {n: i for i, n in enumerate(JOINT_NAMES)}

# ---------------------------------------------------------------------- name cues

_LEFT = {"l", "left", "lt", "lft"}
_RIGHT = {"r", "right", "rt", "rgt"}
#: Leg codes that name a side and a girdle at once, as robot and some animal rigs spell
#: them (``FL_thigh``, ``LH_SHANK``, ``Leg_RR_2``): code → (side, girdle word).
_QUADRANT = {
    **{
        f"{g}{s}": (s, w)
        for g, w in (("f", "front"), ("h", "hind"), ("r", "hind"), ("b", "hind"))
        for s in "lr"
    },
    **{f"{s}{g}": (s, w) for g, w in (("f", "front"), ("h", "hind"), ("b", "hind")) for s in "lr"},
}
_TOKEN_RE = re.compile(r"[A-Z]+(?![a-z])|[A-Z]?[a-z]+|\d+")
_FORE_WORDS = (
    "arm",
    "hand",
    "shoulder",
    "clavicle",
    "scapula",
    "collar",
    "front",
    "fore",
    "finger",
    "elbow",
    "wrist",
    "humerus",
    "carpal",
    "radius",
)
_HIND_WORDS = (
    "upleg",
    "thigh",
    "leg",
    "foot",
    "hind",
    "back",
    "knee",
    "hip",
    "ankle",
    "femur",
    "shin",
    "calf",
    "hock",
    "tibia",
    "toe",
)
#: Name tokens of rig helpers that are never part of a limb: tails, armour plates, 3ds Max
#: biped nubs and footstep trackers, IK poles and targets, twist and roll bones.
_HELPER_TOKENS = frozenset(
    {
        "tail",
        "armor",
        "armour",
        "nub",
        "footstep",
        "footsteps",
        "helper",
        "ik",
        "pole",
        "target",
        "twist",
        "roll",
        "dummy",
        "ctrl",
        "control",
        "prop",
        "weapon",
    }
)
_NOT_LIMB = (
    "ear",
    "eye",
    "jaw",
    "lip",
    "brow",
    "cheek",
    "whisker",
    "horn",
    "antler",
    "mouth",
    "tongue",
    "nostril",
    "wing",
)


def name_cues(name: str) -> tuple[str | None, str]:
    """Side and side-free core of a joint name.

    ``LeftUpLeg`` → ``("l", "upleg")``, ``R_Thigh`` → ``("r", "thigh")``,
    ``hand.L`` → ``("l", "hand")``, ``Spine1`` → ``(None, "spine1")``; a leg code
    (:data:`_QUADRANT`) gives the side and the girdle: ``FL_calf`` → ``("l", "frontcalf")``,
    ``RH_2`` → ``("r", "hind2")``, ``RR_thigh`` (rear right) → ``("r", "hindthigh")``.

    Args:
        name: a source joint name.

    Returns:
        ``("l" | "r" | None, core)``: the side cue and the lower-case name without it.
    """
    toks = _TOKEN_RE.findall(name)
    side: str | None = None
    rest: list[str] = []
    for t in toks:
        low = t.lower()
        if side is None and low in _LEFT:
            side = "l"
        elif side is None and low in _RIGHT:
            side = "r"
        elif side is None and low in _QUADRANT:
            side, girdle = _QUADRANT[low]
            rest.append(girdle)
        else:
            rest.append(low)
    return side, "".join(rest)


def is_helper_name(name: str) -> bool:
    """True if a joint name marks a rig helper that is never a limb bone.

    Tails, armour plates, biped nubs and footstep trackers, IK poles and targets, twist
    and roll bones (:data:`_HELPER_TOKENS`): ``Dog_LeftTail001``, ``Bip01_L_Toe0Nub``,
    ``Bip01_Footsteps``, ``LeftLegIKTarget``, ``forearm_twist.L``.
    """
    toks = [t.lower() for t in _TOKEN_RE.findall(name)]
    if any(t in _HELPER_TOKENS for t in toks):
        return True
    low = name.lower()
    return any(w in low for w in _HELPER_TOKENS if len(w) >= 5) or "tail" in low


def _fore_vote(core: str) -> int:
    if any(w in core for w in _FORE_WORDS):
        return 1
    if any(w in core for w in _HIND_WORDS):
        return -1
    return 0


# ---------------------------------------------------------------------- data types


def _axis_vector(axis: str) -> np.ndarray:
    v = np.zeros(3)
    v["xyz".index(axis[-1])] = -1.0 if axis.startswith("-") else 1.0
    return v


def _axis_name(v: np.ndarray) -> str:
    k = int(np.argmax(np.abs(v)))
    return ("-" if v[k] < 0 else "+") + "xyz"[k]


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
    """

    scale: float
    units: str
    up: str
    forward: str
    matrix: np.ndarray

    @classmethod
    def from_axes(cls, scale: float, units: str, up: str, forward: str) -> FrameConversion:
        u, f = _axis_vector(up), _axis_vector(forward)
        if abs(float(u @ f)) > 1e-9:
            raise SkeletonMappingError(f"forward axis {forward} is not perpendicular to up {up}")
        left = np.cross(u, f)
        return cls(scale, units, up, forward, np.stack([f, left, u]))

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


@dataclass
class JointMapping:
    """Which source joint drives each habitsim joint, and how the file was converted.

    Attributes:
        joints: every habitsim joint name → source joint name, or None if unmapped
            (unmapped joints keep the species' standing pose).
        method: ``"auto"``, ``"map file <path>"``, ``"explicit"`` or ``"identity"``.
        frame: the file-to-habitsim frame conversion (None for the identity import).
        root_scale: factor applied to the source root translation (species hip height /
            source hip height) [-].
        notes: human-readable remarks (guesses made, fallbacks taken).
        confidence: per leg (``lf``, ``rf``, ``lh``, ``rh``) a score in [0, 1] that the
            chain mapped to it is that leg (:data:`CONFIDENCE_CHECKS`); empty until the
            motion has been retargeted.
        warnings: what a user should check by hand (a leg below
            :data:`CONFIDENCE_WARN`, legs that do not mirror each other).
    """

    joints: dict[str, str | None]
    method: str = "auto"
    frame: FrameConversion | None = None
    root_scale: float = 1.0
    notes: list[str] = field(default_factory=list)
    confidence: dict[str, float] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)

    def mapped(self) -> dict[str, str]:
        """Only the mapped habitsim joints: habitsim name → source name."""
        return {k: v for k, v in self.joints.items() if v is not None}

    def lines(self) -> list[str]:
        """One ``"habitsim joint <- source joint"`` line per habitsim joint."""
        w = max(len(n) for n in JOINT_NAMES)
        return [
            f"{n:<{w}} <- {self.joints.get(n) or '(unmapped: standing pose)'}" for n in JOINT_NAMES
        ]

    def __str__(self) -> str:
        head = [f"joint mapping ({self.method}):"]
        if self.frame is not None:
            head.append(f"  frame: {self.frame.describe()}; root scale {self.root_scale:.4g}")
        body = ["  " + s for s in self.lines()]
        if self.confidence:
            body.append(
                "  leg confidence: " + ", ".join(f"{k} {v:.2f}" for k, v in self.confidence.items())
            )
        tail = ["  note: " + n for n in self.notes]
        tail += ["  WARNING: " + w for w in self.warnings]
        return "\n".join(head + body + tail)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (stored in the imported motion's metadata)."""
        d: dict[str, Any] = {
            "method": self.method,
            "joints": self.mapped(),
            "root_scale": self.root_scale,
            "notes": list(self.notes),
            "confidence": dict(self.confidence),
            "warnings": list(self.warnings),
        }
        if self.frame is not None:
            d.update(
                units=self.frame.units,
                unit_scale=self.frame.scale,
                up=self.frame.up,
                forward=self.frame.forward,
            )
        return d


# ---------------------------------------------------------------------- tree helpers


class _Tree:
    def __init__(self, bvh: BVHData):
        self.bvh = bvh
        self.n = bvh.num_joints
        self.parents = bvh.parents
        self.kids: list[list[int]] = [[] for _ in range(self.n)]
        for j, p in enumerate(bvh.parents):
            if p >= 0:
                self.kids[p].append(j)
        self.height = [0] * self.n  # longest path (in joints) below j
        for j in reversed(range(self.n)):
            if self.kids[j]:
                self.height[j] = 1 + max(self.height[c] for c in self.kids[j])
        self.depth = [0] * self.n
        for j, p in enumerate(bvh.parents):
            self.depth[j] = 0 if p < 0 else self.depth[p] + 1
        self.cues = [name_cues(n) for n in bvh.names]
        self.blen = np.linalg.norm(bvh.offsets, axis=1)
        self.helper = [is_helper_name(n) for n in bvh.names]

    def ancestors(self, j: int) -> list[int]:
        out = []
        while self.parents[j] >= 0:
            j = self.parents[j]
            out.append(j)
        return out

    def is_ancestor(self, a: int, b: int) -> bool:
        """True if a is a strict ancestor of b."""
        return a in self.ancestors(b)

    def deepest_path(self, j: int) -> list[int]:
        out = [j]
        while self.kids[j]:
            j = max(self.kids[j], key=lambda c: self.height[c])  # first on ties
            out.append(j)
        return out

    def is_pure(self, j: int) -> bool:
        """True if the subtree of j is one chain (rig helpers hanging off it aside)."""
        while True:
            kids = [c for c in self.kids[j] if not self.helper[c]]
            if not kids:
                return True
            if len(kids) > 1:
                return False
            j = kids[0]

    def leg_path(self, j: int) -> list[int]:
        """The limb chain from j down: rig helpers skipped, the deepest real child taken.

        A trailing End Site is kept only when it hangs directly from the last real joint
        (it is then the toe tip); an End Site below a helper (a biped nub) is not.
        """
        out = [j]
        while True:
            kids = [c for c in self.kids[j] if not self.helper[c]]
            real = [c for c in kids if not self.bvh.is_end_site[c]]
            if real:
                j = max(real, key=lambda c: self.height[c])  # first on ties
                out.append(j)
                continue
            if kids and not self.bvh.is_end_site[j]:
                out.append(kids[0])
            return out

    def path(self, a: int, b: int) -> list[int]:
        """Joints from a to b through the tree (both included)."""
        up_a = [a] + self.ancestors(a)
        up_b = [b] + self.ancestors(b)
        common = next(x for x in up_a if x in up_b)
        return up_a[: up_a.index(common) + 1] + list(reversed(up_b[: up_b.index(common)]))

    def path_length(self, a: int, b: int) -> float:
        """Sum of bone lengths along the tree path from a to b [file units]."""
        p = self.path(a, b)
        lca_pos = min(range(len(p)), key=lambda k: self.depth[p[k]])
        return float(sum(self.blen[j] for k, j in enumerate(p) if k != lca_pos))

    def chain_length(self, chain: list[int]) -> float:
        return float(sum(self.blen[j] for j in chain[1:]))

    def lca(self, joints: list[int]) -> int:
        common = [joints[0]] + self.ancestors(joints[0])
        for j in joints[1:]:
            anc = {j, *self.ancestors(j)}
            common = [c for c in common if c in anc]
        return common[0]


@dataclass
class _Limb:
    root: int
    chain: list[int]
    side: str | None  # from the name, None if unnamed
    vote: int  # >0 fore-like names, <0 hind-like names


@dataclass
class _Analysis:
    joints: dict[str, str | None]
    geometric_sides: list[
        tuple[str, str]
    ]  # leg pairs whose sides need geometry (l-prefix, r-prefix)
    notes: list[str]


# ---------------------------------------------------------------------- automatic mapping


def _sided_limbs(t: _Tree) -> list[_Limb]:
    out = []
    for j in range(t.n):
        side, core = t.cues[j]
        if side is None or t.bvh.is_end_site[j]:
            continue
        p = t.parents[j]
        if p >= 0 and t.cues[p][0] is not None:
            continue
        if any(w in core for w in _NOT_LIMB) or t.helper[j]:
            continue
        chain = t.leg_path(j)
        if len(chain) < 3:
            continue
        vote = sum(_fore_vote(t.cues[c][1]) for c in chain if not t.bvh.is_end_site[c])
        out.append(_Limb(j, chain, side, vote))
    return out


#: Two unnamed chains hanging from one joint are a left/right pair when each bone along
#: them matches its mirror's length within this share of the chain's length
#: (:func:`_unsided_limbs`): mirrored legs do, a tail and a sided tail helper do not.
MIRROR_BONE_TOLERANCE = 0.05


def _mirrored(t: _Tree, a: list[int], b: list[int]) -> bool:
    """True if chains a and b are left/right mirrors: as many joints, the same bone
    lengths (the first bone, from their common parent, included)."""
    if len(a) != len(b):
        return False
    la, lb = t.blen[a], t.blen[b]
    scale = max(float(la.sum()), float(lb.sum()))
    return scale > 0 and bool(np.all(np.abs(la - lb) <= MIRROR_BONE_TOLERANCE * scale))


def _unsided_limbs(t: _Tree) -> list[tuple[_Limb, _Limb]]:
    """The two longest pairs of mirrored chains hanging from one joint, for skeletons
    whose names carry no side.

    A chain is a child's :meth:`_Tree.leg_path` (helpers named as such skipped); side
    branches off it (an unnamed armour plate or a second toe) do not disqualify it. Two
    chains pair when they mirror each other bone by bone (:func:`_mirrored`), so a
    spine, a neck or a tail, which has no mirror, never becomes a leg, and neither does a
    sided helper chain beside a tail.
    """
    pairs: list[tuple[float, _Limb, _Limb]] = []
    for p in range(t.n):
        cands = []
        for c in t.kids[p]:
            core = t.cues[c][1]
            if t.bvh.is_end_site[c] or t.helper[c] or t.height[c] < 2:
                continue
            if any(w in core for w in ("tail", "neck", "head", "spine", "chest") + _NOT_LIMB):
                continue
            chain = t.leg_path(c)
            if len(chain) < 3:
                continue
            cands.append(_Limb(c, chain, None, sum(_fore_vote(t.cues[k][1]) for k in chain)))
        used: set[int] = set()
        for a in range(len(cands)):
            for b in range(a + 1, len(cands)):
                if a in used or b in used:
                    continue
                la, lb = cands[a], cands[b]
                if not _mirrored(t, la.chain, lb.chain):
                    continue
                used |= {a, b}
                pairs.append((t.chain_length(la.chain) + t.chain_length(lb.chain), la, lb))
    pairs.sort(key=lambda x: -x[0])
    return [(a, b) for _, a, b in pairs[:2]]


#: Upper : lower : foot bone proportions of a fore and a hind leg (humerus : radius :
#: wrist-to-toe, femur : tibia : hock-to-toe), the mean over the catalog's 17 species
#: (each between 0.17 and 0.48). A leg chain whose names name no bone starts at its
#: girdle when that fits these better (:func:`_leg_roles`).
LEG_PROPORTIONS = {True: (0.332, 0.372, 0.296), False: (0.342, 0.341, 0.316)}


def _proportion_misfit(t: _Tree, real: list[int], u: int, fore: bool) -> float:
    """How far the upper : lower : foot proportions of a leg whose upper joint is
    ``real[u]`` (foot from ``real[u + 2]`` to the last joint) are from
    :data:`LEG_PROPORTIONS`."""
    seg = np.array(
        [
            t.blen[real[u + 1]],
            t.blen[real[u + 2]],
            sum(t.blen[c] for c in real[u + 3 :]),
        ]
    )
    if seg.sum() <= 0:
        return math.inf
    return float(np.abs(seg / seg.sum() - np.array(LEG_PROPORTIONS[fore])).sum())


#: Name parts that say a joint is a bone of the foot (a chain's last joint so named is
#: its toe whatever its length; see :func:`_digits_trimmed`).
_FOOT_WORDS = (
    "toe",
    "finger",
    "digit",
    "phalan",
    "claw",
    "hoof",
    "nail",
    "paw",
    "foot",
    "hand",
    "ankle",
    "wrist",
    "hock",
    "fetlock",
    "pastern",
)


def _digits_trimmed(t: _Tree, real: list[int]) -> list[int]:
    """A leg chain's real joints without a last joint that is a helper's tip: one whose
    name does not name a foot bone (:data:`_FOOT_WORDS`; ``J018``, ``FL_5``) and whose
    bone is longer than the bone before it. Digits shorten toward their tip, so such a
    joint is a marker past the toe (a biped nub 23 cm beyond a 6 cm paw, once its name
    is gone), not a toe. At least five joints stay."""
    real = list(real)
    while (
        len(real) > 5
        and not any(w in t.cues[real[-1]][1] for w in _FOOT_WORDS)
        and t.blen[real[-1]] > t.blen[real[-2]]
    ):
        real.pop()
    return real


def _leg_roles(t: _Tree, chain: list[int], fore: bool) -> list[int | None]:
    """Source joints for (girdle, upper, lower, foot, toe) along a leg chain."""
    cores = [t.cues[c][1] for c in chain]
    if fore:

        def upper(c: str) -> bool:
            return (
                "arm" in c and not any(w in c for w in ("fore", "lower", "low"))
            ) or "humerus" in c

        girdle_words: tuple[str, ...] = ("shoulder", "clavicle", "scapula", "collar")
    else:

        def upper(c: str) -> bool:
            return any(
                w in c for w in ("upleg", "thigh", "upperleg", "legupper", "femur")
            ) or c.startswith("hip")

        girdle_words = ("pelvis", "ilium", "hipbone")
    real = _digits_trimmed(t, [c for c in chain if not t.bvh.is_end_site[c]])
    u = next((k for k in range(min(3, len(chain))) if upper(cores[k])), None)
    if u is None:
        if any(w in cores[0] for w in girdle_words) and len(chain) >= 5:
            u = 1
        elif len(real) >= 5:
            # names say nothing (``FL_1``, ``J012``): the girdle joint or not, whichever
            # gives upper : lower : foot bones nearer the quadrupeds' own proportions
            u = min((0, 1), key=lambda k: _proportion_misfit(t, real, k, fore))
        else:
            u = 0
    if len(chain) < u + 3:
        raise SkeletonMappingError(
            f"leg chain {' > '.join(t.bvh.names[c] for c in chain)} is too short: a leg needs at "
            "least upper, lower and foot joints (e.g. LeftArm > LeftForeArm > LeftHand)"
        )
    roles: list[int | None] = [chain[u - 1] if u >= 1 else None]
    roles += [chain[u], chain[u + 1], chain[u + 2]]
    # The toe is the chain's last real joint (joints between the foot and it, such as a
    # biped's ankle-to-toe segment, are spanned by the foot bone); an End Site is the toe
    # only when no real joint follows the foot.
    if len(real) > u + 3:
        roles.append(real[-1])
    else:
        roles.append(chain[u + 3] if len(chain) > u + 3 else None)
    return roles


def _describe_limbs(t: _Tree, limbs: list[_Limb]) -> str:
    if not limbs:
        return "none"
    return "; ".join(
        f"{(lb.side or '?').upper()}: {' > '.join(t.bvh.names[c] for c in lb.chain)}"
        for lb in limbs
    )


def _analyse(bvh: BVHData) -> _Analysis:
    t = _Tree(bvh)
    notes: list[str] = []
    limbs = _sided_limbs(t)

    def rank(lb: _Limb) -> tuple[bool, float]:
        # Chains named like limbs first (a long unnamed chain never outranks a named leg),
        # then the longest.
        named = any(_fore_vote(t.cues[c][1]) != 0 for c in lb.chain)
        return (not named, -t.chain_length(lb.chain))

    lefts = sorted((lb for lb in limbs if lb.side == "l"), key=rank)
    rights = sorted((lb for lb in limbs if lb.side == "r"), key=rank)
    pairs: list[tuple[_Limb, _Limb]]
    geometric = False
    if len(lefts) >= 2 and len(rights) >= 2:
        lefts, rights = lefts[:2], rights[:2]

        # Pair each left leg with the right leg hanging from the same joint / of the same kind.
        def key(lb: _Limb) -> tuple[int, int]:
            return (t.depth[t.parents[lb.root]] if t.parents[lb.root] >= 0 else -1, lb.vote)

        ls = sorted(lefts, key=key)
        rs = sorted(rights, key=key)
        pairs = [(ls[0], rs[0]), (ls[1], rs[1])]
    else:
        pairs = _unsided_limbs(t)
        geometric = True
        if len(pairs) < 2:
            raise SkeletonMappingError(
                f"{bvh.source}: cannot map onto a quadruped: found {len(lefts)} left and "
                f"{len(rights)} right leg chains ({_describe_limbs(t, lefts + rights)}) and "
                f"{len(pairs)} pairs of symmetric unnamed chains; need 4 legs - a left and a right "
                "fore leg and a left and a right hind leg, each a chain of at least 3 joints "
                "(named like LeftArm/LeftUpLeg, or symmetric chains hanging from the trunk). "
                "Give an explicit joint map with --map."
            )
        notes.append("legs found from symmetric unnamed chains; left/right decided by geometry")

    # Fore / hind: names, then hierarchy (legs hanging closer to the root are hind legs).
    attach = [t.lca([t.parents[a.root], t.parents[b.root]]) for a, b in pairs]
    votes = [a.vote + b.vote for a, b in pairs]
    by_name: int | None = None  # index of the fore pair
    if votes[0] > 0 > votes[1]:
        by_name = 0
    elif votes[1] > 0 > votes[0]:
        by_name = 1
    by_tree: int | None = None
    if attach[0] != attach[1]:
        if t.is_ancestor(attach[0], attach[1]):
            by_tree = 1
        elif t.is_ancestor(attach[1], attach[0]):
            by_tree = 0
        elif t.depth[attach[0]] != t.depth[attach[1]]:
            by_tree = 0 if t.depth[attach[0]] > t.depth[attach[1]] else 1
    if by_name is not None and by_tree is not None and by_name != by_tree:
        notes.append("fore/hind from the names contradicts the hierarchy; the names were used")
    fore_i = by_name if by_name is not None else by_tree
    if fore_i is None:
        raise SkeletonMappingError(
            f"{bvh.source}: found 4 legs but cannot tell fore from hind legs: all hang from "
            f"{bvh.names[attach[0]]!r} and the names carry no fore/hind cue (Arm/Hand/Shoulder/"
            "Front vs UpLeg/Thigh/Foot/Hind). Give an explicit joint map with --map."
        )
    fore, hind = pairs[fore_i], pairs[1 - fore_i]
    hips, chest = attach[1 - fore_i], attach[fore_i]

    names = bvh.names
    joints: dict[str, str | None] = {n: None for n in JOINT_NAMES}
    joints["pelvis"] = names[hips]
    for pair, limb in ((fore, "f"), (hind, "h")):
        segs = _FORE_SEGS if limb == "f" else _HIND_SEGS
        for lb, side in zip(pair, ("l", "r"), strict=True):
            if lb.side is not None:
                side = lb.side
            for seg, src in zip(segs, _leg_roles(t, lb.chain, limb == "f"), strict=True):
                joints[f"{side}{limb}_{seg}"] = None if src is None else names[src]

    # Spine: hips → chest.
    leg_roots = {lb.root for pair in pairs for lb in pair}
    spine = t.path(hips, chest)[1:] if chest != hips else []
    if spine:
        joints["spine3"] = names[spine[-1]]
        if len(spine) >= 2:
            joints["spine1"] = names[spine[0]]
        if len(spine) >= 3:
            joints["spine2"] = names[spine[len(spine) // 2]]
    else:
        notes.append("fore and hind legs hang from the same joint: no spine mapped")
    on_path = set(t.path(hips, chest)) | set(t.ancestors(hips))

    # Neck and head beyond the chest (or a spine joint before it).
    def free_children(j: int) -> list[int]:
        return [
            c
            for c in t.kids[j]
            if c not in on_path
            and c not in leg_roots
            and t.cues[c][0] is None
            and not bvh.is_end_site[c]
        ]

    head_start = None
    search = [chest] + list(reversed(spine[:-1])) if spine else [hips]
    for j in search:
        cands = free_children(j)
        named = [
            c
            for c in cands
            if any(
                w in "".join(t.cues[k][1] for k in t.deepest_path(c))
                for w in ("neck", "head", "skull")
            )
        ]
        if named:
            head_start = named[0]
            break
        if cands and j == chest and chest != hips:
            head_start = max(cands, key=lambda c: t.height[c])
            break
    head_chain = t.deepest_path(head_start) if head_start is not None else []
    if head_chain:
        non_end = [c for c in head_chain if not bvh.is_end_site[c]]
        head = next((c for c in non_end if any(w in t.cues[c][1] for w in ("head", "skull"))), None)
        if head is None and len(non_end) >= 2:
            head = non_end[-1]
        neck = next((c for c in head_chain if "neck" in t.cues[c][1]), None)
        if neck is None and head_chain[0] != head:
            neck = head_chain[0]
        if neck is not None:
            joints["neck"] = names[neck]
        if head is not None:
            joints["head"] = names[head]
            kids = t.kids[head]
            if kids:
                ends = [c for c in kids if bvh.is_end_site[c]]
                nose = [
                    c for c in kids if any(w in t.cues[c][1] for w in ("nose", "snout", "muzzle"))
                ]
                joints["snout"] = names[(nose or ends or [max(kids, key=lambda c: t.height[c])])[0]]
    else:
        notes.append("no neck/head chain found beyond the chest")

    # Tail from the hips (or, if named so, from an ancestor of the hips).
    cands = free_children(hips)
    if head_start in cands:
        cands.remove(head_start)
    tail_named = [c for c in cands if "tail" in t.cues[c][1]]
    for a in t.ancestors(hips):
        tail_named += [c for c in free_children(a) if "tail" in t.cues[c][1]]
    tail_start = tail_named[0] if tail_named else (cands[0] if len(cands) == 1 else None)
    if tail_start is not None:
        tc = t.deepest_path(tail_start)
        joints["tail1"] = names[tc[0]]
        if len(tc) >= 2:
            joints["tail3"] = names[tc[-1]]
        if len(tc) >= 3:
            joints["tail2"] = names[tc[(len(tc) - 1) // 2]]
    else:
        notes.append("no tail chain found at the hips")

    geo = [("lf", "rf"), ("lh", "rh")] if geometric else []
    return _Analysis(joints, geo, notes)


def auto_map(bvh: BVHData) -> dict[str, str | None]:
    """Automatic habitsim ← source joint mapping from names and hierarchy.

    Left/right comes from name cues (``Left``/``Right``/``L_``/``_R``/``.L``…); legs without
    side names are taken from symmetric chains and assigned left/right here by their
    lateral position in the first frame (after :func:`detect_frame`).

    Args:
        bvh: the parsed source file.

    Returns:
        Every habitsim joint name → source joint name or None.

    Raises:
        SkeletonMappingError: fewer than four legs, or fore and hind legs that cannot be
            told apart.
    """
    an = _analyse(bvh)
    if an.geometric_sides:
        frame = detect_frame(bvh, an.joints)
        _resolve_sides(bvh, an, frame)
    return an.joints


def _resolve_sides(bvh: BVHData, an: _Analysis, frame: FrameConversion) -> None:
    pos = frame.apply(bvh.fk())  # (F, J, 3)
    t = _Tree(bvh)
    for lp, rp in an.geometric_sides:

        def lateral(prefix: str) -> float:
            idx = [t.bvh.index(s) for n in _LEG_CHAINS[prefix] if (s := an.joints[n]) is not None]
            return float(pos[:, idx, 1].mean())

        if lateral(lp) < lateral(rp):
            for a, b in zip(_LEG_CHAINS[lp], _LEG_CHAINS[rp], strict=True):
                an.joints[a], an.joints[b] = an.joints[b], an.joints[a]


# ---------------------------------------------------------------------- explicit map


def load_joint_map(path: str | Path) -> dict[str, Any]:
    """Read a joint-map file (JSON or TOML).

    JSON::

        {"extends": "auto", "units": "cm", "up": "y",
         "map": {"lh_hip": "b_LeftLegUpper", "lh_ilium": null}}

    TOML::

        extends = "auto"    # optional: start from the automatic mapping
        units = "cm"        # optional: m, cm, mm
        up = "y"            # optional: x, y, z with optional sign
        [map]
        pelvis = "Hips"
        lf_shoulder = "LeftArm"
        lh_ilium = ""       # unmapped (JSON: null)

    Without ``extends`` the file is the whole mapping (joints it does not name keep the
    species' standing pose); with ``extends = "auto"`` it overrides only the joints it
    names on top of the automatic mapping (:func:`auto_map`).

    Args:
        path: the ``.json`` or ``.toml`` file.

    Returns:
        ``{"map": {habitsim: source | None}, "units": str | None, "up": str | None,
        "extends": "auto" | None}``.

    Raises:
        SkeletonMappingError: unreadable file, an unknown suffix, a missing ``map`` table,
            non-string values, unknown keys or unknown habitsim joint names (the message
            lists the valid ones).
    """
    p = Path(path)
    kind = p.suffix.lower()
    if kind not in (".json", ".toml"):
        raise SkeletonMappingError(
            f"{p}: unknown joint-map file type {p.suffix!r}; valid: .json, .toml"
        )
    try:
        text = p.read_text(encoding="utf-8")
        data = json.loads(text) if kind == ".json" else tomllib.loads(text)
    except FileNotFoundError:
        raise SkeletonMappingError(f"{p}: no such joint-map file") from None
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError, ValueError) as e:
        raise SkeletonMappingError(
            f"{p}: cannot read joint-map {kind[1:].upper()} ({str(e)[:200]})"
        ) from e
    if not isinstance(data, dict):
        raise SkeletonMappingError(f"{p}: a joint map must be a table/object with a 'map' key")
    unknown = sorted(set(data) - {"map", "units", "up", "extends"})
    if unknown:
        raise SkeletonMappingError(
            f"{p}: unknown keys {unknown[:10]}; valid: map, units, up, extends"
        )
    m = data.get("map")
    if not isinstance(m, dict) or not m:
        raise SkeletonMappingError(
            f'{p}: needs a non-empty [map] table of habitsim_joint = "SourceJoint"'
        )
    out: dict[str, str | None] = {}
    for k, v in m.items():
        if v is not None and not isinstance(v, str):
            raise SkeletonMappingError(
                f"{p}: [map] {k} must be a source joint name (string), got {v!r:.60}"
            )
        out[k] = v or None
    bad = sorted(set(m) - set(JOINT_NAMES))
    if bad:
        raise SkeletonMappingError(
            f"{p}: unknown habitsim joints {bad[:10]}; valid: {', '.join(JOINT_NAMES)}"
        )
    for k in ("units", "up", "extends"):
        if k in data and not isinstance(data[k], str):
            raise SkeletonMappingError(f"{p}: {k} must be a string, got {data[k]!r:.60}")
    ext = data.get("extends")
    if ext is not None and ext != "auto":
        raise SkeletonMappingError(f"{p}: unknown extends {ext!r:.60}; valid: auto")
    return {"map": out, "units": data.get("units"), "up": data.get("up"), "extends": ext}


def validate_joint_map(
    joint_map: Mapping[str, str | None], bvh: BVHData, where: str = "joint map"
) -> dict[str, str | None]:
    """Check an explicit habitsim → source mapping against a BVH skeleton.

    Args:
        joint_map: habitsim joint name → source joint name (End Sites are named
            ``<parent>_End``).
        bvh: the source skeleton.
        where: name used in messages (e.g. the TOML path).

    Returns:
        Every habitsim joint → source name or None.

    Raises:
        SkeletonMappingError: unknown habitsim or source joint names (listing the valid
            ones), a source joint used twice, or no source joint for ``pelvis``.
    """
    bad = sorted(set(joint_map) - set(JOINT_NAMES))
    if bad:
        raise SkeletonMappingError(
            f"{where}: unknown habitsim joints {bad}; valid: {', '.join(JOINT_NAMES)}"
        )
    missing = sorted({v for v in joint_map.values() if v is not None and v not in bvh.names})
    if missing:
        names = ", ".join(bvh.names[:80]) + (" …" if len(bvh.names) > 80 else "")
        raise SkeletonMappingError(
            f"{where}: source joints {missing[:10]} are not in {bvh.source}; its joints: {names}"
        )
    seen: dict[str, str] = {}
    for k, v in joint_map.items():
        if v is None:
            continue
        if v in seen:
            raise SkeletonMappingError(
                f"{where}: source joint {v!r} is mapped to both {seen[v]} and {k}"
            )
        seen[v] = k
    if not joint_map.get("pelvis"):
        raise SkeletonMappingError(
            f'{where}: must map pelvis (the root) to a source joint, e.g. pelvis = "Hips"'
        )
    out: dict[str, str | None] = {n: None for n in JOINT_NAMES}
    out.update(joint_map)
    return out


# ---------------------------------------------------------------------- frame detection


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
) -> FrameConversion:
    """Units, up and forward axis of a BVH file, as a conversion to habitsim's frame.

    * units: explicit, else the candidate (m, cm, mm) that makes the source's hind-leg
      length (hip joint to toe along the bones) a plausible animal leg (0.02–4 m); if
      several or none are plausible, the one closest (in log scale) to the species' leg
      length (default: 0.5 m).
    * up: explicit, else the coordinate axis closest to the mean direction from the feet
      (most distal mapped leg joints) to the hips over the clip.
    * forward: the coordinate axis perpendicular to up closest to the hips → chest
      direction in the first frame (rest pose as a fallback).

    Args:
        bvh: the source file.
        joints: habitsim → source mapping (at least ``pelvis``; legs and a spine/neck/
            head joint unless ``up`` is given and forward can be found).
        units: ``"m"``, ``"cm"``, ``"mm"``, a scale in metres per unit, or None to detect.
        up: ``"y"``, ``"z"``, ``"-y"``… or None to detect.
        species: target species (for unit detection).

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
        plausible = [u for u in DETECTED_UNITS if 0.02 <= leg * UNIT_SCALES[u] <= 4.0]
        if len(plausible) == 1:
            uname = plausible[0]
        else:
            uname = min(DETECTED_UNITS, key=lambda u: abs(math.log(leg * UNIT_SCALES[u] / target)))
        scale = UNIT_SCALES[uname]

    # Up.
    if up is not None:
        up_ax = _parse_up(up)
    else:
        if not feet:
            raise SkeletonMappingError(
                "cannot detect the up axis: no leg joints are mapped; pass up='y' or 'z' (--up)"
            )
        v = (pos[:, hips] - pos[:, feet].mean(axis=1)).mean(axis=0)
        if np.linalg.norm(v) < 1e-9:
            v = rest[0, hips] - rest[0, feet].mean(axis=0)
        if np.linalg.norm(v) < 1e-9:
            raise SkeletonMappingError("cannot detect the up axis (feet at hip level); pass up=")
        up_ax = _axis_name(v)
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
    return FrameConversion.from_axes(scale, uname, up_ax, _axis_name(fwd_vec))


# ---------------------------------------------------------------------- identity


def _habitsim_order(bvh: BVHData) -> list[int] | None:
    """Source indices of the habitsim joints (JOINT_NAMES order) if the file is habitsim's."""
    keep = [j for j in range(bvh.num_joints) if not bvh.is_end_site[j]]
    by_name = {bvh.names[j]: j for j in keep}
    if len(keep) != len(JOINT_NAMES) or set(by_name) != set(JOINT_NAMES):
        return None
    for n, p in zip(JOINT_NAMES, PARENTS, strict=True):
        sp = bvh.parents[by_name[n]]
        if (p < 0) != (sp < 0) or (p >= 0 and bvh.names[sp] != JOINT_NAMES[p]):
            return None
    return [by_name[n] for n in JOINT_NAMES]


def is_habitsim_bvh(bvh: BVHData) -> bool:
    """True if the file's joints (End Sites aside) are exactly habitsim's, same hierarchy."""
    return _habitsim_order(bvh) is not None


def _identity_import(bvh: BVHData, species: Species) -> tuple[Motion, JointMapping]:
    keep = _habitsim_order(bvh)
    assert keep is not None
    q = quat_fix_continuity(bvh.local_rotations()[:, keep], axis=0)
    root = bvh.root_translation()
    skel = get_skeleton(species)
    notes = ["habitsim-exported file: rotations and root translation copied"]
    off = bvh.offsets[keep]
    scale = 1.0
    if not np.allclose(off[1:], skel.offsets[1:], atol=1e-6):
        src_leg = sum(float(np.linalg.norm(off[_IDX[n]])) for n in ("lh_knee", "lh_hock", "lh_toe"))
        scale = species.hind_leg_length / src_leg if src_leg > 0 else 1.0
        notes.append(
            f"bone offsets differ from the {species.name} skeleton: root translation scaled "
            f"by the hind-leg length ratio {scale:.4g}"
        )
    joints: dict[str, str | None] = {n: n for n in JOINT_NAMES}
    notes.append("stance labels detected on the file's own toes (habitsim contact rule)")
    mapping = JointMapping(joints, "identity", None, scale, notes)
    meta = {"source": "bvh", "bvh_file": Path(bvh.source).name, "mapping": mapping.to_dict()}
    m = Motion(species.name, bvh.fps, root * scale, q, metadata=meta)
    from .contacts import detect_contacts

    m = Motion(m.species, m.fps, m.root_positions, m.rotations, detect_contacts(m), meta)
    return m, mapping


# ---------------------------------------------------------------------- retargeting


def _shortest_arc(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Quaternions (F, 4) of the smallest rotations turning unit a (3,) onto unit b (F, 3)."""
    a = np.broadcast_to(a, b.shape)
    d = np.sum(a * b, axis=-1)
    q = np.concatenate([(1.0 + d)[:, None], np.cross(a, b)], axis=-1)
    anti = 1.0 + d < 1e-9
    if np.any(anti):
        a0 = a[anti]
        helper = np.where(
            np.abs(a0[:, 1:2]) < 0.9, np.array([0.0, 1.0, 0.0]), np.array([1.0, 0.0, 0.0])
        )
        perp = np.cross(a0, helper)
        perp /= np.linalg.norm(perp, axis=-1, keepdims=True)
        q[anti] = np.concatenate([np.zeros((len(a0), 1)), perp], axis=-1)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def _aim(bone: np.ndarray, d: np.ndarray, side: np.ndarray | None = None) -> np.ndarray:
    """Quaternions (F, 4) turning unit ``bone`` (3,) onto unit ``d`` (F, 3), in the parent's
    frame, with the joint's lateral axis (+y) kept as close as it can be to ``side``
    ((F, 3), default the parent's own +y).

    Aiming a chain bone by bone with shortest arcs leaves each bone's twist to chance,
    and along the spine the twists add up: a chest rolled by tens of degrees hangs the
    fore legs sideways. Keeping every joint's lateral axis on its parent's (or, for the
    chest, on the source's shoulder line) keeps the rolls the source has and no others.
    Where ``d`` is (nearly) along the lateral reference, the shortest arc is used.
    """
    f = d.shape[0]
    ref = np.broadcast_to(np.array([0.0, 1.0, 0.0]), (f, 3)) if side is None else side

    def frame(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        y = y - np.sum(y * x, axis=-1, keepdims=True) * x
        n = np.linalg.norm(y, axis=-1, keepdims=True)
        ok = (n[:, 0] > 1e-3) & (np.linalg.norm(x, axis=-1) > 0.5)
        y = y / np.where(ok[:, None], n, 1.0)
        return np.stack([x, y, np.cross(x, y)], axis=-1), ok

    a, ok_a = frame(np.broadcast_to(bone, (f, 3)), np.broadcast_to([0.0, 1.0, 0.0], (f, 3)))
    b, ok_b = frame(d, ref)
    ok = ok_a & ok_b
    m = np.where(ok[:, None, None], b @ np.swapaxes(a, -1, -2), np.eye(3))
    return np.where(ok[:, None], matrix_to_quat(m), _shortest_arc(bone, d))


def _driven() -> list[tuple[str, str, tuple[str, ...], int]]:
    """(joint, child, chain, index of joint in chain) for every bone-driving joint."""
    out = []
    for chain in (_AXIAL, _TAIL, *_LEG_CHAINS.values()):
        start = 1 if chain[0] == "pelvis" else 0
        for i in range(start, len(chain) - 1):
            out.append((chain[i], chain[i + 1], chain, i))
    return out


def retarget(
    bvh: BVHData, mapping: JointMapping, species: str | Species, plant: bool = True
) -> Motion:
    """Retarget a BVH motion onto a species' skeleton (see the module docstring).

    Args:
        bvh: the source file.
        mapping: the joint mapping with its ``frame`` set; ``root_scale`` is filled in.
        species: the target species.
        plant: solve the legs onto the source's footholds (:mod:`habitsim.stance.planting`); when
            False the legs keep the bone directions of the source.

    Returns:
        The retargeted :class:`~habitsim.motion.Motion` (fps from the frame time), with
        the source's stance labels as ``contacts`` and ``metadata["import"]`` saying how
        they were found (foot joints, floors, duty factors), how well the imported feet
        agree with them (``contact_f1`` per foot) and how the feet were planted.

    Raises:
        SkeletonMappingError: no frame conversion or no pelvis in the mapping.
    """
    sp = load_species(species)
    skel = get_skeleton(sp)
    if mapping.frame is None:
        raise SkeletonMappingError("retarget needs a mapping with a frame conversion")
    j2s = mapping.mapped()
    if "pelvis" not in j2s:
        raise SkeletonMappingError("the mapping has no source joint for pelvis")
    src = mapping.frame.apply(bvh.fk())  # (F, Js, 3) metres, habitsim axes
    n_f = src.shape[0]

    def s(name: str) -> np.ndarray:
        return src[:, bvh.index(j2s[name])]

    stand_root, stand_q = skel.standing_pose()
    q = np.empty((n_f, skel.num_joints, 4))
    g = np.empty((n_f, skel.num_joints, 3, 3))

    # Pelvis: heading along hips → chest (pitch kept), up from the world up.
    hips = s("pelvis")
    fwd_name = next((n for n in ("spine3", "spine2", "spine1", "neck", "head") if n in j2s), None)
    z_up = np.array([0.0, 0.0, 1.0])
    if fwd_name is not None:
        x = s(fwd_name) - hips
        x_norm = np.linalg.norm(x, axis=-1, keepdims=True)
        ok = x_norm[:, 0] > 1e-9
        x = np.where(ok[:, None], x / np.where(ok[:, None], x_norm, 1.0), np.array([1.0, 0.0, 0.0]))
        y = np.cross(z_up, x)
        y_norm = np.linalg.norm(y, axis=-1)
        for f in range(n_f):  # bone pointing straight up/down: keep the previous lateral axis
            if y_norm[f] < 1e-6:
                y[f] = y[f - 1] if f > 0 else np.array([0.0, 1.0, 0.0])
                y[f] -= (y[f] @ x[f]) * x[f]
        y /= np.linalg.norm(y, axis=-1, keepdims=True)
        z = np.cross(x, y)
        g[:, 0] = np.stack([x, y, z], axis=-1)
        q[:, 0] = matrix_to_quat(g[:, 0])
    else:
        mapping.notes.append("no spine/neck/head mapped: pelvis keeps the standing orientation")
        q[:, 0] = stand_q[0]
        g[:, 0] = quat_to_matrix(stand_q[0])

    driven = {j: (c, chain, i) for j, c, chain, i in _driven()}
    for j in range(1, skel.num_joints):
        name = JOINT_NAMES[j]
        p = skel.parents[j]
        if name in _END_POINTS:
            q[:, j] = quat_identity()
        elif name in driven:
            child, chain, i = driven[name]
            a = next((chain[k] for k in range(i, -1, -1) if chain[k] in j2s), None)
            b = next((chain[k] for k in range(i + 1, len(chain)) if chain[k] in j2s), None)
            if a is None or b is None:
                q[:, j] = stand_q[j]
            else:
                d = s(b) - s(a)
                n = np.linalg.norm(d, axis=-1, keepdims=True)
                ok = n[:, 0] > 1e-9
                d_local = np.einsum("fba,fb->fa", g[:, p], d / np.where(ok[:, None], n, 1.0))
                bone = skel.offsets[_IDX[child]]
                side = None
                if name == "spine3" and "lf_shoulder" in j2s and "rf_shoulder" in j2s:
                    side = np.einsum("fba,fb->fa", g[:, p], s("lf_shoulder") - s("rf_shoulder"))
                rot = _aim(bone / np.linalg.norm(bone), d_local, side)
                q[:, j] = np.where(ok[:, None], rot, stand_q[j])
        else:  # pragma: no cover - every non-root, non-end joint drives a bone
            q[:, j] = stand_q[j]
        g[:, j] = g[:, p] @ quat_to_matrix(q[:, j])

    # Stance of the source's own feet, and the ground they stand on.
    t = _Tree(bvh)
    stance = _source_stance(bvh, t, j2s, src, mapping)
    # Root translation scaled by the hip-height ratio, heights above the source's ground.
    feet = [bvh.index(j2s[n]) for n in ("lf_toe", "rf_toe", "lh_toe", "rh_toe") if n in j2s]
    if not feet:
        feet = _leg_ends(j2s, bvh)
    if stance is not None:
        ground = stance[0].ground
    elif feet:
        ground = float(np.median(src[:, feet, 2].min(axis=1)))
    else:
        ground = float(hips[:, 2].min())
    hip_src = [bvh.index(j2s[n]) for n in ("lh_hip", "rh_hip") if n in j2s]
    if hip_src:
        h_src = float(np.median(src[:, hip_src, 2].mean(axis=1))) - ground
        h_dst = sp.hip_height
    else:
        h_src = float(np.median(hips[:, 2])) - ground
        h_dst = float(stand_root[2])
    if h_src > 1e-6:
        k = h_dst / h_src
    else:
        k = 1.0
        mapping.notes.append("source hip height not measurable: root translation not scaled")
    root = hips * k
    root[:, 2] = (hips[:, 2] - ground) * k
    mapping.root_scale = k

    q = quat_fix_continuity(q, axis=0)
    meta = {"source": "bvh", "bvh_file": Path(bvh.source).name, "mapping": mapping.to_dict()}
    motion = Motion(sp.name, bvh.fps, root, q, metadata=meta)
    if stance is None:
        return motion
    st, foot_idx, anchor_idx, limb_len, points = stance
    report: dict[str, Any] = {
        "contacts": {
            "method": "source foot path",
            "foot_joints": [bvh.names[i] for i in foot_idx],
            "foot_points": [[bvh.names[i] for i in pts] for pts in points],
            "floors_m": [round(float(f - st.ground), 5) for f in st.floors],
            "source_leg_length_m": round(st.leg_length, 5),
            "duty": [round(float(d), 4) for d in st.duty],
        }
    }
    if plant:
        feet_src = smooth_path(src[:, foot_idx], bvh.fps)
        feet_src[..., 2] = st.heights
        target_len = np.array([sp.fore_leg_length] * 2 + [sp.hind_leg_length] * 2)
        motion, pr = plant_legs(
            motion, feet_src, src[:, anchor_idx], st.contacts, target_len / limb_len
        )
        report["planted"] = pr.to_dict(sp.leg_length)
    else:
        motion = motion.with_contacts(st.contacts)
    f1 = stance_f1(motion.detect_contacts(), st.contacts)
    report["contact_f1"] = [round(float(v), 4) for v in f1]
    _limb_confidence(t, j2s, st, limb_len, mapping)
    report["confidence"] = dict(mapping.confidence)
    report["warnings"] = list(mapping.warnings)
    motion.metadata["import"] = report
    motion.metadata["mapping"] = mapping.to_dict()
    return motion


def _limb_confidence(
    t: _Tree,
    j2s: Mapping[str, str],
    st: SourceStance,
    limb_len: np.ndarray,
    mapping: JointMapping,
) -> None:
    """Fill ``mapping.confidence`` and ``mapping.warnings`` (see :data:`CONFIDENCE_CHECKS`)."""
    by_hand = mapping.method != "auto"
    counts = {p: sum(1 for n in _LEG_CHAINS[p] if n in j2s) for p in _LEG_CHAINS}
    floors = st.floors - st.ground
    for k, prefix in enumerate(("lf", "rf", "lh", "rh")):
        fore = prefix[1] == "f"
        if by_hand:
            name = 1.0
        else:
            vote = sum(
                _fore_vote(t.cues[t.bvh.index(j2s[n])][1]) for n in _LEG_CHAINS[prefix] if n in j2s
            )
            name = 0.5 if vote == 0 else float((vote > 0) == fore)
        partner = ("r" if prefix[0] == "l" else "l") + prefix[1]
        kp = ("lf", "rf", "lh", "rh").index(partner)
        ratio = min(limb_len[k], limb_len[kp]) / max(limb_len[k], limb_len[kp])
        same = counts[prefix] == counts[partner]
        sym = 1.0 if same and ratio >= 0.9 else (0.5 if ratio >= 0.75 else 0.0)
        grounded = floors[k] <= 0.1 * st.leg_length
        resting = st.contacts[:, k].any()
        ground = 1.0 if grounded and resting else (0.5 if grounded or resting else 0.0)
        score = round((name + sym + ground) / 3.0, 3)
        mapping.confidence[prefix] = score
        if score < CONFIDENCE_WARN:
            src = " > ".join(j2s[n] for n in _LEG_CHAINS[prefix] if n in j2s)
            mapping.warnings.append(
                f"{prefix} leg ({src}) mapped with low confidence {score:.2f} (names "
                f"{name:g}, symmetry {sym:g}, ground {ground:g}); check it with "
                "'habitsim data inspect-bvh' and fix it with --map"
            )


def _foot_points(t: _Tree, top: int, toe: int) -> list[int]:
    """The foot's joints: ``top`` (wrist / hock) and every real joint below it.

    Rig helpers are skipped, and so is a point that sinks far below the foot's others
    (an unnamed helper pointing into the ground). Below the mapped ``toe`` only its End
    Site tips count: a joint there is a marker the mapping left out (an unnamed nub,
    :func:`_digits_trimmed`).
    """
    out, todo = [], [top]
    while todo:
        j = todo.pop()
        out.append(j)
        kids = [c for c in t.kids[j] if not t.helper[c]]
        if j == toe:
            kids = [c for c in kids if t.bvh.is_end_site[c]]
        todo += kids
    return out


def _source_stance(
    bvh: BVHData, t: _Tree, j2s: Mapping[str, str], src: np.ndarray, mapping: JointMapping
) -> tuple[SourceStance, list[int], list[int], np.ndarray, list[list[int]]] | None:
    """Stance labels of the source's own feet, its toe joints, anchors, limb lengths and
    the joints each foot's stance was found on.

    None (with a note) when a leg lacks a mapped foot or shoulder / hip joint.
    """
    foot_idx, anchor_idx, lengths, points = [], [], [], []
    for prefix, anchor in zip(("lf", "rf", "lh", "rh"), FOOT_ANCHORS, strict=True):
        chain = _LEG_CHAINS[prefix]
        toe = next((j2s[n] for n in reversed(chain[2:]) if n in j2s), None)
        top = next((j2s[n] for n in reversed(chain[2:4]) if n in j2s), None)
        if toe is None or top is None or anchor not in j2s:
            mapping.notes.append(
                f"{prefix} leg has no mapped foot or {anchor.split('_')[1]} joint: feet not "
                "labelled or planted from the source"
            )
            return None
        a, f = bvh.index(j2s[anchor]), bvh.index(toe)
        foot_idx.append(f)
        anchor_idx.append(a)
        lengths.append(t.path_length(a, f) * (mapping.frame.scale if mapping.frame else 1.0))
        points.append(_foot_points(t, bvh.index(top), f))
    # A point that sinks far below the feet's typical lowest point is an unnamed helper.
    z5 = [np.percentile(src[:, pts, 2], 5, axis=0) for pts in points]
    ref = float(np.median([z.min() for z in z5]))
    tol = 0.1 * float(np.mean(lengths))
    points = [
        [p for p, z in zip(pts, zs, strict=True) if z >= ref - tol] or pts
        for pts, zs in zip(points, z5, strict=True)
    ]
    limb_len = np.array(lengths)
    if np.any(limb_len <= 1e-6):
        mapping.notes.append("a source leg has zero length: feet not planted")
        return None
    st = label_source_stance([src[:, pts] for pts in points], bvh.fps, float(limb_len[2:].mean()))
    return st, foot_idx, anchor_idx, limb_len, points


# ---------------------------------------------------------------------- entry point


def describe_hierarchy(bvh: BVHData, mapping: JointMapping | None = None) -> str:
    """The source hierarchy as an indented tree, each joint with its proposed habitsim joint.

    Each line: the joint, its bone length in file units, ``[helper]`` for rig helpers that
    are never limbs, ``[end]`` for End Sites, and ``-> habitsim_joint`` where mapped.
    """
    inv = {v: k for k, v in mapping.mapped().items()} if mapping is not None else {}
    t = _Tree(bvh)
    lines = []
    for j, name in enumerate(bvh.names):
        tags = []
        if bvh.is_end_site[j]:
            tags.append("[end]")
        elif t.helper[j]:
            tags.append("[helper]")
        text = f"{'  ' * t.depth[j]}{name}  ({t.blen[j]:.4g})"
        if tags:
            text += " " + " ".join(tags)
        if name in inv:
            text += f"  -> {inv[name]}"
        lines.append(text)
    return "\n".join(lines)


#: File types :func:`read_source` reads (BVH motion capture, glTF skinned animations).
SOURCE_SUFFIXES: tuple[str, ...] = (".bvh", ".glb", ".gltf")


def read_source(
    path: str | Path,
    animation: str | int | None = None,
    fps: float | None = None,
    strict: bool = True,
) -> BVHData:
    """Read a source clip: a BVH file, or one animation of a glTF/GLB skinned model.

    Args:
        path: a ``.bvh``, ``.glb`` or ``.gltf`` file.
        animation: glTF only: the animation's name or index (None: the first).
        fps: glTF only: sampling rate [Hz] (default 30).
        strict: BVH only: see :func:`habitsim.bvh.parse_bvh`.

    Returns:
        The clip as :class:`~habitsim.bvh.BVHData`.

    Raises:
        SkeletonMappingError: an unknown file type (lists the valid ones), or glTF
            options given for a BVH file.
        BVHParseError, GLTFError: an unreadable file.
    """
    p = Path(path)
    kind = p.suffix.lower()
    if kind == ".bvh":
        if animation is not None or fps is not None:
            raise SkeletonMappingError(
                f"{p.name}: animation and fps apply to glTF files only (.glb, .gltf)"
            )
        return read_bvh(p, strict=strict)
    if kind in (".glb", ".gltf"):
        from .gltf import read_gltf

        return read_gltf(p, animation=animation, fps=30.0 if fps is None else fps)
    raise SkeletonMappingError(
        f"{p.name}: unknown source file type {p.suffix!r}; valid: {', '.join(SOURCE_SUFFIXES)}"
    )


def import_bvh(
    path: str | Path | BVHData,
    species: str | Species,
    joint_map: str | Path | Mapping[str, str] | None = None,
    units: str | float | None = None,
    up: str | None = None,
    strict: bool = True,
    plant: bool = True,
    animation: str | int | None = None,
    fps: float | None = None,
) -> tuple[Motion, JointMapping]:
    """Read a BVH file (or a glTF/GLB animation) and retarget it onto a species' skeleton.

    Args:
        path: the ``.bvh`` file (or an already parsed :class:`~habitsim.bvh.BVHData`).
        species: target catalog species.
        joint_map: None for the automatic mapping, a joint-map TOML path
            (:func:`load_joint_map`) or a dict habitsim joint → source joint.
        units: source length unit (``"m"``, ``"cm"``, ``"mm"`` or metres per unit);
            None = detect (a TOML's ``units`` applies when this is None).
        up: source up axis (``"y"``, ``"z"``, ``"-y"``…); None = detect.
        strict: see :func:`habitsim.bvh.parse_bvh`.
        plant: plant the legs on the source's footholds (see :func:`retarget`).
        animation, fps: for a glTF/GLB file, the animation and the sampling rate
            (:func:`read_source`).

    Returns:
        ``(motion, mapping)``; print ``mapping`` for the habitsim ← source lines.

    Raises:
        UnknownSpeciesError: unknown species (lists the known ones).
        BVHParseError: unreadable / malformed file.
        SkeletonMappingError: unmappable skeleton or invalid joint map.
    """
    sp = load_species(species)
    bvh = (
        path
        if isinstance(path, BVHData)
        else read_source(path, animation=animation, fps=fps, strict=strict)
    )
    plain = (units is None or (isinstance(units, str) and units.lower() == "m")) and (
        up is None or _parse_up(up) == "+z"
    )
    if joint_map is None and is_habitsim_bvh(bvh) and plain:
        return _identity_import(bvh, sp)

    notes: list[str] = []
    geometric: list[tuple[str, str]] = []
    if joint_map is None:
        if is_habitsim_bvh(bvh):
            joints = validate_joint_map({n: n for n in JOINT_NAMES}, bvh)
            method = "habitsim names, converted"
        else:
            an = _analyse(bvh)
            joints, geometric, notes = an.joints, an.geometric_sides, an.notes
            method = "auto"
    elif isinstance(joint_map, Mapping):
        joints = validate_joint_map(joint_map, bvh)
        method = "explicit"
    else:
        spec = load_joint_map(joint_map)
        if spec["extends"] == "auto":
            an = _analyse(bvh)
            base = dict(an.joints)
            base.update(spec["map"])
            joints = validate_joint_map(base, bvh, where=str(joint_map))
            notes = an.notes + [f"joints set by hand: {', '.join(sorted(spec['map']))}"]
            geometric = [
                (lp, rp)
                for lp, rp in an.geometric_sides
                if not any(n in spec["map"] for n in _LEG_CHAINS[lp] + _LEG_CHAINS[rp])
            ]
            method = f"auto, overridden by map file {joint_map}"
        else:
            joints = validate_joint_map(spec["map"], bvh, where=str(joint_map))
            method = f"map file {joint_map}"
        units = units if units is not None else spec["units"]
        up = up if up is not None else spec["up"]

    frame = detect_frame(bvh, joints, units=units, up=up, species=sp)
    if geometric:
        an2 = _Analysis(joints, geometric, notes)
        _resolve_sides(bvh, an2, frame)
    mapping = JointMapping(joints, method, frame, 1.0, list(notes))
    motion = retarget(bvh, mapping, sp, plant=plant)
    motion.metadata["mapping"] = mapping.to_dict()
    return motion, mapping
