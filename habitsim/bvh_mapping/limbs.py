"""Limbs of the source rig: sided chains, mirrored unnamed pairs, and the roles of a
leg chain's joints (girdle, upper, lower, foot, toe)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import SkeletonMappingError
from .clip_cues import chain_motion
from .names import _NOT_LIMB, _fore_vote
from .options import MappingOptions
from .tree import _Tree


@dataclass
class _Limb:
    root: int
    chain: list[int]
    side: str | None  # from the name, None if unnamed
    vote: int  # >0 fore-like names, <0 hind-like names
    motion: float = 0.0  # how far its tip moves, in chain lengths (clip_cues.chain_motion)
    control: bool = False  # a control-layer chain (IK, MCH, ORG...), twist segments aside
    grounded: bool = True  # its tip reaches the feet's ground


def _is_control_chain(t: _Tree, chain: list[int]) -> bool:
    return any(t.control[c] and not t.segment[c] for c in chain if not t.bvh.is_end_site[c])


def _named(t: _Tree, lb: _Limb) -> bool:
    return any(_fore_vote(t.cues[c][1]) != 0 for c in lb.chain)


def _duplicates(t: _Tree, a: _Limb, b: _Limb, share: float) -> bool:
    """True if two chains are one leg drawn twice (a deforming chain and its IK or control
    copy): their first joints lie within ``share`` of the shorter chain's length, on
    average over the clip (:attr:`MappingOptions.duplicate_share`)."""
    pos, _ = t.fk()
    gap = float(np.linalg.norm(pos[:, a.root] - pos[:, b.root], axis=-1).mean())
    return gap < share * min(t.chain_length(a.chain), t.chain_length(b.chain))


def _pick_legs(t: _Tree, cands: list[_Limb], options: MappingOptions) -> list[_Limb]:
    """One side's leg chains, best first, one chain per leg.

    The order: chains that animate (:attr:`MappingOptions.animated_share`) before static
    ones, then chains whose tip reaches the ground, then deforming chains before control
    chains (IK, MCH, ORG…), then chains named like limbs, then the longest. A chain that
    duplicates one already taken (:func:`_duplicates`) is left out, so a static
    deforming leg gives way to its animated IK copy, and an IK copy that animates like
    the deforming leg gives way to it.
    """

    def key(lb: _Limb) -> tuple[bool, bool, bool, bool, float]:
        return (
            lb.motion <= options.animated_share,
            not lb.grounded,
            lb.control,
            not _named(t, lb),
            -t.chain_length(lb.chain),
        )

    out: list[_Limb] = []
    for lb in sorted(cands, key=key):
        if not any(_duplicates(t, lb, o, options.duplicate_share) for o in out):
            out.append(lb)
    return out


def _sided_limbs(t: _Tree) -> list[_Limb]:
    out = []
    for j in range(t.n):
        side, core = t.cues[j]
        if side is None or t.bvh.is_end_site[j]:
            continue
        p = t.parents[j]
        if p >= 0 and t.cues[p][0] is not None:
            continue
        if any(w in core for w in _NOT_LIMB) or t.never[j]:
            continue
        chain = t.leg_path(j)
        if len(chain) < 3:
            continue
        vote = sum(_fore_vote(t.cues[c][1]) for c in chain if not t.bvh.is_end_site[c])
        out.append(_Limb(j, chain, side, vote, chain_motion(t, chain), _is_control_chain(t, chain)))
    return out


def _mirrored(t: _Tree, a: list[int], b: list[int], tolerance: float) -> bool:
    """True if chains a and b are left/right mirrors: as many joints, the same bone
    lengths (the first bone, from their common parent, included) within ``tolerance`` of
    the chain's length (:attr:`MappingOptions.mirror_bone_tolerance`)."""
    if len(a) != len(b):
        return False
    la, lb = t.blen[a], t.blen[b]
    scale = max(float(la.sum()), float(lb.sum()))
    return scale > 0 and bool(np.all(np.abs(la - lb) <= tolerance * scale))


def _unsided_limbs(t: _Tree, options: MappingOptions) -> list[tuple[_Limb, _Limb]]:
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
            if t.bvh.is_end_site[c] or t.never[c] or t.height[c] < 2:
                continue
            if any(w in core for w in ("tail", "neck", "head", "spine", "chest") + _NOT_LIMB):
                continue
            chain = t.leg_path(c)
            if len(chain) < 3:
                continue
            vote = sum(_fore_vote(t.cues[k][1]) for k in chain)
            cands.append(
                _Limb(c, chain, None, vote, chain_motion(t, chain), _is_control_chain(t, chain))
            )
        used: set[int] = set()
        for a in range(len(cands)):
            for b in range(a + 1, len(cands)):
                if a in used or b in used:
                    continue
                la, lb = cands[a], cands[b]
                if not _mirrored(t, la.chain, lb.chain, options.mirror_bone_tolerance):
                    continue
                used |= {a, b}
                pairs.append((t.chain_length(la.chain) + t.chain_length(lb.chain), la, lb))

    def key(x: tuple[float, _Limb, _Limb]) -> tuple[bool, bool, float]:
        # pairs that animate first, deforming before control chains, then the longest
        _, la, lb = x
        still = min(la.motion, lb.motion) <= options.animated_share
        return (still, la.control or lb.control, -x[0])

    pairs.sort(key=key)
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


def _leg_roles(
    t: _Tree, chain: list[int], fore: bool, partner: list[int] | None = None
) -> list[int | None]:
    """Source joints for (girdle, upper, lower, foot, toe) along a leg chain (twist and
    roll segments in series spanned). Where the proportions decide the girdle, they are
    those of the chain and its left/right ``partner`` together (one choice for both)."""
    spanned = [c for c in chain if not t.segment[c]]
    if len(spanned) >= 3:
        chain = spanned
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
            both = [real]
            if partner is not None:
                other = [c for c in partner if not t.segment[c] and not t.bvh.is_end_site[c]]
                other = _digits_trimmed(t, other)
                if len(other) == len(real):
                    both.append(other)
            u = min((0, 1), key=lambda k: sum(_proportion_misfit(t, r, k, fore) for r in both))
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
