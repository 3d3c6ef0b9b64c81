"""Foot-contact detection from toe kinematics, with thresholds scaled to the animal's size.

A foot (its toe end point, see :meth:`habitsim.motion.Motion.foot_positions`) is in
contact with the ground (the plane z = 0) in a frame when

* its height is below :data:`CONTACT_HEIGHT_PER_LEG` × leg length (2 %, the contact
  definition of docs/metrics.md's ``skate_mm``), and
* its horizontal speed is below :attr:`ContactOptions.speed_per_leg` × leg length per second
  (0.3 leg lengths per second; for a 0.61 m dog leg that is 0.18 m/s, for a cat's 0.27 m
  leg 0.08 m/s). The speed of frame t is the smaller of the backward and the forward
  one-frame displacement times fps, so the touchdown frame (foot still moving into frame
  t, resting from t on) and the last stance frame (resting until t, moving after) both
  count as resting.

"Leg length" is the species' hind-leg length (:attr:`habitsim.species.Species.leg_length`).

Cleanup, in this order:

1. hysteresis: a frame that only meets the looser thresholds
   (× :attr:`ContactOptions.hysteresis`, i.e. 1.5 × both limits) is in contact if it
   belongs to a run of such frames that contains at least one frame meeting the strict
   thresholds — noise around the threshold does not break a stance phase, but a
   hovering foot never starts one;
2. single-frame gaps inside a stance phase are filled (``1 0 1`` → ``1 1 1``);
3. single-frame contacts between two swing frames are removed (``0 1 0`` → ``0 0 0``).

Everything is vectorised numpy. The two thresholds of the algorithm are the fields of
:class:`ContactOptions` (``options`` of :func:`detect_contacts` and
:func:`contacts_from_feet`); the contact height is the shared convention
:data:`habitsim.physics_constants.CONTACT_HEIGHT_PER_LEG`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np

from .errors import InvalidMotionError
from .physics_constants import CONTACT_HEIGHT_PER_LEG, GRAVITY
from .stance.labels import runs_holding, stance_runs, swing_gaps

if TYPE_CHECKING:  # pragma: no cover
    from .species import Species

__all__ = [
    "CONTACT_HEIGHT_PER_LEG",
    "ContactOptions",
    "FootTrack",
    "detect_contacts",
    "contacts_from_feet",
    "ground_reach",
    "bearing_contacts",
    "contacts_by_duty",
    "touchdown_frames",
    "drop_short_runs",
    "lengthen_stance",
    "fill_support",
    "warp_contacts",
    "foot_stride_periods",
    "stride_period",
    "quicken_contacts",
]


class FootTrack(Protocol):
    """What :func:`detect_contacts` reads of a motion (:class:`habitsim.motion.Motion`,
    which imports this module: contacts sit below motions)."""

    fps: float

    @property
    def species_info(self) -> Species: ...

    def foot_positions(self) -> np.ndarray: ...


@dataclass(frozen=True)
class ContactOptions:
    """The knobs of contact detection from toe kinematics (:func:`detect_contacts`).

    Attributes:
        speed_per_leg: horizontal toe speed threshold [hind-leg lengths per second].
        hysteresis: factor on both thresholds (height and speed) for the loose,
            staying-in-contact condition [unitless, ≥ 1].
    """

    speed_per_leg: float = 0.3
    hysteresis: float = 1.5


def _toe_speed(feet: np.ndarray, fps: float) -> np.ndarray:
    """(T, F) horizontal toe speed [m/s]: min of backward and forward differences."""
    t = feet.shape[0]
    if t < 2:
        return np.zeros(feet.shape[:2])
    step = np.linalg.norm(np.diff(feet[..., :2], axis=0), axis=-1) * fps  # (T-1, F)
    back = np.concatenate([step[:1], step], axis=0)
    fwd = np.concatenate([step, step[-1:]], axis=0)
    return np.minimum(back, fwd)


def _fill_and_open(c: np.ndarray) -> np.ndarray:
    """Fill single-frame gaps, then remove single-frame contacts (along axis 0)."""
    c = c.copy()
    if c.shape[0] >= 3:
        gap = ~c[1:-1] & c[:-2] & c[2:]
        c[1:-1] |= gap
        lone = c[1:-1] & ~c[:-2] & ~c[2:]
        c[1:-1] &= ~lone
    return c


def _checked_feet(feet: np.ndarray, fps: float, leg_length: float) -> np.ndarray:
    """``feet`` as float64 (T, F, 3), after checking it and the scalars."""
    feet = np.asarray(feet, dtype=np.float64)
    if feet.ndim != 3 or feet.shape[-1] != 3:
        raise InvalidMotionError(f"feet must have shape (T, F, 3), got {feet.shape}")
    if not (leg_length > 0 and fps > 0):
        raise InvalidMotionError("leg_length and fps must be positive")
    return feet


def contacts_from_feet(
    feet: np.ndarray, fps: float, leg_length: float, options: ContactOptions = ContactOptions()
) -> np.ndarray:
    """Contacts from toe trajectories (the core of :func:`detect_contacts`).

    Args:
        feet: (T, F, 3) toe positions [m], z up, ground at z = 0.
        fps: frame rate [Hz].
        leg_length: the normalising hind-leg length [m].
        options: the detection's thresholds.

    Returns:
        (T, F) bool contact flags.
    """
    feet = _checked_feet(feet, fps, leg_length)
    h_thr = CONTACT_HEIGHT_PER_LEG * leg_length
    v_thr = options.speed_per_leg * leg_length
    height = feet[..., 2]
    speed = _toe_speed(feet, fps)
    strict = (height < h_thr) & (speed < v_thr)
    k = options.hysteresis
    loose = (height < k * h_thr) & (speed < k * v_thr)
    return _fill_and_open(runs_holding(loose, strict))


def detect_contacts(motion: FootTrack, options: ContactOptions = ContactOptions()) -> np.ndarray:
    """Foot contacts of a motion from toe height and horizontal speed.

    Thresholds are size-normalised (see the module docstring): height < 2 % and
    horizontal speed < 0.3 hind-leg lengths per second, with 1.5× hysteresis and
    single-frame cleanup.

    Args:
        motion: the motion (its ``contacts`` labels are ignored).
        options: the detection's thresholds.

    Returns:
        (T, 4) bool, feet LF, RF, LH, RH.
    """
    return contacts_from_feet(
        motion.foot_positions(), motion.fps, motion.species_info.leg_length, options
    )


def ground_reach(leg_length: float, options: ContactOptions | None = None) -> float:
    """The highest a foot may be above the ground and still bear weight [m].

    The contact height (:data:`CONTACT_HEIGHT_PER_LEG` × leg length) times the detection's
    hysteresis factor: the highest toe :func:`detect_contacts` ever keeps in contact
    (3 % of the leg with the default options), so every detected contact bears weight and
    a labelled foot higher than that does not.

    Args:
        leg_length: the normalising hind-leg length [m].
        options: the detection's thresholds (default :class:`ContactOptions`).
    """
    o = ContactOptions() if options is None else options
    return CONTACT_HEIGHT_PER_LEG * o.hysteresis * float(leg_length)


def bearing_contacts(
    contacts: np.ndarray,
    heights: np.ndarray,
    leg_length: float,
    options: ContactOptions | None = None,
) -> np.ndarray:
    """Contact labels the geometry allows: a labelled foot in mid-air bears nothing.

    Args:
        contacts: (T, F) bool contact labels.
        heights: (T, F) height of each foot's lowest point above the ground [m] (below the
            ground, negative, still bears: sinking is the penetration metric's business).
        leg_length: the normalising hind-leg length [m].
        options: the detection's thresholds (:func:`ground_reach`).

    Returns:
        (T, F) bool: labelled and no higher than :func:`ground_reach`.

    Raises:
        InvalidMotionError: the shapes differ.
    """
    c = np.asarray(contacts, dtype=bool)
    z = np.asarray(heights, dtype=np.float64)
    if c.shape != z.shape:
        raise InvalidMotionError(f"contacts {c.shape} and foot heights {z.shape} must match")
    return c & (z <= ground_reach(leg_length, options))


def contacts_by_duty(
    feet: np.ndarray, fps: float, leg_length: float, duty: float | np.ndarray
) -> np.ndarray:
    """Stance labels of a gait whose feet never quite rest (a generated motion that skates).

    Each foot is taken to be in stance for the share ``duty`` of the clip (its gait's duty
    factor): the frames where it is slowest and lowest, ranked by
    ``speed / √(g·leg) + height / leg``, then cleaned by a 5-frame majority vote and the
    single-frame rules of :func:`detect_contacts`. A stance foot moves backward relative
    to the body and sits at the bottom of its path, so the ranking finds the stance
    phases of a cyclic gait even where no frame meets the resting thresholds; the labels
    then tell a refinement (:mod:`habitsim.refine`) where to plant the feet.

    Args:
        feet: (T, F, 3) toe positions [m], z up.
        fps: frame rate [Hz].
        leg_length: the normalising hind-leg length [m].
        duty: duty factor in (0, 1), one for all feet or one per foot (F,).

    Returns:
        (T, F) bool stance flags.
    """
    feet = _checked_feet(feet, fps, leg_length)
    d = np.broadcast_to(np.asarray(duty, dtype=np.float64), (feet.shape[1],))
    if np.any(~np.isfinite(d)) or np.any(d <= 0.0) or np.any(d >= 1.0):
        raise InvalidMotionError(f"duty factors must lie in (0, 1), got {d.tolist()}")
    score = _toe_speed(feet, fps) / np.sqrt(GRAVITY * leg_length) + feet[..., 2] / leg_length
    thr = np.array([np.quantile(score[:, f], d[f]) for f in range(feet.shape[1])])
    c = score <= thr[None, :]
    if c.shape[0] >= 5:  # 5-frame majority vote per foot (a binary median), edges repeated
        from scipy.ndimage import median_filter  # (on use: scipy.ndimage takes 0.3 s)

        c = median_filter(c, size=(5, 1), mode="nearest")
    return _fill_and_open(c)


def touchdown_frames(contacts: np.ndarray) -> list[np.ndarray]:
    """Touchdown frames per foot: frames t ≥ 1 with contact at t and none at t − 1.

    A contact already present in frame 0 is not a touchdown (its start is unknown).

    Args:
        contacts: (T, F) bool contact flags.

    Returns:
        For each foot, an int array of touchdown frame indices (ascending).
    """
    c = np.asarray(contacts, dtype=bool)
    if c.ndim != 2:
        raise InvalidMotionError(f"contacts must have shape (T, F), got {c.shape}")
    td = c[1:] & ~c[:-1]
    return [np.flatnonzero(td[:, f]) + 1 for f in range(c.shape[1])]


def drop_short_runs(contacts: np.ndarray, min_frames: int = 2) -> np.ndarray:
    """Contact labels without runs shorter than ``min_frames``.

    First every swing gap shorter than ``min_frames`` between two stance phases of a foot
    is filled, then every stance run shorter than ``min_frames`` is removed (swing), so a
    flicker neither splits a stance phase nor makes a stance of its own. With
    ``min_frames = 2`` this is the single-frame cleanup of :func:`detect_contacts`, also at
    the clip's ends.

    Args:
        contacts: (T, F) bool contact flags.
        min_frames: shortest run kept [frames], ≥ 1.

    Returns:
        (T, F) bool, a new array.
    """
    c = np.asarray(contacts, dtype=bool)
    if c.ndim != 2:
        raise InvalidMotionError(f"contacts must have shape (T, F), got {c.shape}")
    if int(min_frames) < 1:
        raise InvalidMotionError(f"min_frames must be >= 1, got {min_frames}")
    out = c.copy()
    t = c.shape[0]
    for f, runs in enumerate(swing_gaps(out)):
        for a, b in runs:
            if a > 0 and b < t and b - a < min_frames:  # a gap between two stance phases
                out[a:b, f] = True
    for f, runs in enumerate(stance_runs(out)):
        for a, b in runs:
            if b - a < min_frames:
                out[a:b, f] = False
    return out


def lengthen_stance(contacts: np.ndarray, min_share: float) -> np.ndarray:
    """Contact labels whose every foot stands at least ``min_share`` of the frames.

    The stance runs of a foot that stands less are lengthened by the same number of
    frames at both ends (a binary dilation; runs at the clip's ends grow inward), the
    smallest number that reaches the share: each run keeps its middle, so the footfall
    schedule keeps its phases and only the duty factor rises. Runs that meet merge. A
    foot with no stance, or one already standing ``min_share`` of the clip, is kept.

    Args:
        contacts: (T, F) bool contact flags.
        min_share: the least stance share in [0, 1].

    Returns:
        (T, F) bool, a new array.
    """
    from scipy.ndimage import distance_transform_edt  # (on use: scipy.ndimage takes 0.3 s)

    c = np.asarray(contacts, dtype=bool)
    if c.ndim != 2:
        raise InvalidMotionError(f"contacts must have shape (T, F), got {c.shape}")
    share = float(min_share)
    if not 0.0 <= share <= 1.0:
        raise InvalidMotionError(f"min_share must lie in [0, 1], got {min_share!r}")
    out = c.copy()
    need = max(1, int(np.ceil(share * c.shape[0] - 1e-9)))  # stance frames wanted
    for f in range(c.shape[1]):
        col = c[:, f]
        if not col.any() or col.mean() >= share:
            continue
        dist = distance_transform_edt(~col)  # frames to the nearest stance frame
        out[:, f] = dist <= np.sort(dist)[need - 1]
    return out


def fill_support(contacts: np.ndarray, min_feet: int = 2) -> np.ndarray:
    """Contact labels with at least ``min_feet`` feet in stance on every frame.

    Frame by frame from the first short one, the stance run nearest in time to it is
    lengthened to cover it: the run of a foot that lifted off last is held longer, or
    the run of the foot that lands next lands earlier, whichever changes fewer frames.
    A frame no run can reach (a foot with no stance at all) stays short.

    Args:
        contacts: (T, F) bool contact flags.
        min_feet: the least number of feet in stance, in [0, F].

    Returns:
        (T, F) bool, a new array.
    """
    c = np.array(contacts, dtype=bool)
    if c.ndim != 2:
        raise InvalidMotionError(f"contacts must have shape (T, F), got {c.shape}")
    t, nf = c.shape
    if not 0 <= int(min_feet) <= nf:
        raise InvalidMotionError(f"min_feet must lie in [0, {nf}], got {min_feet!r}")
    skip = np.zeros(t, dtype=bool)
    while True:
        short = np.flatnonzero((c.sum(axis=1) < int(min_feet)) & ~skip)
        if short.size == 0:
            return c
        k = int(short[0])
        best: tuple[int, int, int, int] | None = None  # (cost, foot, lo, hi)
        for foot in np.flatnonzero(~c[k]).tolist():
            on = np.flatnonzero(c[:, foot])
            before, after = on[on < k], on[on > k]
            if before.size and (best is None or k - before[-1] < best[0]):
                best = (k - int(before[-1]), foot, int(before[-1]) + 1, k + 1)
            if after.size and (best is None or after[0] - k < best[0]):
                best = (int(after[0]) - k, foot, k, int(after[0]))
        if best is None:
            skip[k] = True
            continue
        _, foot, lo, hi = best
        c[lo:hi, foot] = True


def warp_contacts(contacts: np.ndarray, n_frames: int) -> np.ndarray:
    """Contact labels carried to a clip of another length in normalised time.

    Frame ``i`` of the ``n_frames`` result takes the label of the source frame nearest to
    ``i · (T − 1) / (n_frames − 1)``: the same footfall schedule over the same share of
    the clip (a time warp when a stage changes the clip's length or cadence).

    Args:
        contacts: (T, F) bool contact flags.
        n_frames: frames of the result, ≥ 1.

    Returns:
        (n_frames, F) bool (a copy when the lengths match).
    """
    c = np.asarray(contacts, dtype=bool)
    if c.ndim != 2 or c.shape[0] < 1:
        raise InvalidMotionError(f"contacts must have shape (T, F) with T >= 1, got {c.shape}")
    n = int(n_frames)
    if n < 1:
        raise InvalidMotionError(f"n_frames must be >= 1, got {n_frames}")
    t = c.shape[0]
    if n == t:
        return c.copy()
    if n == 1 or t == 1:
        return np.repeat(c[:1], n, axis=0)
    src = np.rint(np.arange(n) * (t - 1) / (n - 1)).astype(int)
    return c[np.clip(src, 0, t - 1)]


def foot_stride_periods(contacts: np.ndarray) -> np.ndarray:
    """(F,) each foot's stride period [frames]: the median interval between its successive
    touchdowns (NaN for a foot that touches down fewer than twice).

    Args:
        contacts: (T, F) bool contact flags.
    """
    return np.array(
        [
            float(np.median(np.diff(td))) if len(td) >= 2 else np.nan
            for td in touchdown_frames(contacts)
        ]
    )


def stride_period(contacts: np.ndarray) -> float | None:
    """The stride period of a footfall schedule [frames]: the median of the feet's own
    periods (:func:`foot_stride_periods`), when at least two feet touch down twice.

    Args:
        contacts: (T, F) bool contact flags.

    Returns:
        The period, or ``None`` when fewer than two feet touch down twice (a clip that
        does not step: standing, sitting, a single jump).
    """
    per_foot = foot_stride_periods(contacts)
    finite = per_foot[np.isfinite(per_foot)]
    return float(np.median(finite)) if len(finite) >= 2 else None


def quicken_contacts(contacts: np.ndarray, rate: np.ndarray, period: float) -> np.ndarray:
    """A footfall schedule played faster where ``rate`` > 1, over the same frames.

    Frame ``t`` of the result takes the label of schedule time Σ rate[1..t] (nearest
    frame): where the rate is 1 the schedule is unchanged, where it is 2 the feet step
    twice as often; the duty factor and the feet's phase offsets stay the schedule's.
    Schedule times past the clip's end are wrapped back by whole periods into its last
    stride, so a cyclic gait keeps stepping.

    Args:
        contacts: (T, F) bool contact flags.
        rate: (T,) playback rate per frame, ≥ 1.
        period: the schedule's stride period [frames] (:func:`stride_period`), ≤ T.

    Returns:
        (T, F) bool, a new array.

    Raises:
        InvalidMotionError: shapes that do not match, a rate below 1, a bad period.
    """
    c = np.asarray(contacts, dtype=bool)
    if c.ndim != 2 or c.shape[0] < 1:
        raise InvalidMotionError(f"contacts must have shape (T, F) with T >= 1, got {c.shape}")
    t = c.shape[0]
    r = np.asarray(rate, dtype=np.float64)
    if r.shape != (t,) or not np.all(np.isfinite(r)) or np.any(r < 1.0):
        raise InvalidMotionError(f"rate must be ({t},) finite values >= 1, got shape {r.shape}")
    if not (0.0 < float(period) <= t):
        raise InvalidMotionError(f"period must be in (0, {t}] frames, got {period}")
    pos = np.concatenate([[0.0], np.cumsum(r[1:])])
    lo = t - float(period)  # start of the clip's last stride
    pos = np.where(pos >= t, lo + np.mod(pos - lo, float(period)), pos)
    return c[np.clip(np.rint(pos).astype(int), 0, t - 1)]
