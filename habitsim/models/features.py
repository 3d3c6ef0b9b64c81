"""The network's per-frame representation of a motion and its inverse.

Per frame t (``FEAT_DIM`` = J·4 + J·3 + 1 + 4 = 215 numbers):

* ``q_t`` (J·4): local joint quaternions wxyz, hemisphere-continuous in time (the first
  frame of a clip has w ≥ 0) — the paper's q (Sec. 3.1);
* ``v_t`` (J·3): global joint velocities, backward differences (x_t − x_{t−1})·fps with
  v_0 = v_1, divided by √(g·h) (h = the species' standing hip height), i.e. in units of
  the Froude velocity — the paper's v, made size-free so that one network serves a cat
  and an elephant (transferred speeds follow the Froude scaling of gaits);
* ``h_t`` (1): pelvis height / h. The paper recovers the root from velocities only; a
  height channel keeps long clips from drifting vertically (a habitsim addition);
* ``c_t`` (4): foot contacts LF, RF, LH, RH (1 = stance) — the clip's stance labels
  (a synthetic clip's planned stance, an import's labels found on the source skeleton),
  detected on its toes when it has none. The decoder outputs *logits* on these channels
  (their normalisation is the identity), trained against the labels; a decoded frame is
  in stance where the logit is > 0 (:func:`decoded_contacts`). Feature version 3.

Windows are *heading-canonical*: positions, velocities and the pelvis quaternion are
turned about z by −ψ₀, ψ₀ = the pelvis heading at the window's first frame, so every
window starts facing +x; :func:`uncanonicalize` turns decoded windows back. Velocities
are expressed in that one window frame (feature version 2), not in each frame's own
heading: the root's horizontal path is then the plain integral of the decoded pelvis
velocity, and an error of the decoded pelvis yaw no longer turns the whole path
(with per-frame heading velocities, version 1, it did).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from ..motion import Motion
from ..physics_constants import GRAVITY
from ..rotations import heading_yaw, quat_fix_continuity, quat_mul
from ..skeleton import JOINT_NAMES, get_skeleton
from ..species import load_species
from .kinematics import batched_fk

__all__ = [
    "FEATURE_VERSION",
    "GRAVITY",
    "NUM_JOINTS",
    "Q_DIM",
    "V_DIM",
    "FEAT_DIM",
    "H_INDEX",
    "C_INDEX",
    "C_DIM",
    "ClipArrays",
    "clip_arrays",
    "velocity_scale",
    "heading_yaw",
    "canonical_window",
    "uncanonicalize",
    "features_to_motion",
    "decoded_contacts",
    "window_positions",
    "batched_fk",
    "species_offsets",
]

#: Version of this representation; a checkpoint records the one it was trained on.
FEATURE_VERSION = 3
NUM_JOINTS = len(JOINT_NAMES)
Q_DIM = NUM_JOINTS * 4
V_DIM = NUM_JOINTS * 3
H_INDEX = Q_DIM + V_DIM
C_INDEX = H_INDEX + 1
C_DIM = 4
FEAT_DIM = C_INDEX + C_DIM


def velocity_scale(species: str) -> float:
    """√(g·h) [m/s] of a species (h = standing hip height): the unit of ``v_t``."""
    return math.sqrt(GRAVITY * load_species(species).hip_height)


def _yaw_quat(yaw: np.ndarray | float) -> np.ndarray:
    half = 0.5 * np.asarray(yaw, dtype=np.float64)
    return np.stack([np.cos(half), np.zeros_like(half), np.zeros_like(half), np.sin(half)], axis=-1)


def _rotate_z(v: np.ndarray, yaw: np.ndarray | float) -> np.ndarray:
    """Rotate vectors (…, 3) about z by ``yaw`` (broadcast against v's leading axes)."""
    yaw = np.asarray(yaw, dtype=np.float64)
    yaw = yaw.reshape(yaw.shape + (1,) * (np.ndim(v) - 1 - yaw.ndim))
    c, s = np.cos(yaw), np.sin(yaw)
    out = np.array(v, dtype=np.float64, copy=True)
    out[..., 0] = c * v[..., 0] - s * v[..., 1]
    out[..., 1] = s * v[..., 0] + c * v[..., 1]
    return out


@dataclass(frozen=True)
class ClipArrays:
    """A motion pre-processed for windowing (world frame, float64).

    Attributes:
        species: catalog species name.
        fps: frame rate [Hz].
        quats: (T, J, 4) local quaternions, continuous in time, w ≥ 0 at frame 0.
        velocities: (T, J, 3) global joint velocities / √(g·h), world frame.
        height: (T,) pelvis height / h.
        yaw: (T,) pelvis heading [rad].
        root: (T, 3) pelvis positions [m].
        contacts: (T, 4) stance labels as 0.0 / 1.0, feet LF, RF, LH, RH.
        meta: the motion's metadata (action, pair key, …).
    """

    species: str
    fps: float
    quats: np.ndarray
    velocities: np.ndarray
    height: np.ndarray
    yaw: np.ndarray
    root: np.ndarray
    contacts: np.ndarray
    meta: dict[str, Any]

    @property
    def num_frames(self) -> int:
        return int(self.quats.shape[0])


def clip_arrays(motion: Motion) -> ClipArrays:
    """Pre-process a :class:`~habitsim.motion.Motion` (see the module docstring)."""
    q = np.array(motion.rotations, dtype=np.float64, copy=True)
    q[0][q[0, :, 0] < 0] *= -1.0
    q = quat_fix_continuity(q, axis=0)
    x = motion.global_positions()
    v = np.zeros_like(x)
    if x.shape[0] > 1:
        v[1:] = (x[1:] - x[:-1]) * motion.fps
        v[0] = v[1]
    sp = load_species(motion.species)
    yaw = heading_yaw(q[:, 0])
    if motion.contacts is not None:
        labels = np.asarray(motion.contacts, dtype=bool)
    else:
        from ..contacts import contacts_from_feet

        labels = contacts_from_feet(x[:, motion.skeleton.foot_indices], motion.fps, sp.leg_length)
    return ClipArrays(
        species=motion.species,
        fps=float(motion.fps),
        quats=q,
        velocities=v / velocity_scale(motion.species),
        height=motion.root_positions[:, 2] / sp.hip_height,
        yaw=yaw,
        root=np.array(motion.root_positions, dtype=np.float64),
        contacts=labels.astype(np.float64),
        meta=dict(motion.metadata),
    )


def canonical_window(
    clip: ClipArrays, start: int, length: int
) -> tuple[np.ndarray, np.ndarray, float]:
    """Heading-canonical features of frames ``start : start + length``.

    Frames past the clip's end repeat its last frame (edge padding).

    Returns:
        ``(features (length, FEAT_DIM) float32, valid (length,) bool, yaw0 [rad])``.
    """
    t = clip.num_frames
    if not 0 <= start < t:
        raise IndexError(f"window start {start} outside a {t}-frame clip")
    idx = np.minimum(np.arange(start, start + length), t - 1)
    valid = np.arange(start, start + length) < t
    yaw0 = float(clip.yaw[start])
    q = clip.quats[idx].copy()
    q[:, 0] = quat_mul(_yaw_quat(-yaw0), q[:, 0])
    v = _rotate_z(clip.velocities[idx], -yaw0)
    feats = np.concatenate(
        [
            q.reshape(length, -1),
            v.reshape(length, -1),
            clip.height[idx, None],
            clip.contacts[idx],
        ],
        axis=1,
    )
    return feats.astype(np.float32), valid, yaw0


def uncanonicalize(feats: np.ndarray, yaw0: float) -> np.ndarray:
    """Turn canonical window features (T, FEAT_DIM) back to heading ``yaw0`` (float64).

    The pelvis quaternion and every joint velocity turn; local rotations, the height and
    the contacts do not.
    """
    f = np.array(feats, dtype=np.float64, copy=True)
    t = f.shape[0]
    q = f[:, :Q_DIM].reshape(t, NUM_JOINTS, 4)
    q[:, 0] = quat_mul(_yaw_quat(yaw0), q[:, 0])
    f[:, :Q_DIM] = q.reshape(t, -1)
    v = f[:, Q_DIM:H_INDEX].reshape(t, NUM_JOINTS, 3)
    f[:, Q_DIM:H_INDEX] = _rotate_z(v, yaw0).reshape(t, -1)
    return f


def features_to_motion(
    feats: np.ndarray,
    species: str,
    fps: float,
    root_start_xy: np.ndarray | None = None,
    metadata: dict[str, Any] | None = None,
) -> Motion:
    """Build a Motion on ``species``' skeleton from world-frame features (T, FEAT_DIM).

    Rotations are the normalised quaternion part; the pelvis height is h·``h_t``; its
    horizontal path integrates the (world-frame) pelvis velocity ·√(g·h) from
    ``root_start_xy`` [m].
    """
    f = np.asarray(feats, dtype=np.float64)
    t = f.shape[0]
    sp = load_species(species)
    q = f[:, :Q_DIM].reshape(t, NUM_JOINTS, 4)
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    q = np.where(n > 1e-6, q / np.maximum(n, 1e-12), np.array([1.0, 0.0, 0.0, 0.0]))
    v_root = f[:, Q_DIM : Q_DIM + 3] * velocity_scale(species)
    root = np.zeros((t, 3))
    start = (
        np.zeros(2) if root_start_xy is None else np.asarray(root_start_xy, dtype=np.float64)[:2]
    )
    steps = np.concatenate([np.zeros((1, 2)), v_root[1:, :2] / fps], axis=0)
    root[:, :2] = start[None] + np.cumsum(steps, axis=0)
    root[:, 2] = f[:, H_INDEX] * sp.hip_height
    return Motion(species, fps, root, q, None, dict(metadata or {}))


def decoded_contacts(feats: np.ndarray) -> np.ndarray:
    """Stance labels (T, 4) bool of decoded features (T, FEAT_DIM): contact logit > 0.

    (A clip's own features hold 0 / 1 there, which read back as its labels.)
    """
    return np.asarray(feats)[:, C_INDEX : C_INDEX + C_DIM] > 0.0


def species_offsets(species: list[str], dtype: torch.dtype = torch.float32) -> torch.Tensor:
    """(B, J, 3) bone offsets [m] of each item's species."""
    return torch.as_tensor(np.stack([get_skeleton(s).offsets for s in species]), dtype=dtype)


def window_positions(feats: torch.Tensor, species: list[str], fps: float) -> torch.Tensor:
    """Joint positions (B, T, J, 3) [m] of canonical windows (B, T, FEAT_DIM), differentiable.

    The root starts at the origin (x, y) and integrates the pelvis velocity like
    :func:`features_to_motion`; each item uses its own species' skeleton.
    """
    b, t, _ = feats.shape
    q = feats[..., :Q_DIM].reshape(b, t, NUM_JOINTS, 4)
    scale = torch.tensor([velocity_scale(s) / fps for s in species], dtype=feats.dtype)[
        :, None, None
    ]
    hip = torch.tensor([load_species(s).hip_height for s in species], dtype=feats.dtype)[
        :, None, None
    ]
    vr = feats[..., Q_DIM : Q_DIM + 2] * scale
    xy = torch.cumsum(torch.cat([torch.zeros_like(vr[:, :1]), vr[:, 1:]], dim=1), dim=1)
    root = torch.cat([xy, feats[..., H_INDEX : H_INDEX + 1] * hip], dim=-1)
    return batched_fk(root, q, species_offsets(species, feats.dtype))
