"""Stance labels of a source skeleton's own feet, and legs planted where the source's were.

An imported or retargeted clip is only as good as its feet: a paw that hovers 5 cm above
the ground, or sinks into it, makes every later stage (transfer, refinement, tracking)
start from a motion that no animal could make. This module does the two steps that keep
the feet on the ground through a change of skeleton.

1. :func:`label_source_stance` labels each foot's stance on the *source* skeleton, from
   its own foot path, size-normalised by its own leg length. Foot points of motion
   capture sit at a marker or joint, not at the sole, so each foot gets its own *floor*
   (its height when planted: a low percentile of its height over the frames where it
   rests); heights are measured above that floor. The labelling itself is
   :func:`habitsim.contacts.contacts_from_feet` (the project's one contact rule: height
   below 2 % and horizontal speed below 0.3 leg lengths per second, with hysteresis), on
   a foot path smoothed by a Savitzky–Golay filter of about 0.1 s (marker noise at 120 fps
   otherwise breaks the speed test).
2. :func:`plant_legs` solves the target's legs by analytic IK (:func:`habitsim.ik.
   pose_from_targets`, in the target species' own posture) onto toe targets that follow
   the source feet: each foot's offset from its shoulder / hip joint is scaled by the
   ratio of the two limbs' lengths, its height above its floor likewise; during a stance
   run the foothold is fixed (the run's median) and the toe is on the ground (z = 0); in
   swing the difference between the footholds and the scaled path is blended in (a
   smoothstep), so there are no jumps at lift-off or touch-down. Where a stance foot
   cannot reach its foothold (the target's legs are shorter relative to the source's
   stride), the pelvis is lowered by the shortfall and the legs are solved again.

Everything is vectorised over frames.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import (
    gaussian_filter1d,
    maximum_filter1d,
    minimum_filter1d,
    uniform_filter1d,
)
from scipy.signal import savgol_filter

from ..contacts import CONTACT_HEIGHT_PER_LEG, contacts_from_feet
from ..errors import InvalidMotionError
from ..ik import axial_frames, foot_inclination, pose_from_targets
from ..motion import Motion
from ..skeleton import ABDUCTION_SIGN, JOINT_NAMES, get_skeleton
from ..species import Species, load_species
from .labels import StanceLabels, StanceSource, stance_runs
from .policy import PlantingOptions, PlantingOptionsError, resolve_planting

__all__ = [
    "FOOT_ANCHORS",
    "PlantingOptions",
    "PlantingOptionsError",
    "SourceStance",
    "label_source_stance",
    "smooth_path",
    "PlantReport",
    "plant_legs",
    "plant_motion",
    "stance_reach_shortfall",
    "carriage_drop",
    "stance_run_shortfall",
    "stance_sweep_limit",
    "stance_driven_root",
    "stance_slip",
    "leg_pose_angles",
]

#: The habitsim joint each foot's offset is measured from (its shoulder / hip joint).
FOOT_ANCHORS: tuple[str, ...] = ("lf_shoulder", "rf_shoulder", "lh_hip", "rh_hip")
_IDX = {n: i for i, n in enumerate(JOINT_NAMES)}
#: Joint indices of :data:`FOOT_ANCHORS`.
_ANCHOR_IDX = [_IDX[n] for n in FOOT_ANCHORS]
_FORE = ("scapula", "shoulder", "elbow", "wrist")
_HIND = ("ilium", "hip", "knee", "hock")


def carriage_drop(
    short: np.ndarray, fps: float, options: PlantingOptions | None = None
) -> np.ndarray:
    """(T,) how far to lower a body whose stance feet fall ``short`` (T,) [m] of their
    footholds: the shortfall's running maximum over twice
    :attr:`PlantingOptions.drop_smooth_s`, smoothed by a Gaussian of that σ, and never
    less than the shortfall itself (a lower carriage, not a dip at every stance)."""
    sigma = max(1.0, resolve_planting(options).drop_smooth_s * fps)
    need = gaussian_filter1d(maximum_filter1d(short, size=int(2 * sigma) | 1), sigma)
    return np.maximum(need, short)


@dataclass(frozen=True)
class SourceStance:
    """Stance of a source skeleton's feet, found on the source itself.

    Attributes:
        contacts: (T, 4) bool stance labels, feet LF, RF, LH, RH.
        heights: (T, 4) height of each foot's lowest point above its floor [m] (smoothed).
        floors: (4,) height of each foot's lowest point when planted, in the source
            frame [m].
        ground: height of the ground plane in the source frame [m] (the lowest floor).
        leg_length: the normalising length used (the source's hind-leg length) [m].
    """

    contacts: np.ndarray
    heights: np.ndarray
    floors: np.ndarray
    ground: float
    leg_length: float

    @property
    def duty(self) -> np.ndarray:
        """(4,) share of frames each foot is in stance."""
        return self.contacts.mean(axis=0)

    @property
    def labels(self) -> StanceLabels:
        """The (T, 4) stance labels as :class:`StanceLabels` of source
        :attr:`StanceSource.IMPORTED` (found on the source's feet, no edit since)."""
        return StanceLabels(self.contacts, StanceSource.IMPORTED)


def smooth_path(x: np.ndarray, fps: float, options: PlantingOptions | None = None) -> np.ndarray:
    """A path (T, ...) smoothed along time by a Savitzky–Golay filter of about
    :attr:`PlantingOptions.smooth_s` (0.1 s)."""
    x = np.asarray(x, dtype=np.float64)
    t = x.shape[0]
    win = max(5, int(round(resolve_planting(options).smooth_s * fps)) | 1)  # odd
    if t < win:
        win = t if t % 2 else t - 1
    if win < 5:
        return x.copy()
    return savgol_filter(x, win, 2, axis=0, mode="interp")


def _span_velocity(x: np.ndarray, fps: float, span_s: float) -> np.ndarray:
    """Velocity of a path (T, ...) [units/s]: the central difference over ± half of
    ``span_s`` (at least one frame; one-sided at the ends), the same time span at any
    frame rate."""
    t = x.shape[0]
    if t < 2:
        return np.zeros_like(x)
    h = max(1, int(round(0.5 * span_s * fps)))
    i = np.arange(t)
    a, b = np.clip(i - h, 0, t - 1), np.clip(i + h, 0, t - 1)
    return (x[b] - x[a]) * (fps / (b - a)).reshape((t,) + (1,) * (x.ndim - 1))


def label_source_stance(
    points: Sequence[np.ndarray],
    fps: float,
    leg_length: float,
    options: PlantingOptions | None = None,
) -> SourceStance:
    """Stance labels of a source's feet from their own paths (see the module docstring).

    Args:
        points: four arrays (T, P, 3), one per foot (LF, RF, LH, RH): the positions of
            the foot's joints (wrist / hock and the real joints below it) in metres, z up;
            the ground height need not be known. In each frame the foot's lowest point
            gives its height and its horizontal speed, so a paw that rolls over its toes
            is measured where it touches the ground.
        fps: frame rate [Hz].
        leg_length: the source's own hind-leg length [m] (thresholds scale with it).
        options: the knobs (smoothing, floors, the share of the body's speed a foot
            point at rest may move at, the contact rule); the defaults when None.

    Returns:
        The :class:`SourceStance`.

    Raises:
        InvalidMotionError: bad shapes, non-finite values or non-positive sizes.
    """
    if len(points) != 4:
        raise InvalidMotionError(f"points must hold 4 feet, got {len(points)}")
    opts = resolve_planting(options)
    rest_speed = opts.contact.speed_per_leg * leg_length
    if not (np.isfinite(fps) and fps > 0 and np.isfinite(leg_length) and leg_length > 0):
        raise InvalidMotionError(
            f"fps and leg_length must be positive and finite, got {fps}, {leg_length}"
        )
    t = None
    low = []
    for k, p in enumerate(points):
        p = np.asarray(p, dtype=np.float64)
        if p.ndim != 3 or p.shape[1] < 1 or p.shape[2] != 3 or (t is not None and len(p) != t):
            raise InvalidMotionError(f"foot {k} points must have shape (T, P, 3), got {p.shape}")
        if not np.all(np.isfinite(p)):
            raise InvalidMotionError(f"foot {k} points contain NaN or inf")
        t = len(p)
        sm = smooth_path(p, fps, opts)
        vel = _span_velocity(sm[..., :2], fps, opts.velocity_span_s)
        arg = np.argmin(sm[..., 2], axis=1)
        rows = np.arange(t)
        low.append(np.concatenate([vel[rows, arg], sm[rows, arg, 2:3]], axis=-1))
    lowest = np.stack(low, axis=1)  # (T, 4, 3): horizontal velocity, lowest height
    t = lowest.shape[0]
    speed = np.linalg.norm(lowest[..., :2], axis=-1)
    rest = speed < rest_speed
    floors = np.empty(4)
    for k in range(4):
        z = lowest[:, k, 2]
        zr = z[rest[:, k]]
        enough = zr.size >= opts.min_rest_frames
        floors[k] = np.percentile(zr, 10) if enough else np.percentile(z, 2)
    # Feet stand on one ground. The two feet of a pair carry the same rig: one may sit at
    # most floor_spread_per_leg above its partner, so a foot held in the air for the whole
    # clip does not get a floor of its own. The fore and hind feet's points may sit at
    # other heights above their soles (a marker on the wrist, a toe tip placed higher on
    # the hind paws): no floor lies more than pair_spread_per_leg above the lowest one.
    pair = np.repeat([floors[:2].min(), floors[2:].min()], 2)
    floors = np.minimum(floors, pair + opts.floor_spread_per_leg * leg_length)
    floors = np.minimum(floors, floors.min() + opts.pair_spread_per_leg * leg_length)
    # A foot rests at slightly different heights over a clip (the paw's pose, an uneven or
    # sloping capture floor): each frame's floor is the lower envelope of the foot's
    # resting heights over about floor_window_s (between rests, interpolated), but never
    # more than floor_rise_per_leg above the clip floor (a paw held up stays in the air).
    size = max(3, int(round(opts.floor_window_s * fps)) | 1)
    resting = np.where(rest, lowest[..., 2], np.inf)
    env = minimum_filter1d(resting, size=size, axis=0, mode="nearest")
    frames = np.arange(t)
    for k in range(4):
        seen = np.isfinite(env[:, k])
        env[:, k] = np.interp(frames, frames[seen], env[seen, k]) if seen.any() else floors[k]
    env = uniform_filter1d(env, size=size, axis=0, mode="nearest")
    local = np.clip(env, floors, floors + opts.floor_rise_per_leg * leg_length)
    heights = lowest[..., 2] - np.minimum(local, lowest[..., 2].max(axis=0))
    # The contact rule of habitsim.contacts on a path with this speed and height: a path
    # that is the running integral of the lowest point's velocity.
    path = np.zeros((t, 4, 3))
    vel = lowest[..., :2]
    if opts.stance_speed_per_body > 0 and t >= 2:
        # A planted paw of a fast gait rolls over its toes: its points move at a fraction
        # of the body's speed, above the absolute rest speed. The body's speed is the mean
        # of the four feet's velocities over about a stride.
        size_b = max(3, int(round(opts.body_speed_s * fps)) | 1)
        body = np.linalg.norm(
            uniform_filter1d(vel.mean(axis=1), size_b, axis=0, mode="nearest"), axis=-1
        )
        limit = np.maximum(rest_speed, opts.stance_speed_per_body * body)
        vel = vel * (rest_speed / limit)[:, None, None]
    if t >= 2:
        path[1:, :, :2] = np.cumsum(0.5 * (vel[1:] + vel[:-1]), axis=0) / fps
    path[..., 2] = heights
    contacts = contacts_from_feet(path, fps, leg_length, opts.contact)
    return SourceStance(contacts, heights, floors, float(floors.min()), float(leg_length))


@dataclass(frozen=True)
class PlantReport:
    """What :func:`plant_legs` did.

    Attributes:
        reach_error: (T, 4) distance of each toe from its target after IK [m].
        pelvis_drop: (T,) how far the pelvis was lowered so stance feet reach [m].
        stance_toe_height: (4,) median height of each toe over its stance frames [m].
        min_toe_height: lowest toe height over the clip [m] (negative: under the ground).
    """

    reach_error: np.ndarray
    pelvis_drop: np.ndarray
    stance_toe_height: np.ndarray
    min_toe_height: float

    def to_dict(self, leg_length: float) -> dict[str, object]:
        """JSON-ready summary, lengths also per leg length of the target."""
        return {
            "stance_toe_height_per_leg": [
                round(float(h) / leg_length, 5) for h in self.stance_toe_height
            ],
            "min_toe_height_per_leg": round(self.min_toe_height / leg_length, 5),
            "max_pelvis_drop_per_leg": round(float(self.pelvis_drop.max()) / leg_length, 5),
            "max_reach_error_per_leg": round(float(self.reach_error.max()) / leg_length, 5),
        }


@functools.lru_cache(maxsize=512)
def _smoothstep(n: int) -> np.ndarray:
    """(n,) smoothstep weights of a swing's n inner frames (read-only, shared)."""
    s = (np.arange(n) + 1.0) / (n + 1.0)
    w = s * s * (3.0 - 2.0 * s)
    w.flags.writeable = False
    return w


def _median0(x: np.ndarray) -> np.ndarray:
    """Median along the first axis of a short (n, d) array (``np.median``'s result,
    without its overhead: the planting takes one per stance run and rule)."""
    xs = np.sort(x, axis=0)
    n = xs.shape[0]
    return xs[n // 2] if n % 2 else 0.5 * (xs[n // 2 - 1] + xs[n // 2])


def _centred_hold(
    raw: np.ndarray, anchors: np.ndarray, leg: float, travel_per_leg: float
) -> np.ndarray:
    """Foothold (2,) of one stance run whose sweep is centred under its anchor.

    Args:
        raw: (n, 2) the run's toe path; anchors: (n, 2) its shoulder / hip path; leg: leg
            length [m]; travel_per_leg: the anchor's travel from which on the foothold is
            fully centred (:attr:`PlantingOptions.centre_travel_per_leg`) [leg lengths].

    Along the anchor's travel over the run the foothold sits half-way between where the
    anchor starts and ends, so the leg reaches as far behind the joint at lift-off as in
    front of it at touch-down (the foothold a leg of given length holds over the longest
    sweep); across it the toe path's median offset from the anchor is kept (the gait's
    stance width). A run that hardly travels keeps the toe path's median, and in between
    the two are blended.
    """
    hold = _median0(raw)
    travel = anchors[-1] - anchors[0]
    dist = float(np.linalg.norm(travel))
    w = min(1.0, dist / (travel_per_leg * leg))
    if w <= 0.0:
        return hold
    u = travel / dist
    off = _median0(raw - anchors)
    side = off - (off @ u) * u
    centred = 0.5 * (anchors[0] + anchors[-1]) + side
    return (1.0 - w) * hold + w * centred


def _planted_targets(
    raw: np.ndarray,
    contacts: np.ndarray,
    anchors: np.ndarray | None = None,
    leg: float = 1.0,
    free: np.ndarray | None = None,
    options: PlantingOptions | None = None,
) -> np.ndarray:
    """Toe targets (T, 4, 3): stance runs fixed on the ground, swing blended in between.

    Each run's foothold is the median of its toe path, or with ``anchors`` ((T, 4, 3)
    shoulder / hip paths) and ``leg`` (leg length [m]) the foothold that centres the run's
    sweep under the joint (:func:`_centred_hold`); then a swing between two runs goes
    straight from one foothold to the next (smoothstep, the toe path's height kept).
    A run with a frame in ``free`` ((T, 4) bool) is not held: its toes keep their own
    path (not under the ground), and the swings around it start and end where it does.
    """
    travel = resolve_planting(options).centre_travel_per_leg
    out = raw.copy()
    out[..., 2] = np.maximum(out[..., 2], 0.0)
    t = raw.shape[0]
    for k, segs in enumerate(stance_runs(contacts)):
        if not segs:
            continue
        runs = [(a, b - 1) for a, b in segs]  # inclusive last stance frame
        if anchors is None:
            holds = [_median0(raw[a : b + 1, k, :2]) for a, b in runs]
        else:
            holds = [
                _centred_hold(raw[a : b + 1, k, :2], anchors[a : b + 1, k, :2], leg, travel)
                for a, b in runs
            ]
        # where each run starts and ends (a held run: its foothold)
        starts, ends = list(holds), list(holds)
        for i, (a, b) in enumerate(runs):
            if free is not None and free[a : b + 1, k].any():
                starts[i], ends[i] = out[a, k, :2].copy(), out[b, k, :2].copy()
                continue
            out[a : b + 1, k, :2] = holds[i]
            out[a : b + 1, k, 2] = 0.0
        # swing phases (lo, hi exclusive of both): before the first run, between runs,
        # after the last
        bounds: list[tuple[int, int, int | None, int | None]] = [(-1, runs[0][0], None, 0)]
        bounds += [(runs[i][1], runs[i + 1][0], i, i + 1) for i in range(len(runs) - 1)]
        bounds.append((runs[-1][1], t, len(runs) - 1, None))
        for lo, hi, ip, inx in bounds:
            n = hi - lo - 1
            if n <= 0:
                continue
            w = _smoothstep(n)[:, None]
            if anchors is not None and ip is not None and inx is not None:
                # centred footholds: the toe goes from one to the next (the toe path
                # between them may belong to another cadence than the labels)
                out[lo + 1 : hi, k, :2] = (1.0 - w) * ends[ip] + w * starts[inx]
                continue
            d0 = None if ip is None else ends[ip] - raw[lo, k, :2]
            d1 = None if inx is None else starts[inx] - raw[hi, k, :2]
            d0 = d1 if d0 is None else d0
            d1 = d0 if d1 is None else d1
            assert d0 is not None and d1 is not None  # a swing has a stance run at one end
            out[lo + 1 : hi, k, :2] = raw[lo + 1 : hi, k, :2] + (1.0 - w) * d0 + w * d1
    return out


def plant_legs(
    motion: Motion,
    source_feet: np.ndarray,
    source_anchors: np.ndarray,
    contacts: np.ndarray,
    limb_scale: np.ndarray,
    iterations: int = 3,
    options: PlantingOptions | None = None,
) -> tuple[Motion, PlantReport]:
    """Solve a motion's legs so its toes are planted where the source's feet were.

    Args:
        motion: the retargeted motion (trunk, neck, tail as wanted; legs are re-solved).
        source_feet: (T, 4, 3) source foot points in the motion's frame, heights above
            each foot's floor (so a planted foot reads z ≈ 0) [m].
        source_anchors: (T, 4, 3) the source's shoulder / hip joints in the same frame
            (the same horizontal scaling as ``source_feet``) [m].
        contacts: (T, 4) bool stance labels.
        limb_scale: (4,) target limb length / source limb length per foot.
        iterations: pelvis-lowering passes for stance feet out of reach.
        options: the knobs (the pelvis lowering's smoothing); the defaults when None.

    Returns:
        ``(planted motion with ``contacts`` set, report)``.

    Raises:
        InvalidMotionError: shapes that do not match the motion.
    """
    t = motion.num_frames
    for name, a in (("source_feet", source_feet), ("source_anchors", source_anchors)):
        if np.shape(a) != (t, 4, 3):
            raise InvalidMotionError(f"{name} must have shape ({t}, 4, 3), got {np.shape(a)}")
    c = np.asarray(contacts, dtype=bool)
    if c.shape != (t, 4):
        raise InvalidMotionError(f"contacts must have shape ({t}, 4), got {c.shape}")
    scale = np.asarray(limb_scale, dtype=np.float64).reshape(1, 4, 1)
    # The shoulders / hips where the IK will put them: girdles in the species' standing
    # pose (the retargeted girdle bones aim along whatever the source's clavicles do,
    # often sideways in a biped-style rig).
    rot_std = motion.rotations.copy()
    stand = get_skeleton(motion.species).standing_pose()[1]
    girdles = [
        _IDX[f"{p}_{g}"]
        for p, g in zip(("lf", "rf", "lh", "rh"), ("scapula",) * 2 + ("ilium",) * 2, strict=True)
    ]
    rot_std[:, girdles] = stand[girdles]
    std = Motion(motion.species, motion.fps, motion.root_positions, rot_std)
    anchors_t = std.global_positions()[:, _ANCHOR_IDX]
    rel = (np.asarray(source_feet) - np.asarray(source_anchors)) * scale
    raw = np.empty((t, 4, 3))
    raw[..., :2] = anchors_t[..., :2] + rel[..., :2]
    raw[..., 2] = np.asarray(source_feet)[..., 2] * scale[..., 0]
    # The anchors move with the pelvis; their path only depends on the trunk, which the
    # lowering below shifts vertically, so the horizontal targets stay valid.
    targets = _planted_targets(raw, c, options=options)
    return _solve_planted(
        motion, targets, c, None, None, iterations, limit_abduction=True, options=options
    )


def _solve_planted(
    motion: Motion,
    targets: np.ndarray,
    c: np.ndarray,
    girdle_flex: np.ndarray | None,
    foot_inclination: np.ndarray | None,
    iterations: int,
    limit_abduction: bool = False,
    free: np.ndarray | None = None,
    options: PlantingOptions | None = None,
) -> tuple[Motion, PlantReport]:
    """Leg IK onto toe targets; the pelvis lowered where a stance foot is out of reach."""
    sp: Species = load_species(motion.species)
    t = motion.num_frames
    root = motion.root_positions.copy()
    rot = motion.rotations
    leg = sp.leg_length
    drop = np.zeros(t)
    pose = pose_from_targets(
        sp, root, rot, targets, girdle_flex, foot_inclination, limit_abduction=limit_abduction
    )
    if limit_abduction:
        # A foothold the leg cannot reach within its abduction range would make the toe
        # slide over the stance: move each stance run's foothold to where the leg does
        # put it (the median of the solved toes), blend the shift into the swings, solve
        # again.
        solved = pose.toes
        moved = targets.copy()
        moved[..., :2] = np.where(c[..., None], solved[..., :2], targets[..., :2])
        targets = _planted_targets(moved, c, free=free, options=options)
        pose = pose_from_targets(
            sp, root, rot, targets, girdle_flex, foot_inclination, limit_abduction=True
        )
    for _ in range(iterations):
        # how far each stance toe hangs above its foothold (a lateral miss of a leg at
        # its abduction limit is not helped by a lower pelvis)
        toe_z = pose.toes[..., 2]
        short = np.where(c, np.maximum(toe_z - targets[..., 2], 0.0), 0.0).max(axis=1)
        if short.max() <= 0.002 * leg:
            break
        drop += carriage_drop(short, motion.fps, options)
        root = motion.root_positions.copy()
        root[:, 2] -= drop
        pose = pose_from_targets(
            sp, root, rot, targets, girdle_flex, foot_inclination, limit_abduction=limit_abduction
        )
    for _ in range(4):  # a toe the IK could not hold on its target must not sink
        toe_z = pose.toes[..., 2]
        under = toe_z < -1e-6 * leg  # below round-off: an IK miss, lifted with a margin
        if not under.any():
            break
        targets = targets.copy()
        targets[..., 2] += np.where(under, -toe_z * 1.05 + 0.001 * leg, 0.0)
        pose = pose_from_targets(
            sp, root, rot, targets, girdle_flex, foot_inclination, limit_abduction=limit_abduction
        )
    out = Motion(motion.species, motion.fps, root, pose.rotations, c.copy(), dict(motion.metadata))
    toes = pose.toes[..., 2]  # the IK's toes are the FK's
    stance_h = np.array(
        [np.median(toes[c[:, k], k]) if c[:, k].any() else np.nan for k in range(4)]
    )
    report = PlantReport(pose.reach_error, drop, stance_h, float(toes.min()))
    return out, report


def leg_pose_angles(motion: Motion) -> tuple[np.ndarray, np.ndarray]:
    """(T, 4) girdle flexion and (T, 4) foot inclination [rad] of a motion's legs.

    The two leg angles :func:`habitsim.ik.leg_ik` takes besides the toe target, read off
    the motion (feet LF, RF, LH, RH), so re-solving a leg for a moved toe keeps the
    motion's own girdle and foot carriage.
    """
    from ..hinges import hinge_angles

    h = hinge_angles(motion)
    frames = axial_frames(motion.species, motion.root_positions, motion.rotations)
    girdle = np.empty((motion.num_frames, 4))
    incl = np.empty((motion.num_frames, 4))
    for k, (prefix, segs) in enumerate(
        zip(("lf", "rf", "lh", "rh"), [_FORE] * 2 + [_HIND] * 2, strict=True)
    ):
        g, up, lo, ft = (f"{prefix}_{s}" for s in segs)
        girdle[:, k] = h[f"{g}_flex"]
        abd = h[f"{up}_abd"] * ABDUCTION_SIGN[prefix[0]]
        incl[:, k] = foot_inclination(
            frames.parent_rotation[:, k],
            abd,
            girdle[:, k],
            h[f"{up}_flex"],
            h[f"{lo}_flex"],
            h[f"{ft}_flex"],
        )
    return girdle, incl


def _global_positions(motion: Motion, glob: np.ndarray | None) -> np.ndarray:
    """``motion``'s (T, J, 3) global joint positions: ``glob`` when given (checked against
    the motion's shape), else one forward-kinematics pass.

    Raises:
        InvalidMotionError: a ``glob`` whose shape does not match the motion.
    """
    if glob is None:
        return motion.global_positions()
    want = (motion.num_frames, motion.skeleton.num_joints, 3)
    if np.shape(glob) != want:
        raise InvalidMotionError(f"glob must have shape {want}, got {np.shape(glob)}")
    return glob


def stance_slip(toes: np.ndarray, contacts: np.ndarray) -> np.ndarray:
    """(T-1, 2) the mean horizontal step of the toes in stance on both frames of each
    frame step (zero where none is): what a body's path loses so its stance feet stay
    put. ``toes``: (T, 4, 2) horizontal toe positions; ``contacts``: (T, 4) bool."""
    c = np.asarray(contacts, dtype=bool)
    on = (c[1:] & c[:-1]).astype(np.float64)  # (T-1, 4)
    n = on.sum(axis=1, keepdims=True)
    return (np.diff(toes, axis=0) * on[..., None]).sum(axis=1) / np.maximum(n, 1.0)


def stance_driven_root(
    motion: Motion, contacts: np.ndarray, glob: np.ndarray | None = None
) -> tuple[Motion, float]:
    """The motion with its pelvis' horizontal path moved by what its stance feet slide.

    On every frame step where at least one foot is in stance on both frames, the pelvis'
    horizontal step loses the mean horizontal step of those toes, so the body travels as
    far as its stance legs carry it and the stance toes (on average) stay put; flight
    steps keep the pelvis' own step. The legs, the trunk's rotation and the pelvis
    height are kept. The speed ratio it returns measures how far a motion's legs carry
    its body: 1 for feet that rest in stance, near 0 for legs that slide along with the
    body (``habitsim bench model`` reports it for the decoder's transfers).

    Args:
        motion: the motion.
        contacts: (T, 4) bool stance labels.
        glob: optional (T, J, 3) global joint positions of ``motion``, when already at
            hand.

    Returns:
        ``(motion with the new root path, mean horizontal speed new / old)`` (1 for a
        motion that does not move).
    """
    t = motion.num_frames
    c = np.asarray(contacts, dtype=bool)
    if c.shape != (t, 4):
        raise InvalidMotionError(f"contacts must have shape ({t}, 4), got {c.shape}")
    if t < 2:
        return motion, 1.0
    g = _global_positions(motion, glob)
    root = np.array(motion.root_positions, dtype=np.float64)
    root[1:, :2] -= np.cumsum(stance_slip(g[:, motion.skeleton.foot_indices, :2], c), axis=0)
    old = np.linalg.norm(np.diff(motion.root_positions[:, :2], axis=0), axis=1).sum()
    new = np.linalg.norm(np.diff(root[:, :2], axis=0), axis=1).sum()
    out = Motion(
        motion.species, motion.fps, root, motion.rotations, motion.contacts, dict(motion.metadata)
    )
    return out, float(new / old) if old > 1e-12 else 1.0


def _own_targets(
    motion: Motion,
    c: np.ndarray,
    centre: bool,
    glob: np.ndarray | None = None,
    free: np.ndarray | None = None,
    options: PlantingOptions | None = None,
) -> np.ndarray:
    """:func:`plant_motion`'s toe targets (T, 4, 3) before any swing floor (``glob``: the
    motion's global joint positions, if already at hand)."""
    g = motion.global_positions() if glob is None else glob
    raw = g[:, motion.skeleton.foot_indices]
    if not centre:
        return _planted_targets(raw, c, free=free, options=options)
    anchors = g[:, _ANCHOR_IDX]
    return _planted_targets(raw, c, anchors, motion.species_info.leg_length, free, options)


def _stretched(species: str) -> np.ndarray:
    """(4,) shoulder / hip → toe length of each stretched leg (LF, RF, LH, RH) [m]."""
    from ..ik import leg_geometry

    geo = [leg_geometry(species, leg) for leg in ("LF", "RF", "LH", "RH")]
    return np.array([g.upper + g.lower + g.foot for g in geo])


def stance_run_shortfall(
    motion: Motion,
    contacts: np.ndarray,
    centre: bool = False,
    max_drop: float = 0.0,
    free: np.ndarray | None = None,
    glob: np.ndarray | None = None,
    options: PlantingOptions | None = None,
) -> np.ndarray:
    """(T, 4) how far [m] each stance frame's foothold of :func:`plant_motion` lies beyond
    the fully stretched leg, with the pelvis lowered by ``max_drop`` [m] (0 within reach,
    and on swing frames and stance runs left ``free``).

    A cheap test (one forward-kinematics pass, no IK): the distance from each stance
    frame's shoulder / hip to its foothold against the upper + lower + foot segment
    lengths. ``options``: the planting's knobs (the centring's travel), the defaults when
    None.

    Raises:
        InvalidMotionError: contacts that do not match the motion.
    """
    t = motion.num_frames
    c = np.asarray(contacts, dtype=bool)
    if c.shape != (t, 4):
        raise InvalidMotionError(f"contacts must have shape ({t}, 4), got {c.shape}")
    if not c.any():
        return np.zeros((t, 4))
    glob = motion.global_positions() if glob is None else glob
    targets = _own_targets(motion, c, centre, glob, free, options)
    anchors = glob[:, _ANCHOR_IDX]
    d = targets - anchors
    d[..., 2] = np.minimum(d[..., 2] + max_drop, 0.0)  # the pelvis comes down to the foot
    dist = np.linalg.norm(d, axis=-1)
    held = c if free is None else c & ~np.asarray(free, dtype=bool)
    return np.where(held, np.maximum(dist - _stretched(motion.species)[None, :], 0.0), 0.0)


def stance_reach_shortfall(
    motion: Motion,
    contacts: np.ndarray,
    centre: bool = False,
    max_drop: float = 0.0,
    glob: np.ndarray | None = None,
    options: PlantingOptions | None = None,
) -> float:
    """How far [m] the farthest stance foothold of :func:`plant_motion` lies beyond the
    fully stretched leg, with the pelvis lowered by ``max_drop`` [m]; 0 when every
    foothold is within reach (the largest of :func:`stance_run_shortfall`).

    Raises:
        InvalidMotionError: contacts that do not match the motion.
    """
    short = stance_run_shortfall(motion, contacts, centre, max_drop, glob=glob, options=options)
    return float(short.max(initial=0.0))


def stance_sweep_limit(
    motion: Motion, reach_share: float = 0.92, glob: np.ndarray | None = None
) -> float:
    """The longest distance [m] the body can travel over one planted foot: twice the
    horizontal reach of the shortest-reaching leg from its shoulder / hip (at its median
    height over the clip) to the ground, the leg stretched to ``reach_share`` of its
    upper + lower + foot segments (a fully straight leg cannot push)."""
    anchors = (motion.global_positions() if glob is None else glob)[:, _ANCHOR_IDX, 2]
    h = np.median(anchors, axis=0)
    half = np.sqrt(np.maximum((reach_share * _stretched(motion.species)) ** 2 - h**2, 0.0))
    return float(2.0 * half.min())


def plant_motion(
    motion: Motion,
    contacts: np.ndarray,
    swing_floor: np.ndarray | None = None,
    iterations: int = 3,
    centre: bool = False,
    free: np.ndarray | None = None,
    glob: np.ndarray | None = None,
    options: PlantingOptions | None = None,
) -> tuple[Motion, PlantReport]:
    """Plant a motion's own feet on its stance labels, by leg IK.

    Each stance run of a foot is held at one foothold (the median of the run's toe
    positions, or with ``centre`` the foothold that centres the run's sweep under the
    shoulder / hip, :func:`_centred_hold`) on the ground; in swing the differences to the
    neighbouring footholds are blended in (with ``centre``: the toe goes straight from
    one foothold to the next), so lift-off and touch-down do not jump, and the toe is
    lifted to at
    least ``swing_floor``, held over the foothold wherever that floor is below
    :data:`habitsim.contacts.CONTACT_HEIGHT_PER_LEG` (a foot rises before it moves). The
    legs are re-solved with the motion's own girdle flexion and foot inclination; the
    pelvis is lowered where a stance foot is out of reach. Used on transferred motions
    before refinement, so the optimisation starts from planted feet.

    Args:
        motion: the motion (its trunk, neck and tail are kept).
        contacts: (T, 4) bool stance labels.
        swing_floor: optional (T, 4) lowest toe height [m] in swing (NaN: none).
        iterations: pelvis-lowering passes.
        centre: centre each travelling stance run's sweep under its shoulder / hip (for
            decoded legs whose feet slide: the median of a sliding toe path can lie so
            far ahead of or behind the joint that the leg cannot reach it at one end of
            the run).
        free: optional (T, 4) bool; a stance run with a frame in it is not held but
            keeps its own toe path (not under the ground), e.g. a run whose foothold
            no leg reaches (:func:`stance_run_shortfall`).
        glob: optional (T, J, 3) global joint positions of ``motion``
            (:meth:`~habitsim.motion.Motion.global_positions`), when already at hand.
        options: the knobs (the centring's travel, the pelvis lowering's smoothing);
            the defaults when None.

    Returns:
        ``(planted motion with ``contacts`` set, report)``.
    """
    t = motion.num_frames
    c = np.asarray(contacts, dtype=bool)
    if c.shape != (t, 4):
        raise InvalidMotionError(f"contacts must have shape ({t}, 4), got {c.shape}")
    if free is not None and np.shape(free) != (t, 4):
        raise InvalidMotionError(f"free must have shape ({t}, 4), got {np.shape(free)}")
    free = None if free is None else np.asarray(free, dtype=bool)
    if glob is not None:
        glob = _global_positions(motion, glob)
    targets = _own_targets(motion, c, centre, glob, free, options)
    if swing_floor is not None:
        fl = np.asarray(swing_floor, dtype=np.float64)
        if fl.shape != (t, 4):
            raise InvalidMotionError(f"swing_floor must have shape ({t}, 4), got {fl.shape}")
        fl = np.where(c | ~np.isfinite(fl), 0.0, fl)
        targets[..., 2] = np.maximum(targets[..., 2], fl)
        low = ~c & (fl < CONTACT_HEIGHT_PER_LEG * motion.species_info.leg_length) & (fl > 0)
        for k in range(4):
            stance = np.flatnonzero(c[:, k])
            frames = np.flatnonzero(low[:, k])
            if len(stance) and len(frames):
                near = stance[np.abs(frames[:, None] - stance[None, :]).argmin(axis=1)]
                targets[frames, k, :2] = targets[near, k, :2]
    girdle, incl = leg_pose_angles(motion)
    return _solve_planted(
        motion,
        targets,
        c,
        girdle,
        incl,
        iterations,
        limit_abduction=True,
        free=free,
        options=options,
    )
