"""The error of retargeting: :class:`RetargetError`."""

from __future__ import annotations

from ..errors import HabitsimError

__all__ = ["RetargetError", "StandingPoseError", "RobotSourceError", "VendorError"]


class RetargetError(HabitsimError, ValueError):
    """Bad input to retargeting: a robot file that does not load, a robot without a free
    joint, unknown foot names (the message lists the valid ones), a foot count that does
    not match the motion's, bad sizes or rates, an unreadable robot clip file."""


class StandingPoseError(RetargetError):
    """The robot has no usable standing pose: no keyframe to stand on and a ``qpos0``
    that is folded (its trunk low over its legs, its joints at their limits). The message
    says what was found and how to point at a keyframe (``--keyframe NAME``,
    ``--keyframe-from FILE``)."""


class RobotSourceError(RetargetError):
    """A robot named by its MuJoCo Menagerie name that cannot be had here: the optional
    package ``mujoco-menagerie`` is not installed, or it cannot fetch the model (offline,
    an unknown name). The message says how to install it or vendor a copy instead."""


class VendorError(RetargetError):
    """A robot model that cannot be made into a collision-only single-file copy: it does
    not load, a collision mesh in a ``<frame>``, a height field or skin read from a file,
    an output that would overwrite the input, a bad option (the message says which are
    valid)."""
