"""Controller construction for a clip (names of the one registry, or instances) and the
control rate."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import mujoco

from ..controllers import CONTROLLERS, REGISTRY, ControllerError, make_controller
from ..errors import SimulationError, unknown_choice

if TYPE_CHECKING:
    from .clip import _Clip


def _make_controller(
    controller: Any,
    model: mujoco.MjModel,
    clip: _Clip | None = None,
    control_dt: float | None = None,
) -> Any:
    """A controller instance for a name (on ``model``, already servo-configured when the
    name asks for servos) or the given instance. The balance-aware controllers
    (``balance``, ``mpc``) get the clip's reference plan (qpos, fps, contact table)."""
    if not isinstance(controller, str):
        if not hasattr(controller, "control"):
            raise SimulationError(
                f"controller must be one of {', '.join(CONTROLLERS)} or a Controller, "
                f"got {type(controller).__name__}"
            )
        if clip is not None and hasattr(controller, "set_plan"):
            controller.set_plan(clip.qpos, clip.fps, clip.contacts)
        return controller
    if controller not in CONTROLLERS:
        raise SimulationError(unknown_choice("controller", controller, CONTROLLERS))
    spec = REGISTRY[controller]
    kw: dict[str, Any] = {}
    if spec.planned:
        if control_dt is not None:
            kw["control_dt"] = control_dt
        if clip is not None:
            kw.update(qpos=clip.qpos, fps=clip.fps, contacts=clip.contacts)
            kw["species"] = clip.species if clip.feet is None else None
    if (spec.planned or controller.endswith("+stance")) and clip is not None:
        kw["feet"] = clip.feet
    try:
        return make_controller(controller, model, **kw)
    except ControllerError as e:
        raise SimulationError(f"controller {controller!r} does not fit the model: {e}") from e


def _control_every(model: mujoco.MjModel, control_hz: float | None) -> int:
    if control_hz is None:
        return 1
    if not (math.isfinite(control_hz) and control_hz > 0):
        raise SimulationError(f"control_hz must be positive, got {control_hz}")
    every = int(round(1.0 / (control_hz * model.opt.timestep)))
    if every < 1:
        raise SimulationError(
            f"control_hz {control_hz} is above the simulation rate {1 / model.opt.timestep:g} Hz"
        )
    return every
