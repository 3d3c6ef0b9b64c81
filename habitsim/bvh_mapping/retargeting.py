"""Retargeting a mapped source motion onto a species' skeleton: bone directions aimed
root to leaf, root translation scaled, the source's own stance labelled and its feet
planted, and each leg's mapping confidence (:func:`retarget`)."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from ..bvh import BVHData
from ..errors import SkeletonMappingError
from ..motion import Motion
from ..rotations import matrix_to_quat, quat_fix_continuity, quat_identity, quat_to_matrix
from ..skeleton import JOINT_NAMES, get_skeleton
from ..species import Species, load_species
from ..stance.labels import stance_f1
from ..stance.planting import (
    FOOT_ANCHORS,
    PlantingOptions,
    PlantReport,
    SourceStance,
    label_source_stance,
    plant_legs,
    smooth_path,
)
from ..stance.policy import resolve_planting
from .chains import _AXIAL, _END_POINTS, _HEADING, _IDX, _LEG_CHAINS, _TAIL
from .frame import _leg_ends
from .inplace import (
    InPlaceFit,
    InPlaceOptions,
    recover_in_place,
    refit_in_place,
    sweep_labels,
    trim_unreached,
)
from .loops import LoopFit, LoopOptions, detect_loop
from .names import _fore_vote
from .report import ImportReport, InPlaceRecord, SourceStanceRecord
from .result import CONFIDENCE_WARN, JointMapping, MappingNote
from .tree import _Tree


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
    bvh: BVHData,
    mapping: JointMapping,
    species: str | Species,
    plant: bool = True,
    options: PlantingOptions | None = None,
    inplace: InPlaceOptions | None = None,
    loops: LoopOptions | None = None,
) -> Motion:
    """Retarget a BVH motion onto a species' skeleton (see :mod:`habitsim.bvh_mapping`).

    Args:
        bvh: the source file.
        mapping: the joint mapping with its ``frame`` set; ``root_scale`` is filled in.
        species: the target species.
        plant: solve the legs onto the source's footholds (:mod:`habitsim.stance.planting`); when
            False the legs keep the bone directions of the source.
        options: the knobs of labelling the source's stance and planting the legs
            (:class:`~habitsim.stance.planting.PlantingOptions`); the defaults when None.
        inplace: the knobs of detecting an in-place clip and recovering its travel
            (:class:`~habitsim.bvh_mapping.inplace.InPlaceOptions`); defaults when None.
        loops: the knobs of telling a loop (:class:`~habitsim.bvh_mapping.loops.
            LoopOptions`); defaults when None.

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
    fwd_name = next((n for n in _HEADING if n in j2s), None)
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
        mapping.note(
            MappingNote.PELVIS_STANDING,
            "no spine/neck/head mapped: pelvis keeps the standing orientation",
        )
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

    # An in-place clip gets the travel its stance feet show; then the stance of the
    # source's own feet, and the ground they stand on.
    t = _Tree(bvh)
    feet_found = _source_feet(bvh, t, j2s, src, mapping, options)
    fit, loop = None, None
    if feet_found is not None:
        src, fit, loop = _recovered(src, feet_found, bvh.fps, inplace, loops, options)
        hips = s("pelvis")
    stance = _source_stance(bvh.fps, feet_found, src, options)
    # Root translation scaled by the legs' ratio (the hip-height ratio without feet),
    # heights above the source's ground; with the source's stance, the body then stands
    # on its toes (root_height_shift).
    feet = [bvh.index(j2s[n]) for n in ("lf_toe", "rf_toe", "lh_toe", "rh_toe") if n in j2s]
    if not feet:
        feet = _leg_ends(j2s, bvh)
    if stance is not None:
        ground = stance[0].ground
    elif feet:
        ground = float(np.median(src[:, feet, 2].min(axis=1)))
    else:
        ground = float(hips[:, 2].min())
    if stance is not None:
        k = leg_root_scale(sp, stance[3])
    else:
        k = _hip_root_scale(bvh, j2s, src, hips, ground, sp, stand_root, mapping)
    root = hips * k
    root[:, 2] = (hips[:, 2] - ground) * k
    mapping.root_scale = k

    q = quat_fix_continuity(q, axis=0)
    meta = {"source": "bvh", "bvh_file": Path(bvh.source).name, "mapping": mapping.to_dict()}
    motion = Motion(sp.name, bvh.fps, root, q, metadata=meta)
    if stance is None:
        return motion
    st, foot_idx, anchor_idx, limb_len, points = stance
    swept: tuple[int, ...] = ()
    labels = st.labels
    if fit is not None and fit.detected:
        labels, swept = sweep_labels(labels, fit, inplace)
        st = dataclasses.replace(st, contacts=labels.array)
    shift = root_height_shift(motion)
    if shift != 0.0:
        root = root.copy()
        root[:, 2] -= shift
        motion = Motion(sp.name, bvh.fps, root, q, metadata=meta)
    planted = None
    unreached = 0
    if plant:
        feet_src = smooth_path(src[:, foot_idx], bvh.fps, options)
        feet_src[..., 2] = st.heights
        target_len = np.array([sp.fore_leg_length] * 2 + [sp.hind_leg_length] * 2)
        unplanted = motion

        def planted_on(c: np.ndarray) -> tuple[Motion, PlantReport]:
            return plant_legs(
                unplanted,
                feet_src,
                src[:, anchor_idx],
                c,
                target_len / limb_len,
                options=options,
            )

        motion, pr = planted_on(st.contacts)
        # A swept foot's stance ends that the target's leg does not reach planted are
        # swing (a keyframed sweep longer than the leg); the legs are planted again.
        limit = (inplace or InPlaceOptions()).reach_per_leg * sp.leg_length
        cyclic = loop is not None and loop.kind is not None
        for _ in range(3 if swept else 0):
            toes = motion.foot_positions()[..., 2]
            labels, n = trim_unreached(labels, toes, swept, limit, cyclic)
            if n == 0:
                break
            unreached += n
            motion, pr = planted_on(labels.array)
        st = dataclasses.replace(st, contacts=labels.array)
        planted = tuple(pr.to_dict(sp.leg_length).items())
    else:
        motion = motion.with_contacts(st.contacts)
    found = SourceStanceRecord(
        "source foot path",
        tuple(bvh.names[i] for i in foot_idx),
        tuple(tuple(bvh.names[i] for i in pts) for pts in points),
        tuple(round(float(f - st.ground), 5) for f in st.floors),
        round(st.leg_length, 5),
        tuple(round(float(d), 4) for d in st.duty),
    )
    f1 = stance_f1(motion.detect_contacts(), st.contacts)
    _limb_confidence(t, j2s, st, limb_len, mapping)
    report = ImportReport(
        found,
        tuple(round(float(v), 4) for v in f1),
        tuple(mapping.confidence.items()),
        tuple(mapping.warnings),
        planted,
        None if fit is None or loop is None else _in_place_record(fit, loop, swept, unreached),
    )
    motion.metadata["import"] = report.to_metadata()
    motion.metadata["mapping"] = mapping.to_dict()
    return motion


