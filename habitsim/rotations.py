"""Rotation utilities on unit quaternions (w, x, y, z), rotation matrices and the 6-D form.

The functions wrap :class:`scipy.spatial.transform.Rotation` (maintained, vectorised C).
scipy stores quaternions scalar-last, habitsim stores them scalar-first (w, x, y, z)
everywhere, so every conversion between the two conventions happens in this module only
(and, for the batched, differentiable torch versions, in :mod:`habitsim.models.kinematics`).

The 6-D form is the first two columns of the rotation matrix, concatenated
``[r00, r10, r20, r01, r11, r21]`` (continuous representation, Zhou et al. CVPR 2019).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from scipy.spatial.transform import Rotation

__all__ = [
    "quat_identity",
    "quat_normalize",
    "quat_mul",
    "quat_conj",
    "quat_apply",
    "quat_to_matrix",
    "matrix_to_quat",
    "quat_from_axis_angle",
    "quat_to_axis_angle",
    "quat_fix_continuity",
    "quat_angle",
    "euler_to_quat",
    "quat_to_euler",
    "matrix_to_6d",
    "sixd_to_matrix",
    "quat_to_6d",
    "sixd_to_quat",
    "quat_slerp",
    "rot_y",
    "rot_x",
    "rot_z",
    "heading_yaw",
]


def _rotation() -> type[Rotation]:
    """scipy's Rotation, imported on first use (scipy.spatial takes ~0.3 s to import)."""
    global _ROTATION
    if _ROTATION is None:
        from scipy.spatial.transform import Rotation

        _ROTATION = Rotation
    return _ROTATION


_ROTATION: type[Rotation] | None = None


def _flat(q: np.ndarray) -> tuple[np.ndarray, tuple[int, ...]]:
    q = np.asarray(q, dtype=np.float64)
    return q.reshape(-1, q.shape[-1]), q.shape[:-1]


def quat_identity(shape: tuple[int, ...] = ()) -> np.ndarray:
    """Identity quaternions of the given batch shape, (*shape, 4)."""
    q = np.zeros((*shape, 4))
    q[..., 0] = 1.0
    return q


def quat_normalize(q: np.ndarray) -> np.ndarray:
    """Unit quaternions (…, 4); raises ValueError on a zero-norm quaternion."""
    q = np.asarray(q, dtype=np.float64)
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    if np.any(n < 1e-12):
        raise ValueError("zero-norm quaternion cannot be normalised")
    return q / n


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a ⊗ b of quaternions (…, 4) wxyz, broadcast over the batch.

    Written as the explicit product (not through scipy) so that the sign of the result
    is the algebraic one: composing keeps a time series continuous.
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


