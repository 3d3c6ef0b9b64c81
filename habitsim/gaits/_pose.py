"""Shared machinery of the gait generator: trunk state, leg solving, reach and sway fixes.

Internal module. Angles in rad, lengths in m, arrays have a leading frame axis T.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace
from typing import TypedDict

import numpy as np

from ..body import center_of_mass
from ..ik import (
    LEGS,
    AxialFrames,
    LegIKResult,
    axial_frames,
    foot_inclination,
    leg_geometry,
    leg_ik,
    wrap_angle,
)
from ..rotations import quat_mul, rot_x, rot_y, rot_z
from ..skeleton import JOINT_NAMES, fk, get_skeleton, standing_leg_angles
from ..species import Species
from .options import GeneratorOptions

_J = {n: i for i, n in enumerate(JOINT_NAMES)}


class StandingInfo(TypedDict):
    """What :func:`standing_info` returns (a plain dict)."""

    root_z: float
    pitch: float
    neutral: np.ndarray
    loc: dict[str, float]
    d_stand: np.ndarray
    trunk_span: float


@functools.lru_cache(maxsize=64)
def standing_info(sp: Species) -> StandingInfo:
    """Standing root height, trunk values and neutral toe offsets of a species.

    Returns a dict with ``root_z`` [m], ``pitch`` (trunk, nose up) [rad], ``neutral``
    (4, 2) toe xy offsets from the root in the heading frame [m], ``loc`` standing local
    angles, ``d_stand`` (4,) standing proximal-to-distal distances [m], ``trunk_span``
    horizontal pelvis-to-withers distance [m].
    """
    skel = get_skeleton(sp)
    root, quats = skel.standing_pose()
    pos = fk(skel, root, quats)
    toes = pos[skel.foot_indices]
    d_stand = np.zeros(4)
    for k, leg in enumerate(LEGS):
        geo = leg_geometry(sp, leg)
        d_stand[k] = np.linalg.norm(pos[_J[geo.joints[1]]] - pos[_J[geo.joints[3]]])
    return StandingInfo(
        root_z=float(root[2]),
        pitch=float(sp.trunk_pitch),
        neutral=toes[:, :2] - root[None, :2],
        loc=standing_leg_angles(sp),
        d_stand=d_stand,
        trunk_span=float(np.linalg.norm(pos[_J["spine3"], [0, 2]] - pos[_J["pelvis"], [0, 2]])),
    )


@dataclass
class Trunk:
    """Per-frame trunk, spine, neck, head and tail state (local hinge angles).

    Attributes:
        root: (T, 3) pelvis position [m].
        yaw, pitch, roll: (T,) pelvis heading, nose-up pitch and roll [rad]; the pelvis
            rotation is R_z(yaw)·R_y(−pitch)·R_x(roll).
        spine_pitch, spine_yaw: (T, 3) local angles of spine1..3.
        neck_pitch, neck_yaw, head_pitch, head_yaw: (T,) local angles.
        tail_pitch, tail_yaw: (T, 2) local angles of tail1..2.
    """

    root: np.ndarray
    yaw: np.ndarray
    pitch: np.ndarray
    roll: np.ndarray
    spine_pitch: np.ndarray
    spine_yaw: np.ndarray
    neck_pitch: np.ndarray
    neck_yaw: np.ndarray
    head_pitch: np.ndarray
    head_yaw: np.ndarray
    tail_pitch: np.ndarray
    tail_yaw: np.ndarray

    @classmethod
    def standing(cls, sp: Species, t: int) -> Trunk:
        """The standing trunk repeated over T frames (root at the origin, yaw 0)."""
        info = standing_info(sp)
        loc = info["loc"]
        root = np.zeros((t, 3))
        root[:, 2] = info["root_z"]
        z = np.zeros(t)
        return cls(
            root=root,
            yaw=z.copy(),
            pitch=np.full(t, info["pitch"]),
            roll=z.copy(),
            spine_pitch=np.zeros((t, 3)),
            spine_yaw=np.zeros((t, 3)),
            neck_pitch=np.full(t, loc["neck_pitch"]),
            neck_yaw=z.copy(),
            head_pitch=np.full(t, loc["head_pitch"]),
            head_yaw=z.copy(),
            tail_pitch=np.stack([np.full(t, loc["tail_pitch"]), z], 1),
            tail_yaw=np.zeros((t, 2)),
        )

    def copy(self) -> Trunk:
        return replace(self, **{k: np.array(v, copy=True) for k, v in self.__dict__.items()})

    def rotations(self) -> np.ndarray:
        """(T, J, 4) local rotations of the axial joints (legs identity)."""
        t = self.root.shape[0]
        q = np.zeros((t, len(JOINT_NAMES), 4))
        q[..., 0] = 1.0
        q[:, _J["pelvis"]] = quat_mul(
            quat_mul(rot_z(self.yaw), rot_y(-self.pitch)), rot_x(self.roll)
        )
        for i in range(3):
            q[:, _J[f"spine{i + 1}"]] = quat_mul(
                rot_z(self.spine_yaw[:, i]), rot_y(self.spine_pitch[:, i])
            )
        q[:, _J["neck"]] = quat_mul(rot_z(self.neck_yaw), rot_y(self.neck_pitch))
        q[:, _J["head"]] = quat_mul(rot_z(self.head_yaw), rot_y(self.head_pitch))
        for i in range(2):
            q[:, _J[f"tail{i + 1}"]] = quat_mul(
                rot_z(self.tail_yaw[:, i]), rot_y(self.tail_pitch[:, i])
            )
        return q


@dataclass
class LegPlan:
    """World toe targets and foot-shape modulation for the four legs.

    Attributes:
        targets: (T, 4, 3) toe targets [m], legs LF, RF, LH, RH.
        contacts: (T, 4) planned stance.
        swing_s: (T, 4) swing progress in [0, 1] (0 in stance).
        foot_extra: (T, 4) extra foot inclination [rad] added to the modulated one.
        girdle_extra: (T, 4) extra girdle flexion [rad].
        sweep_gain: multiply the girdle / foot sweep gains by this (0 = rigid legs); a
            number or a (T,) array (a chained clip eases from walking into a sit).
    """

    targets: np.ndarray
    contacts: np.ndarray
    swing_s: np.ndarray
    # None: zeros (T, 4), set by __post_init__
    foot_extra: np.ndarray = None  # type: ignore[assignment]
    girdle_extra: np.ndarray = None  # type: ignore[assignment]
    sweep_gain: float | np.ndarray = 1.0

    def __post_init__(self) -> None:
        t = self.targets.shape[0]
        if self.foot_extra is None:
            self.foot_extra = np.zeros((t, 4))
        if self.girdle_extra is None:
            self.girdle_extra = np.zeros((t, 4))


@dataclass
class Solved:
    """A solved pose: rotations, the legs' IK results and the reach errors."""

    rotations: np.ndarray
    legs: tuple[LegIKResult, ...]
    reach_error: np.ndarray  # (T, 4) [m]


