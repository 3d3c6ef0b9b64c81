"""Analytic leg inverse kinematics on the habitsim skeleton's hinge convention.

A leg is the chain girdle root (``scapula`` / ``ilium``) → ``shoulder`` / ``hip`` →
``elbow`` / ``knee`` → ``wrist`` / ``hock`` → ``toe``. Following the hinge convention of
:mod:`habitsim.skeleton`, the girdle joint is R_y(girdle_flex), the shoulder / hip is
R_x(abduction)·R_y(upper_flex) and the two distal joints are R_y(flex). All the rotations
below the shoulder / hip are about one axis, so the upper, lower and foot segments lie
in one plane (the *leg plane*) through the shoulder / hip joint. The solver

1. places the shoulder / hip from the girdle root, the trunk orientation and the given
   girdle flexion;
2. picks the abduction that puts the toe target in the leg plane (exact);
3. sets the foot segment to the requested *foot inclination* and derives the wrist /
   hock target from the toe target;
4. solves the upper + lower two-link chain with the law of cosines, the middle joint
   bending the way the species' standing posture bends it (usually the knee points
   forward and the elbow backward);
5. clamps an out-of-reach wrist / hock distance to the reachable interval and reports
   the resulting toe error honestly (never NaN).

Foot inclination: the angle [rad] of the foot segment (wrist/hock → toe) from the
downward vertical, measured in the leg plane, positive when the toe lies ahead (toward
the leg frame's +x) of the wrist / hock — the same sign convention as the species'
standing ``[posture]`` inclinations. For an unabducted leg of a level trunk it is exactly
the posture inclination.

Everything is vectorised over a leading frame axis of length T.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np

from .errors import IKError
from .hinges import hinge_limits
from .rotations import quat_mul, quat_to_matrix, rot_x, rot_y
from .skeleton import ABDUCTION_SIGN, JOINT_NAMES, get_skeleton, standing_leg_angles
from .species import FEET, Species, load_species

__all__ = [
    "LEGS",
    "LegIKResult",
    "LegGeometry",
    "leg_geometry",
    "leg_ik",
    "leg_fk",
    "foot_inclination",
    "axial_frames",
    "pose_from_targets",
    "PoseIK",
    "wrap_angle",
]

#: Leg names, the order of :data:`habitsim.species.FEET`.
LEGS: tuple[str, ...] = FEET
_J = {n: i for i, n in enumerate(JOINT_NAMES)}
_SEGS = {
    "fore": ("scapula", "shoulder", "elbow", "wrist", "toe"),
    "hind": ("ilium", "hip", "knee", "hock", "toe"),
}


@dataclass(frozen=True)
class LegGeometry:
    """Segment lengths and standing angles of one leg of a species.

    Attributes:
        leg: ``LF``, ``RF``, ``LH`` or ``RH``.
        limb: ``fore`` or ``hind``.
        prefix: joint-name prefix (``lf`` …).
        girdle, upper, lower, foot: segment lengths [m].
        bend: +1 if the middle joint (knee / elbow) points forward (+x of the leg
            plane), −1 if it points backward.
        girdle_flex0: standing girdle flexion [rad].
        foot_inclination0: standing foot-segment inclination [rad].
        joints: the five joint names of the chain (girdle … toe).
    """

    leg: str
    limb: str
    prefix: str
    girdle: float
    upper: float
    lower: float
    foot: float
    bend: float
    girdle_flex0: float
    foot_inclination0: float
    joints: tuple[str, ...]

    @property
    def max_reach(self) -> float:
        """Longest proximal-to-distal (shoulder/hip → wrist/hock) distance [m]."""
        return self.upper + self.lower

    @property
    def min_reach(self) -> float:
        """Shortest proximal-to-distal distance [m] (fully folded)."""
        return abs(self.upper - self.lower)


def _check_leg(leg: str) -> str:
    if not isinstance(leg, str) or leg.upper() not in LEGS:
        raise IKError(f"unknown leg {leg!r}; valid: {', '.join(LEGS)}")
    return leg.upper()


def leg_geometry(species: str | Species, leg: str) -> LegGeometry:
    """The :class:`LegGeometry` of ``leg`` of a species.

    Raises:
        IKError: unknown leg name (the message lists the valid ones).
        UnknownSpeciesError: unknown species.
    """
    return _leg_geometry(load_species(species), _check_leg(leg))


@functools.lru_cache(maxsize=512)
def _leg_geometry(sp: Species, leg: str) -> LegGeometry:
    limb = "fore" if leg[1] == "F" else "hind"
    s = sp.segments
    loc = standing_leg_angles(sp)
    mid = loc[f"{limb}_lower_flex"]
    if abs(mid) > 1e-6:
        bend = math.copysign(1.0, mid)
    else:  # straight column: knees forward, elbows backward, as in mammals
        bend = 1.0 if limb == "hind" else -1.0
    prefix = leg.lower()
    return LegGeometry(
        leg=leg,
        limb=limb,
        prefix=prefix,
        girdle=s[f"{limb}_girdle"],
        upper=s[f"{limb}_upper"],
        lower=s[f"{limb}_lower"],
        foot=s[f"{limb}_foot"],
        bend=bend,
        girdle_flex0=loc[f"{limb}_girdle_flex"],
        foot_inclination0=sp.inclinations[f"{limb}_foot"],
        joints=tuple(f"{prefix}_{j}" for j in _SEGS[limb]),
    )


@dataclass(frozen=True)
class LegIKResult:
    """Solution of :func:`leg_ik` (all arrays have the leading frame axis T).

    Attributes:
        abduction: (T,) R_x angle of the shoulder / hip [rad] in the hinge convention
            (positive swings the leg toward +y, the animal's left).
        girdle_flex: (T,) scapula / ilium flexion [rad].
        upper_flex: (T,) shoulder / hip flexion [rad].
        lower_flex: (T,) elbow / knee flexion [rad].
        foot_flex: (T,) wrist / hock flexion [rad].
        toe: (T, 3) toe position the solution actually reaches [m].
        reach_error: (T,) |toe − target| [m] (0 up to rounding when reachable).
        proximal: (T, 3) shoulder / hip joint position [m].
        distal_target: (T, 3) wrist / hock position demanded by the toe target and the
            foot inclination [m] (before clamping).
        reach_ratio: (T,) demanded proximal-to-distal distance / maximal reach.
    """

    abduction: np.ndarray
    girdle_flex: np.ndarray
    upper_flex: np.ndarray
    lower_flex: np.ndarray
    foot_flex: np.ndarray
    toe: np.ndarray
    reach_error: np.ndarray
    proximal: np.ndarray
    distal_target: np.ndarray
    reach_ratio: np.ndarray

    def quaternions(self) -> np.ndarray:
        """(T, 4, 4) local quaternions of girdle, shoulder/hip, elbow/knee, wrist/hock."""
        return _chain_quaternions(
            self.girdle_flex, self.abduction, self.upper_flex, self.lower_flex, self.foot_flex
        )


def _chain_quaternions(
    girdle: np.ndarray, abd: np.ndarray, upper: np.ndarray, lower: np.ndarray, foot: np.ndarray
) -> np.ndarray:
    """(S, 4, 4) local quaternions of a leg chain's four joints from its angles (S,)."""
    return np.stack(
        [rot_y(girdle), quat_mul(rot_x(abd), rot_y(upper)), rot_y(lower), rot_y(foot)],
        axis=-2,
    )


def wrap_angle(a: np.ndarray) -> np.ndarray:
    """Angles wrapped to [−π, π)."""
    return (a + np.pi) % (2.0 * np.pi) - np.pi


def _as_frames(x: np.ndarray | float, t: int, name: str) -> np.ndarray:
    a = np.asarray(x, dtype=np.float64)
    try:
        a = np.broadcast_to(a, (t,)) if a.ndim <= 1 else a
    except ValueError:
        raise IKError(f"{name} must be a scalar or have shape ({t},), got {a.shape}") from None
    if a.shape != (t,):
        raise IKError(f"{name} must be a scalar or have shape ({t},), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise IKError(f"{name} contains NaN or inf")
    return a


def _as_rotmats(r: np.ndarray, t: int) -> np.ndarray:
    r = np.asarray(r, dtype=np.float64)
    if r.shape[-1:] == (4,) and r.ndim in (1, 2):
        r = quat_to_matrix(r)
    if r.shape == (3, 3):
        r = np.broadcast_to(r, (t, 3, 3))
    if r.shape != (t, 3, 3):
        raise IKError(f"parent rotation must be (3, 3), (T, 3, 3), (4,) or (T, 4); got {r.shape}")
    if not np.all(np.isfinite(r)):
        raise IKError("parent rotation contains NaN or inf")
    return r


def _as_leg_frames(x: np.ndarray, t: int, name: str) -> np.ndarray:
    """``x`` as (T, 4) finite per-leg angles (a (4,) vector holds for every frame)."""
    try:
        a = np.broadcast_to(np.asarray(x, dtype=np.float64), (t, 4))
    except ValueError:
        raise IKError(f"{name} must have shape ({t}, 4), got {np.shape(x)}") from None
    if not np.all(np.isfinite(a)):
        raise IKError(f"{name} contains NaN or inf")
    return a


def _ry(a: np.ndarray) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    m = np.zeros((*np.shape(a), 3, 3))
    m[..., 0, 0] = c
    m[..., 0, 2] = s
    m[..., 1, 1] = 1.0
    m[..., 2, 0] = -s
    m[..., 2, 2] = c
    return m


def _rx(a: np.ndarray) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    m = np.zeros((*np.shape(a), 3, 3))
    m[..., 0, 0] = 1.0
    m[..., 1, 1] = c
    m[..., 1, 2] = -s
    m[..., 2, 1] = s
    m[..., 2, 2] = c
    return m


def _mv(m: np.ndarray, v: np.ndarray) -> np.ndarray:
    return np.einsum("...ij,...j->...i", m, v)


def _mtv(m: np.ndarray, v: np.ndarray) -> np.ndarray:
    return np.einsum("...ji,...j->...i", m, v)


def leg_ik(
    species: str | Species,
    leg: str,
    girdle_root: np.ndarray,
    parent_rotation: np.ndarray,
    target: np.ndarray,
    girdle_flex: np.ndarray | float | None = None,
    foot_inclination: np.ndarray | float | None = None,
    distal_band: tuple[float, float] | None = None,
    max_inclination_change: np.ndarray | float = 0.0,
    abduction_range: tuple[float, float] | None = None,
) -> LegIKResult:
    """Analytic IK of one leg for a toe target, vectorised over frames.

    Args:
        species: species name or :class:`~habitsim.species.Species`.
        leg: ``LF``, ``RF``, ``LH`` or ``RH`` (case-insensitive).
        girdle_root: (T, 3) or (3,) world position of the scapula / ilium joint [m].
        parent_rotation: global rotation of the girdle's parent (``spine3`` for the
            fore legs, ``pelvis`` for the hind legs): (T, 3, 3) / (3, 3) matrices or
            (T, 4) / (4,) quaternions wxyz.
        target: (T, 3) or (3,) world toe target [m].
        girdle_flex: (T,) or scalar girdle flexion [rad]; default: the standing value.
        foot_inclination: (T,) or scalar foot-segment inclination [rad] (module
            docstring); default: the species' standing foot inclination.
        distal_band: optional (d_min, d_max) [m] band for the proximal-to-distal
            (shoulder/hip → wrist/hock) distance. Where the demanded distance leaves the
            band, the foot inclination is turned by the least angle that brings it back
            (toward the toe–shoulder line to shorten it, away to lengthen it), by at
            most ``max_inclination_change``: the foot segment takes up the reach, as the
            fetlock and hock do in a real stance, instead of the trunk bobbing.
        max_inclination_change: (T,) or scalar bound [rad] of that turn (0: none).
        abduction_range: optional (lo, hi) bounds [rad] of the abduction as the R_x angle
            of the shoulder / hip. A toe target close to the girdle's height (a paw
            tucked up in swing) otherwise asks for an abduction of up to 90° to put it in
            the leg plane; clamped, the leg stays in its range and the toe lands at the
            target's projection on the leg plane (``reach_error`` reports the miss).

    Returns:
        The :class:`LegIKResult`; ``reach_error`` is the honest toe error after clamping
        an unreachable target.

    Raises:
        IKError: unknown leg, bad shapes or non-finite inputs.
    """
    geo = leg_geometry(species, leg)
    tgt = np.asarray(target, dtype=np.float64)
    if tgt.ndim == 1:
        tgt = tgt[None]
    if tgt.ndim != 2 or tgt.shape[1] != 3:
        raise IKError(f"target must have shape (T, 3) or (3,), got {tgt.shape}")
    if not np.all(np.isfinite(tgt)):
        raise IKError("target contains NaN or inf")
    t = tgt.shape[0]
    root = np.asarray(girdle_root, dtype=np.float64)
    if root.shape == (3,):
        root = np.broadcast_to(root, (t, 3))
    if root.shape != (t, 3):
        raise IKError(f"girdle_root must have shape ({t}, 3) or (3,), got {root.shape}")
    if not np.all(np.isfinite(root)):
        raise IKError("girdle_root contains NaN or inf")
    prot = _as_rotmats(parent_rotation, t)
    gflex = _as_frames(geo.girdle_flex0 if girdle_flex is None else girdle_flex, t, "girdle_flex")
    finc = _as_frames(
        geo.foot_inclination0 if foot_inclination is None else foot_inclination,
        t,
        "foot_inclination",
    )

    sol = _solve_legs(
        (geo.girdle, geo.upper, geo.lower, geo.foot, geo.bend),
        root,
        prot,
        tgt,
        gflex,
        finc,
        None if abduction_range is None else (min(abduction_range), max(abduction_range)),
        None
        if distal_band is None
        else (distal_band, _as_frames(max_inclination_change, t, "max_inclination_change")),
    )
    return LegIKResult(**sol)


def _solve_legs(
    lengths: tuple,
    root: np.ndarray,
    prot: np.ndarray,
    tgt: np.ndarray,
    gflex: np.ndarray,
    finc: np.ndarray,
    abduction: tuple | None,
    comply: tuple | None = None,
) -> dict[str, np.ndarray]:
    """The analytic solve of :func:`leg_ik` over any leading shape ``S`` (frames, or
    frames × legs): ``lengths`` = (girdle, upper, lower, foot, bend) scalars or arrays
    broadcast to ``S``, root / tgt (S, 3), prot (S, 3, 3), gflex / finc (S,),
    ``abduction`` = (lo, hi) bounds broadcast to ``S`` or None, ``comply`` =
    (distal band, max inclination change) or None. Returns :class:`LegIKResult`'s fields."""
    girdle, upper, lower, foot, bend = (np.asarray(x, dtype=np.float64) for x in lengths)
    shape = tgt.shape[:-1]
    g = prot @ _ry(gflex)  # girdle global rotation
    down = np.zeros((*girdle.shape, 3))
    down[..., 2] = -girdle
    shoulder = root + _mv(g, down)
    d = _mtv(g, tgt - shoulder)  # target in the girdle frame
    abd = np.arctan2(d[..., 1], -d[..., 2])
    clamped = np.zeros(shape, dtype=bool)
    if abduction is not None:
        free = abd
        abd = np.clip(abd, abduction[0], abduction[1])
        clamped = abd != free
    frame = g @ _rx(abd)  # leg-plane frame: the chain rotates about its +y
    p = _mtv(frame, tgt - shoulder)
    if np.any(clamped):
        # the target is off the leg plane: aim at the plane's point at the target's
        # height (the miss is horizontal, a foot on the ground stays on it)
        f20, f22 = frame[..., 2, 0], frame[..., 2, 2]
        ok = clamped & (np.abs(f22) > 1e-3)
        pz = (tgt[..., 2] - shoulder[..., 2] - f20 * p[..., 0]) / np.where(ok, f22, 1.0)
        p[..., 2] = np.where(ok, pz, p[..., 2])
    w = _mtv(frame, np.broadcast_to(np.array([0.0, 0.0, -1.0]), (*shape, 3)))
    beta_down = np.arctan2(-w[..., 0], -w[..., 2])
    b3 = beta_down - finc
    if comply is not None:
        b3 = _comply_foot(p[..., [0, 2]], b3, float(foot), comply[0], comply[1])
    foot_dir = np.stack([-np.sin(b3), -np.cos(b3)], -1)
    wx = p[..., [0, 2]] - foot[..., None] * foot_dir  # demanded wrist/hock, plane (x, z)
    dist = np.linalg.norm(wx, axis=-1)
    lo, hi = np.abs(upper - lower), upper + lower
    dc = np.clip(dist, lo, hi)
    bw = np.arctan2(-wx[..., 0], -wx[..., 1])
    den = np.maximum(2.0 * upper * dc, 1e-12)
    cos_a = np.clip((upper**2 + dc**2 - lower**2) / den, -1.0, 1.0)
    alpha = np.arccos(cos_a)
    b1 = bw - bend * alpha
    knee = upper[..., None] * np.stack([-np.sin(b1), -np.cos(b1)], -1)
    wc = dc[..., None] * np.stack([-np.sin(bw), -np.cos(bw)], -1)
    lower_vec = wc - knee
    b2 = np.arctan2(-lower_vec[..., 0], -lower_vec[..., 1])
    toe_plane = wc + foot[..., None] * foot_dir
    zero = np.zeros(shape)
    toe = shoulder + _mv(frame, np.stack([toe_plane[..., 0], zero, toe_plane[..., 1]], -1))
    distal = shoulder + _mv(frame, np.stack([wx[..., 0], zero, wx[..., 1]], -1))
    return {
        "abduction": abd,
        "girdle_flex": gflex.copy(),
        "upper_flex": wrap_angle(b1),
        "lower_flex": wrap_angle(b2 - b1),
        "foot_flex": wrap_angle(b3 - b2),
        "toe": toe,
        "reach_error": np.linalg.norm(toe - tgt, axis=-1),
        "proximal": shoulder,
        "distal_target": distal,
        "reach_ratio": dist / hi,
    }


def _comply_foot(
    p: np.ndarray, b3: np.ndarray, foot: float, band: tuple[float, float], limit: np.ndarray
) -> np.ndarray:
    """Foot angle b3 turned (least angle, at most ``limit``) so |p − foot·u(b3)| is in ``band``.

    In leg-plane coordinates (x, z) a direction of angle b is u(b) = (−sin b, −cos b); the
    distal joint sits at p − foot·u(b3), at distance² |p|² + foot² − 2·foot·|p|·cos(b3 − θp)
    from the proximal joint, θp being the angle of p.
    """
    lo, hi = band
    r = np.linalg.norm(p, axis=-1)
    theta = np.arctan2(-p[..., 0], -p[..., 1])
    rel = wrap_angle(b3 - theta)
    side = np.where(rel >= 0.0, 1.0, -1.0)
    den = np.maximum(2.0 * foot * r, 1e-12)
    dist = np.sqrt(np.maximum(r**2 + foot**2 - 2.0 * foot * r * np.cos(rel), 0.0))
    # angle from the toe-shoulder line giving exactly the band edge (clipped: an edge out
    # of reach of any foot angle gives the closest one)
    ang_hi = np.arccos(np.clip((r**2 + foot**2 - hi**2) / den, -1.0, 1.0))
    ang_lo = np.arccos(np.clip((r**2 + foot**2 - lo**2) / den, -1.0, 1.0))
    new = np.where(
        dist > hi,
        side * np.minimum(np.abs(rel), ang_hi),
        np.where(dist < lo, side * np.maximum(np.abs(rel), ang_lo), rel),
    )
    change = np.clip(new - rel, -limit, limit)
    return b3 + change


def leg_fk(
    species: str | Species,
    leg: str,
    girdle_root: np.ndarray,
    parent_rotation: np.ndarray,
    abduction: np.ndarray,
    girdle_flex: np.ndarray,
    upper_flex: np.ndarray,
    lower_flex: np.ndarray,
    foot_flex: np.ndarray,
) -> np.ndarray:
    """Toe position (T, 3) [m] of a leg from its hinge angles (the inverse of :func:`leg_ik`)."""
    geo = leg_geometry(species, leg)
    root = np.atleast_2d(np.asarray(girdle_root, dtype=np.float64))
    t = root.shape[0]
    prot = _as_rotmats(parent_rotation, t)
    angles = (abduction, girdle_flex, upper_flex, lower_flex, foot_flex)
    a = [_as_frames(x, t, "angle") for x in angles]
    g = prot @ _ry(a[1])
    pos = root + _mv(g, np.array([0.0, 0.0, -geo.girdle]))
    r = g @ _rx(a[0]) @ _ry(a[2])
    pos = pos + _mv(r, np.array([0.0, 0.0, -geo.upper]))
    r = r @ _ry(a[3])
    pos = pos + _mv(r, np.array([0.0, 0.0, -geo.lower]))
    r = r @ _ry(a[4])
    return pos + _mv(r, np.array([0.0, 0.0, -geo.foot]))


def foot_inclination(
    parent_rotation: np.ndarray,
    abduction: np.ndarray,
    girdle_flex: np.ndarray,
    upper_flex: np.ndarray,
    lower_flex: np.ndarray,
    foot_flex: np.ndarray,
) -> np.ndarray:
    """Foot-segment inclination (T,) [rad] of a posed leg, as defined in the module docstring."""
    a = np.asarray(abduction, dtype=np.float64)
    t = a.shape[0] if a.ndim else 1
    prot = _as_rotmats(parent_rotation, t)
    frame = prot @ _ry(np.broadcast_to(girdle_flex, (t,))) @ _rx(np.broadcast_to(a, (t,)))
    w = _mtv(frame, np.broadcast_to(np.array([0.0, 0.0, -1.0]), (t, 3)))
    beta_down = np.arctan2(-w[:, 0], -w[:, 2])
    b3 = np.asarray(upper_flex) + np.asarray(lower_flex) + np.asarray(foot_flex)
    return wrap_angle(beta_down - b3)


@dataclass(frozen=True)
class AxialFrames:
    """Global frames of the trunk needed by the legs (leading axis T).

    Attributes:
        girdle_root: (T, 4, 3) scapula / ilium joint positions, legs LF, RF, LH, RH [m].
        parent_rotation: (T, 4, 3, 3) global rotation of each girdle's parent.
    """

    girdle_root: np.ndarray
    parent_rotation: np.ndarray


def axial_frames(
    species: str | Species, root_positions: np.ndarray, rotations: np.ndarray
) -> AxialFrames:
    """Girdle roots and parent rotations from the root and the axial joint rotations.

    Args:
        species: the species.
        root_positions: (T, 3) pelvis positions [m].
        rotations: (T, J, 4) local rotations (only pelvis and spine1..3 are used).
    """
    skel = get_skeleton(species)
    off = skel.offsets
    idx = [_J["pelvis"], _J["spine1"], _J["spine2"], _J["spine3"]]
    m = quat_to_matrix(np.asarray(rotations)[:, idx])  # (T, 4, 3, 3)
    r_pel = m[:, 0]
    r1 = r_pel @ m[:, 1]
    r2 = r1 @ m[:, 2]
    r3 = r2 @ m[:, 3]
    p1 = root_positions + _mv(r_pel, off[_J["spine1"]])
    p2 = p1 + _mv(r1, off[_J["spine2"]])
    p3 = p2 + _mv(r2, off[_J["spine3"]])
    roots = np.stack(
        [
            p3 + _mv(r3, off[_J["lf_scapula"]]),
            p3 + _mv(r3, off[_J["rf_scapula"]]),
            root_positions + _mv(r_pel, off[_J["lh_ilium"]]),
            root_positions + _mv(r_pel, off[_J["rh_ilium"]]),
        ],
        axis=1,
    )
    parents = np.stack([r3, r3, r_pel, r_pel], axis=1)
    return AxialFrames(girdle_root=roots, parent_rotation=parents)


def _abduction_range(sp: Species, leg: str) -> tuple[float, float]:
    """The R_x-angle range of a leg's shoulder / hip abduction from the species' limits."""
    geo = leg_geometry(sp, leg)
    lo, hi = hinge_limits(sp)[f"{geo.joints[1]}_abd"]
    sign = ABDUCTION_SIGN[geo.prefix[0]]
    return (sign * lo, sign * hi)


@dataclass(frozen=True)
class _LegsTable:
    """A species' four legs (LF, RF, LH, RH) as (4,) arrays for :func:`_solve_legs`."""

    lengths: tuple[np.ndarray, ...]  # girdle, upper, lower, foot, bend
    girdle_flex0: np.ndarray
    foot_inclination0: np.ndarray
    abduction: tuple[np.ndarray, np.ndarray]  # (lo, hi) of :func:`_abduction_range`
    joints: tuple[tuple[str, ...], ...]


@functools.lru_cache(maxsize=64)
def _legs_table(sp: Species) -> _LegsTable:
    geos = [leg_geometry(sp, leg) for leg in LEGS]

    def arr(values: list[float]) -> np.ndarray:
        a = np.array(values, dtype=np.float64)
        a.flags.writeable = False  # shared by every call
        return a

    ranges = [_abduction_range(sp, leg) for leg in LEGS]
    return _LegsTable(
        lengths=tuple(
            arr([getattr(g, n) for g in geos]) for n in ("girdle", "upper", "lower", "foot", "bend")
        ),
        girdle_flex0=arr([g.girdle_flex0 for g in geos]),
        foot_inclination0=arr([g.foot_inclination0 for g in geos]),
        abduction=(arr([min(r) for r in ranges]), arr([max(r) for r in ranges])),
        joints=tuple(g.joints for g in geos),
    )


@dataclass(frozen=True)
class PoseIK:
    """Result of :func:`pose_from_targets`.

    Attributes:
        reach_error: (T, 4) toe error per leg [m] (LF, RF, LH, RH).
        toes: (T, 4, 3) toe positions the solution reaches [m].
        frames: the trunk frames the legs were solved in.
        rotations: (T, J, 4) local rotations with the legs solved (assembled on first
            use: an iteration that only needs the toes does not pay for them).
        legs: the four :class:`LegIKResult` (made on first use).
    """

    reach_error: np.ndarray
    toes: np.ndarray
    frames: AxialFrames
    _input_rotations: np.ndarray = field(repr=False, compare=False)
    _solution: dict[str, np.ndarray] = field(repr=False, compare=False)
    _joints: tuple[tuple[str, ...], ...] = field(repr=False, compare=False)

    @functools.cached_property
    def rotations(self) -> np.ndarray:
        sol = self._solution
        q = _chain_quaternions(
            sol["girdle_flex"],
            sol["abduction"],
            sol["upper_flex"],
            sol["lower_flex"],
            sol["foot_flex"],
        )  # (T, 4 legs, 4 joints, 4)
        rot = self._input_rotations  # pose_from_targets' own copy
        for k, joints in enumerate(self._joints):
            for n, joint in enumerate(joints[:4]):
                rot[:, _J[joint]] = q[:, k, n]
            rot[:, _J[joints[4]]] = np.array([1.0, 0.0, 0.0, 0.0])
        return rot

    @functools.cached_property
    def legs(self) -> tuple[LegIKResult, ...]:
        return tuple(
            LegIKResult(**{name: v[:, k] for name, v in self._solution.items()})
            for k in range(len(LEGS))
        )


def pose_from_targets(
    species: str | Species,
    root_positions: np.ndarray,
    rotations: np.ndarray,
    toe_targets: np.ndarray,
    girdle_flex: np.ndarray | None = None,
    foot_inclination: np.ndarray | None = None,
    limit_abduction: bool = False,
) -> PoseIK:
    """Solve all four legs for toe targets on a posed trunk.

    Args:
        species: the species.
        root_positions: (T, 3) pelvis positions [m].
        rotations: (T, J, 4) local rotations giving the pelvis and spine (the leg
            joints are overwritten; other joints are kept).
        toe_targets: (T, 4, 3) world toe targets, legs LF, RF, LH, RH [m].
        girdle_flex: optional (T, 4) girdle flexion [rad] (default: standing).
        foot_inclination: optional (T, 4) foot inclination [rad] (default: standing).
        limit_abduction: keep each shoulder / hip abduction within the species' joint
            range (:func:`leg_ik`'s ``abduction_range``).

    Returns:
        A :class:`PoseIK` with the completed rotations and per-leg reach errors.

    Raises:
        IKError: bad shapes or non-finite targets.
    """
    sp = load_species(species)
    root = np.asarray(root_positions, dtype=np.float64)
    rot = np.array(rotations, dtype=np.float64, copy=True)  # the legs are written into it
    tg = np.asarray(toe_targets, dtype=np.float64)
    t = root.shape[0]
    if tg.shape != (t, 4, 3):
        raise IKError(f"toe_targets must have shape ({t}, 4, 3), got {tg.shape}")
    if rot.shape != (t, len(JOINT_NAMES), 4):
        raise IKError(f"rotations must have shape ({t}, {len(JOINT_NAMES)}, 4), got {rot.shape}")
    if not np.all(np.isfinite(tg)):
        raise IKError("toe_targets contains NaN or inf")
    frames = axial_frames(sp, root, rot)
    table = _legs_table(sp)
    gflex = table.girdle_flex0 if girdle_flex is None else girdle_flex
    finc = table.foot_inclination0 if foot_inclination is None else foot_inclination
    # the four legs in one vectorised solve over (T, 4)
    sol = _solve_legs(
        table.lengths,
        frames.girdle_root,
        frames.parent_rotation,
        tg,
        _as_leg_frames(gflex, t, "girdle_flex"),
        _as_leg_frames(finc, t, "foot_inclination"),
        table.abduction if limit_abduction else None,
    )
    return PoseIK(
        reach_error=sol["reach_error"],
        toes=sol["toe"],
        frames=frames,
        _input_rotations=rot,
        _solution=sol,
        _joints=table.joints,
    )
