"""Kinematic physical-plausibility metrics (docs/metrics.md, "Kinematic physical plausibility").

Every metric works on the joint positions of a motion from forward kinematics, with the
ground plane at z = 0 and thresholds relative to the species' hind-leg length L
(:attr:`habitsim.species.Species.leg_length`). Keys (exactly docs/metrics.md's, plus the
size-normalised variants):

=============================  ===========================================================
key                            definition
=============================  ===========================================================
``penetration_mm``             per frame, depth below the ground of the lowest foot point
                               (the four toe end points), 0 if above; mean over frames [mm]
``float_mm``                   per frame, height of the lowest body point (any joint) above
                               the ground if it exceeds 1 % of L, else 0; mean over frames
``skate_mm``                   over consecutive frames (t, t+1), the horizontal toe
                               displacement of every foot in contact in both frames, averaged
                               over all such foot-frame pairs [mm] (0 when there is none).
                               A foot sliding 1 cm per frame while in contact reads 10.
``skate_ratio``                share of frame pairs (t, t+1) in which at least one foot in
                               contact in both frames moves horizontally faster than 10 % of
                               L per second, the speed being a 5-frame centred moving average
                               over that foot's contacting frame pairs (swing speed never
                               leaks into the average); 0 for a one-frame clip
``jerk``                       mean over frames and joints of ‖Δ³x‖·fps³ [m/s³], the third
                               forward difference of the global joint positions (NaN with
                               fewer than 4 frames)
``bone_length_error_mm``       max over frames and bones of | ‖x_j − x_parent(j)‖ − the
                               skeleton's bone length | [mm]
``joint_limit_violation_rad``  mean over frames and hinges (:data:`habitsim.hinges.HINGE_NAMES`,
                               34 angles) of the amount by which the hinge angle lies outside
                               the species' limits [lo, hi] (0 inside) [rad]
``penetration_per_leg``        penetration_mm / 1000 / L (dimensionless)
``float_per_leg``              float_mm / 1000 / L
``skate_per_leg``              skate_mm / 1000 / L
``bone_length_error_per_leg``  bone_length_error_mm / 1000 / L
=============================  ===========================================================

Contact for ``skate_mm`` / ``skate_ratio`` is docs/metrics.md's: toe height < 2 % of L in
*both* frames of a pair. When explicit ``contacts`` labels (T, 4) are passed to
:func:`kinematic_metrics` (e.g. simulated contacts), a foot counts as contacting in a
pair when the labels say so in both frames instead. A motion's own ``contacts``
attribute is not used implicitly, so the default is always the literal definition.
"""

from __future__ import annotations

import math

import numpy as np

from habitsim.errors import InvalidMotionError
from habitsim.hinges import hinge_angles, hinge_limits
from habitsim.motion import Motion
from habitsim.physics_constants import CONTACT_HEIGHT_PER_LEG

__all__ = [
    "FLOAT_TOLERANCE_PER_LEG",
    "SKATE_SPEED_PER_LEG",
    "SKATE_SMOOTHING_FRAMES",
    "KINEMATIC_KEYS",
    "penetration_mm",
    "float_mm",
    "skate_mm",
    "skate_ratio",
    "jerk",
    "bone_length_error_mm",
    "joint_limit_violation_rad",
    "kinematic_metrics",
]

#: ``float_mm`` tolerance as a fraction of the hind-leg length.
FLOAT_TOLERANCE_PER_LEG = 0.01
#: ``skate_ratio`` speed threshold in hind-leg lengths per second.
SKATE_SPEED_PER_LEG = 0.10
#: Moving-average window of ``skate_ratio`` [frames].
SKATE_SMOOTHING_FRAMES = 5

KINEMATIC_KEYS = (
    "penetration_mm",
    "float_mm",
    "skate_mm",
    "skate_ratio",
    "jerk",
    "bone_length_error_mm",
    "joint_limit_violation_rad",
    "penetration_per_leg",
    "float_per_leg",
    "skate_per_leg",
    "bone_length_error_per_leg",
)


def _leg(motion: Motion) -> float:
    return motion.species_info.leg_length


def _positions(motion: Motion, positions: np.ndarray | None) -> np.ndarray:
    return motion.global_positions() if positions is None else np.asarray(positions, np.float64)


def penetration_mm(motion: Motion, positions: np.ndarray | None = None) -> float:
    """Mean over frames of the lowest toe's depth below the ground [mm].

    Args:
        motion: the motion.
        positions: optional precomputed (T, J, 3) global joint positions [m].
    """
    pos = _positions(motion, positions)
    low = pos[:, motion.skeleton.foot_indices, 2].min(axis=1)
    return float(np.maximum(-low, 0.0).mean() * 1000.0)


def float_mm(motion: Motion, positions: np.ndarray | None = None) -> float:
    """Mean over frames of the lowest body point's height if above 1 % of L, else 0 [mm]."""
    pos = _positions(motion, positions)
    low = pos[:, :, 2].min(axis=1)
    tol = FLOAT_TOLERANCE_PER_LEG * _leg(motion)
    return float(np.where(low > tol, low, 0.0).mean() * 1000.0)


def _pair_contacts(motion: Motion, feet: np.ndarray, contacts: np.ndarray | None) -> np.ndarray:
    """(T-1, 4) bool: foot in contact in both frames of the pair (t, t+1)."""
    if contacts is None:
        c = feet[..., 2] < CONTACT_HEIGHT_PER_LEG * _leg(motion)
    else:
        c = np.asarray(contacts, dtype=bool)
        if c.shape != feet.shape[:2]:
            raise InvalidMotionError(f"contacts must have shape {feet.shape[:2]}, got {c.shape}")
    return c[1:] & c[:-1]