def leg_root_scale(species: Species, limb_len: np.ndarray) -> float:
    """The factor from a source's root travel to the species' [-]: the species' hind-leg
    length over the source's (``limb_len``: (4,) its legs' bone paths, hip or shoulder to
    toe [m], LF, RF, LH, RH; the hind legs carry the stance test's length too).

    A constant of the rig, not of the clip: a stance foot of the source that stays put
    stays put on the species (its legs are the source's scaled by this factor), and the
    export onto a rig (:func:`habitsim.bvh_mapping.export_to_rig`) divides the travel by
    the same number, so the round trip gives the travel back exactly.
    """
    return float(species.hind_leg_length / np.mean(limb_len[2:]))


def root_height_shift(motion: Motion) -> float:
    """How far the motion's root is lowered so its body stands on its toes [m]: the median
    over the frames of the lowest toe's height.

    Heights are the source's above its ground, scaled by the legs' ratio; a rig of other
    proportions than the species' leaves the species' toes above or below the floor by
    the difference, which this removes. A motion whose stance toes rest on the floor in
    most frames (a habitsim clip written onto a rig) is moved by nothing: the export and
    the import keep one rule for the root's height. The lowest toe of a frame does not
    depend on stance labels, so a clip gives the same shift however its stance is read.
    """
    toes = motion.foot_positions()[..., 2]
    return float(np.median(toes.min(axis=1)))


