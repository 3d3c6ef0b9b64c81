"""The contact state machine (:class:`ContactTracker`) and the leg modes.

The schedule comes from the motion; a swing foot that touches the ground in the last
quarter of its swing, near its swing target, switches to stance early (*early
touch-down*; earlier or farther behind it is scuffing and keeps swinging); a scheduled
stance foot that does not touch the ground carries no force (*lost contact*,
:data:`SEEK`) and reaches down until it does.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["STANCE", "SWING", "SEEK", "ContactTracker"]


#: Leg modes of :class:`ContactTracker`: on the ground and carrying force …
STANCE = 0


#: … in the air, following the swing path …
SWING = 1


#: … scheduled on the ground but not touching it: no force, reaching down.
SEEK = 2


class ContactTracker:
    """Leg modes (:data:`STANCE`, :data:`SWING`, :data:`SEEK`) from schedule and touch.

    * scheduled stance and touching → STANCE;
    * scheduled stance, not touching → SEEK (no force, reach down) — a foot that was in
      STANCE keeps it for ``lost_s`` first, so a one-step bounce does not drop its force;
    * scheduled swing → SWING, except when the foot touches the ground after
      ``early_phase`` of its swing *near where it is meant to be* (``near``, see
      :meth:`update`): then STANCE until the schedule agrees (early touch-down). A touch
      earlier in the swing, or far from the swing target, is a scuff (a leg at a joint
      limit under a trunk a little low, a foot lagging its path), not a landing: planted
      there, half a step short, the foot would carry the body on a support polygon the
      plan never had (why ``early_phase`` is 0.75: docs/controllers.md);

    Args:
        n_feet: number of feet.
        lost_s: grace time [s] before a stance foot without contact loses its force.
        early_phase: swing phase after which a touch-down counts as early stance.
    """

    def __init__(self, n_feet: int, lost_s: float = 0.01, early_phase: float = 0.75) -> None:
        self.n = n_feet
        self.lost_s = float(lost_s)
        self.early_phase = float(early_phase)
        self.reset()

    def reset(self) -> None:
        self.mode = np.full(self.n, STANCE, dtype=int)
        self.early = [False] * self.n
        self.last_touch = [-math.inf] * self.n
        self.events = {"early_touchdown": 0, "lost_contact": 0}

    def update(
        self,
        t: float,
        scheduled: np.ndarray,
        touching: np.ndarray,
        phase: np.ndarray,
        near: np.ndarray | None = None,
    ) -> np.ndarray:
        """(nf,) modes at time ``t`` [s] from the scheduled stance, actual touch and swing
        phase (NaN in stance or unknown); ``near`` (nf,) bool: the swing foot is close to
        its swing target, so a touch counts as an early touch-down (default: all)."""
        mode, early, last = self.mode, self.early, self.last_touch
        new = [SWING] * self.n
        for i in range(self.n):
            touch = bool(touching[i])
            if touch:
                last[i] = t
            if scheduled[i]:
                early[i] = False
                if touch or (mode[i] == STANCE and t - last[i] <= self.lost_s):
                    new[i] = STANCE
                else:
                    new[i] = SEEK
                    if mode[i] == STANCE:
                        self.events["lost_contact"] += 1
            elif early[i]:
                new[i] = STANCE
            elif (
                touch
                and phase[i] >= self.early_phase  # NaN compares False
                and (near is None or near[i])
            ):
                early[i] = True
                new[i] = STANCE
                self.events["early_touchdown"] += 1
        self.mode = np.array(new)
        return self.mode
