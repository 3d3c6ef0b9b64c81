"""In-place clips: a root that stays put while the stance feet sweep backwards, and the
root's travel recovered from those feet (:func:`recover_in_place`).

Game-engine animation is usually made *in place*: the character walks on the spot and
the engine moves it. Imported as it is, its stance feet slide backwards under a still
body, so no foot ever rests and the stance labels are nearly empty. A foot in stance is
fixed in the world, so the body moves by the negative of its sweep: the body's velocity
in each frame is minus the velocity of the feet that are on the ground, and integrating
it gives the travel the clip left out. The stance labelling and the planting then run on
the clip with that travel added, as on any captured clip.

The travel is measured twice. :func:`recover_in_place` finds it from the low feet that
sweep back together; the import then labels the stance on the clip with that travel added
and :func:`refit_in_place` measures it again on those stance runs, each without its first
and last frames (:attr:`InPlaceOptions.stance_trim_share`): a paw settles at touch-down
and rolls over its toes at lift-off, so its points move forward with the body there and
would make the body slower than it is. A keyframed loop's stance is its feet's backward
sweeps (:func:`sweep_labels`); where such a sweep is longer than the target's leg reaches
planted, :func:`trim_unreached` makes the ends it does not reach swing.

Detection asks three things of the clip (each an evidence figure of :class:`InPlaceFit`):
the trunk's horizontal travel is a small share of the feet's backward sweep (a moving
clip's trunk travels about as far as its feet sweep back under it); the low feet move
backwards relative to the trunk's facing (a walk, not a dance on the spot); and they
sweep far enough to be a gait (an idle clip's feet barely move). The knobs are the
fields of :class:`InPlaceOptions`; why each default: ``docs/import.md``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.ndimage import uniform_filter1d
from scipy.signal import savgol_filter

from ..errors import HabitsimError
from ..stance.labels import EditReason, StanceLabels, runs

__all__ = [
    "InPlaceOptions",
    "InPlaceOptionsError",
    "InPlaceFit",
    "recover_in_place",
    "refit_in_place",
    "stance_centres",
    "sweep_labels",
    "trim_unreached",
]


class InPlaceOptionsError(HabitsimError, ValueError):
    """An :class:`InPlaceOptions` field outside its valid range."""


@dataclass(frozen=True)
class InPlaceOptions:
    """The knobs of detecting an in-place clip and recovering its travel.

    Attributes:
        enabled: look for an in-place clip at all (False: every clip is imported as it
            is).
        max_root_share: the clip is in place when the trunk's horizontal path is below
            this share of the feet's backward sweep [unitless].
        min_backward_share: ... and the low feet's motion relative to the trunk points
            backwards by at least this share (the mean of −u·forward / |u| over low frames
            of all feet; 1 = straight back) [unitless].
        min_sweep_per_leg: ... and the feet sweep back at least this far (the mean over the
            four feet) [hind-leg lengths].
        low_per_leg: a foot is low (a stance candidate) while its lowest point is below
            this height above its floor [hind-leg lengths].
        agree_share: a low foot is in stance in a frame when its velocity is within this
            share of the body's first estimate of the negative body velocity (stance
            feet move together) [unitless].
        trunk_window_s: the trunk's travel is measured on its position averaged over
            this window (its sway within a stride and marker noise left out) [s].
        smooth_s: window of the Savitzky–Golay filters on the foot paths and on the
            recovered body velocity [s].
        sweep_low_per_leg: a foot sweeps in stance (:attr:`InPlaceFit.sweep`) while it
            moves backwards relative to the trunk below this height above its floor
            [hind-leg lengths]; a keyframed foot rolls and lifts within its stance.
        relabel_share: a foot of an in-place clip whose stance share (labelled on the
            recovered clip) is under this share of its sweep share takes its sweeps as
            stance (:func:`sweep_labels`) [unitless].
        stance_trim_share: :func:`refit_in_place` leaves out this share of each stance
            run's frames at each end (touch-down and lift-off, where a paw settles and
            rolls) [unitless, below 0.5].
        stance_smooth_s: window of the Savitzky–Golay filter on the foot paths whose
            velocities :func:`refit_in_place` reads [s].
        reach_per_leg: a foot that took its sweeps as stance loses the frames at the
            ends of a stance run where its planted toe stays higher than this above the
            ground (:func:`trim_unreached`) [target leg lengths].
    """

    enabled: bool = True
    max_root_share: float = 0.5
    min_backward_share: float = 0.5
    min_sweep_per_leg: float = 0.3
    low_per_leg: float = 0.03
    agree_share: float = 0.25
    trunk_window_s: float = 1.0
    smooth_s: float = 0.2
    sweep_low_per_leg: float = 0.1
    relabel_share: float = 0.8
    stance_trim_share: float = 0.2
    stance_smooth_s: float = 0.1
    reach_per_leg: float = 0.002

    def __post_init__(self) -> None:
        for name in (
            "max_root_share",
            "min_sweep_per_leg",
            "low_per_leg",
            "agree_share",
            "sweep_low_per_leg",
            "relabel_share",
            "reach_per_leg",
            "smooth_s",
            "trunk_window_s",
            "stance_smooth_s",
        ):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0.0):
                raise InPlaceOptionsError(f"InPlaceOptions.{name} must be > 0, got {v!r}")
        if not 0.0 <= self.stance_trim_share < 0.5:
            raise InPlaceOptionsError(
                f"InPlaceOptions.stance_trim_share must be in [0, 0.5), "
                f"got {self.stance_trim_share!r}"
            )
        if not -1.0 <= self.min_backward_share <= 1.0:
            raise InPlaceOptionsError(
                f"InPlaceOptions.min_backward_share must be in [-1, 1], "
                f"got {self.min_backward_share!r}"
            )


@dataclass(frozen=True)
class InPlaceFit:
    """What :func:`recover_in_place` found.

    Attributes:
        detected: the clip is in place (its travel was recovered).
        travel: (T, 3) the horizontal travel to add to every joint [m] (zeros when not
            detected; z always 0).
        root_travel_m: the trunk's horizontal path length in the clip as given [m].
        foot_sweep_m: the feet's backward sweep relative to the trunk while low, the
            mean over the four feet [m].
        backward_share: how much the low feet's motion relative to the trunk points
            backwards (1 = straight back, 0 = sideways or mixed) [unitless].
        recovered_m: the recovered travel's path length [m] (0 when not detected).
        heading_deg: direction of the recovered travel's net displacement in the
            habitsim frame (0 = +x, 90 = +y) [deg]; None when not detected.
        stance_share: the share of foot-frames the recovery took as stance [0–1] (after
            :func:`refit_in_place`: the central parts of the stance runs).
        reason: one line saying why the clip is or is not in place.
        sweep: (T, 4) where each foot sweeps backwards relative to the trunk while low
            (below :attr:`InPlaceOptions.sweep_low_per_leg`): the stance of an in-place
            loop read from its phases (all False when not detected).
    """

    detected: bool
    travel: np.ndarray = field(repr=False)
    root_travel_m: float
    foot_sweep_m: float
    backward_share: float
    recovered_m: float
    heading_deg: float | None
    stance_share: float
    reason: str
    sweep: np.ndarray = field(default_factory=lambda: np.zeros((0, 4), bool), repr=False)


def _smooth(x: np.ndarray, fps: float, smooth_s: float, cyclic: bool) -> np.ndarray:
    """``x`` (T, ...) smoothed along time by a quadratic Savitzky–Golay filter."""
    t = x.shape[0]
    win = max(5, int(round(smooth_s * fps)) | 1)
    if t < win:
        win = t if t % 2 else t - 1
    if win < 5:
        return x.copy()
    return savgol_filter(x, win, 2, axis=0, mode="wrap" if cyclic else "interp")


def _velocity(x: np.ndarray, fps: float, cyclic: bool) -> np.ndarray:
    """Time derivative of ``x`` (T, ...) [per s]; central differences, around the loop's
    seam when ``cyclic``."""
    if x.shape[0] < 2:
        return np.zeros_like(x)
    if cyclic and x.shape[0] >= 3:
        return (np.roll(x, -1, axis=0) - np.roll(x, 1, axis=0)) * (0.5 * fps)
    return np.gradient(x, axis=0) * fps


def _path_length(xy: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(xy, axis=0), axis=-1).sum()) if len(xy) > 1 else 0.0


def _fill(v: np.ndarray, known: np.ndarray, cyclic: bool) -> np.ndarray:
    """(T, 2) ``v`` with the frames not ``known`` interpolated from the known ones."""
    t = np.arange(len(v))
    if not known.any():
        return np.zeros_like(v)
    out = v.copy()
    for c in range(v.shape[1]):
        out[:, c] = np.interp(t, t[known], v[known, c], period=len(v) if cyclic else None)
    return out


def _lowest(
    feet: Sequence[np.ndarray], fps: float, smooth_s: float, cyclic: bool
) -> tuple[np.ndarray, np.ndarray]:
    """(T, 4, 2) horizontal velocity and (T, 4) height above its floor (the 2nd percentile)
    of each foot's lowest point, on paths smoothed over ``smooth_s``."""
    t = np.asarray(feet[0]).shape[0]
    vel = np.empty((t, 4, 2))
    height = np.empty((t, 4))
    rows = np.arange(t)
    for k, p in enumerate(feet):
        sm = _smooth(np.asarray(p, dtype=np.float64), fps, smooth_s, cyclic)
        arg = np.argmin(sm[..., 2], axis=1)
        vel[:, k] = _velocity(sm[..., :2], fps, cyclic)[rows, arg]
        z = sm[rows, arg, 2]
        height[:, k] = z - np.percentile(z, 2)
    return vel, height


