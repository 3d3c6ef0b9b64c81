"""Controllers usable on any MuJoCo model (installed as ``habitsim.controllers``)."""

from .base import (
    Controller,
    ControllerError,
    ControllerStats,
    JointActuatorMap,
    PDController,
    Reference,
    actuated_joints,
)

__all__ = [
    "Controller",
    "ControllerError",
    "ControllerStats",
    "JointActuatorMap",
    "PDController",
    "Reference",
    "actuated_joints",
]
