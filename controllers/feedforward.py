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
* ``"include"``: MuJoCo's soft-contact inverse at the reference pose is used. The
  contact forces then come from the reference's penetration and acceleration, which for a
  kinematic reference (feet exactly at the surface) are small and arbitrary, so this is
  mainly useful for references produced by a physics-aware optimiser.

The evaluation uses a separate ``MjData``, so the simulation state is never touched.
"""

from __future__ import annotations

import copy
from collections.abc import Sequence

import mujoco
import numpy as np

from .base import ControllerError, Reference, actuated_joints

__all__ = ["InverseDynamicsFeedforward"]

_CONTACTS = ("ignore", "include")


class InverseDynamicsFeedforward:
    """Callable ``(model, data, ref) -> (n,)`` joint torques [N·m] from ``mj_inverse``.

    Args:
        model: the MuJoCo model (a private copy is kept; the model passed at call time is
            not used for the inverse, only the reference).
        joints: joint names (default: every actuated hinge/slide joint); the torques are
            returned in this order (:attr:`joint_names`).
        contacts: ``"ignore"`` or ``"include"`` (see the module docstring).
        scale: factor on the returned torques (1 = full inverse dynamics).

    Attributes:
        residual_root_wrench: (6,) free-joint part of the last ``qfrc_inverse``
            (world-frame force [N] at the free body's origin, then torque [N·m] in the free
            body's frame); zeros if the model has no free joint.
        last_qfrc_inverse: (nv,) the whole last ``qfrc_inverse``.
    """

    def __init__(self, model: mujoco.MjModel, joints: Sequence[str] | None = None, *,
                 contacts: str = "ignore", scale: float = 1.0) -> None:
        if contacts not in _CONTACTS:
            raise ControllerError(
                f"unknown contacts mode {contacts!r}; valid: {', '.join(_CONTACTS)}")
        if not np.isfinite(scale):
            raise ControllerError(f"scale must be finite, got {scale}")
        self.map = actuated_joints(model, joints)
        self.contacts = contacts
        self.scale = float(scale)
        self._model = copy.copy(model)
        if contacts == "ignore":
            self._model.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
        self._data = mujoco.MjData(self._model)
        self._free_dofs = np.array([], dtype=int)
        for j in range(model.njnt):
            if int(model.jnt_type[j]) == int(mujoco.mjtJoint.mjJNT_FREE):
                a = int(model.jnt_dofadr[j])
                self._free_dofs = np.arange(a, a + 6)
                break
        self.residual_root_wrench = np.zeros(6)
        self.last_qfrc_inverse = np.zeros(model.nv)

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

    def __call__(self, model: mujoco.MjModel, data: mujoco.MjData, ref: Reference) -> np.ndarray:
        return self.scale * self.inverse(ref)[self.map.dof_adr]
