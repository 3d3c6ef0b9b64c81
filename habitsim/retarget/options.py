"""The knobs of retargeting onto a robot: :class:`RetargetOptions`."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
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
        keyframe: the keyframe the robot stands on (None: the ``home`` argument, default
            ``"home"``).
        keyframe_from: an MJCF file whose ``<keyframe>`` holds the standing pose (a key
            of the robot's qpos size, named ``keyframe`` or the file's only one); None:
            the robot's own keyframes.
        stand_max_limit_share: a standing pose with more than this share of its limited
            leg joints at a range limit is no standing pose (refused when it is
            ``qpos0``, warned about when it is a keyframe).
        stand_limit_margin: a joint is at its limit within this share of its range.
        stand_min_height: a standing pose whose trunk stands lower than this share of
            the legs' length (hip to knee plus knee to foot) is folded, no standing pose.
    """

    straight_reach: float = 0.97
    crouch_height: float = 0.85
    crouch_bend: float = 0.5
    hinge_span: float = math.pi
    max_ik_step: float = 0.3
    lower_passes: int = 4
    keyframe: str | None = None
    keyframe_from: str | Path | None = None
    stand_max_limit_share: float = 0.25
    stand_limit_margin: float = 0.02
    stand_min_height: float = 0.4

    def __post_init__(self) -> None:
        for name in (
            "straight_reach",
            "crouch_height",
            "stand_max_limit_share",
            "stand_limit_margin",
            "stand_min_height",
        ):
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