def _leg_shape(
    sp: Species,
    k: int,
    plan: LegPlan,
    frames: AxialFrames,
    swing_fold: np.ndarray,
    options: GeneratorOptions,
) -> tuple[np.ndarray, np.ndarray]:
    """Girdle flexion and foot inclination (before compliance) of leg ``k``, (T,) each."""
    geo = leg_geometry(sp, LEGS[k])
    groot = frames.girdle_root[:, k]
    prot = frames.parent_rotation[:, k]
    fwd = prot[:, :, 0].copy()
    fwd[:, 2] = 0.0
    fwd /= np.maximum(np.linalg.norm(fwd, axis=-1, keepdims=True), 1e-9)
    rel = plan.targets[:, k] - groot
    sweep = np.arctan2(np.sum(rel * fwd, -1), -rel[:, 2])
    g = np.asarray(plan.sweep_gain, dtype=float)
    o = options
    gflex = (
        geo.girdle_flex0
        - g * o.limb(o.girdle_sweep_gain, geo.limb) * sweep
        + plan.girdle_extra[:, k]
    )
    finc = (
        geo.foot_inclination0
        + g * o.limb(o.foot_sweep_gain, geo.limb) * sweep
        - o.limb(o.swing_foot_fold_rad, geo.limb) * swing_fold[:, k]
        + plan.foot_extra[:, k]
    )
    return gflex, finc


def _nominal_inclination(
    sp: Species, k: int, plan: LegPlan, frames: AxialFrames, options: GeneratorOptions
) -> np.ndarray:
    """Foot inclination of leg ``k`` before the reach compliance, (T,)."""
    return _leg_shape(sp, k, plan, frames, np.sin(np.pi * plan.swing_s), options)[1]


