"""Cyclic locomotion: walk, trot, pace, amble, canter, gallops, bounds, turns, backward walk.

Internal module used by :func:`habitsim.gaits.generate`. Order of construction:

1. gait numbers: v = sqrt(Fr·g·h), stride λ = 2.3·Fr^0.3·h (Alexander 1976), stride
   frequency f = v/λ, duty factor β, footfall phases φ_i (LH = 0);
2. root path: heading ψ(t) = ψ0 + ω·t, speed v along the heading (closed form, so it can
   be evaluated before and after the clip);
3. stance schedule: foot i is in stance when frac(Φ(t) − φ_i) < β, Φ(t) = Φ0 + f·t;
4. footholds: the k-th stance of foot i is planted at the root path's mid-stance position
   plus the foot's neutral (standing) offset rotated by the mid-stance heading — exact
   world points, zero slide, height 0;
5. swing: minimum-jerk horizontal path between consecutive footholds and a vertical
   sin(π·s) lift of ``swing_height × leg length``;
6. trunk: vertical and pitch oscillations (twice per stride for symmetric gaits, once
   for asymmetric ones), spine flexion for asymmetric gaits, head bob, tail sway, spine
   bend into turns, lateral trunk sway for slow gaits (toward the support polygon);
7. leg IK; the pelvis / withers are lowered (smoothly) wherever a leg would over-reach.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from ..errors import GaitError
from ..physics_constants import GRAVITY
from ..species import FEET, Species
from ._pose import (
    LegPlan,
    Solved,
    Trunk,
    apply_sway,
    fix_reach,
    min_jerk,
    respect_limits,
    standing_info,
)
from .actions import ASYMMETRIC_GAITS
from .options import GeneratorOptions

_IDX = {f: i for i, f in enumerate(FEET)}


@dataclass
class GaitNumbers:
    """The numbers a cyclic clip is built from (SI units)."""

    froude: float
    speed_mps: float  # signed along the heading (negative = backward)
    stride_length_m: float
    stride_frequency_hz: float
    duty_factor: float
    phases: dict[str, float]
    turn_rate: float  # [rad/s], left positive
    start_phase: float
    heading: float


def gait_numbers(
    sp: Species,
    gait: str,
    froude: float,
    duty: float,
    phases: dict[str, float],
    turn_rate: float,
    start_phase: float,
    heading: float,
    direction: float,
) -> GaitNumbers:
    """Speed, stride length and frequency from the Froude number (Alexander 1976)."""
    if not (froude > 0 and math.isfinite(froude)):
        raise GaitError(f"a {gait} needs a positive Froude number, got {froude}")
    h = sp.hip_height
    v = math.sqrt(froude * GRAVITY * h)
    lam = 2.3 * froude**0.3 * h
    return GaitNumbers(
        froude=froude,
        speed_mps=direction * v,
        stride_length_m=lam,
        stride_frequency_hz=v / lam,
        duty_factor=duty,
        phases=phases,
        turn_rate=turn_rate,
        start_phase=start_phase,
        heading=heading,
    )


def _root_path(g: GaitNumbers, tt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Root xy (N, 2) and heading (N,) of the nominal path at times tt [s]."""
    v, w, p0 = g.speed_mps, g.turn_rate, g.heading
    psi = p0 + w * tt
    if abs(w) < 1e-9:
        xy = np.stack([v * math.cos(p0) * tt, v * math.sin(p0) * tt], -1)
    else:
        xy = np.stack(
            [(v / w) * (np.sin(psi) - math.sin(p0)), -(v / w) * (np.cos(psi) - math.cos(p0))], -1
        )
    return xy, psi


def _rotate(xy: np.ndarray, psi: np.ndarray) -> np.ndarray:
    c, s = np.cos(psi), np.sin(psi)
    return np.stack([c * xy[..., 0] - s * xy[..., 1], s * xy[..., 0] + c * xy[..., 1]], -1)


_GRID = np.linspace(0.0, 1.0, 2001)