def _travel(body: np.ndarray, fps: float) -> np.ndarray:
    """(T, 3) the path of a (T, 2) horizontal velocity from the first frame on [m]
    (trapezoids; z 0)."""
    travel = np.zeros((len(body), 3))
    travel[1:, :2] = np.cumsum(0.5 * (body[1:] + body[:-1]), axis=0) / fps
    return travel


def _heading(travel: np.ndarray) -> float:
    net = travel[-1, :2] - travel[0, :2]
    return math.degrees(math.atan2(net[1], net[0]))


def recover_in_place(
    feet: Sequence[np.ndarray],
    trunk: np.ndarray,
    forward: np.ndarray,
    fps: float,
    leg_length: float,
    cyclic: bool = False,
    options: InPlaceOptions | None = None,
) -> InPlaceFit:
    """Detect an in-place clip and recover its root travel from the stance feet.

    Args:
        feet: four arrays (T, P, 3), one per foot (LF, RF, LH, RH): the positions of the
            foot's points in metres, z up (each frame's lowest point is the foot's sole).
        trunk: (T, 3) the trunk (pelvis) position [m].
        forward: (T, 3) the trunk's facing direction (any length; only x, y are used).
        fps: frame rate [Hz].
        leg_length: the source's hind-leg length [m].
        cyclic: the clip is a loop (its last frame runs on into its first): filters and
            derivatives wrap around the seam.
        options: the knobs (defaults when None).

    Returns:
        The :class:`InPlaceFit`; its ``travel`` is added to every joint of the clip.
    """
    opts = options or InPlaceOptions()
    trunk = np.asarray(trunk, dtype=np.float64)
    t = trunk.shape[0]
    zero = np.zeros((t, 3))
    if t < 5 or len(feet) != 4:
        return InPlaceFit(False, zero, 0.0, 0.0, 0.0, 0.0, None, 0.0, "too short to tell")
    fwd = np.asarray(forward, dtype=np.float64)[:, :2]
    n = np.linalg.norm(fwd, axis=-1, keepdims=True)
    fwd = np.where(n > 1e-9, fwd / np.maximum(n, 1e-9), np.array([1.0, 0.0]))

    # Each foot's lowest point: its height above the foot's floor and its velocity.
    vel, height = _lowest(feet, fps, opts.smooth_s, cyclic)
    trunk_xy = _smooth(trunk[:, :2], fps, opts.smooth_s, cyclic)
    rel = vel - _velocity(trunk_xy, fps, cyclic)[:, None, :]
    size = min(t, max(1, int(round(opts.trunk_window_s * fps))))
    trunk_mean = uniform_filter1d(trunk[:, :2], size, axis=0, mode="wrap" if cyclic else "nearest")
    low = height < opts.low_per_leg * leg_length

    # Evidence: the feet's backward sweep while low, and how straight back it points.
    back = -np.einsum("tkc,tc->tk", rel, fwd)
    speed = np.linalg.norm(rel, axis=-1)
    sweep = float((np.clip(back, 0.0, None) * low).sum(axis=0).mean() / fps)
    moving = low & (speed > 1e-9)
    share = float(back[moving].sum() / speed[moving].sum()) if moving.any() else 0.0
    root = _path_length(trunk_mean)
    ratio = root / sweep if sweep > 1e-9 else math.inf
    why_not = []
    if sweep < opts.min_sweep_per_leg * leg_length:
        why_not.append(
            f"feet sweep {sweep / leg_length:.2f} leg lengths "
            f"(a gait sweeps >= {opts.min_sweep_per_leg:g})"
        )
    if share < opts.min_backward_share:
        why_not.append(
            f"low feet move backwards by {share:.2f} (a gait >= {opts.min_backward_share:g})"
        )
    if ratio > opts.max_root_share:
        why_not.append(
            f"trunk travels {min(ratio, 99.0):.2f} of the feet's sweep "
            f"(in place <= {opts.max_root_share:g})"
        )
    if not opts.enabled or why_not:
        reason = "detection off" if not opts.enabled else "; ".join(why_not)
        return InPlaceFit(False, zero, root, sweep, share, 0.0, None, 0.0, reason)

    # The body's velocity: minus the velocity of the feet in stance. A first estimate
    # from the low feet sweeping backwards, then the low feet that move with it.
    cand = low & (back > 0.0)
    first = _fill(
        -(vel * cand[..., None]).sum(axis=1) / np.maximum(cand.sum(axis=1), 1)[:, None],
        cand.any(axis=1),
        cyclic,
    )
    ref = np.maximum(np.linalg.norm(first, axis=-1), 1e-6)[:, None]
    stance = low & (np.linalg.norm(vel + first[:, None, :], axis=-1) < opts.agree_share * ref)
    body = -(vel * stance[..., None]).sum(axis=1) / np.maximum(stance.sum(axis=1), 1)[:, None]
    body = _smooth(_fill(body, stance.any(axis=1), cyclic), fps, opts.smooth_s, cyclic)
    travel = _travel(body, fps)
    reason = (
        f"trunk travels {ratio:.2f} of the feet's sweep "
        f"({root:.3f} m against {sweep:.3f} m), low feet move backwards by {share:.2f}"
    )
    swept = (back > 0.0) & (height < opts.sweep_low_per_leg * leg_length)
    return InPlaceFit(
        True,
        travel,
        root,
        sweep,
        share,
        _path_length(travel[:, :2]),
        _heading(travel),
        float(stance.mean()),
        reason,
        swept,
    )


