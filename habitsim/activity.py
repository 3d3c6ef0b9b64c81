"""What the animal does over time: a clip cut into lying, sitting, standing, locomotion
and transition segments, on the clip's own skeleton (no transfer).

:func:`timeline` reads four per-frame features of a :class:`~habitsim.motion.Motion`:

* **hind and fore trunk height**: the pelvis and the withers (``spine3``) above the
  ground, each as a share of its height in the species' standing pose
  (:meth:`habitsim.skeleton.Skeleton.standing_pose`); the ground is the clip's toe
  level (the median of the lowest toe per frame), so a clip recorded on a raised floor
  reads the same;
* **root speed**: the pelvis' horizontal speed in leg lengths per second;
* **stepping**: the share of feet in swing under the motion's stance labels
  (:mod:`habitsim.stance.labels`; detected from the feet when the motion has none),
  averaged over twice the smoothing window.

The features are smoothed with :func:`scipy.ndimage.median_filter` and
:func:`scipy.ndimage.uniform_filter1d` over :attr:`ActivityOptions.smooth_s`, then each
frame is classified:

* ``lying``: both trunk heights below :attr:`ActivityOptions.lying_ratio`;
* ``sitting``: the hind end below :attr:`ActivityOptions.sitting_hind_ratio` while the
  fore end stays at or above :attr:`ActivityOptions.sitting_fore_ratio`;
* ``locomotion``: otherwise, when the animal moves (root speed above
  :attr:`ActivityOptions.moving_speed_per_leg`, or feet stepping: a share of feet in
  swing above :attr:`ActivityOptions.stepping_share`) with its hind end at or above the
  sitting ratio, however low it runs;
* ``standing``: not moving, both heights at or above
  :attr:`ActivityOptions.upright_ratio`;
* ``transition``: anything between (lying down, getting up, sitting down, a crouch),
  and any frame whose hind or fore end rises or sinks faster than
  :attr:`ActivityOptions.settle_rate` without lying or sitting.

Runs shorter than :attr:`ActivityOptions.min_segment_s` join the segment before them
(the first joins the one after). A locomotion segment gets its gait from its footfall
pattern (:func:`habitsim.gait_stats.gait_statistics`' touchdown phases and duty factor,
matched against the species' gait table; None when it has fewer than two strides) and its
mean speed in leg lengths per second. Lying and sitting segments rest the trunk on the
ground (:attr:`Segment.trunk_on_ground`).

:func:`default_span` is the part of a clip a command runs by default (from the first
standing or locomotion segment on: a clip that starts lying or sitting is trimmed), and
:func:`choose_windows` the windows a benchmark cuts from a clip (from the locomotion
segments, never across a resting trunk; a clip shorter than a window gives one shorter
window).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum
from typing import TYPE_CHECKING

import numpy as np
from scipy.ndimage import median_filter, uniform_filter1d

from .errors import HabitsimError
from .stance.labels import runs

if TYPE_CHECKING:  # pragma: no cover
    from .motion import Motion

__all__ = [
    "Activity",
    "ActivityError",
    "ActivityOptions",
    "Segment",
    "Timeline",
    "Window",
    "choose_windows",
    "default_span",
    "timeline",
]


class ActivityError(HabitsimError, ValueError):
    """A clip that has no part a command can run (lying or sitting throughout), or bad
    activity options."""


class Activity(StrEnum):
    """What the animal does in a segment (the value is printed and written to reports)."""

    LYING = "lying"
    SITTING = "sitting"
    STANDING = "standing"
    LOCOMOTION = "locomotion"
    TRANSITION = "transition"

    @property
    def rests(self) -> bool:
        """The trunk rests on the ground (lying, or the haunches of a sit)."""
        return self in (Activity.LYING, Activity.SITTING)

    @property
    def upright(self) -> bool:
        """Standing or moving on four legs."""
        return self in (Activity.STANDING, Activity.LOCOMOTION)


_ORDER = tuple(Activity)


@dataclass(frozen=True)
class ActivityOptions:
    """The knobs of :func:`timeline` (reasons in docs/activity.md, "Why the defaults").

    Attributes:
        lying_ratio: lying when both trunk heights are below this share of their standing
            heights [unitless].
        sitting_hind_ratio: sitting when the pelvis is below this share of its standing
            height … [unitless]
        sitting_fore_ratio: … while the withers stay at or above this share [unitless].
        upright_ratio: standing when both are at or above this share [unitless].
        moving_speed_per_leg: locomotion above this root speed [leg lengths / s] …
        stepping_share: … or above this share of feet in swing (stepping on the spot,
            turning) [unitless].
        smooth_s: window of the feature smoothing [s].
        min_segment_s: shorter runs join their neighbour [s].
        gait_window_s: a locomotion segment is cut into pieces of about this length,
            each given its gait; neighbours of one gait join [s].
        ground_percentile: the ground is this percentile of the lowest toe height per
            frame [%].
        settle_rate: a frame whose hind or fore trunk height (averaged over twice the
            smoothing window) changes faster than this many standing heights per second is a
            transition, unless it lies or sits [1/s].
    """

    lying_ratio: float = 0.5
    sitting_hind_ratio: float = 0.5
    sitting_fore_ratio: float = 0.6
    upright_ratio: float = 0.75
    moving_speed_per_leg: float = 0.25
    stepping_share: float = 0.15
    smooth_s: float = 0.25
    min_segment_s: float = 0.3
    gait_window_s: float = 2.0
    ground_percentile: float = 50.0
    settle_rate: float = 0.6

    def __post_init__(self) -> None:
        if not 0 < self.lying_ratio <= self.sitting_hind_ratio <= self.upright_ratio:
            raise ActivityError(
                "activity options need 0 < lying_ratio <= sitting_hind_ratio <= "
                f"upright_ratio, got {self.lying_ratio}, {self.sitting_hind_ratio}, "
                f"{self.upright_ratio}"
            )
        if not 0 < self.sitting_fore_ratio:
            raise ActivityError(
                f"activity option sitting_fore_ratio must be > 0, got {self.sitting_fore_ratio}"
            )
        for name in (
            "settle_rate",
            "gait_window_s",
            "moving_speed_per_leg",
            "stepping_share",
            "smooth_s",
            "min_segment_s",
        ):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ActivityError(f"activity option {name} must be finite and >= 0, got {v}")
        if not 0 <= self.ground_percentile <= 100:
            raise ActivityError(
                f"activity option ground_percentile must be in 0..100, got {self.ground_percentile}"
            )


@dataclass(frozen=True)
class Segment:
    """A stretch of one activity: frames ``[start, stop)`` of a clip at ``fps``.

    Attributes:
        activity: what the animal does.
        start, stop: first frame and one past the last.
        fps: the clip's frame rate [Hz].
        speed_per_leg: mean horizontal root speed [leg lengths / s].
        gait: the gait of a locomotion segment from its footfall pattern (a name of the
            species' gait table), None when not locomotion or too short to tell.
        backward: a locomotion segment moving against the trunk's heading.
        hind_height, fore_height: median pelvis / withers height over the segment, as a
            share of the standing pose's.
    """

    activity: Activity
    start: int
    stop: int
    fps: float
    speed_per_leg: float
    gait: str | None = None
    backward: bool = False
    hind_height: float = 1.0
    fore_height: float = 1.0

    @property
    def start_s(self) -> float:
        return self.start / self.fps

    @property
    def end_s(self) -> float:
        return self.stop / self.fps

    @property
    def frames(self) -> int:
        return self.stop - self.start

    @property
    def duration(self) -> float:
        return self.frames / self.fps

    @property
    def trunk_on_ground(self) -> bool:
        """The trunk rests on the ground (lying or sitting)."""
        return self.activity.rests

    def describe(self) -> str:
        """One line: ``start–end s  activity  gait  speed``."""
        what = self.activity.value
        if self.activity is Activity.LOCOMOTION:
            what += f" ({(self.gait or 'gait unknown') + (', backward' if self.backward else '')})"
        elif self.trunk_on_ground:
            what += " (trunk on the ground)"
        return (
            f"{self.start_s:6.2f}–{self.end_s:6.2f} s  {what:<32s} "
            f"{self.speed_per_leg:5.2f} leg/s, trunk {self.hind_height:.2f}/"
            f"{self.fore_height:.2f} of standing (hind/fore)"
        )


@dataclass(frozen=True)
class Timeline:
    """A clip's segments, in order, covering every frame.

    Attributes:
        segments: the segments (consecutive, the first starting at frame 0).
        fps: the clip's frame rate [Hz].
        n_frames: the clip's frame count.
    """

    segments: tuple[Segment, ...]
    fps: float
    n_frames: int

    @property
    def duration(self) -> float:
        return self.n_frames / self.fps

    def labels(self) -> np.ndarray:
        """(T,) per-frame activity values (strings)."""
        out = np.empty(self.n_frames, dtype=object)
        for s in self.segments:
            out[s.start : s.stop] = s.activity.value
        return out

    def resting(self) -> np.ndarray:
        """(T,) bool: the trunk rests on the ground."""
        out = np.zeros(self.n_frames, dtype=bool)
        for s in self.segments:
            out[s.start : s.stop] = s.trunk_on_ground
        return out

    def of(self, activity: Activity) -> list[Segment]:
        return [s for s in self.segments if s.activity is activity]

    def describe(self) -> str:
        return "\n".join(s.describe() for s in self.segments)


# ---------------------------------------------------------------------------- features


def _heights(motion: Motion, options: ActivityOptions) -> tuple[np.ndarray, np.ndarray]:
    """Pelvis and withers height over the ground, shares of the standing pose's."""
    skel = motion.skeleton
    pos = motion.global_positions()
    root0, quats0 = skel.standing_pose()
    stand = skel.fk(root0[None], quats0[None])[0]
    toes = pos[:, skel.foot_indices, 2].min(axis=1)
    ground = float(np.percentile(toes, options.ground_percentile))
    i_p, i_c = skel.index("pelvis"), skel.index("spine3")
    ground0 = stand[skel.foot_indices, 2].min()
    hind = (pos[:, i_p, 2] - ground) / (stand[i_p, 2] - ground0)
    fore = (pos[:, i_c, 2] - ground) / (stand[i_c, 2] - ground0)
    return hind, fore


def _speed(motion: Motion) -> tuple[np.ndarray, np.ndarray]:
    """Horizontal root velocity (T, 2) [m/s] and the trunk's heading (T, 2) unit."""
    from .rotations import quat_to_matrix

    root = motion.root_positions[:, :2]
    vel = np.gradient(root, axis=0) * motion.fps if motion.num_frames > 1 else np.zeros_like(root)
    fwd = quat_to_matrix(motion.rotations[:, 0])[:, :2, 0]
    norm = np.linalg.norm(fwd, axis=1, keepdims=True)
    return vel, fwd / np.maximum(norm, 1e-9)


def _contacts(motion: Motion) -> np.ndarray:
    if motion.contacts is not None:
        return np.asarray(motion.contacts, bool)
    return np.asarray(motion.detect_contacts(), bool)


def _merge_short(codes: np.ndarray, min_frames: int) -> np.ndarray:
    """Runs shorter than ``min_frames`` take the code of the run before them (the first
    run: the one after), until every run is long enough or one run is left."""
    codes = codes.copy()
    while True:
        bounds = _code_runs(codes)
        if len(bounds) <= 1:
            return codes
        lengths = [b - a for a, b, _ in bounds]
        i = int(np.argmin(lengths))
        if lengths[i] >= min_frames:
            return codes
        a, b, _ = bounds[i]
        codes[a:b] = bounds[i - 1][2] if i > 0 else bounds[i + 1][2]


def _code_runs(codes: np.ndarray) -> list[tuple[int, int, int]]:
    """``(start, stop, code)`` of the runs of equal codes."""
    out = []
    for c in np.unique(codes):
        out += [(int(a), int(b), int(c)) for a, b in runs(codes == c)]
    return sorted(out)


def _gait(motion: Motion, contacts: np.ndarray) -> str | None:
    """The gait of the species' table whose touchdown phases (relative to LH) and duty
    factor band are nearest the clip's; None without two strides."""
    from .gait_stats import gait_statistics

    st = gait_statistics(motion, contacts)
    phases = st.phase_offsets
    if not all(math.isfinite(phases.get(f, math.nan)) for f in ("LF", "RF", "RH")):
        return None
    best, cost = None, math.inf
    for name, habit in motion.species_info.gaits.items():
        c = 0.0
        for f in ("LF", "RF", "RH"):
            d = abs(phases[f] - habit.footfall[f]) % 1.0
            c += min(d, 1.0 - d)
        lo, hi = habit.duty_factor
        c += max(0.0, lo - st.duty_factor, st.duty_factor - hi)
        if c < cost:
            best, cost = name, c
    return best


def timeline(motion: Motion, options: ActivityOptions = ActivityOptions()) -> Timeline:
    """The activity segments of ``motion`` on its own skeleton (module docstring).

    Args:
        motion: a clip (imported, synthetic, transferred) with or without stance labels.
        options: the classification's knobs.

    Returns:
        The :class:`Timeline`, every frame in exactly one segment.
    """
    o = options
    n, fps = motion.num_frames, motion.fps
    leg = motion.species_info.leg_length
    win = max(1, int(round(o.smooth_s * fps)))
    hind, fore = _heights(motion, o)
    hind = median_filter(hind, size=win, mode="nearest")
    fore = median_filter(fore, size=win, mode="nearest")
    vel, heading = _speed(motion)
    vel = uniform_filter1d(vel, size=win, axis=0, mode="nearest")
    speed = np.linalg.norm(vel, axis=1) / leg
    contacts = _contacts(motion)
    swing = uniform_filter1d((~contacts).mean(axis=1), size=2 * win, mode="nearest")
    moving = (speed > o.moving_speed_per_leg) | (swing > o.stepping_share)
    level = uniform_filter1d(np.stack([hind, fore], 1), size=2 * win, axis=0, mode="nearest")
    rate = np.abs(np.gradient(level, axis=0)).max(axis=1) * fps if n > 1 else np.zeros(n)
    settling = rate > o.settle_rate
    lying = (hind < o.lying_ratio) & (fore < o.lying_ratio)
    sitting = (hind < o.sitting_hind_ratio) & (fore >= o.sitting_fore_ratio)
    act = np.full(n, _ORDER.index(Activity.TRANSITION))
    act[(hind >= o.upright_ratio) & (fore >= o.upright_ratio)] = _ORDER.index(Activity.STANDING)
    act[moving & (hind >= o.sitting_hind_ratio) & (fore >= o.lying_ratio)] = _ORDER.index(
        Activity.LOCOMOTION
    )
    act[settling] = _ORDER.index(Activity.TRANSITION)
    act[sitting] = _ORDER.index(Activity.SITTING)
    act[lying] = _ORDER.index(Activity.LYING)
    act = _merge_short(act, max(1, int(round(o.min_segment_s * fps))))
    pieces: list[tuple[int, int, Activity, str | None]] = []
    for a, b, code in _code_runs(act):
        activity = _ORDER[code]
        if activity is not Activity.LOCOMOTION:
            pieces.append((a, b, activity, None))
            continue
        k = max(1, int(round((b - a) / max(o.gait_window_s * fps, 1.0))))
        edges = np.linspace(a, b, k + 1).round().astype(int).tolist()
        for c0, c1 in zip(edges[:-1], edges[1:], strict=True):
            gait = _gait(motion.slice(c0, c1), contacts[c0:c1])
            last = pieces[-1] if pieces else None
            if (
                last is not None
                and last[2] is Activity.LOCOMOTION
                and (gait is None or last[3] in (None, gait))
            ):
                pieces[-1] = (last[0], c1, activity, last[3] or gait)
            else:
                pieces.append((c0, c1, activity, gait))
    segs = []
    for a, b, activity, gait in pieces:
        backward = False
        if activity is Activity.LOCOMOTION:
            along = float(np.einsum("ti,ti->t", vel[a:b], heading[a:b]).mean())
            backward = along < -o.moving_speed_per_leg * leg
        segs.append(
            Segment(
                activity,
                a,
                b,
                fps,
                float(speed[a:b].mean()),
                gait,
                backward,
                float(np.median(hind[a:b])),
                float(np.median(fore[a:b])),
            )
        )
    return Timeline(tuple(segs), fps, n)


# ---------------------------------------------------------------------------- spans


def default_span(tl: Timeline, options: ActivityOptions = ActivityOptions()) -> tuple[int, int]:
    """Frames ``[start, stop)`` a command runs by default: the whole clip when it starts
    standing or moving; else from :attr:`ActivityOptions.smooth_s` into its first
    standing or locomotion segment (the smoothing blurs a segment's edge by that much:
    the body has settled there) to the end of the clip. A lying or sitting start, and
    the transition out of it, are left out.

    Raises:
        ActivityError: the clip never stands or moves on its legs.
    """
    for s in tl.segments:
        if s.activity.upright:
            if s.start == 0:
                return 0, tl.n_frames
            settle = int(round(options.smooth_s * tl.fps))
            return min(s.start + settle, s.stop - 1), tl.n_frames
    raise ActivityError(
        f"no standing or locomotion segment in the clip ({tl.duration:.2f} s: "
        + ", ".join(f"{s.activity.value} {s.start_s:.2f}–{s.end_s:.2f} s" for s in tl.segments)
        + "); give a clip in which the animal stands or moves, or pick its part by hand"
    )


@dataclass(frozen=True)
class Window:
    """A window a benchmark cuts from a clip: frames ``[start, stop)``; ``short`` when the
    clip (or its longest upright stretch) is shorter than the window asked for."""

    start: int
    stop: int
    short: bool = False

    @property
    def frames(self) -> int:
        return self.stop - self.start


def choose_windows(
    tl: Timeline,
    frames: int,
    max_windows: int,
    min_frames: int = 1,
    options: ActivityOptions = ActivityOptions(),
) -> list[Window]:
    """Windows of ``frames`` frames from the clip's locomotion.

    The clip splits into upright stretches (consecutive standing, locomotion and
    transition segments between the resting ones); lying and sitting segments, and a
    transition touching them, are kept out. In each stretch with locomotion, consecutive
    windows start at its first locomotion segment that travels (mean speed above
    :attr:`ActivityOptions.moving_speed_per_leg`; else its first locomotion segment),
    moved back so the window fits the stretch when it would run past its end, up to
    ``max_windows`` in all. A stretch after a resting segment begins
    :attr:`ActivityOptions.smooth_s` into it, where :func:`default_span` begins. When no
    stretch holds a whole window, the longest stretch with locomotion (else the longest
    upright one) of at least ``min_frames`` frames is one shorter window (``short``).

    Returns:
        The windows in clip order; [] when the clip has no upright stretch of
        ``min_frames`` frames.
    """
    if frames < 1 or max_windows < 1:
        raise ActivityError(
            f"windows need frames >= 1 and a count >= 1, got {frames}, {max_windows}"
        )
    segs = list(tl.segments)
    keep = []
    for i, s in enumerate(segs):
        near_rest = s.activity is Activity.TRANSITION and any(
            0 <= j < len(segs) and segs[j].activity.rests for j in (i - 1, i + 1)
        )
        keep.append(not s.activity.rests and not near_rest)
    stretches: list[list[Segment]] = []
    for s, k in zip(segs, keep, strict=True):
        if not k:
            if stretches and stretches[-1]:
                stretches.append([])
            continue
        if not stretches:
            stretches.append([])
        stretches[-1].append(s)
    stretches = [st for st in stretches if st]
    out: list[Window] = []
    settle = int(round(options.smooth_s * tl.fps))

    def bounds(st: list[Segment]) -> tuple[int, int]:
        a, b = st[0].start, st[-1].stop
        return (min(a + settle, b) if a > 0 else a), b

    for st in stretches:
        a, b = bounds(st)  # after a resting segment: where the body has settled
        loco = [s for s in st if s.activity is Activity.LOCOMOTION]
        if not loco or b - a < frames:
            continue
        travels = [s for s in loco if s.speed_per_leg > options.moving_speed_per_leg]
        first = min(max((travels or loco)[0].start, a), b - frames)
        at = first
        while at + frames <= b and len(out) < max_windows:
            out.append(Window(at, at + frames))
            at += frames
    if out:
        return out

    moving = [st for st in stretches if any(s.activity is Activity.LOCOMOTION for s in st)]
    pool = [bounds(st) for st in (moving or stretches)]
    if not pool:
        return []
    a, b = max(pool, key=lambda ab: ab[1] - ab[0])
    if b - a < min_frames:
        return []
    return [Window(a, b, short=True)]