@functools.lru_cache(maxsize=8)
def _profile_table(ramp: float) -> np.ndarray:
    """The swing progress on :data:`_GRID` for a ramp share (cached per ramp; read only)."""
    vel = np.minimum(1.0, np.minimum(_GRID, 1.0 - _GRID) / ramp)
    vel = min_jerk(vel)  # smooth ramps: zero velocity and acceleration at the ends
    pos = np.concatenate([[0.0], np.cumsum(0.5 * (vel[1:] + vel[:-1]) * np.diff(_GRID))])
    return pos / pos[-1]


def swing_profile(s: np.ndarray, ramp: float) -> np.ndarray:
    """Horizontal swing progress in [0, 1] for swing phase s: the foot leaves and lands
    with zero velocity and acceleration but reaches its cruise speed within ``ramp`` of
    the swing (``GeneratorOptions.swing_ramp``), so it stays close to the moving body (a
    foot that accelerates over the whole swing lags far behind the body in a fast gait)."""
    return np.interp(np.clip(s, 0.0, 1.0), _GRID, _profile_table(ramp))


def plan_feet(
    sp: Species, g: GaitNumbers, t: np.ndarray, swing_height: float, options: GeneratorOptions
) -> LegPlan:
    """Toe targets, stance schedule and swing progress of the four feet."""
    info = standing_info(sp)
    neutral = np.asarray(info["neutral"])
    f, beta = g.stride_frequency_hz, g.duty_factor
    phi_t = g.start_phase + f * t
    n = t.shape[0]
    targets = np.zeros((n, 4, 3))
    contacts = np.zeros((n, 4), dtype=bool)
    swing_s = np.zeros((n, 4))
    xy_now, psi_now = _root_path(g, t)
    for i, foot in enumerate(FEET):
        x = phi_t - g.phases[foot]
        k = np.floor(x)
        u = x - k
        k0 = int(k.min())
        ks = np.arange(k0, int(k.max()) + 2)
        t_mid = (g.phases[foot] + ks + 0.5 * beta - g.start_phase) / f
        xy, psi = _root_path(g, t_mid)
        holds = xy + _rotate(np.broadcast_to(neutral[i], xy.shape), psi)  # (K, 2)
        kk = (k - k0).astype(int)
        stance = u < beta
        s = np.where(stance, 0.0, (u - beta) / (1.0 - beta))
        a, b = holds[kk], holds[np.minimum(kk + 1, len(ks) - 1)]
        m = min_jerk(s)[:, None]
        world = a + (b - a) * swing_profile(s, options.swing_ramp)[:, None]
        # Swing relative to the moving body: a world-frame minimum-jerk path lags far
        # behind the body early in the swing of a fast gait (beyond the leg's reach);
        # the body-frame path keeps the foot under the body. Blended with weight
        # sin²(πs), so the swing leaves and lands with zero world velocity.
        t_lo = (g.phases[foot] + ks + beta - g.start_phase) / f
        t_td = (g.phases[foot] + ks + 1.0 - g.start_phase) / f
        xy_lo, psi_lo = _root_path(g, t_lo)
        xy_td, psi_td = _root_path(g, t_td)
        rel_a = _rotate(holds - xy_lo, -psi_lo)  # lift-off foothold in the body frame
        rel_b = _rotate(np.roll(holds, -1, axis=0) - xy_td, -psi_td)  # next foothold
        rel = rel_a[kk] + (rel_b[kk] - rel_a[kk]) * m
        body = xy_now + _rotate(rel, psi_now)
        w = np.sin(np.pi * s)[:, None] ** 2
        swing_xy = (1.0 - w) * world + w * body
        targets[:, i, :2] = np.where(stance[:, None], a, swing_xy)
        targets[:, i, 2] = np.where(stance, 0.0, swing_height * np.sin(np.pi * s))
        contacts[:, i] = stance
        swing_s[:, i] = s
    return LegPlan(targets=targets, contacts=contacts, swing_s=swing_s)