def _hip_root_scale(
    bvh: BVHData,
    j2s: Mapping[str, str],
    src: np.ndarray,
    hips: np.ndarray,
    ground: float,
    sp: Species,
    stand_root: np.ndarray,
    mapping: JointMapping,
) -> float:
    """The root scale of a source without feet to measure legs on: the species' hip
    height over the source's median hip height above its ground (1 with a note when that
    is not measurable)."""
    hip_src = [bvh.index(j2s[n]) for n in ("lh_hip", "rh_hip") if n in j2s]
    if hip_src:
        h_src = float(np.median(src[:, hip_src, 2].mean(axis=1))) - ground
        h_dst = sp.hip_height
    else:
        h_src = float(np.median(hips[:, 2])) - ground
        h_dst = float(stand_root[2])
    if h_src > 1e-6:
        return h_dst / h_src
    mapping.note(
        MappingNote.ROOT_UNSCALED,
        "source hip height not measurable: root translation not scaled",
    )
    return 1.0


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

    Rig helpers are skipped (control bones too, below a joint that is not one), and so
    is a point that sinks far below the foot's others (an unnamed helper pointing into
    the ground). Below the mapped ``toe`` only its End
    Site tips count: a joint there is a marker the mapping left out (an unnamed nub,
    :func:`_digits_trimmed`).
    """
    out, todo = [], [top]
    while todo:
        j = todo.pop()
        out.append(j)
        kids = [c for c in t.kids[j] if not t.never[c] and (t.control[j] or not t.control[c])]
        if j == toe:
            kids = [c for c in kids if t.bvh.is_end_site[c]]
        todo += kids
    return out


def _in_place_record(
    fit: InPlaceFit, loop: LoopFit, swept: tuple[int, ...], unreached: int
) -> InPlaceRecord:
    """The report's record of an in-place recovery and a loop test."""
    return InPlaceRecord(
        fit.detected,
        round(fit.recovered_m, 4),
        None if fit.heading_deg is None else round(fit.heading_deg, 2),
        round(fit.root_travel_m, 4),
        round(fit.foot_sweep_m, 4),
        round(fit.backward_share, 3),
        fit.reason,
        loop.kind or "no",
        round(loop.mismatch, 4) if math.isfinite(loop.mismatch) else 99.0,
        tuple(("lf", "rf", "lh", "rh")[k] for k in swept),
        unreached_frames=unreached,
    )


_Feet = tuple[list[int], list[int], np.ndarray, list[list[int]]]


