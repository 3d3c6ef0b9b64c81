"""Dynamic plausibility metrics (docs/metrics.md, "Dynamic plausibility").

The question: which external "hand of god" wrench on the trunk does a motion need, once
the ground has pushed as much as it physically can? For every reference frame:

1. ``qvel`` and ``qacc`` by finite differences of the qpos trajectory
   (:func:`habitsim.mjutils.finite_differences`).
2. ``mj_inverse`` with every constraint disabled gives the generalised force the motion
   needs without any ground, ``τ = M(q)·q̈ + c(q, q̇) − passive``. For a body in the air
   its free-joint force part is exactly ``m·g`` upward.
3. The ground may explain part of it: each foot in contact can push with a force inside
   its friction pyramid (4 edges, μ = the larger friction of foot and floor, as MuJoCo
   combines them), applied at the lowest point of the foot sphere. A foot is in contact
   when the labels say so *and* the geometry allows it: the lowest point of its sphere is
   no higher than :func:`habitsim.contacts.ground_reach` (the contact height
   :data:`habitsim.physics_constants.CONTACT_HEIGHT_PER_LEG` × L with contact
   detection's hysteresis: 3 % of L, the highest foot detection keeps in contact). A
   labelled stance foot higher than that pushes on nothing, so a walk lifted off the
   floor needs its whole weight from outside; a foot below the floor still pushes
   (sinking is the penetration metric's business). The non-negative edge weights
   minimising the remaining free-joint wrench ``[F/(m·g), T/(m·g·L)]`` come from
   non-negative least squares (``scipy.optimize.nnls``), with a small penalty on the
   forces so that of the many splits over two or more feet that explain the wrench alike
   the least-norm one is taken: the joint torques then follow the motion continuously.
4. What is left on the free joint is the residual: ``root_residual_mg`` = mean ‖F‖/(m·g),
   ``root_residual_torque_mgl`` = mean ‖T‖/(m·g·L) (torque about the trunk origin, in the
   trunk frame, MuJoCo's free-joint convention; L the hind-leg length). The joint part
   minus the contact forces' share is the feed-forward joint torque; ``torque_saturation``
   is the share of frames where any joint exceeds its actuator's torque limit
   (gear × control range of the species' motors).

Why not read ``qfrc_inverse`` with contacts enabled, as docs/metrics.md's sentence suggests:
MuJoCo's soft contacts only push when a foot penetrates, and the force then depends on
the penetration depth, so a kinematic reference with feet exactly on the floor reads
1.0 standing still (checked: the dog's home pose gives ‖qfrc_inverse[0:3]‖ = m·g). The
contact-wrench fit above is the same "unexplained external force" with the contact forces
the motion could actually get; a floating body still reads exactly 1.0 and a still
standing pose 0 (to within 1e-6 m·g, the bias of the force penalty).

Keys: :data:`DYNAMIC_KEYS`.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from scipy.optimize import nnls

from habitsim.contacts import ground_reach
from habitsim.errors import InvalidMotionError
from habitsim.mjutils import free_joints
from habitsim.motion import Motion
from habitsim.qpos import motion_to_qpos, species_model

__all__ = [
    "DYNAMIC_KEYS",
    "InverseDynamics",
    "inverse_dynamics",
    "dynamic_metrics",
]

DYNAMIC_KEYS = ("root_residual_mg", "root_residual_torque_mgl", "torque_saturation")

_LEGS = ("lf", "rf", "lh", "rh")


@dataclass(frozen=True)
class InverseDynamics:
    """Per-frame inverse dynamics of a reference trajectory.

    Attributes:
        root_force: (T, 3) residual force on the free joint [N] (world frame).
        root_torque: (T, 3) residual torque on the free joint [N·m] (trunk frame).
        joint_torque: (T, n) feed-forward torques of the actuated joints [N·m].
        contact_force: (T, 4, 3) ground forces on the feet [N] (world frame).
        contacts: (T, 4) bool feet that could push: labelled in contact and no higher
            than :func:`habitsim.contacts.ground_reach` (LF, RF, LH, RH).
        torque_limit: (n,) the actuators' torque limits [N·m].
        joint_names: the n actuated joints.
        mg: m·g [N]; leg_length: L [m].
    """

    root_force: np.ndarray
    root_torque: np.ndarray
    joint_torque: np.ndarray
    contact_force: np.ndarray
    contacts: np.ndarray
    torque_limit: np.ndarray
    joint_names: tuple[str, ...]
    mg: float
    leg_length: float

    def metrics(self) -> dict[str, float]:
        """The :data:`DYNAMIC_KEYS` metrics of these frames."""
        f = np.linalg.norm(self.root_force, axis=1) / self.mg
        t = np.linalg.norm(self.root_torque, axis=1) / (self.mg * self.leg_length)
        sat = np.any(np.abs(self.joint_torque) > self.torque_limit * (1 + 1e-9), axis=1)
        return {
            "root_residual_mg": float(f.mean()),
            "root_residual_torque_mgl": float(t.mean()),
            "torque_saturation": float(sat.mean()),
        }


def _pyramid(mu: float) -> np.ndarray:
    """(4, 3) friction-pyramid edge directions for a horizontal floor (normal +z)."""
    return np.array([[mu, 0, 1], [-mu, 0, 1], [0, mu, 1], [0, -mu, 1]], dtype=float)


def inverse_dynamics(
    model: mujoco.MjModel,
    qpos: np.ndarray,
    fps: float,
    contacts: np.ndarray | None,
    leg_length: float,
    split: float = 1e-3,
) -> InverseDynamics:
    """Residual root wrench, joint torques and ground forces of a qpos trajectory.

    Args:
        model: a habitsim-named model (free joint, ``<leg>_foot`` sphere geoms, joint
            actuators) with a floor.
        qpos: (T, nq) reference frames.
        fps: frame rate [Hz].
        contacts: (T, 4) bool feet labelled in contact (LF, RF, LH, RH); None = no contact
            at all. A labelled foot whose sphere's lowest point is higher than
            :func:`habitsim.contacts.ground_reach` above the floor exerts no force.
        leg_length: normalising length L [m] (also scales the contact height).
        split: weight of the penalty on the contact forces, ``split``·‖f‖/(m·g) beside the
            wrench residual in units of m·g: among the splits of the ground force over
            the feet that explain the wrench equally well, the least-norm one (unique, so
            the joint torques do not jump between equally good splits); its bias on the
            residual is of order ``split``² (1e-6 m·g by default).

    Raises:
        InvalidMotionError: shapes or model do not fit.
    """
    from habitsim.controllers import actuated_joints
    from habitsim.errors import SimulationError
    from habitsim.mjutils import finite_differences
    from habitsim.mjutils import species_foot_geoms as foot_geoms

    try:
        qvel, qacc = finite_differences(model, qpos, fps)
        feet = foot_geoms(model)
    except SimulationError as e:
        raise InvalidMotionError(str(e)) from e
    q = np.atleast_2d(np.asarray(qpos, dtype=np.float64))
    t = q.shape[0]
    c = np.zeros((t, 4), bool) if contacts is None else np.asarray(contacts, bool)
    if c.shape != (t, 4):
        raise InvalidMotionError(f"contacts must have shape ({t}, 4), got {c.shape}")
    free = free_joints(model)
    if len(free) != 1:
        raise InvalidMotionError(f"the model needs exactly one free joint, found {len(free)}")
    r0 = int(model.jnt_dofadr[free[0]])
    root = slice(r0, r0 + 6)
    amap = actuated_joints(model)
    mg = float(mujoco.mj_getTotalmass(model) * np.linalg.norm(model.opt.gravity))
    ground = np.flatnonzero(model.geom_bodyid == 0)
    floor_mu = float(model.geom_friction[ground, 0].max()) if len(ground) else 1.0
    edges = [_pyramid(max(float(model.geom_friction[g, 0]), floor_mu)) for g in feet]
    # inverse dynamics without ground or limits: what the motion needs from outside
    free_model = model.__copy__()
    free_model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONSTRAINT
    d = mujoco.MjData(free_model)
    reach = ground_reach(leg_length)  # highest foot the ground can push [m]
    pushing = np.zeros((t, 4), bool)
    weight = np.r_[np.full(3, 1.0 / mg), np.full(3, 1.0 / (mg * leg_length))]
    jac = np.zeros((3, model.nv))
    root_f = np.zeros((t, 3))
    root_t = np.zeros((t, 3))
    joint_tau = np.zeros((t, len(amap.names)))
    forces = np.zeros((t, 4, 3))
    for k in range(t):
        d.qpos[:], d.qvel[:], d.qacc[:] = q[k], qvel[k], qacc[k]
        mujoco.mj_inverse(free_model, d)
        tau = d.qfrc_inverse.copy()
        cols, dirs = [], []
        for f in np.flatnonzero(c[k]):
            g = feet[f]
            point = d.geom_xpos[g] - np.array([0.0, 0.0, model.geom_size[g, 0]])
            if point[2] > reach:  # a labelled stance foot in mid-air pushes on nothing
                continue
            pushing[k, f] = True
            mujoco.mj_jac(free_model, d, jac, None, point, int(model.geom_bodyid[g]))
            for edge in edges[f]:
                cols.append(jac.T @ edge)  # generalised force of a unit force along edge
                dirs.append((f, edge))
        if cols:
            a = np.array(cols).T  # (nv, m)
            # with two or more feet down many splits explain the wrench alike; the small
            # penalty on the forces picks the one of least norm, so the split (and the
            # joint torques) move continuously with the motion
            fit = np.vstack([weight[:, None] * a[root], np.eye(len(cols)) * (split / mg)])
            rhs = np.r_[weight * tau[root], np.zeros(len(cols))]
            beta, _ = nnls(fit, rhs, maxiter=400)
            tau = tau - a @ beta
            for b, (f, edge) in zip(beta, dirs, strict=True):
                forces[k, f] += b * edge
        root_f[k], root_t[k] = tau[r0 : r0 + 3], tau[r0 + 3 : r0 + 6]
        joint_tau[k] = tau[amap.dof_adr]
    return InverseDynamics(
        root_f,
        root_t,
        joint_tau,
        forces,
        pushing,
        amap.torque_limit,
        amap.names,
        mg,
        float(leg_length),
    )


def dynamic_metrics(
    motion: Motion,
    model: mujoco.MjModel | None = None,
    contacts: np.ndarray | None = None,
) -> dict[str, float]:
    """The dynamic plausibility metrics of a motion (keys: :data:`DYNAMIC_KEYS`).

    Args:
        motion: the motion (its species' shipped model unless ``model`` is given).
        model: a habitsim-named MuJoCo model with torque motors (their control range is
            the torque limit).
        contacts: (T, 4) feet in contact; default the motion's labels, else
            :meth:`~habitsim.motion.Motion.detect_contacts`. Either way a foot higher than
            :func:`habitsim.contacts.ground_reach` above the floor exerts no force
            (:func:`inverse_dynamics`).

    Returns:
        ``root_residual_mg``, ``root_residual_torque_mgl``, ``torque_saturation``.
    """
    model = species_model(motion.species) if model is None else model
    traj = motion_to_qpos(motion, model)
    if contacts is None:
        contacts = motion.contacts if motion.contacts is not None else motion.detect_contacts()
    inv = inverse_dynamics(model, traj.qpos, motion.fps, contacts, motion.species_info.leg_length)
    return inv.metrics()
