"""Simulated-tracking metrics (docs/metrics.md, "Simulated tracking").

Computed by :func:`habitsim.sim.track` on every run and stored in its report; the
functions take plain arrays so they also score a simulation made elsewhere. Keys (exactly
docs/metrics.md's, plus the leg-length-normalised variants):

=======================  ==================================================================
key                      definition
=======================  ==================================================================
``survival``             fraction of the clip completed before a fall or an unstable step
                         (1.0 = whole clip)
``fell``                 True when the run fell (docs/metrics.md's rule, see
                         :class:`habitsim.sim.FallDetector`) or became unstable
``sim_mpjpe_mm``         mean over the survived frames and the 30 habitsim joints of the
                         distance between simulated and reference world joint positions,
                         both by MuJoCo FK of the same model (global, no alignment) [mm];
                         on a robot (no habitsim joint names) over its body origins
``root_drift_mm``        horizontal distance between the simulated and the reference root
                         (free-joint position) at the last survived frame [mm]
``contact_f1``           F1 of simulated foot contacts (touch > 1 % m·g) against the
                         reference labels over the survived frames, all feet pooled; 1.0
                         when neither has a contact
``assist_force_mg``      mean root-assistance force / (m·g) (0 when off)
``cost_of_transport``    Σ|τ·q̇|·dt over the joint actuators / (m·g·d), d the horizontal
                         path length of the simulated root over the survived part; NaN
                         when d < 1 % of leg length (standing still)
``realtime_factor``      simulated seconds per wall-clock second of the run
``sim_mpjpe_per_leg``    sim_mpjpe_mm / 1000 / L
``root_drift_per_leg``   root_drift_mm / 1000 / L
=======================  ==================================================================

L is the species' hind-leg length (:attr:`habitsim.species.Species.leg_length`).
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from habitsim.errors import InvalidMotionError
from habitsim.mjutils import free_joints
from habitsim.qpos import qpos_joint_positions
from habitsim.stance.labels import pooled_stance_f1

__all__ = [
    "SIMULATED_KEYS",
    "sim_mpjpe_mm",
    "root_drift_mm",
    "contact_f1",
    "cost_of_transport",
    "simulated_metrics",
]

SIMULATED_KEYS = (
    "survival",
    "fell",
    "sim_mpjpe_mm",
    "root_drift_mm",
    "contact_f1",
    "assist_force_mg",
    "cost_of_transport",
    "realtime_factor",
    "sim_mpjpe_per_leg",
    "root_drift_per_leg",
)

#: Below this path length (fraction of leg length) cost of transport is undefined (NaN).
MIN_DISTANCE_PER_LEG = 0.01


def _root_adr(model: mujoco.MjModel) -> int:
    free = free_joints(model)
    if len(free) != 1:
        raise InvalidMotionError(f"the model needs exactly one free joint, found {len(free)}")
    return int(model.jnt_qposadr[free[0]])


def sim_mpjpe_mm(model: mujoco.MjModel, sim_qpos: np.ndarray, ref_qpos: np.ndarray) -> float:
    """Mean per-joint position error [mm] over the frames of ``sim_qpos`` (K ≤ T).

    Args:
        model: a model with habitsim joint names (bodies/sites named after the joints),
            or any other model (a robot): then the error is over its bodies' origins.
        sim_qpos: (K, nq) simulated frames.
        ref_qpos: (T, nq) reference frames; the first K are compared.
    """
    k = len(sim_qpos)
    if k == 0:
        return math.nan
    try:
        a = qpos_joint_positions(model, sim_qpos)
        b = qpos_joint_positions(model, np.asarray(ref_qpos)[:k])
    except InvalidMotionError:  # not a habitsim model: every body but the world
        a = _body_positions(model, sim_qpos)
        b = _body_positions(model, np.asarray(ref_qpos)[:k])
    return float(np.linalg.norm(a - b, axis=-1).mean() * 1000.0)


def _body_positions(model: mujoco.MjModel, qpos: np.ndarray) -> np.ndarray:
    """(T, nbody − 1, 3) world positions of the body origins (world body left out)."""
    q = np.atleast_2d(np.asarray(qpos, dtype=np.float64))
    d = mujoco.MjData(model)
    out = np.empty((len(q), model.nbody - 1, 3))
    for t, row in enumerate(q):
        d.qpos[:] = row
        mujoco.mj_kinematics(model, d)
        out[t] = d.xpos[1:]
    return out


def root_drift_mm(model: mujoco.MjModel, sim_qpos: np.ndarray, ref_qpos: np.ndarray) -> float:
    """Horizontal root position error at the last simulated frame [mm]."""
    k = len(sim_qpos)
    if k == 0:
        return math.nan
    a = _root_adr(model)
    d = np.asarray(sim_qpos)[k - 1, a : a + 2] - np.asarray(ref_qpos)[k - 1, a : a + 2]
    return float(np.linalg.norm(d) * 1000.0)


def contact_f1(sim_contacts: np.ndarray, ref_contacts: np.ndarray) -> float:
    """F1 of simulated vs. reference contacts over the simulated frames, pooled over feet
    and frames (:func:`habitsim.stance.labels.pooled_stance_f1`).

    Args:
        sim_contacts: (K, 4) bool.
        ref_contacts: (T, 4) bool, T ≥ K; the first K frames are compared.

    Returns:
        2·TP / (2·TP + FP + FN); 1.0 when neither side has a contact; NaN for K = 0.
    """
    s = np.asarray(sim_contacts, bool)
    r = np.asarray(ref_contacts, bool)[: len(s)]
    if s.shape != r.shape:
        raise InvalidMotionError(f"contacts shapes differ: {s.shape} vs {r.shape}")
    if s.size == 0:
        return math.nan
    return pooled_stance_f1(s, r)


def cost_of_transport(
    model: mujoco.MjModel, sim_qpos: np.ndarray, work_j: float, leg_length: float
) -> float:
    """Σ|τ·q̇|dt / (m·g·d), d the horizontal root path length; NaN when d is tiny."""
    if len(sim_qpos) < 2:
        return math.nan
    a = _root_adr(model)
    xy = np.asarray(sim_qpos)[:, a : a + 2]
    dist = float(np.linalg.norm(np.diff(xy, axis=0), axis=1).sum())
    if dist < MIN_DISTANCE_PER_LEG * leg_length:
        return math.nan
    mg = mujoco.mj_getTotalmass(model) * float(np.linalg.norm(model.opt.gravity))
    return float(work_j / (mg * dist))


def simulated_metrics(
    model: mujoco.MjModel,
    sim_qpos: np.ndarray,
    ref_qpos: np.ndarray,
    sim_contacts: np.ndarray,
    ref_contacts: np.ndarray,
    *,
    leg_length: float,
    survival: float,
    fell: bool,
    work_j: float,
    assist_force_mg: float,
    sim_time_s: float,
    wall_time_s: float,
) -> dict[str, float | bool]:
    """All simulated-tracking metrics (keys: :data:`SIMULATED_KEYS`).

    The error metrics use the survived frames only: the first
    ``round(survival · (T − 1)) `` frames when the run failed, else every simulated
    frame.

    Args:
        model: the simulated model.
        sim_qpos: (K, nq) simulated frames (K ≤ T).
        ref_qpos: (T, nq) reference frames.
        sim_contacts: (K, 4) bool simulated foot contacts.
        ref_contacts: (T, 4) bool reference contact labels.
        leg_length: normalising length L [m].
        survival: share of the clip completed.
        fell: whether the run fell (or became unstable).
        work_j: Σ|τ·q̇|·dt over the survived part [J].
        assist_force_mg: mean assistance force / (m·g).
        sim_time_s, wall_time_s: simulated and wall-clock duration of the run [s].
    """
    t = len(ref_qpos)
    k = len(sim_qpos)
    if fell:
        k = min(k, max(1, int(round(survival * (t - 1)))))
    sq, sc = np.asarray(sim_qpos)[:k], np.asarray(sim_contacts)[:k]
    leg_mm = leg_length * 1000.0
    out: dict[str, float | bool] = {
        "survival": float(survival),
        "fell": bool(fell),
        "sim_mpjpe_mm": sim_mpjpe_mm(model, sq, ref_qpos),
        "root_drift_mm": root_drift_mm(model, sq, ref_qpos),
        "contact_f1": contact_f1(sc, ref_contacts),
        "assist_force_mg": float(assist_force_mg),
        "cost_of_transport": cost_of_transport(model, sq, work_j, leg_length),
        "realtime_factor": float(sim_time_s / wall_time_s) if wall_time_s > 0 else math.nan,
    }
    out["sim_mpjpe_per_leg"] = float(out["sim_mpjpe_mm"]) / leg_mm
    out["root_drift_per_leg"] = float(out["root_drift_mm"]) / leg_mm
    return out