def _recovered(
    src: np.ndarray,
    feet: _Feet,
    fps: float,
    inplace: InPlaceOptions | None,
    loops: LoopOptions | None,
    planting: PlantingOptions | None = None,
) -> tuple[np.ndarray, InPlaceFit, LoopFit]:
    """The source positions with an in-place clip's travel added, what the recovery
    found and whether the clip is a loop (its poses relative to the trunk).

    The travel is found twice: from the feet that sweep back together, then again on the
    stance labelled on the clip with that travel added (``planting``: the labelling's
    knobs; :func:`~habitsim.bvh_mapping.inplace.refit_in_place`)."""
    _, anchor_idx, limb_len, points = feet
    leg = float(limb_len[2:].mean())
    trunk = src[:, anchor_idx].mean(axis=1)
    loop = detect_loop(src - trunk[:, None, :], leg, loops)
    forward = src[:, anchor_idx[:2]].mean(axis=1) - src[:, anchor_idx[2:]].mean(axis=1)
    cyclic = loop.kind is not None
    foot_paths = [src[:, pts] for pts in points]
    fit = recover_in_place(foot_paths, trunk, forward, fps, leg, cyclic=cyclic, options=inplace)
    if fit.detected:
        moved = src + fit.travel[:, None, :]
        st = label_source_stance([moved[:, pts] for pts in points], fps, leg, planting)
        labels, _ = sweep_labels(st.labels, fit, inplace)
        fit = refit_in_place(fit, foot_paths, labels.array, fps, cyclic, inplace)
        src = src + fit.travel[:, None, :]
    return src, fit, loop


def _source_feet(
    bvh: BVHData,
    t: _Tree,
    j2s: Mapping[str, str],
    src: np.ndarray,
    mapping: JointMapping,
    options: PlantingOptions | None = None,
) -> _Feet | None:
    """The source's toe joints, anchors, limb lengths and the joints each foot's stance
    is found on (``options``: the labelling's knobs, for the feet's height spread).

    None (with a note) when a leg lacks a mapped foot or shoulder / hip joint.
    """
    foot_idx, anchor_idx, lengths, points = [], [], [], []
    for prefix, anchor in zip(("lf", "rf", "lh", "rh"), FOOT_ANCHORS, strict=True):
        chain = _LEG_CHAINS[prefix]
        toe = next((j2s[n] for n in reversed(chain[2:]) if n in j2s), None)
        top = next((j2s[n] for n in reversed(chain[2:4]) if n in j2s), None)
        if toe is None or top is None or anchor not in j2s:
            mapping.note(
                MappingNote.LEG_UNPLANTED,
                f"{prefix} leg has no mapped foot or {anchor.split('_')[1]} joint: feet not "
                "labelled or planted from the source",
            )
            return None
        a, f = bvh.index(j2s[anchor]), bvh.index(toe)
        foot_idx.append(f)
        anchor_idx.append(a)
        lengths.append(t.path_length(a, f) * (mapping.frame.scale if mapping.frame else 1.0))
        points.append(_foot_points(t, bvh.index(top), f))
    # A point that sinks far below the feet's typical lowest point is an unnamed helper;
    # the fore and hind feet's points may lie up to pair_spread_per_leg apart.
    z5 = [np.percentile(src[:, pts, 2], 5, axis=0) for pts in points]
    ref = float(np.median([z.min() for z in z5]))
    tol = resolve_planting(options).pair_spread_per_leg * float(np.mean(lengths[2:]))
    points = [
        [p for p, z in zip(pts, zs, strict=True) if z >= ref - tol] or pts
        for pts, zs in zip(points, z5, strict=True)
    ]
    limb_len = np.array(lengths)
    if np.any(limb_len <= 1e-6):
        mapping.note(MappingNote.ZERO_LEG, "a source leg has zero length: feet not planted")
        return None
    return foot_idx, anchor_idx, limb_len, points


def _source_stance(
    fps: float,
    feet: _Feet | None,
    src: np.ndarray,
    options: PlantingOptions | None = None,
) -> tuple[SourceStance, list[int], list[int], np.ndarray, list[list[int]]] | None:
    """Stance labels of the source's own feet (None without ``feet``), with the feet's
    toe joints, anchors, limb lengths and points."""
    if feet is None:
        return None
    foot_idx, anchor_idx, limb_len, points = feet
    st = label_source_stance(
        [src[:, pts] for pts in points], fps, float(limb_len[2:].mean()), options
    )
    return st, foot_idx, anchor_idx, limb_len, points