def _feet(motion: Motion, positions: np.ndarray | None) -> np.ndarray:
    return _positions(motion, positions)[:, motion.skeleton.foot_indices]


def skate_mm(
    motion: Motion, contacts: np.ndarray | None = None, positions: np.ndarray | None = None
) -> float:
    """Mean horizontal toe displacement over foot-frame pairs in contact in both frames [mm].

    Args:
        motion: the motion.
        contacts: optional (T, 4) contact labels replacing the height criterion.
        positions: optional precomputed (T, J, 3) global joint positions [m].
    """
    feet = _feet(motion, positions)
    if feet.shape[0] < 2:
        return 0.0
    both = _pair_contacts(motion, feet, contacts)
    disp = np.linalg.norm(np.diff(feet[..., :2], axis=0), axis=-1)  # (T-1, 4) [m]
    if not both.any():
        return 0.0
    return float(disp[both].mean() * 1000.0)


def _masked_moving_average(x: np.ndarray, mask: np.ndarray, window: int) -> np.ndarray:
    """Centred moving average along axis 0 over the entries where ``mask`` holds."""
    half = window // 2
    xm = np.where(mask, x, 0.0)
    pad = ((half, half), (0, 0))
    cs = np.cumsum(np.pad(xm, pad), axis=0)
    cn = np.cumsum(np.pad(mask.astype(np.float64), pad), axis=0)
    cs = np.concatenate([np.zeros((1, x.shape[1])), cs], axis=0)
    cn = np.concatenate([np.zeros((1, x.shape[1])), cn], axis=0)
    s = cs[window:] - cs[:-window]
    n = cn[window:] - cn[:-window]
    return np.where(n > 0, s / np.maximum(n, 1.0), 0.0)


def skate_ratio(
    motion: Motion, contacts: np.ndarray | None = None, positions: np.ndarray | None = None
) -> float:
    """Share of frame pairs with a contacting foot faster than 10 % of L per second.

    Speeds are smoothed with a 5-frame centred moving average over the foot's
    contacting frame pairs (see the module docstring).
    """
    feet = _feet(motion, positions)
    if feet.shape[0] < 2:
        return 0.0
    both = _pair_contacts(motion, feet, contacts)
    speed = np.linalg.norm(np.diff(feet[..., :2], axis=0), axis=-1) * motion.fps  # (T-1, 4)
    smooth = _masked_moving_average(speed, both, SKATE_SMOOTHING_FRAMES)
    skating = both & (smooth > SKATE_SPEED_PER_LEG * _leg(motion))
    return float(skating.any(axis=1).mean())


def jerk(motion: Motion, positions: np.ndarray | None = None) -> float:
    """Mean norm of the third finite difference of joint positions times fps³ [m/s³].

    NaN for clips shorter than 4 frames.
    """
    pos = _positions(motion, positions)
    if pos.shape[0] < 4:
        return math.nan
    d3 = np.diff(pos, n=3, axis=0) * motion.fps**3
    return float(np.linalg.norm(d3, axis=-1).mean())


def bone_length_error_mm(motion: Motion, positions: np.ndarray | None = None) -> float:
    """Max deviation of the bone lengths measured on the positions from the skeleton's [mm]."""
    pos = _positions(motion, positions)
    skel = motion.skeleton
    child = np.array([j for j, p in enumerate(skel.parents) if p >= 0])
    par = np.array([skel.parents[j] for j in child])
    lengths = np.linalg.norm(pos[:, child] - pos[:, par], axis=-1)
    return float(np.abs(lengths - skel.bone_lengths[child]).max() * 1000.0)


def joint_limit_violation_rad(motion: Motion) -> float:
    """Mean over frames and hinges of the amount outside the species' joint limits [rad]."""
    ang = hinge_angles(motion)
    lim = hinge_limits(motion.species)
    a = np.stack([ang[h] for h in ang], axis=1)  # (T, H)
    lo = np.array([lim[h][0] for h in ang])
    hi = np.array([lim[h][1] for h in ang])
    excess = np.maximum(lo - a, 0.0) + np.maximum(a - hi, 0.0)
    return float(excess.mean())


def kinematic_metrics(motion: Motion, contacts: np.ndarray | None = None) -> dict[str, float]:
    """All kinematic plausibility metrics of a motion (keys: :data:`KINEMATIC_KEYS`).

    Args:
        motion: the motion.
        contacts: optional (T, 4) bool contact labels (LF, RF, LH, RH) used by the skating
            metrics instead of docs/metrics.md's height criterion.

    Returns:
        Metric key → value (floats; ``jerk`` is NaN for clips under 4 frames).
    """
    pos = motion.global_positions()
    leg_mm = _leg(motion) * 1000.0
    out = {
        "penetration_mm": penetration_mm(motion, pos),
        "float_mm": float_mm(motion, pos),
        "skate_mm": skate_mm(motion, contacts, pos),
        "skate_ratio": skate_ratio(motion, contacts, pos),
        "jerk": jerk(motion, pos),
        "bone_length_error_mm": bone_length_error_mm(motion, pos),
        "joint_limit_violation_rad": joint_limit_violation_rad(motion),
    }
    out["penetration_per_leg"] = out["penetration_mm"] / leg_mm
    out["float_per_leg"] = out["float_mm"] / leg_mm
    out["skate_per_leg"] = out["skate_mm"] / leg_mm
    out["bone_length_error_per_leg"] = out["bone_length_error_mm"] / leg_mm
    return out
