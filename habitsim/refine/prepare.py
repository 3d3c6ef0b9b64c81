"""Preparing a clip for its windows: targets, labels, ground alignment, initial guess."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np

from ..errors import InvalidMotionError
from ..motion import Motion
from ..qpos import (
    motion_to_qpos,
    qpos_joint_positions,
    qpos_to_motion,
)
from ..stance.labels import StanceLabels
from ..stance.planting import PlantingOptions, plant_motion
from .cleaning import clean_contact_labels, cleaning_summary
from .clearance import swing_clearance
from .filtering import _lowpass_qpos, jitter_autocorr
from .options import RefineOptions
from .problem import (
    ModelInfo,
    RefinementProblem,
)


def _cleaned(
    labels_in: StanceLabels,
    toes: np.ndarray,
    fps: float,
    leg_length: float,
    opts: RefineOptions,
) -> tuple[StanceLabels, dict[str, Any]]:
    """``labels_in`` cleaned on the toe paths ``toes`` (T, 4, 3) [m] with the options'
    cleaning knobs, and the cleaning's report entry (:func:`cleaning_summary`)."""
    labels = clean_contact_labels(
        labels_in,
        toes,
        fps,
        leg_length,
        slip_per_leg=opts.stance_slip_per_leg,
        min_run_s=opts.min_run_s,
        trim=opts.trim_contacts,
        max_trim_share=opts.max_trim_share,
    )
    return labels, cleaning_summary(labels, since=len(labels_in.edits))


