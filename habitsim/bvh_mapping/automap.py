"""The automatic mapping: legs, fore / hind, hips and chest, spine, neck and head, and
tail found from a source rig's names and hierarchy (:func:`auto_map`)."""

from __future__ import annotations

from dataclasses import dataclass

from ..bvh import BVHData
from ..errors import SkeletonMappingError
from ..skeleton import JOINT_NAMES
from .chains import _FORE_SEGS, _HIND_SEGS, _LEG_CHAINS
from .frame import FrameConversion, detect_frame
from .limbs import _describe_limbs, _leg_roles, _Limb, _sided_limbs, _unsided_limbs
from .names import _fore_vote
from .options import MappingOptions
from .result import MappingNote
from .tree import _Tree


@dataclass
class _Analysis:
    joints: dict[str, str | None]
    geometric_sides: list[
        tuple[str, str]
    ]  # leg pairs whose sides need geometry (l-prefix, r-prefix)
    notes: list[str]
    note_codes: list[MappingNote]


def _analyse(bvh: BVHData, options: MappingOptions) -> _Analysis:
    t = _Tree(bvh)
    notes: list[str] = []
    codes: list[MappingNote] = []

    def note(code: MappingNote, text: str) -> None:
        codes.append(code)
        notes.append(text)

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
        pairs = _unsided_limbs(t, options)
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
        note(
            MappingNote.GEOMETRIC_SIDES,
            "legs found from symmetric unnamed chains; left/right decided by geometry",
        )

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
        note(
            MappingNote.NAMES_OVER_HIERARCHY,
            "fore/hind from the names contradicts the hierarchy; the names were used",
        )
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
        note(MappingNote.NO_SPINE, "fore and hind legs hang from the same joint: no spine mapped")
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
        note(MappingNote.NO_NECK, "no neck/head chain found beyond the chest")

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
        note(MappingNote.NO_TAIL, "no tail chain found at the hips")

    geo = [("lf", "rf"), ("lh", "rh")] if geometric else []
    return _Analysis(joints, geo, notes, codes)


def auto_map(bvh: BVHData, options: MappingOptions | None = None) -> dict[str, str | None]:
    """Automatic habitsim ← source joint mapping from names and hierarchy.

    Left/right comes from name cues (``Left``/``Right``/``L_``/``_R``/``.L``…); legs without
    side names are taken from symmetric chains and assigned left/right here by their
    lateral position in the first frame (after :func:`detect_frame`).

    Args:
        bvh: the parsed source file.
        options: the mapping's tuning knobs (default :class:`MappingOptions`).

    Returns:
        Every habitsim joint name → source joint name or None.

    Raises:
        SkeletonMappingError: fewer than four legs, or fore and hind legs that cannot be
            told apart.
    """
    an = _analyse(bvh, options or MappingOptions())
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
