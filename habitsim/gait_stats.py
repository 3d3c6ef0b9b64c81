"""Measured gait statistics of a motion: speed, Froude number, duty factor, footfall phases,
stride period and length, and the static stability margin.

Definitions (keys of :meth:`GaitStats.to_dict`; docs/metrics.md names where it has them):

* ``duration_s``: T / fps.
* ``speed_mps``: the mean horizontal root displacement over one stride period P,
  ‖x(t + P) − x(t)‖ / P averaged over every t with t + P inside the clip — the speed
  along the path (a turn reads its path speed, not its chord; one stride averages out
  the trunk's sway). Without a stride period (standing, fewer than two touchdowns) or a
  clip shorter than one stride: the net displacement from the first to the last frame
  over (T − 1) / fps. 0 for a one-frame clip.
* ``froude``: v² / (g·h), g = :data:`~habitsim.physics_constants.GRAVITY` (9.81 m/s²),
  h = the species' standing hip height.
* ``duty_factor_per_foot``: the share of frames in contact, counted over the foot's
  complete strides (from its first to its last touchdown, exclusive) when it has at
  least two touchdowns, else over the whole clip. ``duty_factor`` is the mean over feet.
* touchdowns: frames t ≥ 1 with contact at t and none at t − 1
  (:func:`habitsim.contacts.touchdown_frames`).
* ``stride_period_per_foot``: median interval between consecutive touchdowns of a foot
  [s] (NaN with fewer than two touchdowns); ``stride_period_s``: median over the feet
  that have one. ``stride_frequency_hz`` = 1 / period.
* ``stride_length_m`` = speed × stride period; ``relative_stride_length`` = stride
  length / h (Alexander 1976: ≈ 2.3·Fr^0.3).
* ``phase_offsets``: per foot, the touchdown phase relative to the left hind foot
  (Hildebrand; LH = 0). For every touchdown of the foot at or after an LH touchdown, the
  phase is (t − t_LH) / P where t_LH is the latest LH touchdown at or before t and P the
  interval to the next LH touchdown (or the stride period when there is none); the
  result is the circular mean of these phases, in [0, 1). NaN when the foot or LH has
  no usable touchdown (standing still, a clip without steps).
* static stability: per frame, the signed horizontal distance from the centre of mass
  (:func:`habitsim.body.center_of_mass`) to the support polygon (convex hull of the
  toes in contact that can bear weight: a toe higher than
  :func:`habitsim.contacts.ground_reach`, the contact height with the detection's
  hysteresis, supports nothing whatever its label says, so a walk lifted off the floor
  has no support): positive inside (distance to the nearest edge), negative outside
  (minus the distance to the polygon). With fewer than three feet in contact — or three
  or four collinear ones — the support is a segment or a point and the margin is minus
  the distance to it (≤ 0). Frames without any contact (flight) have no margin and are
  left out. ``stability_margin_min_m`` / ``stability_margin_mean_m`` are the min / mean
  over the remaining frames, ``stability_margin_per_leg`` = min / hind-leg length, and
  ``statically_stable_fraction`` = frames with ≥ 3 contacts and margin > 0 divided by
  frames with ≥ 3 contacts (NaN if there are none).

Undefined numbers are ``float('nan')`` in the dataclass and ``None`` in ``to_dict()``.

:func:`peak_froude` is the fastest stretch of a clip, for clips that change gait (a walk
that breaks into a gallop): the largest v² / (g·h) of the horizontal root speed averaged
over any ``span_s`` (default :data:`PEAK_SPAN_S`) of the clip, the path length over that
span divided by its duration. Its regimes follow docs/biomechanics.md (Alexander & Jayes 1983):
walk below about 0.5, trot or amble up to :data:`GALLOP_FROUDE`, gallop above.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from .body import center_of_mass
from .contacts import bearing_contacts, detect_contacts, foot_stride_periods, touchdown_frames
from .errors import InvalidMotionError
from .physics_constants import GRAVITY
from .species import FEET

if TYPE_CHECKING:  # pragma: no cover
    from .motion import Motion

__all__ = [
    "GRAVITY",
    "GALLOP_FROUDE",
    "PEAK_SPAN_S",
    "GaitStats",
    "gait_statistics",
    "peak_froude",
    "stability_margins",
    "circular_mean",
]

#: Froude number of the trot → gallop transition (Alexander & Jayes 1983: animals of very
#: different size change to a gallop or canter near Fr 2–3, often quoted 2.5).
GALLOP_FROUDE = 2.5
#: Span [s] :func:`peak_froude` averages the speed over: about one gallop stride of a
#: medium dog (≈ 4.5·M^-0.14 Hz, Heglund et al. 1974: 2.9 Hz at 25 kg), and two of a cat.
PEAK_SPAN_S = 0.5
_LH = FEET.index("LH")


def _finite_or_none(x: float) -> float | None:
    return float(x) if x is not None and math.isfinite(x) else None


@dataclass(frozen=True)
class GaitStats:
    """Gait statistics of one motion (see the module docstring for every definition).

    Attributes:
        duration_s: clip length [s].
        speed_mps: mean horizontal speed [m/s].
        froude: v²/(g·h).
        duty_factor: mean duty factor over the four feet.
        duty_factor_per_foot: per foot ``LF, RF, LH, RH``.
        stride_period_s: stride period [s] (NaN if no foot has two touchdowns).
        stride_period_per_foot: per foot [s].
        stride_frequency_hz: 1 / stride period [Hz].
        stride_length_m: speed × stride period [m].
        relative_stride_length: stride length / hip height.
        phase_offsets: touchdown phase per foot relative to LH, in [0, 1) (NaN if unknown).
        stability_margin_min_m: min static stability margin [m].
        stability_margin_mean_m: mean static stability margin [m].
        stability_margin_per_leg: min margin / hind-leg length.
        statically_stable_fraction: share of ≥3-contact frames with the CoM inside.
        hip_height_m: the species' hip height h [m].
        leg_length_m: the species' hind-leg length [m].
    """

    duration_s: float
    speed_mps: float
    froude: float
    duty_factor: float
    duty_factor_per_foot: dict[str, float] = field(default_factory=dict)
    stride_period_s: float = math.nan
    stride_period_per_foot: dict[str, float] = field(default_factory=dict)
    stride_frequency_hz: float = math.nan
    stride_length_m: float = math.nan
    relative_stride_length: float = math.nan
    phase_offsets: dict[str, float] = field(default_factory=dict)
    stability_margin_min_m: float = math.nan
    stability_margin_mean_m: float = math.nan
    stability_margin_per_leg: float = math.nan
    statically_stable_fraction: float = math.nan
    hip_height_m: float = math.nan
    leg_length_m: float = math.nan

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (docs/metrics.md keys; NaN becomes None; per-foot values as dicts)."""
        out: dict[str, Any] = {}
        for k, v in self.__dict__.items():
            if isinstance(v, dict):
                out[k] = {f: _finite_or_none(x) for f, x in v.items()}
            else:
                out[k] = _finite_or_none(v)
        return out


