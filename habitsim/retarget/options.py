"""The knobs of retargeting onto a robot: :class:`RetargetOptions`."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final

from .errors import RetargetError

__all__ = [
    "RetargetOptions",
    "STRAIGHT_REACH",
    "CROUCH_HEIGHT",
    "CROUCH_BEND",
    "HINGE_SPAN",
    "MAX_IK_STEP",
    "LOWER_PASSES",
]


@dataclass(frozen=True)
class RetargetOptions:
    """Knobs of :func:`~habitsim.retarget.robot_legs`, :func:`~habitsim.retarget.leg_ik`,
    :func:`~habitsim.retarget.retarget` and the references (:func:`~habitsim.retarget.trot`,
    :func:`~habitsim.retarget.stand`). Why each default: docs/robots.md, "Why the
    defaults".

    Attributes:
        straight_reach: a leg whose extension (:func:`~habitsim.retarget.leg_extension`,
            hip-to-foot over the summed segment lengths, 1 = straight) is above this is
            straight: a singular pose for the leg IK and the stance forces. A standing
            pose on straight legs is crouched; a stance leg straighter than this lowers
            the trunk in :func:`~habitsim.retarget.retarget`.
        crouch_height: trunk height of the crouched standing pose, share of the
            straight-legged height.
        crouch_bend: knee bend that starts the crouch's leg IK off the straight-leg
            singularity [rad].
        hinge_span: the leg IK keeps every hinge of a leg within this of its standing
            angle (inside the joint's own range) [rad].
        max_ik_step: largest change of one joint in one damped-least-squares step of the
            leg IK [rad].
        lower_passes: passes of lowering the trunk where a stance leg would be straighter
            than ``straight_reach`` or its foot short of the ground.
    """

    straight_reach: float = 0.97
    crouch_height: float = 0.85
    crouch_bend: float = 0.5
    hinge_span: float = math.pi
    max_ik_step: float = 0.3
    lower_passes: int = 4

    def __post_init__(self) -> None:
        for name in ("straight_reach", "crouch_height"):
            v = getattr(self, name)
            if not (math.isfinite(v) and 0 < v <= 1):
                raise RetargetError(f"{name} must be in (0, 1], got {v!r}")
        for name in ("crouch_bend", "hinge_span", "max_ik_step"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise RetargetError(f"{name} must be > 0 [rad], got {v!r}")
        if int(self.lower_passes) < 0:
            raise RetargetError(f"lower_passes must be ≥ 0, got {self.lower_passes!r}")


#: Read-only aliases of the defaults of :class:`RetargetOptions` (names of
#: :mod:`habitsim.retarget` from before the options held them); changing one changes
#: nothing: pass ``RetargetOptions(...)``.
STRAIGHT_REACH: Final = RetargetOptions.straight_reach
CROUCH_HEIGHT: Final = RetargetOptions.crouch_height
CROUCH_BEND: Final = RetargetOptions.crouch_bend
HINGE_SPAN: Final = RetargetOptions.hinge_span
MAX_IK_STEP: Final = RetargetOptions.max_ik_step
LOWER_PASSES: Final = RetargetOptions.lower_passes
