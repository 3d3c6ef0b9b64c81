"""Robots habitsim did not build: position actuators, feet by the robot's own names.

A robot MJCF (MuJoCo Menagerie's Unitree Go1 or A1, ANYmal C, …) differs from a habitsim
species model in two ways the controllers care about:

* **Actuators.** Robots usually ship position servos (``<position kp=… forcerange=…>``,
  ``force = kp·(ctrl − q) − kv·q̇``, clamped to the force range), while the balance and
  MPC controllers compute joint torques. They accept both:
  :class:`ServoTorque` inverts each servo's law, so the torque a controller wants comes out
  of the servo at the state it was computed for (the control a torque ``τ`` needs is
  ``ctrl = (τ/g − b₀ − b₁·g·q − b₂·g·q̇) / kp``, ``g`` the gear, ``b`` the bias
  parameters), clipped to the control and force ranges. That is exact at the control
  tick and one step old on the steps between ticks; :func:`torque_model` gives the exact
  alternative, a copy of the model whose servos are torque motors with the same limits
  (the force range becomes the control range), which :func:`habitsim.sim.track` simulates
  for ``"pd"``, ``"balance"`` and ``"mpc"`` by name.
* **Feet.** Foot points are named as the robot names them: a site, geom or body
  (Menagerie's Go1 names its foot geoms and sites ``FL``, ``FR``, ``RL``, ``RR``).
  :func:`foot_geoms` finds the colliding geom of each (the one nearest the named point),
  which the tracking runner measures touch and falls with.

Nothing here adds a force or changes a body: masses, contacts, friction, joint damping
and limits stay the robot's own.
"""

from __future__ import annotations

from collections.abc import Sequence

import mujoco
import numpy as np

from habitsim import mjutils

from .base import ControllerError, JointActuatorMap, actuator_force_range

__all__ = ["ServoTorque", "torque_model", "foot_geoms", "is_position_servo"]


def is_position_servo(model: mujoco.MjModel, actuator: int) -> bool:
    """True for a fixed-gain actuator with an affine bias and no activation dynamics on a
    joint (MuJoCo's ``<position>``, or a ``<general>`` written the same way)."""
    return (
        int(model.actuator_gaintype[actuator]) == int(mujoco.mjtGain.mjGAIN_FIXED)
        and int(model.actuator_biastype[actuator]) == int(mujoco.mjtBias.mjBIAS_AFFINE)
        and int(model.actuator_dyntype[actuator]) == int(mujoco.mjtDyn.mjDYN_NONE)
        and int(model.actuator_trntype[actuator]) == int(mujoco.mjtTrn.mjTRN_JOINT)
        and float(model.actuator_gainprm[actuator, 0]) != 0.0
    )


