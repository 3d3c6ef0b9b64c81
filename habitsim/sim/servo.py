"""In-engine position servos: the servo model, its targets and power, and which model a
controller is simulated on."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import mujoco
import numpy as np

from ..controllers import REGISTRY
from ..errors import SimulationError
from .model import _species_model

if TYPE_CHECKING:
    from .clip import _Clip


def servo_model(model: mujoco.MjModel) -> mujoco.MjModel:
    """A copy of ``model`` whose joint motors are in-engine position servos.

    :func:`habitsim.controllers.servo.configure_servos` with its default gain rule
    (kp = τmax / 0.15 rad, critical kv on M_ii); torque limits are kept as force limits.
    """
    from ..controllers.servo import configure_servos

    return configure_servos(model)


def servo_targets(
    model: mujoco.MjModel, qpos: np.ndarray, qvel: np.ndarray | None = None
) -> np.ndarray:
    """(N, nu) controls of in-engine servos for reference positions (N, nq) and, for the
    velocity lead, velocities (N, nv).

    The law of :class:`habitsim.controllers.servo.ServoController`
    (:meth:`~habitsim.controllers.servo.ServoMap.position_targets`), vectorised, so the
    ``mujoco.rollout`` path and the Python loop apply identical controls. Actuators that
    are not servos keep 0.

    Raises:
        SimulationError: the model has no joint position servos.
    """
    from ..controllers import ControllerError
    from ..controllers.servo import servo_map

    try:
        sm = servo_map(model)
    except ControllerError as e:
        raise SimulationError(f"{e}") from e
    q = np.atleast_2d(qpos)
    u = np.zeros((q.shape[0], model.nu))
    u[:, sm.actuator_ids] = sm.position_targets(q, None if qvel is None else np.atleast_2d(qvel))
    return u


def _servo_power(
    model: mujoco.MjModel, q: np.ndarray, v: np.ndarray, v_next: np.ndarray, ctrl: np.ndarray
) -> np.ndarray:
    """(N,) Σ|τ·q̇| of the servos per step: torque at (q, v) under ``ctrl`` (vectorised
    :meth:`~habitsim.controllers.servo.ServoMap.predicted_torque`) times ``v_next``."""
    from ..controllers.servo import servo_map

    sm = servo_map(model)
    g = sm.gear
    qj, vj = q[:, sm.qpos_adr], v[:, sm.dof_adr]
    force = sm.kp / g**2 * (ctrl[:, sm.actuator_ids] - g * qj) - sm.kv / g**2 * (g * vj)
    tau = np.clip(g * force, sm.torque_lo, sm.torque_hi)
    return np.abs(tau * v_next[:, sm.dof_adr]).sum(axis=1)


def _has_servos(model: mujoco.MjModel) -> bool:
    from ..controllers import ControllerError
    from ..controllers.servo import servo_map

    try:
        servo_map(model)
    except ControllerError:
        return False
    return True


def _sim_model(controller: Any, clip: _Clip, given: mujoco.MjModel | None) -> mujoco.MjModel:
    """The model to simulate: servos for the servo controllers (unless already there);
    torque motors for ``pd``, ``balance`` and ``mpc`` by name on a model with position
    servos (a robot's: :func:`habitsim.controllers.robot.torque_model`, same limits)."""
    if (
        isinstance(controller, str)
        and REGISTRY.get(controller) is not None
        and REGISTRY[controller].actuators == "servo"
    ):
        if given is None:
            return _species_model(clip.species, True)
        return given if _has_servos(given) else servo_model(given)
    if isinstance(controller, str) and given is not None and _has_position_servos(given):
        from ..controllers import ControllerError
        from ..controllers.robot import torque_model

        try:
            return torque_model(given)
        except ControllerError as e:
            raise SimulationError(f"controller {controller!r} does not fit the model: {e}") from e
    return clip.base


def _has_position_servos(model: mujoco.MjModel) -> bool:
    from ..controllers.robot import is_position_servo

    return any(
        is_position_servo(model, a) for a in range(int(getattr(model, "nactuator", model.nu)))
    )
