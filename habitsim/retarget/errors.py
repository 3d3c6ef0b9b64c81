"""The error of retargeting: :class:`RetargetError`."""

from __future__ import annotations

from ..errors import HabitsimError

__all__ = ["RetargetError"]


class RetargetError(HabitsimError, ValueError):
    """Bad input to retargeting: a robot file that does not load, a robot without a free
    joint, unknown foot names (the message lists the valid ones), a foot count that does
    not match the motion's, bad sizes or rates, an unreadable robot clip file."""
