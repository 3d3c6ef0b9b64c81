"""MuJoCo lookups shared by tracking, the controllers, refinement and the metrics.

Written once here, below all of them (:mod:`habitsim.sim` re-exports what it always
offered): a qpos trajectory checked against its model, its finite differences, the lowest
point of a geom, the foot geoms of a habitsim model.
"""

from __future__ import annotations

import mujoco
import numpy as np

from .errors import SimulationError

__all__ = ["check_qpos", "finite_differences", "lowest_z", "species_foot_geoms"]


def check_qpos(model: mujoco.MjModel, qpos: np.ndarray) -> np.ndarray:
    """(T, nq) float copy of a qpos trajectory that fits the model, without NaN or inf.

    Raises:
        SimulationError: wrong shape for the model, a NaN or inf.
    """
    q = np.atleast_2d(np.asarray(qpos, dtype=np.float64))
    if q.ndim != 2 or q.shape[1] != model.nq:
        raise SimulationError(
            f"reference qpos must have shape (T, {model.nq}) for this model, got {q.shape}"
        )
    if not np.all(np.isfinite(q)):
        bad = np.argwhere(~np.isfinite(q))[0]
        raise SimulationError(
            f"reference qpos contains NaN or inf (frame {bad[0]}, coordinate {bad[1]})"
        )
    return q


def finite_differences(
    model: mujoco.MjModel, qpos: np.ndarray, fps: float
) -> tuple[np.ndarray, np.ndarray]:
    """Generalised velocities and accelerations of a qpos trajectory.

    Central differences inside, one-sided at the ends; the velocity between two frames is
    ``mj_differentiatePos`` (free-joint angular velocity in the body frame, as MuJoCo's
    qvel). A single frame gives zeros.

    Args:
        model: the model the qpos belongs to.
        qpos: (T, nq) positions at ``fps``.
        fps: frame rate [Hz].

    Returns:
        qvel (T, nv) and qacc (T, nv).
    """
    q = check_qpos(model, qpos)
    t = q.shape[0]
    dt = 1.0 / float(fps)
    if t < 2:
        return np.zeros((t, model.nv)), np.zeros((t, model.nv))
    seg = np.empty((t - 1, model.nv))  # velocity over (k, k+1)
    for k in range(t - 1):
        mujoco.mj_differentiatePos(model, seg[k], dt, q[k], q[k + 1])
    qvel = np.empty((t, model.nv))
    qvel[0], qvel[-1] = seg[0], seg[-1]
    qvel[1:-1] = 0.5 * (seg[:-1] + seg[1:])
    qacc = np.empty_like(qvel)
    qacc[1:-1] = (seg[1:] - seg[:-1]) / dt
    if t > 2:
        qacc[0], qacc[-1] = qacc[1], qacc[-2]
    else:
        qacc[:] = 0.0
    return qvel, qacc


def lowest_z(
    model: mujoco.MjModel, geoms: np.ndarray, pos: np.ndarray, mat: np.ndarray
) -> np.ndarray:
    """(..., n) height [m] of the lowest point of each geom (exact for spheres, capsules,
    boxes, ellipsoids; other shapes by their bounding sphere).

    Args:
        geoms: (n,) geom ids; pos: (..., n, 3) their ``geom_xpos``; mat: (..., n, 9)
            their ``geom_xmat``.
    """
    z = pos[..., 2]
    rz = mat[..., 6:9]  # z-row of each rotation matrix
    size = model.geom_size[geoms]
    kind = model.geom_type[geoms]
    gt = mujoco.mjtGeom
    out = z - model.geom_rbound[geoms]
    for k, low in (
        (gt.mjGEOM_SPHERE, lambda s, r: s[..., 0] + 0 * r[..., 0]),
        (gt.mjGEOM_CAPSULE, lambda s, r: np.abs(r[..., 2]) * s[..., 1] + s[..., 0]),
        (gt.mjGEOM_BOX, lambda s, r: (np.abs(r) * s).sum(axis=-1)),
        (gt.mjGEOM_ELLIPSOID, lambda s, r: np.sqrt(((r * s) ** 2).sum(axis=-1))),
    ):
        sel = kind == k
        if sel.any():
            out[..., sel] = z[..., sel] - low(size[sel], rz[..., sel, :])
    return out


def species_foot_geoms(model: mujoco.MjModel) -> np.ndarray:
    """(4,) geom ids of the feet of a habitsim model: ``lf_foot, rf_foot, lh_foot, rh_foot``
    (a robot's feet, named its own way: :func:`habitsim.sim.foot_geoms`).

    Raises:
        SimulationError: a foot geom is missing (the message lists the model's geoms).
    """
    ids = []
    for leg in ("lf", "rf", "lh", "rh"):
        g = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, f"{leg}_foot")
        if g < 0:
            names = [model.geom(i).name for i in range(model.ngeom) if model.geom(i).name]
            raise SimulationError(
                f"the model has no foot geom '{leg}_foot'; geoms: {', '.join(names[:40])} "
                "(name a robot's feet with feet=[...])"
            )
        ids.append(g)
    return np.array(ids)