def solve(sp: Species, trunk: Trunk, plan: LegPlan, options: GeneratorOptions) -> Solved:
    """Leg IK on a trunk: girdle and foot modulated by each leg's sweep angle."""
    rot = trunk.rotations()
    frames = axial_frames(sp, trunk.root, rot)
    swing_fold = np.sin(np.pi * plan.swing_s)
    legs = []
    for k, leg in enumerate(LEGS):
        groot = frames.girdle_root[:, k]
        prot = frames.parent_rotation[:, k]
        tgt = plan.targets[:, k]
        gflex, finc = _leg_shape(sp, k, plan, frames, swing_fold, options)
        res = leg_ik(
            sp,
            leg,
            groot,
            prot,
            tgt,
            gflex,
            finc,
            distal_band=reach_band(sp, k, options),
            max_inclination_change=options.foot_compliance_rad,
        )
        q = res.quaternions()
        for n, joint in enumerate(leg_geometry(sp, leg).joints[:4]):
            rot[:, _J[joint]] = q[:, n]
        legs.append(res)
    err = np.stack([r.reach_error for r in legs], axis=1)
    return Solved(rotations=rot, legs=tuple(legs), reach_error=err)


def _odd(n: int) -> int:
    return n if n % 2 else n + 1


def upper_envelope(x: np.ndarray, window: int) -> np.ndarray:
    """Smooth function ≥ x (1-D): moving average of a moving maximum of one window."""
    if window <= 1 or x.size < 2:
        return x.copy()
    from scipy.ndimage import maximum_filter1d, uniform_filter1d  # (on use: 0.3 s import)

    w = _odd(window)
    return uniform_filter1d(maximum_filter1d(x, w, mode="nearest"), w, mode="nearest")


@functools.lru_cache(maxsize=256)
def reach_band(sp: Species, k: int, options: GeneratorOptions) -> tuple[float, float]:
    """(d_min, d_max) [m] proximal-to-distal distances leg ``k`` may take.

    d_max = max(standing extension, (1 − reach_margin)·(upper + lower)) (below full
    extension); d_min = fold_margin·|upper − lower| (at most 0.9·(upper + lower)), with
    the margins of ``options``.
    """
    geo = leg_geometry(sp, LEGS[k])
    d_stand = float(standing_info(sp)["d_stand"][k])
    dmax = min(geo.max_reach * (1 - 1e-9), max(d_stand, geo.max_reach * (1 - options.reach_margin)))
    dmin = min(options.fold_margin * geo.min_reach, 0.9 * geo.max_reach)
    return dmin, dmax


def required_lowering(
    sp: Species, legs: tuple[LegIKResult, ...], options: GeneratorOptions
) -> np.ndarray:
    """(T, 4) how far [m] each girdle must come down so its leg keeps its reach reserve.

    A leg may reach d_max of :func:`reach_band`.
    """
    out = []
    for k, res in enumerate(legs):
        dmax = reach_band(sp, k, options)[1]
        v = res.proximal - res.distal_target
        dz = v[:, 2]
        dist = np.linalg.norm(v, axis=-1)
        r2 = np.maximum(dist**2 - dz**2, 0.0)
        dz_new = np.sqrt(np.maximum(dmax**2 - r2, (0.3 * dmax) ** 2))
        out.append(np.where(dist > dmax, np.maximum(dz - dz_new, 0.0), 0.0))
    return np.stack(out, axis=1)


def required_raising(
    sp: Species, legs: tuple[LegIKResult, ...], options: GeneratorOptions
) -> np.ndarray:
    """(T, 4) how far [m] each girdle must come up so its leg is not folded past its range."""
    out = []
    for k, res in enumerate(legs):
        dmin = reach_band(sp, k, options)[0]
        v = res.proximal - res.distal_target
        dz = v[:, 2]
        dist = np.linalg.norm(v, axis=-1)
        r2 = np.maximum(dist**2 - dz**2, 0.0)
        dz_new = np.sqrt(np.maximum(dmin**2 - r2, 0.0))
        out.append(np.where(dist < dmin, np.maximum(dz_new - dz, 0.0), 0.0))
    return np.stack(out, axis=1)