def _seam_runs(col: np.ndarray, cyclic: bool) -> tuple[int, list[tuple[int, int, bool, bool]]]:
    """The stance runs of one foot's (T,) flags, counted from frame ``shift``: ``(shift,
    [(start, stop, touches_down, lifts_off)])`` in the order ``np.roll(col, -shift)``.

    An end at the clip's first or last frame is no touch-down or lift-off, unless the
    clip is a loop (``cyclic``), whose runs go on across the seam: its count starts at a
    swing frame.
    """
    t = len(col)
    swings = cyclic and not col.all()
    shift = int(np.argmin(col)) if swings else 0
    return shift, [(a, b, a > 0, b < t or swings) for a, b in runs(np.roll(col, -shift))]


def stance_centres(stance: np.ndarray, share: float, cyclic: bool = False) -> np.ndarray:
    """(T, F) bool: the central part of every stance run of ``stance`` (T, F), ``share`` of
    its frames (rounded down) left out at each end.

    An end at the clip's first or last frame is no touch-down or lift-off and keeps its
    frames, unless the clip is a loop (``cyclic``), whose runs go on across the seam.
    """
    c = np.asarray(stance, dtype=bool)
    out = np.zeros_like(c)
    for k in range(c.shape[1]):
        shift, found = _seam_runs(c[:, k], cyclic)
        keep = np.zeros(c.shape[0], dtype=bool)
        for a, b, down, up in found:
            cut = int(math.floor(share * (b - a)))
            keep[a + cut * down : b - cut * up] = True
        out[:, k] = np.roll(keep, shift)
    return out


