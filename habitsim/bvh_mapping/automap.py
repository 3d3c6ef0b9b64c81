"""The automatic mapping: legs, fore / hind, hips and chest, spine, neck and head, and
tail found from a source rig's names and hierarchy (:func:`auto_map`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..bvh import BVHData
from ..errors import SkeletonMappingError
from ..skeleton import JOINT_NAMES
from .chains import _FORE_SEGS, _HIND_SEGS, _LEG_CHAINS
from .clip_cues import axis_vector, body_travel, carries_skull, low_heights
from .frame import FrameConversion, detect_frame, find_up
from .limbs import (
    _describe_limbs,
    _duplicates,
    _leg_roles,
    _Limb,
    _pick_legs,
    _sided_limbs,
    _unsided_limbs,
)
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
    lefts = _pick_legs(t, [lb for lb in limbs if lb.side == "l"], options)
    rights = _pick_legs(t, [lb for lb in limbs if lb.side == "r"], options)
    pairs: list[tuple[_Limb, _Limb]]
    geometric = False
    if len(lefts) >= 2 and len(rights) >= 2:
        # the ground the first choice of feet stands on decides which chains reach it
        if _mark_grounded(t, lefts[:2] + rights[:2], limbs, options):
            lefts = _pick_legs(t, [lb for lb in limbs if lb.side == "l"], options)
            rights = _pick_legs(t, [lb for lb in limbs if lb.side == "r"], options)
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
    _note_leg_choice(t, pairs, limbs, options, note)

    # Fore / hind: the end of the trunk that carries the head, then names, then which way
    # the body goes over the clip, then hierarchy (legs hanging closer to the root are hind).
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
    geo = _trunk_geometry(t, pairs, attach, options)
    fore_i: int | None
    if geo.by_head is not None and geo.head_chain:
        fore_i = geo.by_head
        if fore_i != (by_name if by_name is not None else by_tree):
            note(
                MappingNote.FORE_FROM_HEAD,
                f"fore legs are those at the head's end of the trunk "
                f"({bvh.names[geo.head_chain[0]]} carries the skull), against the "
                f"{'names' if by_name is not None else 'hierarchy'}",
            )
    elif by_name is not None:
        fore_i = by_name
        if by_tree is not None and by_name != by_tree:
            note(
                MappingNote.NAMES_OVER_HIERARCHY,
                "fore/hind from the names contradicts the hierarchy; the names were used",
            )
    elif geo.by_travel is not None:
        fore_i = geo.by_travel
        note(
            MappingNote.FORE_FROM_TRAVEL,
            f"fore legs are those the body moves toward over the clip "
            f"({abs(geo.travel):.2f} leg lengths/s)"
            + ("" if by_tree is None or by_tree == fore_i else ", against the hierarchy"),
        )
    else:
        fore_i = by_tree
    if fore_i is None:
        raise SkeletonMappingError(
            f"{bvh.source}: found 4 legs but cannot tell fore from hind legs: all hang from "
            f"{bvh.names[attach[0]]!r}, no head chain carries a skull, the clip does not travel "
            "and the names carry no fore/hind cue (Arm/Hand/Shoulder/"
            "Front vs UpLeg/Thigh/Foot/Hind). Give an explicit joint map with --map."
        )
    if geo.by_travel is not None and geo.by_travel != fore_i:
        note(
            MappingNote.TRAVEL_DISAGREES,
            f"the body moves toward the hind legs over the clip ({abs(geo.travel):.2f} leg "
            "lengths/s): a backward walk, or fore and hind swapped (check with inspect-bvh)",
        )
    fore, hind = pairs[fore_i], pairs[1 - fore_i]
    hips, chest = attach[1 - fore_i], attach[fore_i]

    names = bvh.names
    joints: dict[str, str | None] = {n: None for n in JOINT_NAMES}
    joints["pelvis"] = names[hips]
    for pair, limb in ((fore, "f"), (hind, "h")):
        segs = _FORE_SEGS if limb == "f" else _HIND_SEGS
        for lb, side, other in zip(pair, ("l", "r"), pair[::-1], strict=True):
            if lb.side is not None:
                side = lb.side
            roles = _leg_roles(t, lb.chain, limb == "f", other.chain)
            for seg, src in zip(segs, roles, strict=True):
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
    skulls = [c for c in geo.ends[fore_i] if geo.skull[c]]
    if skulls and head_start not in skulls:
        # the chain at the fore end that carries the skull is the head, whatever the names
        by_names = head_start
        head_start = _best_named(t, skulls, ("neck", "head", "skull"))
        note(
            MappingNote.HEAD_TAIL_FROM_GEOMETRY,
            f"head chain {names[head_start]} found by geometry (at the fore end, carries "
            "the skull)"
            + ("" if by_names is None else f", not {names[by_names]} as the names say"),
        )
    head_chain = t.deepest_path(head_start) if head_start is not None else []
    if head_chain:
        non_end = [c for c in head_chain if not bvh.is_end_site[c]]
        head = next((c for c in non_end if any(w in t.cues[c][1] for w in ("head", "skull"))), None)
        if head is None and head_start in skulls:
            # the joint that carries the skull (jaw, ears, nose hang from it)
            head = next(c for c in reversed(non_end) if len(t.kids[c]) >= 2)
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
    behind = [c for c in geo.ends[1 - fore_i] if geo.behind[c] and c != head_start]
    if behind and tail_start not in behind:
        # the tail lies behind the hind legs, whatever the names
        by_names = tail_start
        tail_start = _best_named(t, behind, ("tail",))
        note(
            MappingNote.HEAD_TAIL_FROM_GEOMETRY,
            f"tail chain {names[tail_start]} found by geometry (behind the hind legs)"
            + ("" if by_names is None else f", not {names[by_names]} as the names say"),
        )
    if tail_start is not None:
        tc = t.deepest_path(tail_start)
        joints["tail1"] = names[tc[0]]
        if len(tc) >= 2:
            joints["tail3"] = names[tc[-1]]
        if len(tc) >= 3:
            joints["tail2"] = names[tc[(len(tc) - 1) // 2]]
    else:
        note(MappingNote.NO_TAIL, "no tail chain found at the hips")

    sides = [("lf", "rf"), ("lh", "rh")] if geometric else []
    return _Analysis(joints, sides, notes, codes)


def _best_named(t: _Tree, chains: list[int], words: tuple[str, ...]) -> int:
    """The chain start among ``chains`` whose chain is named with one of ``words``, else
    the one with the longest chain below it."""

    def key(c: int) -> tuple[bool, int]:
        named = any(w in t.cues[k][1] for k in t.deepest_path(c) for w in words)
        return (not named, -t.height[c])

    return min(chains, key=key)


@dataclass
class _TrunkGeometry:
    """What the clip shows of the trunk's two ends (the two leg pairs' ends)."""

    ends: tuple[list[int], list[int]]  # free chain starts at each pair's end
    skull: dict[int, bool]  # chain start -> carries a skull (branches)
    behind: dict[int, bool]  # chain start -> lies beyond its end's leg roots
    by_head: int | None  # the pair at the only end with a skull-carrying chain
    head_chain: list[int]  # that chain (start first)
    travel: float  # the body's speed toward pair 1 [leg lengths / s]
    by_travel: int | None  # the pair the body moves toward, if fast enough


def _trunk_geometry(
    t: _Tree,
    pairs: list[tuple[_Limb, _Limb]],
    attach: list[int],
    options: MappingOptions,
) -> _TrunkGeometry:
    """The head's end and the body's travel, from the clip.

    The free chains (unsided, neither a leg nor a control bone, with two joints or a
    branch) hanging from the trunk between the leg pairs or above it belong to the end
    whose leg roots they lie nearer over the clip. A chain carries a skull when it
    branches (jaw, ears, eyes; :func:`~habitsim.bvh_mapping.clip_cues.carries_skull`);
    when only one end has such a chain, that end is the head's. The travel is the
    stance feet's sweep along the trunk (:func:`~habitsim.bvh_mapping.clip_cues.body_travel`).
    """
    pos, _ = t.fk()
    roots = [[lb.root for lb in pair] for pair in pairs]
    feet = [lb.chain[-1] for pair in pairs for lb in pair]
    leg = float(np.mean([t.chain_length(lb.chain) for pair in pairs for lb in pair]))
    ev = find_up(
        pos,
        t.bvh.fk(rest=True),
        feet,
        roots[0] + roots[1],
        max(leg, 1e-9),
        options=options,
    )
    up = axis_vector(ev.axis)
    a, b = pos[:, roots[0]].mean(axis=1), pos[:, roots[1]].mean(axis=1)
    d = b - a
    d = d - (d @ up)[:, None] * up
    n = np.linalg.norm(d, axis=-1, keepdims=True)
    d = d / np.where(n > 1e-9, n, 1.0)
    mid = 0.5 * (a + b)
    half = np.maximum(0.5 * n[:, 0], 1e-9)

    trunk = set(t.path(attach[0], attach[1]))
    for j in list(trunk):
        trunk |= set(t.ancestors(j))
    leg_joints = {c for pair in pairs for lb in pair for c in lb.chain}
    ends: tuple[list[int], list[int]] = ([], [])
    skull: dict[int, bool] = {}
    behind: dict[int, bool] = {}
    for j in sorted(trunk):
        for c in t.kids[j]:
            if (
                c in trunk
                or c in leg_joints
                or t.bvh.is_end_site[c]
                or t.cues[c][0] is not None
                or t.control[c]
            ):
                continue
            chain = [k for k in t.deepest_path(c) if not t.bvh.is_end_site[k]]
            branched = carries_skull(t, chain)
            if len(chain) < 2 and not branched:
                continue
            # where the chain lies along the trunk: -1 at pair 0's roots, +1 at pair 1's
            along = np.sum((pos[:, chain].mean(axis=1) - mid) * d, axis=-1) / half
            k = int(np.median(along) > 0)
            ends[k].append(c)
            skull[c] = branched
            behind[c] = bool(abs(float(np.median(along))) > 1.0)
    with_skull = [k for k in (0, 1) if any(skull[c] for c in ends[k])]
    by_head = with_skull[0] if len(with_skull) == 1 else None
    head_chain: list[int] = []
    if by_head is not None:
        start = _best_named(t, [c for c in ends[by_head] if skull[c]], ("neck", "head", "skull"))
        head_chain = t.deepest_path(start)
    travel = body_travel(
        pos,
        feet,
        (roots[0], roots[1]),
        up,
        leg,
        t.bvh.fps,
        options.low_percentile,
        options.down_share,
    )
    by_travel = None if abs(travel) < options.travel_speed else int(travel > 0)
    return _TrunkGeometry(ends, skull, behind, by_head, head_chain, travel, by_travel)


def _mark_grounded(
    t: _Tree, picks: list[_Limb], limbs: list[_Limb], options: MappingOptions
) -> bool:
    """Mark which leg chains reach the ground the first choice of feet stands on
    (:attr:`MappingOptions.ground_share`); True if any does not."""
    pos, _ = t.fk()
    feet = [lb.chain[-1] for lb in picks]
    leg = float(np.mean([t.chain_length(lb.chain) for lb in picks]))
    if leg <= 0:
        return False
    ev = find_up(pos, t.bvh.fk(rest=True), feet, [lb.root for lb in picks], leg, options=options)
    up = axis_vector(ev.axis)
    pct = options.low_percentile
    ground = float(low_heights(pos, feet, up, pct).min())
    tips = low_heights(pos, [lb.chain[-1] for lb in limbs], up, pct)
    for lb, low in zip(limbs, tips, strict=True):
        lb.grounded = bool(low <= ground + options.ground_share * t.chain_length(lb.chain))
    return not all(lb.grounded for lb in limbs)


def _note_leg_choice(
    t: _Tree,
    pairs: list[tuple[_Limb, _Limb]],
    limbs: list[_Limb],
    options: MappingOptions,
    note: Callable[[MappingNote, str], None],
) -> None:
    """Notes on control chains taken as legs and on legs that hardly animate.

    Raises:
        SkeletonMappingError: a leg chosen keeps one pose while other legs move: no chain
            of the rig animates it.
    """
    names = t.bvh.names
    chosen = [lb for pair in pairs for lb in pair]
    for lb in chosen:
        if not lb.control:
            continue
        passed = [
            o
            for o in limbs
            if o not in chosen
            and o.side == lb.side
            and not o.control
            and _duplicates(t, o, lb, options.duplicate_share)
        ]
        why = (
            f"; the deforming chain {names[passed[0].root]} does not animate"
            if passed and passed[0].motion <= options.animated_share
            else ""
        )
        note(
            MappingNote.CONTROL_LEG,
            f"control-named chain {names[lb.root]} > … > {names[lb.chain[-1]]} taken as a leg: "
            f"it animates{why}",
        )
    moving = [lb for lb in chosen if lb.motion > options.animated_share]
    if not moving:
        return
    # a tip moving less than a millionth of its chain is the arithmetic, not motion
    frozen = [lb for lb in chosen if lb.motion <= 1e-6]
    if frozen:
        chains = "; ".join(" > ".join(names[c] for c in lb.chain) for lb in frozen)
        raise SkeletonMappingError(
            f"{t.bvh.source}: no chain of this rig animates {len(frozen)} of its legs "
            f"({chains} keep one pose while the other legs move); the clip may drive them "
            "by IK targets that were not baked into the joints. Export the clip with the "
            "leg joints baked, or map the animated chains with --map "
            "(habitsim data inspect-bvh lists the rig's chains)"
        )
    for lb in chosen:
        if lb.motion <= options.animated_share:
            note(
                MappingNote.LEG_STATIC,
                f"leg chain {names[lb.root]} hardly animates while other legs do; "
                "check the mapping with inspect-bvh",
            )


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
    options = options or MappingOptions()
    an = _analyse(bvh, options)
    if an.geometric_sides:
        frame = detect_frame(bvh, an.joints, options=options)
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