def quat_conj(q: np.ndarray) -> np.ndarray:
    """Conjugate (= inverse for unit quaternions), (…, 4)."""
    q = np.array(q, dtype=np.float64, copy=True)
    q[..., 1:] *= -1.0
    return q


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (…, 3, 3) from quaternions (…, 4) wxyz (normalised first)."""
    flat, shape = _flat(q)
    return _rotation().from_quat(flat, scalar_first=True).as_matrix().reshape(*shape, 3, 3)


def matrix_to_quat(m: np.ndarray) -> np.ndarray:
    """Quaternions (…, 4) wxyz with w ≥ 0 from rotation matrices (…, 3, 3)."""
    m = np.asarray(m, dtype=np.float64)
    shape = m.shape[:-2]
    q = _rotation().from_matrix(m.reshape(-1, 3, 3)).as_quat(canonical=True, scalar_first=True)
    return q.reshape(*shape, 4)


def quat_apply(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vectors v (…, 3) by quaternions q (…, 4), broadcast over the batch."""
    q = np.asarray(q, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    w = q[..., :1]
    u = q[..., 1:]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def quat_from_axis_angle(axis: np.ndarray, angle: np.ndarray | float) -> np.ndarray:
    """Quaternion of a rotation by ``angle`` [rad] about ``axis`` (…, 3), (…, 4)."""
    axis = np.asarray(axis, dtype=np.float64)
    axis = axis / np.linalg.norm(axis, axis=-1, keepdims=True)
    half = 0.5 * np.asarray(angle, dtype=np.float64)[..., None]
    return np.concatenate([np.cos(half), np.sin(half) * axis], axis=-1)


def quat_to_axis_angle(q: np.ndarray) -> np.ndarray:
    """Rotation vectors (…, 3) [rad] from quaternions (…, 4)."""
    flat, shape = _flat(q)
    return _rotation().from_quat(flat, scalar_first=True).as_rotvec().reshape(*shape, 3)


def quat_angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Geodesic angle [rad] between unit quaternions a and b, (…)."""
    rel = quat_mul(quat_conj(a), b)  # atan2 form stays accurate for tiny angles
    return 2.0 * np.arctan2(np.linalg.norm(rel[..., 1:], axis=-1), np.abs(rel[..., 0]))


def quat_fix_continuity(q: np.ndarray, axis: int = 0) -> np.ndarray:
    """Flip signs along ``axis`` (time) so consecutive quaternions lie in one hemisphere."""
    q = np.array(q, dtype=np.float64, copy=True)
    q = np.moveaxis(q, axis, 0)
    for t in range(1, q.shape[0]):
        flip = np.sum(q[t] * q[t - 1], axis=-1) < 0.0
        q[t][flip] *= -1.0
    return np.moveaxis(q, 0, axis)


def euler_to_quat(angles: np.ndarray, order: str) -> np.ndarray:
    """Quaternions from intrinsic Euler angles [rad] (…, 3), ``order`` like ``"ZXY"``.

    Upper-case order = intrinsic rotations (the BVH convention: the first named axis is
    applied outermost), matching scipy's convention for upper-case sequences.
    """
    a = np.asarray(angles, dtype=np.float64)
    shape = a.shape[:-1]
    q = _rotation().from_euler(order.upper(), a.reshape(-1, 3)).as_quat(scalar_first=True)
    return q.reshape(*shape, 4)


def quat_to_euler(q: np.ndarray, order: str) -> np.ndarray:
    """Intrinsic Euler angles [rad] (…, 3) in ``order`` from quaternions (…, 4)."""
    flat, shape = _flat(q)
    r = _rotation().from_quat(flat, scalar_first=True)
    import warnings

    with warnings.catch_warnings():  # gimbal lock warnings: the result is still valid
        warnings.simplefilter("ignore", UserWarning)
        e = r.as_euler(order.upper())
    return e.reshape(*shape, 3)


def matrix_to_6d(m: np.ndarray) -> np.ndarray:
    """6-D form (…, 6) of rotation matrices (…, 3, 3): first two columns."""
    m = np.asarray(m, dtype=np.float64)
    return np.concatenate([m[..., :, 0], m[..., :, 1]], axis=-1)


def sixd_to_matrix(d6: np.ndarray) -> np.ndarray:
    """Rotation matrices (…, 3, 3) from the 6-D form by Gram–Schmidt."""
    d6 = np.asarray(d6, dtype=np.float64)
    a1, a2 = d6[..., :3], d6[..., 3:]
    b1 = a1 / np.linalg.norm(a1, axis=-1, keepdims=True)
    a2 = a2 - np.sum(b1 * a2, axis=-1, keepdims=True) * b1
    b2 = a2 / np.linalg.norm(a2, axis=-1, keepdims=True)
    b3 = np.cross(b1, b2)
    return np.stack([b1, b2, b3], axis=-1)


def quat_to_6d(q: np.ndarray) -> np.ndarray:
    """6-D form (…, 6) of quaternions (…, 4)."""
    return matrix_to_6d(quat_to_matrix(q))


def sixd_to_quat(d6: np.ndarray) -> np.ndarray:
    """Quaternions (…, 4) wxyz from the 6-D form (…, 6)."""
    return matrix_to_quat(sixd_to_matrix(d6))


def quat_slerp(a: np.ndarray, b: np.ndarray, t: np.ndarray | float) -> np.ndarray:
    """Spherical interpolation between unit quaternions, shortest path, t in [0, 1]."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64)[..., None]
    d = np.sum(a * b, axis=-1, keepdims=True)
    b = np.where(d < 0.0, -b, b)
    d = np.abs(d)
    theta = np.arccos(np.clip(d, -1.0, 1.0))
    s = np.sin(theta)
    small = s < 1e-8
    wa = np.where(small, 1.0 - t, np.sin((1.0 - t) * theta) / np.where(small, 1.0, s))
    wb = np.where(small, t, np.sin(t * theta) / np.where(small, 1.0, s))
    return quat_normalize(wa * a + wb * b)


def _rot_axis(angle: np.ndarray | float, axis: int) -> np.ndarray:
    a = np.asarray(angle, dtype=np.float64)
    q = np.zeros((*a.shape, 4))
    q[..., 0] = np.cos(0.5 * a)
    q[..., 1 + axis] = np.sin(0.5 * a)
    return q


def rot_x(angle: np.ndarray | float) -> np.ndarray:
    """Quaternion of a rotation about +x by ``angle`` [rad]."""
    return _rot_axis(angle, 0)


def rot_y(angle: np.ndarray | float) -> np.ndarray:
    """Quaternion of a rotation about +y by ``angle`` [rad]."""
    return _rot_axis(angle, 1)


def rot_z(angle: np.ndarray | float) -> np.ndarray:
    """Quaternion of a rotation about +z by ``angle`` [rad]."""
    return _rot_axis(angle, 2)


def heading_yaw(pelvis_quats: np.ndarray) -> np.ndarray:
    """Heading ψ [rad] of the pelvis' forward (+x) axis projected on the ground, (…)."""
    q = np.asarray(pelvis_quats, dtype=np.float64)
    w, x, y, z = np.moveaxis(q, -1, 0)
    fx = 1.0 - 2.0 * (y * y + z * z)
    fy = 2.0 * (x * y + w * z)
    return np.arctan2(fy, fx)