def trim_unreached(
    labels: StanceLabels,
    toe_height: np.ndarray,
    feet: Sequence[int],
    limit: float,
    cyclic: bool = False,
) -> tuple[StanceLabels, int]:
    """The labels with the frames at each end of the stance runs of ``feet`` where the
    planted toe stays above ``limit`` taken off, and how many frames were taken off.

    A keyframed in-place loop's stance is its feet's backward sweeps
    (:func:`sweep_labels`), and a sweep can be longer than the target's leg reaches with
    its foot planted: at touch-down or lift-off the leg, stretched and with the pelvis
    lowered, still leaves the toe above its foothold. Such a frame is not stance: the
    foot touches down later or lifts off earlier. Only the ends of a run are taken off,
    frame by frame inwards while the toe stays high (a run high all through goes).

    Args:
        labels: (T, 4) the stance labels the legs were planted on.
        toe_height: (T, 4) the planted toes' heights above the ground [m].
        feet: the feet whose runs may be trimmed (those that took their sweeps).
        limit: the highest planted toe that counts as on its foothold [m].
        cyclic: the clip is a loop (its runs go on across the seam).

    Returns:
        The labels (edited under :attr:`EditReason.IN_PLACE_REACH`, or as they came) and
        the number of frames taken off.
    """
    before = labels.array
    c = before.copy()
    h = np.asarray(toe_height, dtype=np.float64)
    for k in feet:
        shift, found = _seam_runs(c[:, k], cyclic)
        col = np.roll(c[:, k], -shift)
        high = np.roll(h[:, k], -shift) > limit
        for a, b, down, up in found:
            lo, hi = a, b
            while down and lo < hi and high[lo]:
                lo += 1
            while up and hi > lo and high[hi - 1]:
                hi -= 1
            col[a:lo] = False
            col[hi:b] = False
        c[:, k] = np.roll(col, shift)
    n = int((before & ~c).sum())
    if n == 0:
        return labels, 0
    return labels.edited(c, by="bvh_mapping.inplace", reason=EditReason.IN_PLACE_REACH), n