def build_locomotion(
    sp: Species,
    gait: str,
    g: GaitNumbers,
    t: np.ndarray,
    fps: float,
    style: dict[str, float],
    sway_gain: float,
    options: GeneratorOptions,
) -> tuple[Trunk, Solved, LegPlan]:
    """Build one cyclic clip.

    Args:
        sp: species.
        gait: species gait name.
        g: gait numbers.
        t: (T,) frame times [s].
        fps: frame rate [Hz].
        style: per-clip carriage variations (``neck_offset``, ``head_offset``,
            ``tail_offset`` [rad], ``swing_scale``).
        sway_gain: lateral trunk sway gain (0 disables).
        options: the generator's knobs.

    Returns:
        The trunk, the solved pose and the leg plan.
    """
    h = sp.hip_height
    hab = sp.habits
    info = standing_info(sp)
    asym = gait in ASYMMETRIC_GAITS
    fr_max = max(gh.froude[1] for gh in sp.gaits.values())
    u_speed = float(np.clip(g.froude / max(fr_max, 1e-9), 0.0, 1.0))
    f = g.stride_frequency_hz
    phi = g.start_phase + f * t  # gait phase [cycles]
    two_pi = 2.0 * math.pi

    swing_h = (
        hab.swing_height * sp.leg_length * style.get("swing_scale", 1.0) * (0.8 + 0.4 * u_speed)
    )
    plan = plan_feet(sp, g, t, swing_h, options)

    tr = Trunk.standing(sp, t.shape[0])
    xy, psi = _root_path(g, t)
    tr.root[:, :2] = xy
    tr.yaw = psi.copy()
    hind_td = 0.5 * (g.phases["LH"] + g.phases["RH"])
    if asym:
        flex = np.cos(two_pi * (phi - hind_td))  # +1: spine flexed (hind feet far forward)
        a_sp = hab.spine_flex * min(1.0, max(0.3, u_speed)) / 3.0
        tr.spine_pitch += (a_sp * flex)[:, None]
        rock = 0.05 * u_speed * np.sin(two_pi * (phi - hind_td))
        tr.pitch += a_sp * flex + rock  # keep the pelvis-withers chord, add rocking
        tr.root[:, 2] += 0.02 * h * np.cos(two_pi * (phi - hind_td - 0.5))
        nod = 0.7 * hab.head_bob * np.cos(two_pi * (phi - hind_td - 0.25))
        tail_scale = 0.3
        tr.tail_pitch[:, 0] += 0.25 * u_speed
    else:
        beta = g.duty_factor
        tr.root[:, 2] += 0.01 * h * (0.5 + u_speed) * np.cos(2 * two_pi * (phi - 0.5 * beta))
        tr.pitch += math.radians(1.0) * np.sin(2 * two_pi * (phi - 0.5 * beta))
        bob = 1.0 if gait in ("walk", "amble") else 0.4
        nod = bob * hab.head_bob * np.cos(2 * two_pi * (phi - g.phases["LF"]))
        tail_scale = 1.0 if gait in ("walk", "amble") else 0.5
        tr.yaw += math.radians(1.5) * np.sin(two_pi * phi)
    tr.neck_pitch += nod + style.get("neck_offset", 0.0)
    tr.head_pitch += -0.5 * nod + style.get("head_offset", 0.0)
    tr.tail_pitch[:, 0] += style.get("tail_offset", 0.0)
    sway = hab.tail_sway * tail_scale
    tr.tail_yaw[:, 0] = sway * np.sin(two_pi * phi)
    tr.tail_yaw[:, 1] = 0.7 * sway * np.sin(two_pi * (phi - 0.15))
    if abs(g.turn_rate) > 0:
        lim = max(abs(v) for v in sp.joint_limits["spine_yaw"])
        bend = float(
            np.clip(
                g.turn_rate * info["trunk_span"] / max(abs(g.speed_mps), 1e-6), -2 * lim, 2 * lim
            )
        )
        tr.spine_yaw += bend / 3.0
        tr.neck_yaw += 0.5 * bend
        tr.head_yaw += 0.25 * bend

    window = max(3, int(round(0.45 * fps / f)))
    if sway_gain > 0 and g.duty_factor >= 0.5:
        tr = apply_sway(sp, tr, plan, sway_gain, phi, options=options)
    tr, sol = fix_reach(sp, tr, plan, window, options=options)
    sol = respect_limits(sp, tr, plan, sol, max(3, int(round(0.1 * fps / f))), options)
    return tr, sol, plan