def _ground_offset(
    targets: np.ndarray, contacts: np.ndarray, fps: float, toe_idx: list[int]
) -> np.ndarray:
    """(T,) smooth vertical offset: mean toe height of the feet in contact."""
    t = targets.shape[0]
    toe_z = targets[:, toe_idx, 2]
    n = contacts.sum(axis=1)
    have = n > 0
    if not np.any(have):
        return np.zeros(t)
    raw = np.where(have, (toe_z * contacts).sum(axis=1) / np.maximum(n, 1), np.nan)
    frames = np.arange(t)
    filled = np.interp(frames, frames[have], raw[have])
    k = max(1, int(round(0.25 * fps)))
    if k > 1 and t > 1:
        pad = np.pad(filled, (k // 2, k - 1 - k // 2), mode="edge")
        filled = np.convolve(pad, np.ones(k) / k, mode="valid")
    return filled


@dataclass
class _Prepared:
    model: mujoco.MjModel
    qpos_in: np.ndarray
    targets: np.ndarray
    qref: np.ndarray
    href: np.ndarray
    x0: np.ndarray
    labels: StanceLabels  # the labels planted (cleaned)
    glob: dict[str, float]
    offset: np.ndarray
    swing_floor: np.ndarray | None
    clearance: np.ndarray | None
    pins: np.ndarray
    labels_input: StanceLabels  # the labels as they came (given, the input's, detected)
    cleaning: dict[str, Any] | None  # :func:`cleaning_summary` (None: not cleaned)
    filtered: bool = False  # the jitter pre-filter ran
    jitter: float | None = None  # :func:`jitter_autocorr` of the input (None: filter off)
    # how far the model's reading of the input's angles (``href`` as read) lies from the
    # targets: max over the frames of the mean joint distance [leg lengths]
    reading_gap: float = 0.0
    # the reading itself when ``href`` was refitted (:func:`~.attempt.fit_reference`)
    reading: np.ndarray | None = None

    @property
    def href_read(self) -> np.ndarray:
        """(T, n) the model's reading of the input's angles."""
        return self.href if self.reading is None else self.reading

    @property
    def contacts(self) -> np.ndarray:
        """(T, 4) bool labels planted (read-only)."""
        return self.labels.array


def _inside_ranges(info: ModelInfo, hinges: np.ndarray) -> np.ndarray:
    """Hinge angles clipped just inside their joint ranges (an initial guess on a bound
    would start IPOPT's barrier at infinity)."""
    span = np.where(np.isfinite(info.upper - info.lower), info.upper - info.lower, 1.0)
    margin = np.minimum(1e-6, 1e-3 * span)
    return np.clip(hinges, info.lower + margin, info.upper - margin)


def _prepare(
    motion: Motion,
    labels_in: StanceLabels,
    opts: RefineOptions,
    model: mujoco.MjModel,
    pr: RefinementProblem,
) -> _Prepared:
    info, nx, nv = pr.info, pr.nx, pr.nv
    labels = labels_in
    c = labels.array
    q_raw = motion_to_qpos(motion, model).qpos
    # the targets are the input's own joint positions (what the model's hinges cannot
    # represent, e.g. a twist, is not taken for the input's pose); the jitter filter,
    # when the clip jitters, adds its change of the model's joint positions to them
    p_in = motion.global_positions()
    f_c = opts.cutoff_hz(motion.species_info.leg_length, info.gravity)
    score = None if f_c is None else jitter_autocorr(q_raw, info, motion.fps, f_c)
    if f_c is not None and opts.jitter_autocorr is not None and score is not None:
        if score >= opts.jitter_autocorr:
            f_c = None  # no jitter: nothing to filter
    fk_raw = None if f_c is None else qpos_joint_positions(model, q_raw)

    def _filtered(labels_now: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if f_c is None or fk_raw is None:
            return q_raw, p_in
        qf = _lowpass_qpos(q_raw, info, motion.fps, f_c, labels_now)
        return qf, p_in + (qpos_joint_positions(model, qf) - fk_raw)

    q, targets = _filtered(c)
    toe_idx = [motion.skeleton.foot_indices[i] for i in range(4)]
    sp = motion.species_info
    cleaning = None
    if opts.clean_contacts:
        labels, cleaning = _cleaned(labels_in, targets[:, toe_idx], motion.fps, sp.leg_length, opts)
        c = labels.array
        if cleaning["frames_changed"] and f_c is not None:  # corners moved: filter again
            q, targets = _filtered(c)
    fk_q = qpos_joint_positions(model, q)
    gap = np.linalg.norm(fk_q - targets, axis=-1).mean(axis=1) / sp.leg_length
    offset = np.zeros(len(q))
    if opts.align_ground:
        lim = opts.max_align_per_leg * motion.species_info.leg_length
        offset = np.clip(_ground_offset(targets, c, motion.fps, toe_idx), -lim, lim)
    targets = targets.copy()
    targets[..., 2] -= offset[:, None]
    fa = info.free_qposadr
    qref = q[:, fa + 3 : fa + 7]
    href = q[:, info.hinge_qposadr]
    x0 = np.zeros((len(q), nx))
    x0[:, :3] = q[:, fa : fa + 3]
    x0[:, 2] -= offset
    x0[:, 6:nv] = _inside_ranges(info, href)
    # initial guess only: put the feet in contact on the floor frame by frame (clipping
    # out-of-range angles and the smooth alignment leave them off it by centimetres)
    sole0 = np.asarray(pr.frame.map(len(q))(x0[:, :nv].T, qref.T)[1])[2].reshape(len(q), 4)
    x0[:, 2] -= _stance_height(sole0, c)
    if nx > nv:  # stage B: weight shared by the feet in contact, spread over the edges
        share = c / np.maximum(c.sum(axis=1, keepdims=True), 1)
        x0[:, nv : nv + 16] = np.repeat(share / 4.0, 4, axis=1)
        x0[:, nv + 16 :] = np.asarray(pr.frame.map(len(q))(x0[:, :nv].T, qref.T)[2]).T
    glob = {
        "leg_length": sp.leg_length,
        "fps": motion.fps,
        "gravity": info.gravity,
        "mu": info.friction if opts.friction is None else float(opts.friction),
        **opts.weights,
    }
    # swing feet clear docs/metrics.md's contact height wherever they move (refine.solve, step 5)
    if opts.swing_clearance is None:
        clearance, pins = None, c[1:] & c[:-1]
    else:
        clearance, pins = swing_clearance(
            c,
            motion.fps,
            sp.leg_length,
            opts.swing_clearance,
            opts.swing_ramp_s,
            toes=targets[:, toe_idx],
            still=opts.swing_still_per_leg * sp.leg_length,
            sunk=opts.verify_tol_mm / 1000.0,
        )
    if opts.plant_start:
        x0[:, :nv] = _planted_start(
            motion, model, info, q, offset, c, clearance, x0[:, :nv], opts.planting
        )
    return _Prepared(
        model,
        q_raw,
        targets,
        qref,
        href,
        x0,
        labels,
        glob,
        offset,
        None,
        clearance,
        pins,
        labels_in,
        cleaning,
        f_c is not None,
        score,
        float(gap.max()),
    )


def _planted_start(
    motion: Motion,
    model: mujoco.MjModel,
    info: ModelInfo,
    q: np.ndarray,
    offset: np.ndarray,
    contacts: np.ndarray,
    clearance: np.ndarray | None,
    x0: np.ndarray,
    options: PlantingOptions | None = None,
) -> np.ndarray:
    """The initial guess of :attr:`RefineOptions.plant_start`: the (filtered, aligned)
    input with its legs planted on the labels and lifted to the clearance by leg IK.
    The root orientation stays the reference's; a frame IK could not plant keeps
    ``x0``'s pose (the solver starts there either way)."""
    qa = q.copy()
    fa = info.free_qposadr
    qa[:, fa + 2] -= offset
    aligned = qpos_to_motion(model, qa, motion.species, motion.fps)
    floor = None if clearance is None else np.where(contacts, np.nan, clearance)
    try:
        planted, _ = plant_motion(aligned, contacts, floor, options=options)
    except (InvalidMotionError, np.linalg.LinAlgError, ValueError):
        return x0
    qp = motion_to_qpos(planted, model).qpos
    out = x0.copy()
    out[:, :3] = qp[:, fa : fa + 3]
    out[:, 6:] = _inside_ranges(info, qp[:, info.hinge_qposadr])
    bad = ~np.all(np.isfinite(out), axis=1)
    out[bad] = x0[bad]
    return out


def _preplant(
    motion: Motion, labels_in: StanceLabels, opts: RefineOptions
) -> tuple[Motion, StanceLabels, dict[str, Any]]:
    """The input with its feet planted on its (cleaned) labels and lifted to the swing
    clearance by leg IK (:func:`habitsim.stance.planting.plant_motion`), the labels, and the
    label fields of :class:`_Prepared` (input labels, cleaning). The optimisation then
    starts from, and tracks, a motion whose feet already rest where they are labelled to
    and clear the ground where they move."""
    sp = motion.species_info
    labels, cleaning = labels_in, None
    if opts.clean_contacts:
        labels, cleaning = _cleaned(
            labels_in, motion.foot_positions(), motion.fps, sp.leg_length, opts
        )
    c = labels.array
    floor = None
    if opts.swing_clearance is not None:
        floor = swing_clearance(
            c, motion.fps, sp.leg_length, opts.swing_clearance, opts.swing_ramp_s
        )[0]
    planted, _ = plant_motion(motion, c, floor, options=opts.planting)
    fields_ = {"labels_input": labels_in, "cleaning": cleaning}
    return planted, labels, fields_


def _stance_height(sole: np.ndarray, contacts: np.ndarray) -> np.ndarray:
    """(T,) mean height of the soles in contact, interpolated through flight frames."""
    n = contacts.sum(axis=1)
    have = n > 0
    if not np.any(have):
        return np.zeros(len(sole))
    raw = (sole * contacts).sum(axis=1) / np.maximum(n, 1)
    frames = np.arange(len(sole))
    return np.interp(frames, frames[have], raw[have])
