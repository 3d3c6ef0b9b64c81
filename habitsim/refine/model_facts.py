"""What the refinement reads from a habitsim species model: hinges and their ranges,
foot spheres, mass, composite inertia, friction (:func:`model_info`)."""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from ..mjutils import free_joints, home_qpos
from .errors import RefineError
from .layout import FEET


@dataclass(frozen=True)
class ModelInfo:
    """What the refinement reads from a habitsim species model (numbers, no symbols).

    Attributes:
        free_qposadr: qpos address of the pelvis free joint.
        hinge_qposadr: (n,) qpos addresses of the hinge joints, in qpos order.
        hinge_names: their joint names.
        lower, upper: (n,) joint ranges [rad] (±inf where a joint is unlimited).
        foot_geoms: (4,) geom ids of the foot spheres; foot_radius (4,) [m].
        mass: total mass [kg]; gravity: |g| [m/s²].
        inertia: (3, 3) composite inertia about the CoM in the pelvis frame at home [kg m²].
        friction: sliding friction of foot against floor (the larger, as MuJoCo combines).
    """

    free_qposadr: int
    hinge_qposadr: np.ndarray
    hinge_names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    foot_geoms: np.ndarray
    foot_radius: np.ndarray
    mass: float
    gravity: float
    inertia: np.ndarray
    friction: float


def model_info(model: mujoco.MjModel) -> ModelInfo:
    """Read a habitsim species model's refinement facts.

    Raises:
        RefineError: no single free joint, a non-hinge joint, or a missing foot sphere.
    """
    free = free_joints(model)
    if len(free) != 1:
        raise RefineError(f"the model needs exactly one free joint (the pelvis), found {len(free)}")
    hinges = [j for j in range(model.njnt) if j != free[0]]
    bad = [
        model.joint(j).name
        for j in hinges
        if int(model.jnt_type[j]) != int(mujoco.mjtJoint.mjJNT_HINGE)
    ]
    if bad:
        raise RefineError(f"the refinement handles hinge joints only; not hinges: {', '.join(bad)}")
    hinges.sort(key=lambda j: int(model.jnt_qposadr[j]))
    lim = model.jnt_limited[hinges].astype(bool)
    rng = model.jnt_range[hinges]
    lower = np.where(lim, rng[:, 0], -np.inf)
    upper = np.where(lim, rng[:, 1], np.inf)
    feet = []
    for leg in FEET:
        g = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, f"{leg}_foot")
        if g < 0 or int(model.geom_type[g]) != int(mujoco.mjtGeom.mjGEOM_SPHERE):
            raise RefineError(f"the model has no foot sphere geom '{leg}_foot'")
        feet.append(g)
    feet_a = np.array(feet)
    ground = np.flatnonzero(model.geom_bodyid == 0)
    floor_mu = float(model.geom_friction[ground, 0].max()) if len(ground) else 1.0
    mu = max(float(model.geom_friction[feet_a, 0].max()), floor_mu)
    # composite inertia about the CoM, pelvis frame, at the home keyframe (or qpos0)
    d = mujoco.MjData(model)
    d.qpos[:] = home_qpos(model)
    mujoco.mj_kinematics(model, d)
    mujoco.mj_comPos(model, d)
    root = int(model.jnt_bodyid[free[0]])
    masses = model.body_mass[1:]
    mass = float(masses.sum())
    com = (masses[:, None] * d.xipos[1:]).sum(axis=0) / mass
    inertia = np.zeros((3, 3))
    for b in range(1, model.nbody):
        rb = d.ximat[b].reshape(3, 3)
        ib = rb @ np.diag(model.body_inertia[b]) @ rb.T
        r = d.xipos[b] - com
        inertia += ib + model.body_mass[b] * (r @ r * np.eye(3) - np.outer(r, r))
    rr = d.xmat[root].reshape(3, 3)
    inertia = rr.T @ inertia @ rr
    return ModelInfo(
        free_qposadr=int(model.jnt_qposadr[free[0]]),
        hinge_qposadr=np.array([int(model.jnt_qposadr[j]) for j in hinges]),
        hinge_names=tuple(model.joint(j).name for j in hinges),
        lower=lower,
        upper=upper,
        foot_geoms=feet_a,
        foot_radius=model.geom_size[feet_a, 0].copy(),
        mass=mass,
        gravity=float(np.linalg.norm(model.opt.gravity)),
        inertia=inertia,
        friction=mu,
    )
