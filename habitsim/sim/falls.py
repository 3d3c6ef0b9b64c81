"""docs/metrics.md's fall rule (:class:`FallDetector`), checked at every reference frame.

A reference that itself rests its trunk on the ground (lying, sitting: its trunk lower
than :attr:`FallOptions.rest_height_ratio` of the model's standing height) asks the body
to be down: a clause that fires at such a frame is not a fall of the controller. It is
recorded as :class:`ReferenceResting` (:attr:`FallDetector.resting`) and the run goes on;
a body still down when the reference stands up again falls then.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from enum import StrEnum

import mujoco
import numpy as np

from ..mjutils import home_qpos, lowest_z
from .model import _free_body, foot_geoms
from .reference import _check_qpos


@dataclass(frozen=True)
class FallOptions:
    """The thresholds of docs/metrics.md's fall rule (:class:`FallDetector`).

    Attributes:
        height_ratio: a fall when the trunk is lower than this share of its reference
            height [unitless] …
        tilt_deg: … or tilted from the reference's trunk orientation by more than this
            [deg] …
        ground_contact_s: … or a non-foot body touches the ground for longer than this [s].
        ground_tolerance_per_leg: a reference body counts as resting on the ground within
            this share of leg length [unitless] (such bodies may touch it).
        rest_height_ratio: the reference rests its trunk on the ground (lies or sits) at
            a frame whose trunk is lower than this share of the model's standing trunk
            height (its ``home`` keyframe) [unitless]; no clause is a fall there.
    """

    height_ratio: float = 0.5
    tilt_deg: float = 60.0
    ground_contact_s: float = 0.2
    ground_tolerance_per_leg: float = 0.01
    rest_height_ratio: float = 0.6


class FallCause(StrEnum):
    """Which clause of the fall rule (:class:`FallDetector`) fired."""

    #: the trunk is lower than its share of the reference height
    TRUNK_LOW = "trunk_low"
    #: the trunk is tilted from the reference's orientation beyond the limit
    TILT = "tilt"
    #: a non-foot body touched the ground for too long
    BODY_CONTACT = "body_contact"


@dataclass(frozen=True)
class ReferenceResting:
    """A clause of the fall rule that fired while the reference itself rested its trunk
    on the ground (:attr:`FallOptions.rest_height_ratio`): not a fall of the controller.

    Attributes:
        frame: the first reference frame it fired at.
        cause: the clause.
        text: the clause's reason in words, with the figures.
        trunk_ratio: the reference's trunk height at that frame / the standing height.
    """

    frame: int
    cause: FallCause
    text: str
    trunk_ratio: float

    def describe(self, fps: float) -> str:
        return (
            f"reference lying at {self.frame / fps:.2f} s (its trunk at {self.trunk_ratio:.2f} "
            f"of standing height): {self.text}; not counted as a fall"
        )


@dataclass(frozen=True)
class Fall:
    """A fall found by :meth:`FallDetector.fall`.

    Attributes:
        cause: the clause of the rule that fired.
        text: the reason in words, with the figures (what :meth:`FallDetector.check`
            returns).
        bodies: the non-foot bodies on the ground, sorted by name (``BODY_CONTACT``
            only; empty otherwise).
    """

    cause: FallCause
    text: str
    bodies: tuple[str, ...] = ()


class FallDetector:
    """docs/metrics.md's fall rule, evaluated at the reference frames.

    A run has fallen at frame k when (a) the trunk (free-joint body) is lower than
    :attr:`FallOptions.height_ratio` × the reference trunk height at k, (b) the angle
    between the simulated and the reference trunk "up" axes exceeds
    :attr:`FallOptions.tilt_deg` (tilt is measured from the reference orientation, so a
    giraffe's sloping back or a sit does not count), or (c) a non-foot body has touched
    the ground for more than :attr:`FallOptions.ground_contact_s` (bodies that the
    reference itself rests on the ground at that frame, within
    :attr:`FallOptions.ground_tolerance_per_leg` of leg length, are allowed: e.g. the
    haunches of a sit).

    Args:
        model: the simulated model (with a floor: geoms of the world body).
        ref_qpos: (T, nq) reference frames.
        fps: frame rate [Hz].
        leg_length: normalising length [m].
        feet: foot names of a robot (default habitsim's foot geoms, see :func:`foot_geoms`).
        options: the rule's thresholds.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        ref_qpos: np.ndarray,
        fps: float,
        leg_length: float,
        feet: Sequence[str] | None = None,
        options: FallOptions = FallOptions(),
    ) -> None:
        self.model = model
        self.options = options
        self.fps = float(fps)
        self.trunk = _free_body(model)
        geoms = foot_geoms(model, feet)
        self.foot_bodies = set(int(model.geom_bodyid[g]) for g in geoms)
        self.ground = set(int(g) for g in np.flatnonzero(model.geom_bodyid == 0))
        q = _check_qpos(model, ref_qpos)
        # reference trunk height, up axis and bodies resting on the ground per frame
        colliding = np.flatnonzero(
            ((model.geom_contype != 0) | (model.geom_conaffinity != 0)) & (model.geom_bodyid != 0)
        )
        tol = options.ground_tolerance_per_leg * leg_length
        d = mujoco.MjData(model)
        self.ref_height = np.empty(len(q))
        self.ref_up = np.empty((len(q), 3))
        pos = np.empty((len(q), len(colliding), 3))
        mat = np.empty((len(q), len(colliding), 9))
        for k in range(len(q)):
            d.qpos[:] = q[k]
            mujoco.mj_kinematics(model, d)
            self.ref_height[k] = d.xpos[self.trunk, 2]
            self.ref_up[k] = d.xmat[self.trunk, [2, 5, 8]]
            pos[k], mat[k] = d.geom_xpos[colliding], d.geom_xmat[colliding]
        near = lowest_z(model, colliding, pos, mat) < tol  # (T, n)
        bodies = model.geom_bodyid[colliding]
        self.ref_ground = [set(int(b) for b in bodies[row]) for row in near]
        d.qpos[:] = home_qpos(model)
        mujoco.mj_kinematics(model, d)
        self.standing_height = float(d.xpos[self.trunk, 2])
        self.ref_resting = self.ref_height < options.rest_height_ratio * self.standing_height
        self.contact_frames = 0
        self.resting: ReferenceResting | None = None

    def _ground_bodies(self, data: mujoco.MjData) -> set[int]:
        out = set()
        for c in range(data.ncon):
            con = data.contact[c]
            g1, g2 = int(con.geom1), int(con.geom2)
            if g1 in self.ground and g2 not in self.ground:
                out.add(int(self.model.geom_bodyid[g2]))
            elif g2 in self.ground and g1 not in self.ground:
                out.add(int(self.model.geom_bodyid[g1]))
        return out

    def reset(self) -> None:
        self.contact_frames = 0
        self.resting = None

    def check(self, k: int, data: mujoco.MjData) -> str | None:
        """The fall reason at frame k (``data`` after mj_step/mj_forward), or None (the
        text of :meth:`fall`)."""
        fall = self.fall(k, data)
        return None if fall is None else fall.text

    def fall(self, k: int, data: mujoco.MjData) -> Fall | None:
        """The fall at frame k (``data`` after mj_step/mj_forward), typed, or None. A
        clause firing while the reference rests is no fall: the first such is kept in
        :attr:`resting`."""
        k = min(k, len(self.ref_height) - 1)
        fall = self._clause(k, data)
        if fall is None or not self.ref_resting[k]:
            return fall
        if self.resting is None:
            ratio = float(self.ref_height[k] / self.standing_height)
            self.resting = ReferenceResting(k, fall.cause, fall.text, ratio)
        self.contact_frames = 0
        return None

    def _clause(self, k: int, data: mujoco.MjData) -> Fall | None:
        o = self.options
        h = data.xpos[self.trunk, 2]
        if h < o.height_ratio * self.ref_height[k]:
            ref = self.ref_height[k]
            return Fall(
                FallCause.TRUNK_LOW,
                f"trunk height {h:.3f} m < {o.height_ratio:.0%} of reference {ref:.3f} m",
            )
        up = data.xmat[self.trunk, [2, 5, 8]]
        tilt = math.degrees(math.acos(float(np.clip(up @ self.ref_up[k], -1.0, 1.0))))
        if tilt > o.tilt_deg:
            return Fall(FallCause.TILT, f"trunk tilt {tilt:.0f} deg > {o.tilt_deg:.0f} deg")
        touching = self._ground_bodies(data) - self.foot_bodies - self.ref_ground[k]
        if touching:
            self.contact_frames += 1
            if self.contact_frames / self.fps > o.ground_contact_s:
                bodies = tuple(sorted(self.model.body(b).name for b in touching))
                names = ", ".join(bodies)
                return Fall(
                    FallCause.BODY_CONTACT,
                    f"non-foot body on the ground > {o.ground_contact_s} s ({names})",
                    bodies,
                )
        else:
            self.contact_frames = 0
        return None