class ServoTorque:
    """Controls that make position servos give wanted joint torques.

    Args:
        model: the model.
        jmap: the controller's joints (:func:`~habitsim.controllers.base.actuated_joints`);
            the biased ones must be position servos (:func:`is_position_servo`).

    Attributes:
        servo: (n,) bool, the joint's actuator is a servo (others are torque actuators and
            are left to the caller).

    Raises:
        ControllerError: a biased actuator that is not a position servo (pid with an
            integral state, a muscle, a tendon transmission); the message names the joints.
    """

    def __init__(self, model: mujoco.MjModel, jmap: JointActuatorMap) -> None:
        acts = jmap.actuator_ids
        biased = np.zeros(len(acts), bool) if jmap.biased is None else np.asarray(jmap.biased)
        bad = [
            n
            for n, a, b in zip(jmap.names, acts, biased, strict=True)
            if b and not is_position_servo(model, int(a))
        ]
        if bad:
            raise ControllerError(
                "the controller drives torque motors or position servos; these joints have "
                f"other biased actuators: {', '.join(bad[:8])}"
            )
        self.servo = biased.astype(bool)
        self.gear = model.actuator_gear[acts, 0].copy()
        self.kp = model.actuator_gainprm[acts, 0].copy()
        self.bias = model.actuator_biasprm[acts, :3].copy()
        self.qadr, self.dadr = jmap.qpos_adr, jmap.dof_adr
        self.ctrl_lo, self.ctrl_hi = jmap.ctrl_lo, jmap.ctrl_hi
        flo = -np.inf if jmap.force_lo is None else jmap.force_lo
        fhi = np.inf if jmap.force_hi is None else jmap.force_hi
        self.force_lo = np.broadcast_to(flo, self.gear.shape)
        self.force_hi = np.broadcast_to(fhi, self.gear.shape)

    def controls(self, data: mujoco.MjData, tau: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(ctrl (n,), torque (n,)): the servo targets giving joint torques ``tau`` at
        ``data``'s state, and the torques they really give (after the control and force
        ranges). Entries of joints without a servo are returned unchanged (``tau``)."""
        g = self.gear
        length = g * data.qpos[self.qadr]
        vel = g * data.qvel[self.dadr]
        b = self.bias
        passive = b[:, 0] + b[:, 1] * length + b[:, 2] * vel
        ctrl = (tau / g - passive) / self.kp
        ctrl = np.minimum(np.maximum(ctrl, self.ctrl_lo), self.ctrl_hi)
        force = np.minimum(np.maximum(self.kp * ctrl + passive, self.force_lo), self.force_hi)
        return np.where(self.servo, ctrl, tau), np.where(self.servo, g * force, tau)


def torque_model(model: mujoco.MjModel) -> mujoco.MjModel:
    """A copy of ``model`` whose joint position servos are torque motors.

    Each position servo (:func:`is_position_servo`) becomes ``force = ctrl`` (fixed gain 1,
    no bias, the same gear), its control range the servo's force range
    (:func:`~habitsim.controllers.base.actuator_force_range`: the actuator's
    ``forcerange`` and its joint's ``actuatorfrcrange``, so the motor is exactly as
    strong as the servo was), force-limited the same way. Torque motors and
    every other part of the model are left as they are; the input is never modified.

    Raises:
        ControllerError: a servo without a force range, on the actuator or on its joint
            (its strength is unbounded, so no torque limit can be given to the motor).
    """
    from .servo import _copy

    out = _copy(model)
    weak = []
    cadr = (
        np.asarray(model.actuator_ctrladr, dtype=int)
        if hasattr(model, "actuator_ctrladr")
        else np.arange(model.nu)
    )
    for a in range(int(getattr(model, "nactuator", model.nu))):
        if not is_position_servo(model, a):
            continue
        frange = actuator_force_range(model, np.array([a]))[0]
        if not np.all(np.isfinite(frange)):
            weak.append(model.actuator(a).name or f"#{a}")
            continue
        out.actuator_gainprm[a, :] = 0.0
        out.actuator_gainprm[a, 0] = 1.0
        out.actuator_biastype[a] = mujoco.mjtBias.mjBIAS_NONE
        out.actuator_biasprm[a, :] = 0.0
        c = cadr[a]
        out.actuator_ctrllimited[c] = 1
        out.actuator_ctrlrange[c] = frange
        if hasattr(out, "actuator_ctrlspec"):  # MuJoCo >= 4: the control is a force
            out.actuator_ctrlspec[a] = 0
    if weak:
        raise ControllerError(
            f"position servos without a force range cannot become torque motors: "
            f"{', '.join(weak[:8])}; give them forcerange=… (or their joints actuatorfrcrange=…)"
        )
    for k in range(model.nkey):  # a keyframe's ctrl held servo targets: no torque
        out.key_ctrl[k, :] = 0.0
    return out


def foot_geoms(model: mujoco.MjModel, feet: Sequence[str]) -> np.ndarray:
    """(nf,) the colliding geom of each foot, named as the robot names it
    (:func:`habitsim.mjutils.foot_geoms`: a colliding geom of that name as it is; for a
    site or a non-colliding geom, the colliding geom of its body nearest the named point
    at the home pose; for a body, its lowest colliding geom at the home pose).

    Raises:
        ControllerError: an unknown name (the message lists the model's named sites and
            geoms), or a foot body without a colliding geom.
    """
    try:
        return mjutils.foot_geoms(model, list(feet))
    except mjutils.ModelLookupError as e:
        raise ControllerError(str(e)) from e
