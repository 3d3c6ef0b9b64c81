"""What is true of a clip, measured on it: the facts a caption may state.

:func:`clip_facts` reads a :class:`~habitsim.motion.Motion` (any clip on a habitsim
skeleton: synthetic, imported or transferred) and returns :class:`ClipFacts`:

* **species** and its common name (the catalog's);
* **what it does**: the generator's action when the clip says it
  (``metadata["action"]``), otherwise read from the activity timeline
  (:func:`habitsim.activity.timeline`): the gait of its locomotion, turning and
  backward walking from the root's path, standing, sitting or lying;
* **speed**: the root's mean horizontal speed over the clip [m/s] and its Froude number
  v² / (g·h) with h the species' hip height (docs/biomechanics.md);
* **turning**: the pelvis heading's change over the clip [deg] and its mean rate,
  left positive, also dimensionless ω·√(h/g) (the generator's ``turn_rate_nd``);
* **direction**: forward or backward (the root's travel against the pelvis' heading);
* **duration** and the **start and end pose** (the first and last segment of the
  timeline: standing, sitting, lying, moving);
* the timeline's **segments** (a clip that chains activities: walks, then trots).

Every figure is measured on the motion; generator metadata only names the action.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..activity import Activity, ActivityOptions, timeline
from ..errors import CaptionError
from ..physics_constants import GRAVITY
from ..rotations import heading_yaw

if TYPE_CHECKING:  # pragma: no cover
    from ..motion import Motion

__all__ = ["ClipFacts", "FactsOptions", "SegmentFacts", "clip_facts"]


@dataclass(frozen=True)
class FactsOptions:
    """Knobs of :func:`clip_facts`.

    Attributes:
        moving_speed_per_leg: below this mean root speed [leg lengths / s] a clip is not
            described as travelling (not walking backwards, no locomotion read from it
            without a locomotion segment).
        turning_rate_nd: dimensionless mean yaw rate ω·√(h/g) above which a clip turns
            (the generator's turns draw 0.1–0.4; a straight walk wanders below 0.03).
        min_duration_s: shortest clip described [s].
        activity: the timeline's knobs (:class:`~habitsim.activity.ActivityOptions`).
    """

    moving_speed_per_leg: float = 0.25
    turning_rate_nd: float = 0.05
    min_duration_s: float = 0.5
    activity: ActivityOptions = ActivityOptions()


@dataclass(frozen=True)
class SegmentFacts:
    """One segment of the clip's activity timeline.

    Attributes:
        activity: ``lying``, ``sitting``, ``standing``, ``locomotion`` or ``transition``.
        gait: the locomotion segment's gait (None: unknown or not locomotion).
        start_s, end_s: its span [s].
        speed_mps: the root's mean horizontal speed over it [m/s].
        backward: the animal moves backwards.
    """

    activity: str
    gait: str | None
    start_s: float
    end_s: float
    speed_mps: float
    backward: bool


@dataclass(frozen=True)
class ClipFacts:
    """What a caption may say of a clip (see the module docstring).

    Attributes:
        species: catalog name (``dog``).
        common_name: the catalog's common name (``Domestic dog (medium breed)``).
        action: the generator's action, or the one read from the timeline (one of
            :data:`habitsim.gaits.ACTIONS`); None when the clip shows none of them.
        gait: the gait used (``walk``, ``rotary_gallop``, ``stand``, …), None if unknown.
        duration_s: clip length [s].
        speed_mps: mean horizontal root speed [m/s] (path length over duration).
        froude: v² / (g·h) of that speed, h the species' hip height.
        backward: the animal travels (see :class:`FactsOptions`) against the
            pelvis' heading.
        turn_deg: heading change from the first to the last frame [deg], left positive.
        turn_rate_nd: mean yaw rate ω·√(h/g) (dimensionless), left positive.
        turning: ``left``, ``right`` or None (a straight path; see
            :attr:`FactsOptions.turning_rate_nd`).
        start, end: the first and last segment's activity (``standing``, ``sitting``,
            ``lying``, ``locomotion``, ``transition``).
        segments: the whole timeline.
        jump_height_m: the root's rise above its median height, for a jump [m].
        source: ``generator`` (action from the clip's metadata) or ``timeline``.
    """

    species: str
    common_name: str
    action: str | None
    gait: str | None
    duration_s: float
    speed_mps: float
    froude: float
    backward: bool
    turn_deg: float
    turn_rate_nd: float
    turning: str | None
    start: str
    end: str
    segments: tuple[SegmentFacts, ...]
    jump_height_m: float | None
    source: str

    @property
    def travels(self) -> bool:
        """The clip moves the animal along the ground."""
        from ..gaits import LOCOMOTION_ACTIONS

        return self.action in LOCOMOTION_ACTIONS

    def to_dict(self) -> dict[str, object]:
        """JSON-ready facts (rounded)."""
        return {
            "species": self.species,
            "action": self.action,
            "gait": self.gait,
            "duration_s": round(self.duration_s, 3),
            "speed_mps": round(self.speed_mps, 3),
            "froude": round(self.froude, 3),
            "backward": self.backward,
            "turn_deg": round(self.turn_deg, 1),
            "turn_rate_nd": round(self.turn_rate_nd, 3),
            "start": self.start,
            "end": self.end,
            "segments": [
                [s.activity, s.gait, round(s.start_s, 2), round(s.end_s, 2)] for s in self.segments
            ],
            "jump_height_m": None if self.jump_height_m is None else round(self.jump_height_m, 3),
            "source": self.source,
        }


def _backward(motion: Motion, yaw: np.ndarray) -> bool:
    """The root's travel points against the pelvis' heading (over the whole clip)."""
    step = np.diff(motion.root_positions[:, :2], axis=0)
    along = step[:, 0] * np.cos(yaw[1:]) + step[:, 1] * np.sin(yaw[1:])
    return bool(along.sum() < -0.25 * np.abs(along).sum())


def _inferred_action(
    segs: tuple[SegmentFacts, ...], backward: bool, turning: str | None, moving: bool
) -> tuple[str | None, str | None]:
    """(action, gait) read from the timeline."""
    loco = [s for s in segs if s.activity == Activity.LOCOMOTION]
    if loco or moving:
        longest = max(loco, key=lambda s: s.end_s - s.start_s) if loco else None
        gait = longest.gait if longest is not None else None
        if backward:
            return "walk_backward", gait
        if turning is not None:
            return f"turn_{turning}", gait
        if gait is None:
            return None, None
        for action in ("gallop", "bound", "canter", "amble", "pace", "trot", "walk"):
            if action in gait:
                return action, gait
        return None, gait
    last = segs[-1].activity if segs else None
    if last == Activity.SITTING:
        return "sit", None
    if all(s.activity == Activity.STANDING for s in segs):
        return "idle", "stand"
    return None, None


def clip_facts(motion: Motion, options: FactsOptions | None = None) -> ClipFacts:
    """Measure what is true of ``motion`` (see the module docstring).

    Raises:
        CaptionError: a clip shorter than :attr:`FactsOptions.min_duration_s` or with
            non-finite root positions.
    """
    opts = options or FactsOptions()
    sp = motion.species_info
    duration = motion.num_frames / motion.fps
    if duration < opts.min_duration_s:
        raise CaptionError(
            f"a clip of {duration:.2f} s is too short to describe; captions need at least "
            f"{opts.min_duration_s:g} s"
        )
    root = motion.root_positions
    if not np.all(np.isfinite(root)):
        raise CaptionError("the clip's root positions are not finite")
    path = float(np.linalg.norm(np.diff(root[:, :2], axis=0), axis=-1).sum())
    net = float(np.linalg.norm(root[-1, :2] - root[0, :2]))
    speed = path / duration if net > 0.2 * path else net / duration
    froude = speed**2 / (GRAVITY * sp.hip_height)
    yaw = np.unwrap(heading_yaw(motion.rotations[:, 0]))
    turn = float(yaw[-1] - yaw[0])
    turn_nd = turn / duration * math.sqrt(sp.hip_height / GRAVITY)
    moving = speed / sp.leg_length >= opts.moving_speed_per_leg
    backward = moving and _backward(motion, yaw)
    tl = timeline(motion, opts.activity)
    fps = motion.fps
    segs = []
    for s in tl.segments:
        seg_path = np.linalg.norm(np.diff(root[s.start : s.stop, :2], axis=0), axis=-1).sum()
        secs = max((s.stop - s.start) / fps, 1.0 / fps)
        segs.append(
            SegmentFacts(
                str(s.activity), s.gait, s.start / fps, s.stop / fps, seg_path / secs, s.backward
            )
        )
    segments = tuple(segs)
    turning = None
    if abs(turn_nd) >= opts.turning_rate_nd:
        turning = "left" if turn_nd > 0 else "right"
    meta_action = motion.metadata.get("action") if isinstance(motion.metadata, dict) else None
    from ..gaits import ACTIONS

    action: str | None
    gait: str | None
    if isinstance(meta_action, str) and meta_action in ACTIONS:
        action, source = meta_action, "generator"
        named = motion.metadata.get("gait")
        gait = named if isinstance(named, str) else None
    else:
        action, gait = _inferred_action(segments, backward, turning, moving)
        source = "timeline"
    jump = None
    if action == "jump":
        z = root[:, 2]
        jump = float(z.max() - np.median(z))
    return ClipFacts(
        sp.name,
        sp.common_name,
        action,
        gait,
        duration,
        speed,
        froude,
        backward,
        math.degrees(turn),
        turn_nd,
        turning,
        segments[0].activity if segments else "standing",
        segments[-1].activity if segments else "standing",
        segments,
        jump,
        source,
    )