def fix_reach(
    sp: Species,
    trunk: Trunk,
    plan: LegPlan,
    window: int,
    iterations: int = 30,
    mask: np.ndarray | None = None,
    *,
    options: GeneratorOptions,
) -> tuple[Trunk, Solved]:
    """Lower the pelvis and withers (smoothly) until every leg keeps its reach reserve.

    Args:
        sp: species.
        trunk: trunk state (not modified).
        plan: leg targets.
        window: smoothing window [frames] of the lowering envelope.
        iterations: maximal number of correction passes.
        mask: optional (T,) frames where the trunk may be moved (default all).
        options: the generator's knobs (reach margins, foot compliance).

    Returns:
        The corrected trunk and its solved pose.
    """
    tr = trunk.copy()
    span = float(standing_info(sp)["trunk_span"])
    sol = solve(sp, tr, plan, options)
    for _ in range(iterations):
        low = required_lowering(sp, sol.legs, options)
        up = required_raising(sp, sol.legs, options) * plan.contacts
        if mask is not None:
            low = low * mask[:, None]
            up = up * mask[:, None]
        if low.max() < 1e-7 and up.max() < 1e-7:
            break
        # Lowering wins where a girdle's legs disagree (a folded leg is clamped, an
        # over-reaching one would leave the ground).
        lp = upper_envelope(1.05 * low[:, 2:].max(axis=1), window)
        lw = upper_envelope(1.05 * low[:, :2].max(axis=1), window)
        rp = upper_envelope(1.05 * up[:, 2:].max(axis=1), window) * (lp < 1e-9)
        rw = upper_envelope(1.05 * up[:, :2].max(axis=1), window) * (lw < 1e-9)
        dp, dw = lp - rp, lw - rw
        tr.root[:, 2] -= dp
        tr.pitch -= np.arcsin(np.clip((dw - dp) / span, -0.9, 0.9))
        sol = solve(sp, tr, plan, options)
    return tr, sol


def apply_sway(
    sp: Species,
    trunk: Trunk,
    plan: LegPlan,
    gain: float,
    phase: np.ndarray,
    iterations: int = 3,
    harmonics: int = 1,
    *,
    options: GeneratorOptions,
) -> Trunk:
    """Shift the trunk horizontally so the centre of mass moves toward the support polygon.

    Per frame the target is the centroid of the stance toes; the centre of mass is moved
    ``gain`` of the way toward it. Frames with exactly three feet down (where static
    stability is at stake) weigh most, four feet less, fewer feet not at all. The shift
    is a periodic function of the gait phase (a constant plus ``harmonics`` harmonics of
    the stride frequency, fitted by weighted least squares in the heading frame), so it
    is smooth by construction — animals sway at the stride frequency (laterally) and
    twice it (fore-aft), but a second harmonic demands trunk accelerations above g in a
    brisk walk, so one harmonic is the default — and it anticipates every lift-off.

    Args:
        sp: species.
        trunk: trunk state (not modified).
        plan: leg plan (targets and stance).
        gain: share of the way toward the stance centroid (0 disables).
        phase: (T,) gait phase [cycles].
        iterations: refits (the centre of mass moves with the legs' IK).
        harmonics: number of stride-frequency harmonics.
        options: the generator's knobs (leg shape, reach margins).
    """
    if gain <= 0:
        return trunk
    tr = trunk.copy()
    skel = get_skeleton(sp)
    c = plan.contacts
    n = c.sum(axis=1)
    w = np.where(n == 3, 1.0, np.where(n >= 4, 0.25, 0.0))
    cols = [np.ones_like(phase)]
    for h in range(1, harmonics + 1):
        cols += [np.cos(2 * np.pi * h * phase), np.sin(2 * np.pi * h * phase)]
    basis = np.stack(cols, axis=1)  # (T, B)
    gram = basis.T @ (basis * w[:, None]) + 1e-6 * np.eye(basis.shape[1]) * max(w.sum(), 1.0)
    feet_xy = plan.targets[:, :, :2]
    cent = (feet_xy * c[..., None]).sum(axis=1) / np.maximum(n, 1)[:, None]
    limit = 0.12 * sp.leg_length
    cy, sy = np.cos(trunk.yaw), np.sin(trunk.yaw)

    def to_heading(v: np.ndarray) -> np.ndarray:
        return np.stack([cy * v[:, 0] + sy * v[:, 1], -sy * v[:, 0] + cy * v[:, 1]], -1)

    def to_world(v: np.ndarray) -> np.ndarray:
        return np.stack([cy * v[:, 0] - sy * v[:, 1], sy * v[:, 0] + cy * v[:, 1]], -1)

    desired = None
    shift = np.zeros((phase.shape[0], 2))  # heading frame
    for _ in range(iterations):
        sol = solve(sp, tr, plan, options)
        com = center_of_mass(sp, fk(skel, tr.root, sol.rotations))[:, :2]
        if desired is None:
            desired = com + gain * (cent - com)
        err = to_heading(desired - com)
        coef = np.linalg.solve(gram, basis.T @ (err * w[:, None]))
        shift = shift + basis @ coef
        mag = float(np.linalg.norm(shift, axis=-1).max())
        if mag > limit:
            shift *= limit / mag
        tr.root[:, :2] = trunk.root[:, :2] + to_world(shift)
    return tr


