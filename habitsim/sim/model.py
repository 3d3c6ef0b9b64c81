"""Lookups on the simulated model: trunk, feet, touch forces, leg length, shipped models.

Thin wrappers of :mod:`habitsim.mjutils` that raise :class:`SimulationError`.
"""

from __future__ import annotations

from collections.abc import Sequence

import mujoco
import numpy as np

from .. import mjutils
from ..errors import SimulationError
from ..mjutils import (
    HABITSIM_FEET,
    ModelLookupError,
    foot_soles,
    free_dofs,
    free_joints,
    leg_length,
)
from ..qpos import species_model

#: A foot is "in contact" when its touch sensor reads more than this share of m·g.
TOUCH_THRESHOLD_MG = 0.01


def _free_body(model: mujoco.MjModel) -> int:
    free = free_joints(model)
    if len(free) != 1:
        raise SimulationError(
            f"the model needs exactly one free joint (the trunk), found {len(free)}"
        )
    return int(model.jnt_bodyid[free[0]])


def foot_geoms(model: mujoco.MjModel, feet: Sequence[str] | None = None) -> np.ndarray:
    """(nf,) geom ids of the feet: ``lf_foot, rf_foot, lh_foot, rh_foot`` (habitsim's
    models), or the colliding geom of each of ``feet``, named as the robot names them
    (site, geom or body; :func:`habitsim.mjutils.foot_geoms`).

    Raises:
        SimulationError: a foot geom is missing (the message lists the model's geoms), an
            unknown foot name.
    """
    try:
        return mjutils.foot_geoms(model, feet)
    except ModelLookupError as e:
        raise SimulationError(str(e)) from e


def _touch_adr(model: mujoco.MjModel, feet: Sequence[str] | None = None) -> np.ndarray | None:
    """(4,) sensordata addresses of ``<leg>_touch`` sensors, or None if any is missing
    (always None for a robot's named ``feet``: their contact forces are summed)."""
    if feet is not None:
        return None
    adr = []
    for leg in ("lf", "rf", "lh", "rh"):
        s = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SENSOR, f"{leg}_touch")
        if s < 0:
            return None
        adr.append(model.sensor_adr[s])
    return np.array(adr)


def _foot_forces(model: mujoco.MjModel, data: mujoco.MjData, feet: np.ndarray) -> np.ndarray:
    """(nf,) normal contact force [N] on each foot geom (from the contact list)."""
    out = np.zeros(len(feet))
    f6 = np.zeros(6)
    for c in range(data.ncon):
        con = data.contact[c]
        for k, g in enumerate(feet):
            if con.geom1 == g or con.geom2 == g:
                mujoco.mj_contactForce(model, data, c, f6)
                out[k] += abs(f6[0])
    return out


def _total_mass(model: mujoco.MjModel) -> float:
    return float(mujoco.mj_getTotalmass(model))


#: Foot geoms in the order of contact labels (LF, RF, LH, RH).
FOOT_GEOMS = HABITSIM_FEET


def _model_leg_length(model: mujoco.MjModel, feet: Sequence[str] | None = None) -> float:
    """Normalising length of a user model without a species: the trunk's height above
    its feet at home (:func:`habitsim.mjutils.leg_length`)."""
    _free_body(model)
    foot_geoms(model, feet)  # a model without the feet fails here, naming its geoms
    try:
        return leg_length(model, feet)
    except ModelLookupError as e:
        raise SimulationError(str(e)) from e


def _foot_points(
    model: mujoco.MjModel, qpos: np.ndarray, names: Sequence[str] | None = None
) -> np.ndarray:
    """(T, nf, 3) lowest points of the foot spheres."""
    return foot_soles(model, qpos, foot_geoms(model, names))


def _species_model(species: str, servos: bool) -> mujoco.MjModel:
    """The shipped model of a species (:func:`habitsim.qpos.species_model`, the shared
    per-process cache; never mutated here)."""
    return species_model(species, servos)


def _touch(
    model: mujoco.MjModel, data: mujoco.MjData, adr: np.ndarray | None, feet: np.ndarray
) -> np.ndarray:
    if adr is not None:
        return np.asarray(data.sensordata[adr], dtype=float).copy()
    return _foot_forces(model, data, feet)


def _joint_dofs(model: mujoco.MjModel) -> np.ndarray:
    """Every dof except the free joint's."""
    keep = np.ones(model.nv, bool)
    keep[free_dofs(model)] = False
    return np.flatnonzero(keep)