def refit_in_place(
    fit: InPlaceFit,
    feet: Sequence[np.ndarray],
    stance: np.ndarray,
    fps: float,
    cyclic: bool = False,
    options: InPlaceOptions | None = None,
) -> InPlaceFit:
    """The travel of an in-place clip measured again on its labelled stance runs.

    A foot in stance rests in the world, so while it is planted the body moves by minus
    its velocity in the clip as given. At touch-down a paw settles and at lift-off it
    rolls over its toes: there its points move forward with the body. So each stance run
    counts without :attr:`InPlaceOptions.stance_trim_share` of its frames at each end
    (:func:`stance_centres`), the body's velocity is minus the mean velocity of the feet in
    such a central part (their lowest points, paths smoothed over
    :attr:`InPlaceOptions.stance_smooth_s`), frames without one take it from their
    neighbours (a flight phase carries the body on), and its path is the travel.

    Args:
        fit: what :func:`recover_in_place` found (returned as it is when not detected,
            or when no stance run has a central frame).
        feet: the four feet's points (T, P, 3) of the clip as given (without the travel).
        stance: (T, 4) bool stance labels found on the clip with ``fit.travel`` added.
        fps: frame rate [Hz].
        cyclic: the clip is a loop.
        options: the knobs (defaults when None).

    Returns:
        The fit with its travel, recovered path length, heading and stance share of the
        second measurement.
    """
    opts = options or InPlaceOptions()
    c = np.asarray(stance, dtype=bool)
    if not fit.detected or len(feet) != 4 or c.shape != (fit.travel.shape[0], 4):
        return fit
    centre = stance_centres(c, opts.stance_trim_share, cyclic)
    if not centre.any():
        return fit
    vel, _ = _lowest(feet, fps, opts.stance_smooth_s, cyclic)
    n = centre.sum(axis=1)
    body = -(vel * centre[..., None]).sum(axis=1) / np.maximum(n, 1)[:, None]
    body = _smooth(_fill(body, n > 0, cyclic), fps, opts.smooth_s, cyclic)
    travel = _travel(body, fps)
    return dataclasses.replace(
        fit,
        travel=travel,
        recovered_m=_path_length(travel[:, :2]),
        heading_deg=_heading(travel),
        stance_share=float(centre.mean()),
    )


def sweep_labels(
    labels: StanceLabels, fit: InPlaceFit, options: InPlaceOptions | None = None
) -> tuple[StanceLabels, tuple[int, ...]]:
    """Stance labels of an in-place clip with each foot that stands much less than it
    sweeps (:attr:`InPlaceOptions.relabel_share`) given its sweeps as stance.

    A captured clip made in place keeps the labels found on its recovered path (its feet
    rest where they stood); a keyframed loop's feet roll and lift inside their stance, so
    the rest test misses most of it, and the backward sweeps are its stance.

    Returns:
        The labels (edited under :attr:`EditReason.IN_PLACE_SWEEP`, or as they came) and
        the feet that took their sweeps.
    """
    opts = options or InPlaceOptions()
    if not fit.detected or fit.sweep.shape != labels.array.shape:
        return labels, ()
    have = labels.array.mean(axis=0)
    want = fit.sweep.mean(axis=0)
    feet = tuple(int(k) for k in np.flatnonzero(have < opts.relabel_share * want))
    if not feet:
        return labels, ()
    new = labels.array.copy()
    new[:, feet] = fit.sweep[:, feet]
    return labels.edited(new, by="bvh_mapping.inplace", reason=EditReason.IN_PLACE_SWEEP), feet