def _range_excess(sp: Species, limb: str, res: LegIKResult) -> np.ndarray:
    """(T,) summed squared excess [rad²] of a leg's flexion angles over the species' ranges."""
    out = np.zeros(res.upper_flex.shape)
    for role, a in (("upper", res.upper_flex), ("lower", res.lower_flex), ("foot", res.foot_flex)):
        lo, hi = sp.joint_limits[f"{limb}_{role}_flex"]
        out += np.maximum(lo - a, 0.0) ** 2 + np.maximum(a - hi, 0.0) ** 2
    return out


def respect_limits(
    sp: Species, trunk: Trunk, plan: LegPlan, base: Solved, window: int, options: GeneratorOptions
) -> Solved:
    """Turn each foot segment (smoothly in time) so the leg's flexion angles stay in range.

    The foot inclination is the leg's one free angle once the toe target is fixed: per
    frame the offset in ``options.limit_offsets()`` with the least range excess (ties: the
    least offset; a reach error forbids an offset) is taken, smoothed over ``window``
    frames, added to ``plan.foot_extra`` (modified in place) and the pose re-solved.
    ``base`` is the pose already solved for ``trunk`` and ``plan``.
    """
    rot = trunk.rotations()
    frames = axial_frames(sp, trunk.root, rot)
    t = trunk.root.shape[0]
    offsets = options.limit_offsets()
    k_n = offsets.size
    if all(
        float(_range_excess(sp, res_limb, res).max()) < 1e-12
        for res_limb, res in zip(("fore", "fore", "hind", "hind"), base.legs, strict=True)
    ):
        return base
    for k, leg in enumerate(LEGS):
        geo = leg_geometry(sp, leg)
        res0 = base.legs[k]
        finc0 = foot_inclination(
            frames.parent_rotation[:, k],
            res0.abduction,
            res0.girdle_flex,
            res0.upper_flex,
            res0.lower_flex,
            res0.foot_flex,
        )
        rep = lambda a: np.repeat(a, k_n, axis=0)  # noqa: E731
        cand = rep(finc0) + np.tile(offsets, t)
        res = leg_ik(
            sp,
            leg,
            rep(frames.girdle_root[:, k]),
            rep(frames.parent_rotation[:, k]),
            rep(plan.targets[:, k]),
            rep(res0.girdle_flex),
            cand,
        )
        cost = (
            _range_excess(sp, geo.limb, res)
            + 1e3 * (res.reach_error / sp.leg_length) ** 2
            + 1e-4 * np.tile(offsets, t) ** 2
        ).reshape(t, k_n)
        best = offsets[np.argmin(cost, axis=1)]
        # the offset demanded on top of what the compliance already turned
        turned = wrap_angle(finc0 - _nominal_inclination(sp, k, plan, frames, options))
        delta = best + turned
        if window > 1:
            from scipy.ndimage import uniform_filter1d

            delta = uniform_filter1d(delta, _odd(window), mode="nearest")
        plan.foot_extra[:, k] += delta
    return solve(sp, trunk, plan, options)


def min_jerk(s: np.ndarray) -> np.ndarray:
    """Minimum-jerk profile 10s³ − 15s⁴ + 6s⁵ on [0, 1] (clipped outside)."""
    s = np.clip(s, 0.0, 1.0)
    return s * s * s * (10.0 + s * (-15.0 + 6.0 * s))


def smooth_noise(rng: np.random.Generator, t: np.ndarray, freq_hz: float, n: int = 3) -> np.ndarray:
    """A smooth zero-mean signal (sum of ``n`` random sinusoids), amplitude ≈ 1."""
    out = np.zeros_like(t)
    for _ in range(n):
        f = freq_hz * rng.uniform(0.5, 1.5)
        out += np.sin(2 * math.pi * f * t + rng.uniform(0, 2 * math.pi))
    return out / math.sqrt(n)