def circular_mean(phases: np.ndarray) -> float:
    """Circular mean of phases in units of cycles, in [0, 1) (NaN for an empty array)."""
    p = np.asarray(phases, dtype=np.float64)
    if p.size == 0:
        return math.nan
    ang = 2.0 * np.pi * p
    s, c = np.sin(ang).mean(), np.cos(ang).mean()
    if math.hypot(s, c) < 1e-9:  # phases spread uniformly: no mean direction
        return math.nan
    m = (math.atan2(s, c) / (2.0 * math.pi)) % 1.0
    return 0.0 if m >= 1.0 - 1e-12 else m


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _seg_dist(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance from points p (…, 2) to segments a–b (…, 2)."""
    ab = b - a
    den = np.sum(ab * ab, axis=-1)
    t = np.where(den > 0, np.sum((p - a) * ab, axis=-1) / np.where(den > 0, den, 1.0), 0.0)
    t = np.clip(t, 0.0, 1.0)
    return np.linalg.norm(p - (a + t[..., None] * ab), axis=-1)


def stability_margins(com_xy: np.ndarray, feet_xy: np.ndarray, contacts: np.ndarray) -> np.ndarray:
    """Signed distance from the centre of mass to the support polygon, per frame.

    Args:
        com_xy: (T, 2) horizontal centre of mass [m].
        feet_xy: (T, F, 2) horizontal toe positions [m] (F ≤ 4 is typical; any F works).
        contacts: (T, F) bool contact flags.

    Returns:
        (T,) margin [m]: positive inside the convex hull of the contacting toes (distance
        to the nearest edge), negative outside (minus the distance to the hull); for a
        degenerate support (one or two feet, or collinear feet) minus the distance to the
        point / segment; NaN without contact.
    """
    p = np.asarray(com_xy, dtype=np.float64)
    q = np.asarray(feet_xy, dtype=np.float64)
    c = np.asarray(contacts, dtype=bool)
    t, f = c.shape
    n = c.sum(axis=1)
    out = np.full(t, np.nan)
    # Single contact: minus the distance to the point.
    one = n == 1
    if one.any():
        idx = np.argmax(c[one], axis=1)
        out[one] = -np.linalg.norm(p[one] - q[one, idx], axis=-1)
    if f < 2:
        return out
    pairs = [(i, j) for i in range(f) for j in range(i + 1, f)]
    pi = np.array([a for a, _ in pairs])
    pj = np.array([b for _, b in pairs])
    a, b = q[:, pi], q[:, pj]  # (T, P, 2)
    valid = c[:, pi] & c[:, pj]  # (T, P)
    pp = p[:, None, :]
    seg_d = np.where(valid, _seg_dist(pp, a, b), np.inf)  # (T, P)
    min_seg = seg_d.min(axis=1)  # (T,)
    # Side of every other contacting foot relative to each pair's line.
    e = b - a  # (T, P, 2)
    elen = np.linalg.norm(e, axis=-1)
    side = _cross(e[:, :, None, :], q[:, None, :, :] - a[:, :, None, :])  # (T, P, F)
    scale = np.maximum(elen, 1e-12)[..., None]
    side_n = side / scale  # signed distance of foot k to the line [m]
    eps = 1e-9
    others = c[:, None, :] & ~np.eye(f, dtype=bool)[pi] & ~np.eye(f, dtype=bool)[pj]
    pos = np.any(others & (side_n > eps), axis=-1)
    neg = np.any(others & (side_n < -eps), axis=-1)
    hull_edge = valid & (elen > 1e-12) & (pos ^ neg)  # all others strictly on one side…
    # …allowing others on the line itself (collinear third foot on an edge).
    orient = np.where(pos, 1.0, -1.0)  # +1: interior to the left of a→b
    d_line = orient * _cross(e, pp - a) / np.maximum(elen, 1e-12)  # (T, P) inward distance
    has_area = hull_edge.any(axis=1) & (n >= 3)
    inside = np.all(np.where(hull_edge, d_line >= 0.0, True), axis=1)
    inner = np.where(hull_edge, d_line, np.inf).min(axis=1)
    poly = np.where(inside, inner, -min_seg)
    multi = n >= 2
    out[multi] = np.where(has_area[multi], poly[multi], -min_seg[multi])
    return out + 0.0  # no negative zeros


def _contacts_of(motion: Motion, contacts: np.ndarray | None) -> np.ndarray:
    if contacts is None:
        contacts = motion.contacts if motion.contacts is not None else detect_contacts(motion)
    c = np.asarray(contacts, dtype=bool)
    if c.shape != (motion.num_frames, 4):
        raise InvalidMotionError(
            f"contacts must have shape ({motion.num_frames}, 4), got {c.shape}"
        )
    return c


def gait_statistics(motion: Motion, contacts: np.ndarray | None = None) -> GaitStats:
    """Measure the gait statistics of a motion.

    Args:
        motion: the motion.
        contacts: optional (T, 4) bool contacts (LF, RF, LH, RH); default: the motion's
            labels if it has them, else :func:`habitsim.contacts.detect_contacts`.

    Returns:
        The :class:`GaitStats` (definitions in the module docstring). Never raises on
        motions without steps; undefined quantities are NaN.
    """
    c = _contacts_of(motion, contacts)
    sp = motion.species_info
    fps = motion.fps
    t_frames = motion.num_frames
    h = sp.hip_height
    leg = sp.leg_length

    tds = touchdown_frames(c)
    per_foot = foot_stride_periods(c)
    duty: dict[str, float] = {}
    periods: dict[str, float] = {}
    for k, foot in enumerate(FEET):
        td = tds[k]
        duty[foot] = float(c[td[0] : td[-1], k].mean() if td.size >= 2 else c[:, k].mean())
        periods[foot] = float(per_foot[k]) / fps
    finite_p = [v for v in periods.values() if math.isfinite(v)]
    period = float(np.median(finite_p)) if finite_p else math.nan

    root = motion.root_positions
    w = int(round(period * fps)) if math.isfinite(period) else 0
    if 1 <= w < t_frames:
        speed = float(np.linalg.norm(root[w:, :2] - root[:-w, :2], axis=-1).mean() * fps / w)
    elif t_frames >= 2:
        speed = float(np.linalg.norm(root[-1, :2] - root[0, :2]) * fps / (t_frames - 1))
    else:
        speed = 0.0
    froude = speed * speed / (GRAVITY * h)
    stride_len = speed * period
    freq = 1.0 / period if math.isfinite(period) and period > 0 else math.nan

    # Phase offsets relative to LH.
    lh = tds[_LH]
    phases: dict[str, float] = {}
    for k, foot in enumerate(FEET):
        td = tds[k]
        if lh.size == 0 or td.size == 0 or not math.isfinite(period):
            phases[foot] = math.nan
            continue
        prev_i = np.searchsorted(lh, td, side="right") - 1  # latest LH touchdown ≤ t
        ok = prev_i >= 0
        if not ok.any():
            phases[foot] = math.nan
            continue
        tdk, pi = td[ok], prev_i[ok]
        nxt = pi + 1
        local = np.where(nxt < lh.size, (lh[np.minimum(nxt, lh.size - 1)] - lh[pi]) / fps, period)
        phases[foot] = circular_mean(((tdk - lh[pi]) / fps) / local)

    # Static stability.
    pos = motion.global_positions()
    com = center_of_mass(sp, pos)[:, :2]
    toes = pos[:, motion.skeleton.foot_indices]
    support = bearing_contacts(c, toes[..., 2], leg)  # a labelled foot in mid-air bears nothing
    margin = stability_margins(com, toes[..., :2], support)
    have = np.isfinite(margin)
    if have.any():
        m_min = float(margin[have].min())
        m_mean = float(margin[have].mean())
    else:
        m_min = m_mean = math.nan
    three = support.sum(axis=1) >= 3
    stable_frac = float((margin[three] > 0).mean()) if three.any() else math.nan

    return GaitStats(
        duration_s=motion.duration,
        speed_mps=speed,
        froude=froude,
        duty_factor=float(np.mean(list(duty.values()))),
        duty_factor_per_foot=duty,
        stride_period_s=period,
        stride_period_per_foot=periods,
        stride_frequency_hz=freq,
        stride_length_m=stride_len,
        relative_stride_length=stride_len / h,
        phase_offsets=phases,
        stability_margin_min_m=m_min,
        stability_margin_mean_m=m_mean,
        stability_margin_per_leg=m_min / leg,
        statically_stable_fraction=stable_frac,
        hip_height_m=h,
        leg_length_m=leg,
    )


def peak_froude(motion: Motion, span_s: float = PEAK_SPAN_S) -> float:
    """The largest Froude number v² / (g·h) of ``motion`` over any ``span_s`` of it.

    v is the horizontal path length of the root over the span divided by the span's
    duration (a turn counts its path, the trunk's sway within one stride mostly cancels),
    h the species' standing hip height. A clip shorter than the span is one span. 0 for a
    one-frame clip.

    Raises:
        InvalidMotionError: ``span_s`` not positive.
    """
    if not (math.isfinite(span_s) and span_s > 0):
        raise InvalidMotionError(f"span_s must be a positive number of seconds, got {span_s}")
    root = np.asarray(motion.root_positions, dtype=float)
    if len(root) < 2:
        return 0.0
    step = np.linalg.norm(np.diff(root[:, :2], axis=0), axis=1)
    w = min(max(1, int(round(span_s * motion.fps))), len(step))
    path = np.convolve(step, np.ones(w), mode="valid")  # path length over each span
    speed = float(path.max()) * motion.fps / w
    return speed * speed / (GRAVITY * motion.species_info.hip_height)
