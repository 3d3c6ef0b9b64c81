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
* the timeline's **segments** (a clip that chains activities: walks, then trots);
* the **chain** of actions (:class:`ChainStep`): a chained clip's steps from its
  generator metadata (``metadata["chain"]``, :func:`habitsim.gaits.generate_chain`), or,
  for a clip without a generator action, the timeline's segments read as actions when
  they are two or more; each step's speed and turn measured over its own span.

Every figure is measured on the motion; generator metadata only names the action.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from ..activity import Activity, ActivityOptions, timeline
from ..errors import CaptionError
from ..physics_constants import GRAVITY
from ..rotations import heading_yaw

if TYPE_CHECKING:  # pragma: no cover
    from ..motion import Motion

__all__ = ["ChainStep", "ClipFacts", "FactsOptions", "SegmentFacts", "clip_facts"]


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
class ChainStep:
    """One step of a clip that chains actions.

    Attributes:
        action: ``walk``, ``trot``, ``pace``, ``amble``, ``canter``, ``gallop``,
            ``bound``, ``turn_left``, ``turn_right``, ``walk_backward``, ``stop``,
            ``idle``, ``sit`` or ``lie``.
        gait: the species gait (``rotary_gallop``, ``stand``, …), None if unknown.
        start_s, end_s: its span [s].
        speed_mps: the root's mean horizontal speed over it [m/s].
        froude: v² / (g·h) of that speed.
        turn_deg: the pelvis heading's change over it [deg], left positive.
    """

    action: str
    gait: str | None
    start_s: float
    end_s: float
    speed_mps: float
    froude: float
    turn_deg: float

    def to_list(self) -> list[object]:
        """JSON-ready ``[action, gait, start_s, end_s, speed_mps, turn_deg]`` (rounded)."""
        return [
            self.action,
            self.gait,
            round(self.start_s, 2),
            round(self.end_s, 2),
            round(self.speed_mps, 3),
            round(self.turn_deg, 1),
        ]


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
        chain: the steps of a clip that chains actions (empty: one action); ``action``
            is then its longest locomotion step's (or first step's) action.
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
    chain: tuple[ChainStep, ...] = ()

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
            **({"chain": [c.to_list() for c in self.chain]} if self.chain else {}),
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


def _step(
    action: str, gait: str | None, a: int, b: int, motion: Motion, yaw: np.ndarray
) -> ChainStep:
    """A chain step measured over frames [a, b)."""
    root = motion.root_positions
    b = max(min(b, motion.num_frames), a + 2)
    secs = (b - 1 - a) / motion.fps
    path = float(np.linalg.norm(np.diff(root[a:b, :2], axis=0), axis=-1).sum())
    v = path / max(secs, 1e-9)
    sp = motion.species_info
    turn = math.degrees(float(yaw[b - 1] - yaw[a]))
    return ChainStep(
        action, gait, a / motion.fps, b / motion.fps, v, v * v / (GRAVITY * sp.hip_height), turn
    )


def _chain_from_metadata(motion: Motion, yaw: np.ndarray) -> tuple[ChainStep, ...]:
    chain = motion.metadata.get("chain") if isinstance(motion.metadata, dict) else None
    segs = chain.get("segments") if isinstance(chain, dict) else None
    if not isinstance(segs, list):
        return ()
    out = []
    for s in segs:
        if not (isinstance(s, dict) and isinstance(s.get("action"), str)):
            return ()
        a = int(round(float(s["start_s"]) * motion.fps))
        b = int(round(float(s["end_s"]) * motion.fps))
        gait = s.get("gait")
        out.append(_step(s["action"], gait if isinstance(gait, str) else None, a, b, motion, yaw))
    return tuple(out)


def _chain_from_timeline(
    motion: Motion, tl_segments: list[Any], yaw: np.ndarray, opts: FactsOptions
) -> tuple[ChainStep, ...]:
    """The timeline's segments as actions (two or more of them, else none)."""
    sp = motion.species_info
    tau = math.sqrt(sp.hip_height / GRAVITY)
    steps: list[tuple[str, str | None, int, int]] = []
    for s in tl_segments:
        act = str(s.activity)
        if act == Activity.LOCOMOTION:
            gait = s.gait
            name = None
            for a in ("gallop", "bound", "canter", "amble", "pace", "trot", "walk"):
                if gait is not None and a in gait:
                    name = a
                    break
            if s.backward:
                name = "walk_backward"
            elif name in (None, "walk"):
                secs = max((s.stop - s.start) / motion.fps, 1e-9)
                rate = math.radians(_step("walk", gait, s.start, s.stop, motion, yaw).turn_deg)
                nd = rate / secs * tau
                name = (
                    ("turn_left" if nd > 0 else "turn_right")
                    if abs(nd) >= opts.turning_rate_nd
                    else name
                )
            if name is None:
                continue
            step = (name, gait, s.start, s.stop)
        elif act == Activity.STANDING:
            step = ("idle", "stand", s.start, s.stop)
        elif act == Activity.SITTING:
            step = ("sit", "sit", s.start, s.stop)
        elif act == Activity.LYING:
            step = ("lie", "lie", s.start, s.stop)
        else:
            continue  # a transition: it belongs to the steps on either side
        if steps and steps[-1][0] == step[0]:
            steps[-1] = (step[0], steps[-1][1], steps[-1][2], step[3])
        else:
            steps.append(step)
    if len(steps) < 2:
        return ()
    return tuple(_step(a, g, s0, s1, motion, yaw) for a, g, s0, s1 in steps)


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
    chain: tuple[ChainStep, ...] = ()
    if isinstance(meta_action, str) and meta_action in ACTIONS:
        action, source = meta_action, "generator"
        named = motion.metadata.get("gait")
        gait = named if isinstance(named, str) else None
    elif meta_action == "chain" and (chain := _chain_from_metadata(motion, yaw)):
        action, gait, source = _chain_action(chain), None, "generator"
    else:
        action, gait = _inferred_action(segments, backward, turning, moving)
        source = "timeline"
        chain = _chain_from_timeline(motion, list(tl.segments), yaw, opts)
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
        chain,
    )


def _chain_action(chain: tuple[ChainStep, ...]) -> str | None:
    """The action of a chain's longest locomotion step (else of its first step)."""
    from ..gaits import ACTIONS, LOCOMOTION_ACTIONS

    loco = [c for c in chain if c.action in LOCOMOTION_ACTIONS]
    pick = max(loco, key=lambda c: c.end_s - c.start_s) if loco else chain[0]
    return pick.action if pick.action in ACTIONS else None
