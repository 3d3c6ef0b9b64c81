"""The reference at the simulation step: finite differences and interpolation.

:func:`~habitsim.mjutils.finite_differences` gives (qvel, qacc) of a qpos trajectory at
its frame rate (``mj_differentiatePos``, so the free joint's quaternion is handled
correctly); :func:`build_reference` resamples it at the simulation step (cubic Hermite for scalar
coordinates and the root position, slerp for quaternions; velocities and accelerations
interpolated linearly).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from ..errors import SimulationError
from ..mjutils import check_qpos as _check_qpos
from ..mjutils import finite_differences


@dataclass(frozen=True)
class ReferenceTrajectory:
    """A reference sampled at the simulation step.

    Attributes:
        time: (N,) times [s] from the first frame (step i starts at i·dt).
        qpos: (N, nq) positions; qvel, qacc: (N, nv).
        dt: step [s].
    """

    time: np.ndarray
    qpos: np.ndarray
    qvel: np.ndarray
    qacc: np.ndarray
    dt: float


def _quat_slerp(q0: np.ndarray, q1: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Row-wise slerp of (N, 4) wxyz quaternions with weights a (N,)."""
    dot = np.sum(q0 * q1, axis=1)
    q1 = np.where(dot[:, None] < 0, -q1, q1)
    dot = np.abs(dot).clip(-1.0, 1.0)
    theta = np.arccos(dot)
    s = np.sin(theta)
    small = s < 1e-8
    w0 = np.where(small, 1.0 - a, np.sin((1.0 - a) * theta) / np.where(small, 1.0, s))
    w1 = np.where(small, a, np.sin(a * theta) / np.where(small, 1.0, s))
    out = w0[:, None] * q0 + w1[:, None] * q1
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def build_reference(
    model: mujoco.MjModel, qpos: np.ndarray, fps: float, dt: float | None = None
) -> ReferenceTrajectory:
    """Resample a frame-rate qpos trajectory at the simulation step.

    Scalar coordinates (hinges, slides, root position) use cubic Hermite interpolation
    with the finite-difference velocities as tangents; free/ball quaternions use slerp.
    qvel and qacc are the frame-rate finite differences, interpolated linearly.

    Args:
        model: the model.
        qpos: (T, nq) at ``fps``.
        fps: frame rate [Hz].
        dt: sampling step [s] (default ``model.opt.timestep``).

    Returns:
        The :class:`ReferenceTrajectory` covering [0, (T-1)/fps) in steps of ``dt``
        (one sample for a one-frame clip).
    """
    q = _check_qpos(model, qpos)
    if not (math.isfinite(fps) and fps > 0):
        raise SimulationError(f"fps must be positive, got {fps}")
    dt = float(model.opt.timestep if dt is None else dt)
    qvel, qacc = finite_differences(model, q, fps)
    t_frames = q.shape[0]
    n = max(1, int(round((t_frames - 1) / fps / dt)))
    times = np.arange(n) * dt
    s = np.clip(times * fps, 0.0, t_frames - 1)
    i0 = np.minimum(np.floor(s).astype(int), max(t_frames - 2, 0))
    i1 = np.minimum(i0 + 1, t_frames - 1)
    a = s - i0
    h = 1.0 / fps
    out_q = np.empty((n, model.nq))
    # velocity index of each scalar qpos coordinate (hinge/slide/free position)
    h00, h10 = 2 * a**3 - 3 * a**2 + 1, a**3 - 2 * a**2 + a
    h01, h11 = -2 * a**3 + 3 * a**2, a**3 - a**2
    for j in range(model.njnt):
        qa, va = model.jnt_qposadr[j], model.jnt_dofadr[j]
        jt = int(model.jnt_type[j])
        if jt == mujoco.mjtJoint.mjJNT_FREE:
            scal = [(qa + k, va + k) for k in range(3)]
            quat = qa + 3
        elif jt == mujoco.mjtJoint.mjJNT_BALL:
            scal, quat = [], qa
        else:
            scal, quat = [(qa, va)], None
        for qi, vi in scal:
            if t_frames == 1:
                out_q[:, qi] = q[0, qi]
                continue
            out_q[:, qi] = (
                h00 * q[i0, qi] + h10 * h * qvel[i0, vi] + h01 * q[i1, qi] + h11 * h * qvel[i1, vi]
            )
        if quat is not None:
            qa0, qa1 = q[i0, quat : quat + 4], q[i1, quat : quat + 4]
            out_q[:, quat : quat + 4] = _quat_slerp(qa0, qa1, a)
    out_v = (1 - a)[:, None] * qvel[i0] + a[:, None] * qvel[i1]
    out_a = (1 - a)[:, None] * qacc[i0] + a[:, None] * qacc[i1]
    return ReferenceTrajectory(times, out_q, out_v, out_a, dt)
