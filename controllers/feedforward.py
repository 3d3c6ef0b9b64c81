"""Inverse-dynamics feed-forward from ``mj_inverse`` evaluated on the REFERENCE.

For the reference state ``(q, q̇, q̈)``, ``mj_inverse`` gives the generalised force
``τ = M(q) q̈ + c(q, q̇) − τ_passive − Jᵀf_constraint`` that makes the reference exactly
happen. Its joint part is the torque the motors must add on top of the PD (which then only
corrects errors); its free-joint part is the force the reference needs from OUTSIDE the
robot (:attr:`InverseDynamicsFeedforward.residual_root_wrench`): it can only come from
contacts, and for a physically consistent reference it is what the ground provides.

Contacts (``contacts=``):

* ``"ignore"`` (default): the inverse is taken with contacts disabled (a private copy of
  the model with ``mjDSBL_CONTACT``), so the joint torques hold each limb against gravity
  and inertia as if the robot floated, and the free-joint residual is the full
  ``m·(q̈_root − g)`` wrench. The support of the body weight through the stance legs is
  then left to the PD or, better, to :class:`~habitsim.controllers.stance.TrunkStabilizer`
  (which distributes exactly that wrench over the stance feet).
* ``"stance"``: floating-base inverse dynamics with the ground forces solved for. The
  contact-free inverse is taken as for ``"ignore"``; then forces on the feet the
  reference has on the ground (``Reference.contacts``, in the order of ``feet``) are
  found that supply the free-joint residual — non-negative combinations of the edges of
  a linearised friction cone (coefficient ``mu``), least squares with a small force
  regulariser (scipy's NNLS) — and their joint-space effect ``Σ Jᵢᵀ fᵢ`` is taken off the
  joint torques. The stance legs then carry the body in the feed-forward itself, the
  PD only corrects errors, and the part of the residual no admissible foot force can
  supply is left over (:attr:`InverseDynamicsFeedforward.unsupported_root_wrench`).
* ``"include"``: MuJoCo's soft-contact inverse at the reference pose is used. The
  contact forces then come from the reference's penetration and acceleration, which for a
  kinematic reference (feet exactly at the surface) are small and arbitrary, so this is
  mainly useful for references produced by a physics-aware optimiser.

The evaluation uses a separate ``MjData``, so the simulation state is never touched.
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from dataclasses import dataclass

import mujoco
import numpy as np

from habitsim.mjutils import free_dofs

from .base import ControllerError, Reference, actuated_joints

__all__ = ["FeedforwardOptions", "InverseDynamicsFeedforward"]

_CONTACTS = ("ignore", "stance", "include")
#: Edges of the linearised friction cone per foot (a pyramid).
_CONE_EDGES = 4  # ±x, ±y


@dataclass(frozen=True)
class FeedforwardOptions:
    """The knobs of :class:`InverseDynamicsFeedforward`'s ``"stance"`` force distribution.

    Attributes:
        force_reg: weight of the regulariser on the cone-edge forces of the least-squares
            problem, relative to the square of its largest free-joint coefficient
            [unitless].
    """

    force_reg: float = 1e-4


class InverseDynamicsFeedforward:
    """Callable ``(model, data, ref) -> (n,)`` joint torques [N·m] from ``mj_inverse``.

    Args:
        model: the MuJoCo model (a private copy is kept; the model passed at call time is
            not used for the inverse, only the reference).
        joints: joint names (default: every actuated hinge/slide joint); the torques are
            returned in this order (:attr:`joint_names`).
        contacts: ``"ignore"``, ``"stance"`` or ``"include"`` (module docstring).
        scale: factor on the returned torques (1 = full inverse dynamics).
        feet: foot geom names (``"stance"`` mode; required there), in the order of
            ``Reference.contacts``; the contact point is the lowest point of each geom.
        mu: friction coefficient of the cone (``"stance"`` mode).
        options: the force distribution's knobs (``"stance"`` mode).

    Attributes:
        residual_root_wrench: (6,) free-joint part of the last ``qfrc_inverse``
            (world-frame force [N] at the free body's origin, then torque [N·m] in the free
            body's frame); zeros if the model has no free joint.
        last_qfrc_inverse: (nv,) the whole last ``qfrc_inverse``.
        foot_forces: (n_feet, 3) world-frame ground forces of the last ``"stance"``
            distribution [N] (zeros for swing feet).
        unsupported_root_wrench: (6,) the free-joint residual the stance forces could not
            supply (``"stance"`` mode; the whole residual in the other modes).
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        joints: Sequence[str] | None = None,
        *,
        contacts: str = "ignore",
        scale: float = 1.0,
        feet: Sequence[str] | None = None,
        mu: float = 0.8,
        options: FeedforwardOptions = FeedforwardOptions(),
    ) -> None:
        if contacts not in _CONTACTS:
            raise ControllerError(
                f"unknown contacts mode {contacts!r}; valid: {', '.join(_CONTACTS)}"
            )
        if not np.isfinite(scale):
            raise ControllerError(f"scale must be finite, got {scale}")
        if contacts == "stance":
            if not feet:
                raise ControllerError("contacts='stance' needs the foot geom names (feet=...)")
            if not (np.isfinite(mu) and mu > 0):
                raise ControllerError(f"mu must be a positive number, got {mu}")
        self._feet = np.array([], dtype=int)
        if feet:
            ids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, n) for n in feet]
            missing = [n for n, i in zip(feet, ids, strict=True) if i < 0]
            if missing:
                raise ControllerError(f"model has no foot geom(s) {', '.join(missing)}")
            self._feet = np.array(ids, dtype=int)
        self.mu = float(mu)
        self.options = options
        self.map = actuated_joints(model, joints)
        self.contacts = contacts
        self.scale = float(scale)
        self._model = copy.copy(model)
        if contacts in ("ignore", "stance"):
            self._model.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
        self._data = mujoco.MjData(self._model)
        self._sdata = mujoco.MjData(self._model)
        self._free_dofs = free_dofs(model)[:6]  # the (first) free joint's
        self.residual_root_wrench = np.zeros(6)
        self.unsupported_root_wrench = np.zeros(6)
        self.last_qfrc_inverse = np.zeros(model.nv)
        self.foot_forces = np.zeros((self._feet.size, 3))
        self._jacp = np.zeros((3, model.nv))
        e = np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])
        self._edges = np.column_stack([self.mu * e, np.ones(len(e))])  # (E, 3), unnormalised

    @property
    def joint_names(self) -> tuple[str, ...]:
        return self.map.names

    def inverse(self, ref: Reference) -> np.ndarray:
        """(nv,) ``qfrc_inverse`` at the reference; updates :attr:`residual_root_wrench`."""
        d = self._data
        if ref.qpos.shape != (self._model.nq,) or ref.qvel.shape != (self._model.nv,):
            raise ControllerError("reference does not fit the model of the feed-forward")
        d.qpos[:] = ref.qpos
        d.qvel[:] = ref.qvel
        d.qacc[:] = ref.qacc
        mujoco.mj_inverse(self._model, d)
        self.last_qfrc_inverse = d.qfrc_inverse.copy()
        if self._free_dofs.size:
            self.residual_root_wrench = self.last_qfrc_inverse[self._free_dofs]
        return self.last_qfrc_inverse

    def stance_forces(self, ref: Reference, data: mujoco.MjData | None = None) -> np.ndarray:
        """(nv,) ``Σ Jᵢᵀ fᵢ`` of the stance-foot forces that best supply the free-joint
        residual of the last :meth:`inverse` (the private data holds its kinematics).

        With the simulation's ``data``, only feet the reference has down AND that touch
        something in the simulation are loaded: pushing a leg whose foot is still in the
        air (late touch-down) or already off (early lift-off) kicks the body instead.
        Updates :attr:`foot_forces` and :attr:`unsupported_root_wrench`.
        """
        m, d = self._model, self._data
        self.foot_forces = np.zeros((self._feet.size, 3))
        stance = self._stance(ref)
        if data is not None:
            stance = stance & self._touching(data)
        b = self._static_root_wrench(ref)
        if not stance.any() or not self._free_dofs.size:
            self.unsupported_root_wrench = b.copy()
            return np.zeros(m.nv)
        jac = []
        for k in np.flatnonzero(stance):
            g = int(self._feet[k])
            point = d.geom_xpos[g] - np.array([0.0, 0.0, float(m.geom_size[g, 0])])
            mujoco.mj_jac(m, d, self._jacp, None, point, int(m.geom_bodyid[g]))
            jac.append(self._jacp.copy())
        jt = np.stack(jac)  # (S, 3, nv)
        # free-joint effect of each cone edge of each stance foot
        a = np.concatenate(
            [(jt[i].T @ self._edges.T)[self._free_dofs] for i in range(len(jac))], axis=1
        )
        reg = np.sqrt(self.options.force_reg) * max(float(np.abs(a).max()), 1e-9)
        from scipy.optimize import nnls  # (scipy.optimize takes 0.1 s to import)

        lam, _ = nnls(
            np.vstack([a, reg * np.eye(a.shape[1])]),
            np.concatenate([b, np.zeros(a.shape[1])]),
            maxiter=50 * a.shape[1],
        )
        lam = lam.reshape(len(jac), _CONE_EDGES)
        forces = lam @ self._edges  # (S, 3)
        self.foot_forces[np.flatnonzero(stance)] = forces
        gen = np.einsum("sij,si->j", jt, forces)
        self.unsupported_root_wrench = b - gen[self._free_dofs]
        return gen

    def _touching(self, data: mujoco.MjData) -> np.ndarray:
        """(n_feet,) whether each foot geom is in an active contact of the simulation."""
        out = np.zeros(self._feet.size, dtype=bool)
        if data.ncon:
            g = np.concatenate([data.contact.geom1[: data.ncon], data.contact.geom2[: data.ncon]])
            out = np.isin(self._feet, g)
        return out

    def _static_root_wrench(self, ref: Reference) -> np.ndarray:
        """Free-joint part of the inverse at rest in the reference pose (gravity only)."""
        d = self._sdata
        d.qpos[:] = ref.qpos
        d.qvel[:] = 0.0
        d.qacc[:] = 0.0
        mujoco.mj_inverse(self._model, d)
        return d.qfrc_inverse[self._free_dofs].copy()

    def _stance(self, ref: Reference) -> np.ndarray:
        n = self._feet.size
        if ref.contacts is None:
            # no labels: feet whose reference contact point is within 1 % of the body's
            # size of the ground count as on it
            d = self._data
            z = d.geom_xpos[self._feet, 2] - self._model.geom_size[self._feet, 0]
            return z < 0.01 * float(self._model.stat.extent)
        c = np.asarray(ref.contacts, dtype=bool).reshape(-1)
        if c.size != n:
            raise ControllerError(
                f"reference has {c.size} contact flags, the feed-forward {n} feet"
            )
        return c

    def __call__(self, model: mujoco.MjModel, data: mujoco.MjData, ref: Reference) -> np.ndarray:
        qfrc = self.inverse(ref)
        if self.contacts == "stance":
            qfrc = qfrc - self.stance_forces(ref, data)
        else:
            self.unsupported_root_wrench = self.residual_root_wrench.copy()
        return self.scale * qfrc[self.map.dof_adr]
