"""Leg inverse kinematics of a robot: :func:`leg_ik`, frame by frame, and the figures
of the fit."""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np

from .options import RetargetOptions
from .robot import RobotLegs

__all__ = ["leg_ik"]


def leg_ik(
    robot: RobotLegs,
    qpos: np.ndarray,
    targets: np.ndarray,
    *,
    iterations: int = 30,
    tolerance: float = 1e-5,
    damping: float | None = None,
    data: mujoco.MjData | None = None,
    options: RetargetOptions | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Leg joint angles putting each foot point at its target, trunk as in ``qpos``.

    Damped least squares per leg on the leg's own joints,
    ``Δq = Jᵀ (J Jᵀ + λ² I)⁻¹ (p* − p)`` with ``J`` the foot point's translational
    Jacobian (``mujoco.mj_jac``), each step scaled to at most ``options.max_ik_step`` per
    joint and clipped into the leg's bounds (:attr:`RobotLegs.lo` / ``hi``), until every
    foot is within ``tolerance`` [m] or after ``iterations`` steps.

    Args:
        robot: the :class:`RobotLegs`.
        qpos: (nq,) start (trunk pose and initial leg angles).
        targets: (nf, 3) wanted foot points (world) [m].
        damping: λ [m] (default 1 % of the leg length).
        options: the knobs (default :class:`~habitsim.retarget.options.RetargetOptions`).

    Returns:
        (qpos (nq,), residual (nf,) [m] distance of each foot from its target).
    """
    m = robot.model
    d = mujoco.MjData(m) if data is None else data
    max_step = (options or RetargetOptions()).max_ik_step
    q = np.array(qpos, dtype=float)
    lam2 = (0.01 * robot.leg_length if damping is None else float(damping)) ** 2
    legs = robot.legs
    jac = np.zeros((3, m.nv))
    eye = np.eye(3)
    err = np.zeros((len(robot.feet), 3))
    for _ in range(max(int(iterations), 1)):
        d.qpos[:] = q
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        pts = np.array(legs.positions(d))
        err = targets - pts
        if float(np.abs(err).max()) < tolerance:
            break
        for i, b in enumerate(legs.bodies):
            mujoco.mj_jac(m, d, jac, None, pts[i], int(b))
            j = jac[:, robot.dadr[i]]
            step = j.T @ np.linalg.solve(j @ j.T + lam2 * eye, err[i])
            big = float(np.abs(step).max(initial=0.0))
            if big > max_step:  # near a singularity DLS steps grow as |err|/λ
                step *= max_step / big
            qa = robot.qadr[i]
            q[qa] = np.clip(q[qa] + step, robot.lo[i], robot.hi[i])
    d.qpos[:] = q
    mujoco.mj_kinematics(m, d)
    res = np.linalg.norm(targets - np.array(legs.positions(d)), axis=1)
    return q, res


def _solve_frames(
    robot: RobotLegs,
    trunk_pos: np.ndarray,
    trunk_quat: np.ndarray,
    feet: np.ndarray,
    options: RetargetOptions | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """(qpos (T, nq), residual (T, nf)) of trunk poses and foot targets per frame."""
    t = len(trunk_pos)
    m = robot.model
    d = mujoco.MjData(m)
    a = robot.trunk_qadr
    q = robot.home.copy()
    out = np.empty((t, m.nq))
    res = np.empty((t, len(robot.feet)))
    for k in range(t):
        q[a : a + 3] = trunk_pos[k]
        q[a + 3 : a + 7] = trunk_quat[k]
        q, res[k] = leg_ik(
            robot, q, feet[k], iterations=60 if k == 0 else 30, data=d, options=options
        )
        out[k] = q
    return out, res


def _fit_figures(
    rl: RobotLegs, qpos: np.ndarray, res: np.ndarray, extra: dict[str, Any]
) -> dict[str, Any]:
    at_limit = []
    for i in range(len(rl.feet)):
        v = qpos[:, rl.qadr[i]]
        span = np.where(np.isfinite(rl.hi[i] - rl.lo[i]), rl.hi[i] - rl.lo[i], np.inf)
        at_limit.append(((v - rl.lo[i] < 1e-3 * span) | (rl.hi[i] - v < 1e-3 * span)).mean())
    return {
        **extra,
        "ik_residual_max_m": float(res.max()),
        "ik_residual_mean_m": float(res.mean()),
        "joints_at_limit_share": float(np.mean(at_limit)),
        "robot_leg_length_m": rl.leg_length,
        "robot_home": rl.home_source,
    }
