"""Chained clips: one continuous motion through several actions (:func:`generate_chain`).

A chain is a list of (action, seconds) steps, e.g. walk → trot → gallop or walk →
turn_left → stop → sit. The clip is built in one piece:

1. per step, the numbers of its gait (Froude number, duty factor, footfall phases, turn
   rate), drawn like :func:`habitsim.gaits.generate` draws them;
2. speed, turn rate, duty factor, footfall phases and the weight of the asymmetric
   (canter / gallop) trunk motion ease from one step's values to the next over
   ``chain_transition_strides`` strides around the boundary (minimum jerk); a ``stop``
   speeds down to standing over ``chain_stop_strides`` strides, a walk after ``idle``
   speeds up from standing the same way;
3. on a fine time grid: stride frequency from the speed (Alexander 1976, as for single
   clips, never below the slow end of the walk's), gait phase Φ = ∫f dt, heading
   ψ = ∫ω dt, root path ∫v·(cos ψ, sin ψ) dt;
4. per foot, the stance of its k-th stride is when Φ − φ_i(t) lies in [k, k + β(t)); its
   foothold is the root path's mid-stance pose plus the foot's standing offset, fixed
   for the whole stance (a planted foot stays planted through a change of gait); where
   the animal stands (before a start, after a stop) every foot's stances merge into one
   on its square standing foothold;
5. swings between footholds as in single clips; the trunk's oscillations follow the
   gait phase and fade out where the animal stands; an ``idle`` or ``sit`` step is the
   single-clip motion (:mod:`habitsim.gaits.stationary`) on the feet where they
   stopped, eased into over ``chain_blend_s``;
6. leg IK over the whole clip, pelvis / withers lowered where a leg would over-reach.

Allowed transitions (:func:`allowed_transitions`): between neighbours on the species'
speed ladder (walk, then trot / pace / amble, then canter, then gallop / bound, as far
as the species has them); turns to and from a walk or a trot / pace / amble, and
between left and right; ``stop`` from those and from a turn; after ``stop``, ``idle`` or
``sit``; after ``idle``, ``sit``, or, when the chain starts with it, a start at a walk or
a trot / pace / amble. ``sit`` ends a chain.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import GaitError
from ..motion import Motion
from ..physics_constants import GRAVITY
from ..species import FEET, Species, load_species
from ._pose import LegPlan, Trunk, apply_sway, fix_reach, min_jerk, respect_limits, standing_info
from .actions import ASYMMETRIC_GAITS, action_gait, available_actions
from .generator import GENERATOR_VERSION, _duty_from, draw_params
from .locomotion import _rotate, swing_profile
from .options import GeneratorOptions, resolve_generator
from .stationary import build_idle, build_sit

__all__ = [
    "CHAIN_STEPS",
    "allowed_transitions",
    "chain_min_duration",
    "draw_chain",
    "generate_chain",
    "speed_ladder",
]

#: Locomotion actions in order of speed (a species has some of them).
_LADDER: tuple[str, ...] = ("walk", "trot", "pace", "amble", "canter", "gallop", "bound")
_TURNS: tuple[str, ...] = ("turn_left", "turn_right")
#: Every step a chain may hold: locomotion, turns, ``stop`` (speed down to standing),
#: ``idle`` and ``sit``.
CHAIN_STEPS: tuple[str, ...] = (*_LADDER, *_TURNS, "stop", "idle", "sit")
_STILL = ("idle", "sit")


def speed_ladder(species: str | Species) -> list[str]:
    """The species' locomotion actions in order of speed (walk first)."""
    have = set(available_actions(species))
    return [a for a in _LADDER if a in have]


def allowed_transitions(species: str | Species) -> dict[str, list[str]]:
    """Step → the steps that may follow it, for one species (see the module docstring).

    Raises:
        UnknownSpeciesError: unknown species.
    """
    sp = load_species(species)
    have = set(available_actions(sp))
    ladder = speed_ladder(sp)
    slow = [a for a in ladder if a in _LADDER[:4]][:2]  # the walk and a trot / pace / amble
    turns = [t for t in _TURNS if t in have]
    out: dict[str, list[str]] = {}
    for i, a in enumerate(ladder):
        nxt = [ladder[j] for j in (i - 1, i + 1) if 0 <= j < len(ladder)]
        if a in slow:
            nxt += [*turns, "stop"]
        out[a] = nxt
    for t in turns:
        out[t] = [*slow, *(u for u in turns if u != t), "stop"]
    out["stop"] = ["idle", "sit"]
    out["idle"] = [*slow, "sit"]
    out["sit"] = []
    return {k: sorted(v, key=CHAIN_STEPS.index) for k, v in out.items()}


def _tau(sp: Species) -> float:
    return math.sqrt(sp.hip_height / GRAVITY)


def _stride_frequency(sp: Species, v: np.ndarray | float) -> np.ndarray:
    """Stride frequency [Hz] at speed v [m/s] (λ = 2.3·Fr^0.3·h, Alexander 1976)."""
    h = sp.hip_height
    fr = np.maximum(np.asarray(v, dtype=float), 1e-9) ** 2 / (GRAVITY * h)
    return np.asarray(v, dtype=float) / (2.3 * fr**0.3 * h)


def _floor_frequency(sp: Species) -> float:
    """Stride frequency at the slow end of the species' walk [Hz]."""
    v = math.sqrt(sp.gaits["walk"].froude[0] * GRAVITY * sp.hip_height)
    return float(_stride_frequency(sp, v))


def chain_min_duration(
    species: str | Species, action: str, options: GeneratorOptions | None = None
) -> float:
    """The shortest a chained step may last [s].

    Locomotion: two strides at the slow end of its gait; ``stop``: its speed-down plus
    one stride at the slow end of the walk (the feet square up); ``sit``: as long as a
    single sit clip's shortest; ``idle``: ``chain_blend_s`` and half a second.
    """
    sp = load_species(species)
    opts = resolve_generator(options)
    f0 = _floor_frequency(sp)
    if action == "sit":
        return 1.2 * 6.0 * _tau(sp) + opts.chain_blend_s  # sit_start + sit_duration ≤ 6 τ
    if action == "idle":
        return opts.chain_blend_s + 0.5
    if action == "stop":
        return (opts.chain_stop_strides + 1.5) / f0
    gait = action_gait(sp, action)
    v = math.sqrt(sp.gaits[gait].froude[0] * GRAVITY * sp.hip_height)
    return 2.0 / max(float(_stride_frequency(sp, v)), f0)


def _followers(allowed: dict[str, list[str]], action: str, position: int) -> list[str]:
    """The steps that may follow ``action`` at this position (a start only from a
    standing first step: the feet keep the footfall of the gait they stopped in)."""
    if action == "idle" and position > 0:
        return [a for a in allowed["idle"] if a == "sit"]
    return allowed[action]


def _check_chain(sp: Species, steps: Sequence[tuple[str, float]], opts: GeneratorOptions) -> None:
    """Raise :class:`GaitError` unless ``steps`` is a chain the species can make."""
    have = set(available_actions(sp))
    allowed = allowed_transitions(sp)
    if isinstance(steps, str) or len(steps) < 2:
        raise GaitError(
            f"a chain needs at least two (action, seconds) steps, got {steps!r}; "
            f"steps: {', '.join(CHAIN_STEPS)}"
        )
    for i, step in enumerate(steps):
        if not (isinstance(step, tuple | list) and len(step) == 2):
            raise GaitError(f"chain step {i} must be an (action, seconds) pair, got {step!r}")
        action, secs = step
        if action not in CHAIN_STEPS:
            raise GaitError(
                f"chain step {i}: {action!r} cannot be chained; valid: {', '.join(CHAIN_STEPS)}"
            )
        if action != "stop" and action not in have:
            raise GaitError(
                f"chain step {i}: species {sp.name!r} has no action {action!r}; "
                f"it can chain: {', '.join(a for a in CHAIN_STEPS if a in allowed)}"
            )
        lo = chain_min_duration(sp, action, opts)
        if not (isinstance(secs, int | float) and math.isfinite(secs) and secs >= lo - 1e-9):
            raise GaitError(
                f"chain step {i} ({action}) must last at least {lo:.2f} s for a "
                f"{sp.name}, got {secs!r}"
            )
    first = steps[0][0]
    if first in ("stop", "sit"):
        raise GaitError(
            f"a chain cannot start with {first!r}; it starts with one of: "
            + ", ".join(a for a in allowed if a not in ("stop", "sit"))
        )
    for i in range(len(steps) - 1):
        a, b = steps[i][0], steps[i + 1][0]
        after = _followers(allowed, a, i)
        if b not in after:
            valid = ", ".join(after) or "nothing (it ends the chain)"
            raise GaitError(
                f"a {sp.name} cannot go from {a!r} to {b!r} (steps {i}, {i + 1}); "
                f"after {a!r} come: {valid}"
            )


@dataclass
class _Step:
    """One step's numbers (locomotion; zeros for stop / idle / sit)."""

    action: str
    gait: str
    start: float
    end: float
    froude: float
    duty: float
    turn_rate: float
    phases: dict[str, float]
    asym: float


def _plan_steps(
    sp: Species,
    steps: Sequence[tuple[str, float]],
    params: dict[str, Any],
    draws: list[dict[str, float]],
    shrink: float,
    opts: GeneratorOptions,
) -> list[_Step]:
    out: list[_Step] = []
    t = 0.0
    prev: _Step | None = None
    for (action, secs), d in zip(steps, draws, strict=True):
        if action in ("stop", *_STILL):
            base = prev if (prev is not None and action == "stop") else None
            st = _Step(
                action,
                {"stop": "walk", "idle": "stand", "sit": "sit"}[action],
                t,
                t + float(secs),
                0.0,
                base.duty if base else 1.0,
                0.0,
                dict(base.phases) if base else dict(sp.gaits["walk"].footfall),
                0.0,
            )
        else:
            gait = action_gait(sp, action)
            band = sp.gaits[gait]
            u = d["u_froude"] * shrink
            fr = band.froude[0] + u * (band.froude[1] - band.froude[0])
            if prev is not None and prev.action in _LADDER and action in _LADDER:
                # up the ladder never slower, down never faster (within the new band)
                up = _LADDER.index(action) > _LADDER.index(prev.action)
                fr = max(fr, prev.froude) if up else min(fr, prev.froude)
                fr = float(np.clip(fr, *band.froude))
            duty, _ = _duty_from(band.duty_factor, u, d["u_duty_noise"])
            duty = band.duty_factor[0] + (duty - band.duty_factor[0]) * shrink
            w = 0.0
            if action in _TURNS:
                lo_nd = opts.turn_rate_nd_range[0]
                w = (lo_nd + (d["turn_rate_nd"] - lo_nd) * shrink) / _tau(sp)
                w = w if action == "turn_left" else -w
            phases = {f: (band.footfall[f] + params["phase_jitter"][f]) % 1.0 for f in FEET}
            st = _Step(
                action,
                gait,
                t,
                t + float(secs),
                float(fr),
                float(duty),
                w,
                phases,
                1.0 if gait in ASYMMETRIC_GAITS else 0.0,
            )
        out.append(st)
        prev = st
        t += float(secs)
    return out


def _ease(t: np.ndarray, t0: float, t1: float) -> np.ndarray:
    """0 before t0, 1 after t1, minimum jerk between."""
    return min_jerk((t - t0) / max(t1 - t0, 1e-9))


@dataclass
class _Signals:
    """Per grid time: speed, turn rate, duty, phases, asymmetric weight, rest spans."""

    v: np.ndarray
    w: np.ndarray
    beta: np.ndarray
    phases: dict[str, np.ndarray]
    asym: np.ndarray
    rests: list[tuple[float, float]]  # (feet settle from, motion resumes at) [s]
    transitions: list[dict[str, Any]]


def _signals(sp: Species, plan: list[_Step], tg: np.ndarray, opts: GeneratorOptions) -> _Signals:
    first = plan[0]
    if first.action in _STILL and len(plan) > 1 and plan[1].action not in _STILL:
        first = plan[1]  # standing: the feet hold the footfall of the gait they start in
    speed = [math.sqrt(s.froude * GRAVITY * sp.hip_height) for s in plan]
    v = np.full(tg.shape, speed[0] if plan[0].action not in _STILL else 0.0)
    w = np.full(tg.shape, plan[0].turn_rate)
    beta = np.full(tg.shape, first.duty)
    asym = np.full(tg.shape, first.asym)
    ph = {f: np.full(tg.shape, first.phases[f]) for f in FEET}
    rests: list[tuple[float, float]] = []
    transitions: list[dict[str, Any]] = []
    rest_from = -math.inf if first.action in _STILL else None
    f0 = _floor_frequency(sp)
    for i in range(1, len(plan)):
        a, b = plan[i - 1], plan[i]
        bnd = b.start
        if b.action in _STILL and a.action in _STILL:
            continue  # idle → sit: both standing
        if b.action == "stop" or a.action in _STILL:
            moving = a if b.action == "stop" else b
            fm = max(float(_stride_frequency(sp, speed[plan.index(moving)])), f0)
            t0, t1 = bnd, bnd + opts.chain_stop_strides / fm
            e = _ease(tg, t0, t1)
            if b.action == "stop":
                v = v * (1.0 - e)
                w = w * (1.0 - e)
                rest_from = 0.5 * (t0 + t1)
            else:
                v = v + e * (speed[i] - v)
                w = w + e * (b.turn_rate - w)
                asym = asym + e * (b.asym - asym)
                rests.append((-math.inf if rest_from is None else rest_from, bnd))
                rest_from = None
        else:
            # at the slower gait's strides: its feet keep up with the change of footfall
            fm = float(min(_stride_frequency(sp, speed[i - 1]), _stride_frequency(sp, speed[i])))
            half = 0.5 * opts.chain_transition_strides / max(fm, f0)
            t0, t1 = bnd - half, bnd + half
            e = _ease(tg, t0, t1)
            v = v + e * (speed[i] - v)
            w = w + e * (b.turn_rate - w)
            beta = beta + e * (b.duty - beta)
            asym = asym + e * (b.asym - asym)
            for f in FEET:
                d = ((b.phases[f] - a.phases[f] + 0.5) % 1.0) - 0.5
                ph[f] = ph[f] + e * d
        if not (b.action in _STILL and a.action == "stop"):
            transitions.append(
                {"from": a.action, "to": b.action, "start_s": float(t0), "end_s": float(t1)}
            )
    if rest_from is not None:
        rests.append((rest_from, math.inf))
    return _Signals(v, w, beta, ph, asym, rests, transitions)


def _integrate(tg: np.ndarray, rate: np.ndarray, i0: int) -> np.ndarray:
    """∫ rate dt on the grid (trapezoid), zero at grid index ``i0``."""
    c = np.concatenate([[0.0], np.cumsum(0.5 * (rate[1:] + rate[:-1]) * np.diff(tg))])
    return c - c[i0]


@dataclass
class _Stance:
    on: float
    off: float
    hold: np.ndarray  # (2,)


def _schedule(
    foot: int,
    x: np.ndarray,
    beta: np.ndarray,
    tg: np.ndarray,
    path: tuple[np.ndarray, np.ndarray],
    neutral: np.ndarray,
    rests: list[tuple[float, float]],
) -> list[_Stance]:
    """One foot's stances in time order (stances of a rest merged on its square hold)."""
    xy, psi = path
    lo_x = x - beta
    if np.any(np.diff(x) <= 0) or np.any(np.diff(lo_x) <= 0) or np.any(np.diff(x - beta / 2) <= 0):
        raise GaitError("a chained gait's phase runs backwards; lengthen the transitions")
    ks = np.arange(math.ceil(x[0]), math.floor(lo_x[-1]) + 1)
    on = np.interp(ks, x, tg)
    off = np.interp(ks, lo_x, tg)
    mid = np.interp(ks, x - beta / 2, tg)
    hxy = np.stack([np.interp(mid, tg, xy[:, 0]), np.interp(mid, tg, xy[:, 1])], -1)
    hpsi = np.interp(mid, tg, psi)
    holds = hxy + _rotate(np.broadcast_to(neutral[foot], hxy.shape), hpsi)
    stances = [_Stance(float(a), float(b), h) for a, b, h in zip(on, off, holds, strict=True)]
    for r0, r1 in rests:
        t_at = min(r1, tg[-1])  # the root stands still from r0 (at the latest) to r1
        rxy = np.array([np.interp(t_at, tg, xy[:, 0]), np.interp(t_at, tg, xy[:, 1])])
        hold = rxy + _rotate(neutral[foot], np.asarray(np.interp(t_at, tg, psi)))
        first = next((j for j, s in enumerate(stances) if s.on >= r0), len(stances))
        last = next((j for j, s in enumerate(stances) if s.off >= r1), len(stances) - 1)
        if first > last:
            continue
        merged = _Stance(stances[first].on, stances[last].off, hold)
        if math.isinf(r1):
            merged.off = math.inf
        if math.isinf(r0):
            merged.on = -math.inf
        stances = [*stances[:first], merged, *stances[last + 1 :]]
    return stances


def _feet(
    sp: Species,
    t: np.ndarray,
    tg: np.ndarray,
    sig: _Signals,
    phi: np.ndarray,
    path: tuple[np.ndarray, np.ndarray],
    swing_h: np.ndarray,
    opts: GeneratorOptions,
) -> LegPlan:
    """Toe targets, stance and swing progress at the frame times ``t``."""
    neutral = np.asarray(standing_info(sp)["neutral"])
    xy, psi = path
    n = t.shape[0]
    targets = np.zeros((n, 4, 3))
    contacts = np.zeros((n, 4), dtype=bool)
    swing_s = np.zeros((n, 4))
    xy_t = np.stack([np.interp(t, tg, xy[:, 0]), np.interp(t, tg, xy[:, 1])], -1)
    psi_t = np.interp(t, tg, psi)

    def pose(tt: float) -> tuple[np.ndarray, float]:
        return (
            np.array([np.interp(tt, tg, xy[:, 0]), np.interp(tt, tg, xy[:, 1])]),
            float(np.interp(tt, tg, psi)),
        )

    for i, foot in enumerate(FEET):
        x = phi - sig.phases[foot]
        stances = _schedule(i, x, sig.beta, tg, path, neutral, sig.rests)
        ons = np.array([s.on for s in stances])
        j = np.searchsorted(ons, t, side="right") - 1  # the stance begun last
        for fr in range(n):
            jj = int(j[fr])
            if jj < 0 or jj >= len(stances):
                raise GaitError("a chained clip's feet are not planned over the whole clip")
            a = stances[jj]
            if t[fr] < a.off or jj + 1 >= len(stances):
                targets[fr, i, :2] = a.hold
                contacts[fr, i] = True
                continue
            b = stances[jj + 1]
            s = (t[fr] - a.off) / max(b.on - a.off, 1e-9)
            world = a.hold + (b.hold - a.hold) * swing_profile(np.asarray(s), opts.swing_ramp)
            xy_lo, psi_lo = pose(a.off)
            xy_td, psi_td = pose(b.on)
            rel_a = _rotate(a.hold - xy_lo, np.asarray(-psi_lo))
            rel_b = _rotate(b.hold - xy_td, np.asarray(-psi_td))
            rel = rel_a + (rel_b - rel_a) * float(min_jerk(np.asarray(s)))
            body = xy_t[fr] + _rotate(rel, np.asarray(psi_t[fr]))
            wgt = math.sin(math.pi * s) ** 2
            targets[fr, i, :2] = (1.0 - wgt) * world + wgt * body
            targets[fr, i, 2] = swing_h[fr] * math.sin(math.pi * s)
            swing_s[fr, i] = s
    return LegPlan(targets=targets, contacts=contacts, swing_s=swing_s)


def _trunk(
    sp: Species,
    t: np.ndarray,
    tg: np.ndarray,
    sig: _Signals,
    phi: np.ndarray,
    path: tuple[np.ndarray, np.ndarray],
    style: dict[str, float],
) -> tuple[Trunk, np.ndarray, np.ndarray]:
    """The locomotion trunk at the frame times; also the gait phase and the moving weight."""
    h = sp.hip_height
    hab = sp.habits
    info = standing_info(sp)
    two_pi = 2.0 * math.pi
    at = {k: np.interp(t, tg, getattr(sig, k)) for k in ("v", "w", "beta", "asym")}
    ph = {f: np.interp(t, tg, sig.phases[f]) for f in FEET}
    p = np.interp(t, tg, phi)
    fr_max = max(gh.froude[1] for gh in sp.gaits.values())
    u_speed = np.clip(at["v"] ** 2 / (GRAVITY * h) / max(fr_max, 1e-9), 0.0, 1.0)
    v_walk = math.sqrt(sp.gaits["walk"].froude[0] * GRAVITY * h)
    moving = min_jerk(at["v"] / v_walk)  # 0 standing, 1 at the walk's slow end and above
    a_w = at["asym"] * moving
    s_w = (1.0 - at["asym"]) * moving
    tr = Trunk.standing(sp, t.shape[0])
    xy, psi = path
    tr.root[:, 0] = np.interp(t, tg, xy[:, 0])
    tr.root[:, 1] = np.interp(t, tg, xy[:, 1])
    tr.yaw = np.interp(t, tg, psi)
    hind_td = 0.5 * (ph["LH"] + ph["RH"])
    flex = np.cos(two_pi * (p - hind_td))
    a_sp = hab.spine_flex * np.minimum(1.0, np.maximum(0.3, u_speed)) / 3.0
    tr.spine_pitch += (a_w * a_sp * flex)[:, None]
    rock = 0.05 * u_speed * np.sin(two_pi * (p - hind_td))
    tr.pitch += a_w * (a_sp * flex + rock)
    tr.root[:, 2] += a_w * 0.02 * h * np.cos(two_pi * (p - hind_td - 0.5))
    nod_a = 0.7 * hab.head_bob * np.cos(two_pi * (p - hind_td - 0.25))
    tr.tail_pitch[:, 0] += a_w * 0.25 * u_speed
    beta = at["beta"]
    tr.root[:, 2] += s_w * 0.01 * h * (0.5 + u_speed) * np.cos(2 * two_pi * (p - 0.5 * beta))
    tr.pitch += s_w * math.radians(1.0) * np.sin(2 * two_pi * (p - 0.5 * beta))
    walkish = np.clip((beta - 0.5) / 0.1, 0.0, 1.0)  # a walk or amble (duty ≥ 0.6)
    bob = 0.4 + 0.6 * walkish
    nod_s = bob * hab.head_bob * np.cos(2 * two_pi * (p - ph["LF"]))
    tr.yaw += s_w * math.radians(1.5) * np.sin(two_pi * p)
    nod = a_w * nod_a + s_w * nod_s
    tail_scale = a_w * 0.3 + s_w * (0.5 + 0.5 * walkish)
    tr.neck_pitch += nod + style["neck_offset"]
    tr.head_pitch += -0.5 * nod + style["head_offset"]
    tr.tail_pitch[:, 0] += style["tail_offset"]
    sway = hab.tail_sway * tail_scale
    tr.tail_yaw[:, 0] = sway * np.sin(two_pi * p)
    tr.tail_yaw[:, 1] = 0.7 * sway * np.sin(two_pi * (p - 0.15))
    lim = max(abs(v) for v in sp.joint_limits["spine_yaw"])
    bend = np.clip(at["w"] * info["trunk_span"] / np.maximum(at["v"], v_walk), -2 * lim, 2 * lim)
    tr.spine_yaw += (bend / 3.0)[:, None]
    tr.neck_yaw += 0.5 * bend
    tr.head_yaw += 0.25 * bend
    return tr, p, moving


_TRUNK_FIELDS = (
    "root",
    "yaw",
    "pitch",
    "roll",
    "spine_pitch",
    "spine_yaw",
    "neck_pitch",
    "neck_yaw",
    "head_pitch",
    "head_yaw",
    "tail_pitch",
    "tail_yaw",
)


def _still_steps(
    sp: Species,
    plan: list[_Step],
    t: np.ndarray,
    fps: float,
    tr: Trunk,
    legs: LegPlan,
    params: dict[str, Any],
    opts: GeneratorOptions,
) -> dict[str, Any]:
    """Blend the idle / sit steps' own trunk motion into ``tr`` (in place) and the sit's
    leg shaping into ``legs``; returns the sit's metadata (empty without a sit)."""
    extra: dict[str, Any] = {}
    detail = np.random.default_rng(params["detail_seed"])
    gain = np.ones(t.shape[0])
    for k, st in enumerate(plan):
        if st.action not in _STILL:
            continue
        if k > 0 and plan[k - 1].action in _STILL:
            continue  # idle → sit: the sit's own standing start covers the idle
        end = st.end
        if st.action == "idle" and k + 1 < len(plan) and plan[k + 1].action == "sit":
            end = plan[k + 1].end
            st = plan[k + 1]
        sel = (t >= st.start if k > 0 else t >= 0.0) & (t < end + 0.5 / fps)
        idx = np.flatnonzero(sel)
        if idx.size < 2:
            continue
        i0 = int(idx[0])
        span_t = t[idx] - t[i0]
        p = dict(params, heading=float(tr.yaw[i0]))
        if st.action == "sit":
            s_tr, _, s_plan, sx = build_sit(sp, span_t, fps, p, detail, opts)
            extra = {
                k2: float(v2 + (t[i0] if k2 == "sit_start_s" else 0.0)) for k2, v2 in sx.items()
            }
        else:
            s_tr, _, s_plan = build_idle(sp, span_t, fps, p, detail, opts)
        s_tr.root[:, :2] += tr.root[i0, :2]
        # weight of the still motion: eased in after a stop, out before a start
        wgt = np.ones(idx.size)
        if k > 0:
            wgt *= _ease(span_t, 0.0, opts.chain_blend_s)
        if k + 1 < len(plan) and plan[k + 1].action not in _STILL:
            wgt *= 1.0 - _ease(span_t, span_t[-1] - opts.chain_blend_s, span_t[-1])
        for name in _TRUNK_FIELDS:
            a = getattr(tr, name)
            b = getattr(s_tr, name)
            ww = wgt.reshape((-1,) + (1,) * (a.ndim - 1))
            if name == "yaw":
                b = tr.yaw[i0] + (b - b[0])
            a[idx] = (1.0 - ww) * a[idx] + ww * b
        legs.foot_extra[idx] += wgt[:, None] * s_plan.foot_extra
        gain[idx] = 1.0 - wgt * (1.0 - np.asarray(s_plan.sweep_gain, dtype=float))
    legs.sweep_gain = gain
    return extra


def generate_chain(
    species: str | Species,
    steps: Sequence[tuple[str, float]],
    *,
    seed: int,
    fps: float = 30.0,
    options: GeneratorOptions | None = None,
) -> Motion:
    """Generate one continuous clip that chains actions (see the module docstring).

    Args:
        species: catalog species name or :class:`~habitsim.species.Species`.
        steps: (action, seconds) pairs in order; actions from :data:`CHAIN_STEPS` the
            species has (``stop`` for any), each at least :func:`chain_min_duration`
            long, each following the one before as :func:`allowed_transitions` allows.
        seed: integer seed of ``np.random.default_rng`` (speeds, duty factors, turn
            rates, carriage; the same draws as :func:`~habitsim.gaits.generate` for the
            whole-clip numbers).
        fps: frame rate [Hz].
        options: the generator's knobs (the ``chain_*`` ones set transition lengths).

    Returns:
        The :class:`~habitsim.motion.Motion` (contacts = the planned stance) with
        metadata as :func:`~habitsim.gaits.generate`'s (``action`` ``"chain"``, ``gait``
        the steps' gaits joined by ``+``, speed, Froude number, duty factor and turn rate
        the clip's means) and ``chain``: ``{"segments": [{"action", "gait", "start_s",
        "end_s", "froude", "speed_mps", "duty_factor", "turn_rate"}], "transitions":
        [{"from", "to", "start_s", "end_s"}]}`` (times [s] from the clip's start; a
        transition straddles the boundary of its segments, a stop's or a start's begins
        at it).

    Raises:
        UnknownSpeciesError: unknown species.
        GaitError: a step the species cannot chain, a transition it cannot make (the
            message lists the allowed ones), a step too short, a bad seed or fps.
    """
    sp = load_species(species)
    opts = resolve_generator(options)
    if seed is None or isinstance(seed, bool) or not isinstance(seed, int | np.integer):
        raise GaitError(f"seed must be an integer, got {seed!r}")
    if not (isinstance(fps, int | float) and math.isfinite(fps) and fps > 0):
        raise GaitError(f"fps must be positive, got {fps!r}")
    fps = float(fps)
    steps = [(str(a), float(d) if isinstance(d, int | float) else d) for a, d in steps]
    _check_chain(sp, steps, opts)
    rng = np.random.default_rng(int(seed))
    params = draw_params(rng, opts)
    draws = [
        {
            "u_froude": float(rng.uniform(0.08, 0.92)),
            "u_duty_noise": float(rng.normal(0.0, 0.12)),
            "turn_rate_nd": float(rng.uniform(*opts.turn_rate_nd_range)),
        }
        for _ in steps
    ]
    total = sum(d for _, d in steps)
    n = max(2, int(round(total * fps)))
    t = np.arange(n) / fps
    f0 = _floor_frequency(sp)
    pad = 3.0 / f0
    dt = 0.25 / (fps * 4.0)
    tg = np.arange(-pad, total + pad + dt, dt)
    i0 = int(np.argmin(np.abs(tg)))
    neutral_style = {k: params[k] for k in ("neck_offset", "head_offset", "tail_offset")}
    for attempt in range(opts.max_attempts):
        shrink = opts.retry_shrink**attempt
        plan = _plan_steps(sp, steps, params, draws, shrink, opts)
        sig = _signals(sp, plan, tg, opts)
        f = np.maximum(_stride_frequency(sp, sig.v), f0)
        phi = params["start_phase"] + _integrate(tg, f, i0)
        psi = params["heading"] + _integrate(tg, sig.w, i0)
        xy = np.stack(
            [_integrate(tg, sig.v * np.cos(psi), i0), _integrate(tg, sig.v * np.sin(psi), i0)],
            -1,
        )
        tr, p, moving = _trunk(sp, t, tg, sig, phi, (xy, psi), neutral_style)
        u_speed = np.clip(np.interp(t, tg, sig.v) ** 2 / (GRAVITY * sp.hip_height), 0, None)
        fr_max = max(gh.froude[1] for gh in sp.gaits.values())
        swing_h = (
            sp.habits.swing_height
            * sp.leg_length
            * params["swing_scale"]
            * (0.8 + 0.4 * np.clip(u_speed / fr_max, 0.0, 1.0))
        )
        legs = _feet(sp, t, tg, sig, phi, (xy, psi), swing_h, opts)
        if sp.habits.trunk_sway > 0:
            swayed = apply_sway(sp, tr, legs, sp.habits.trunk_sway, p, options=opts)
            walkish = np.clip((np.interp(t, tg, sig.beta) - 0.45) / 0.1, 0.0, 1.0) * moving
            tr.root[:, :2] += walkish[:, None] * (swayed.root[:, :2] - tr.root[:, :2])
        sit_meta = _still_steps(sp, plan, t, fps, tr, legs, params, opts)
        f_max = float(f.max())
        tr, sol = fix_reach(sp, tr, legs, max(3, int(round(0.45 * fps / f_max))), options=opts)
        sol = respect_limits(sp, tr, legs, sol, max(3, int(round(0.1 * fps / f_max))), opts)
        err = sol.reach_error[legs.contacts]
        if err.size == 0 or err.max() <= opts.feasible_stance_error_m:
            break
    v_t = np.interp(t, tg, sig.v)
    segments = []
    for st in plan:
        sel = (t >= st.start) & (t < st.end)
        segments.append(
            {
                "action": st.action,
                "gait": st.gait,
                "start_s": st.start,
                "end_s": st.end,
                "froude": st.froude,
                "speed_mps": math.sqrt(st.froude * GRAVITY * sp.hip_height),
                "duty_factor": st.duty,
                "turn_rate": st.turn_rate,
                "mean_speed_mps": float(v_t[sel].mean()) if sel.any() else 0.0,
            }
        )
    mean_v = float(v_t.mean())
    mean_w = float(np.interp(t, tg, sig.w).mean())
    stance_err = sol.reach_error[legs.contacts]
    meta: dict[str, Any] = {
        "generator": "habitsim.gaits",
        "generator_version": GENERATOR_VERSION,
        "species": sp.name,
        "action": "chain",
        "gait": "+".join(st.gait for st in plan),
        "seed": int(seed),
        "fps": fps,
        "frames": n,
        "duration_s": n / fps,
        "attempts": attempt + 1,
        "speed_mps": mean_v,
        "velocity_mps": mean_v,
        "froude": mean_v**2 / (GRAVITY * sp.hip_height),
        "duty_factor": float(legs.contacts.mean()),
        "stride_frequency_hz": float(np.interp(t, tg, f).mean()),
        "turn_rate": mean_w,
        "turn_rate_nd": mean_w * _tau(sp),
        "start_phase": params["start_phase"],
        "heading": params["heading"],
        "chain": {"segments": segments, "transitions": sig.transitions},
        "max_reach_error_mm": float(sol.reach_error.max() * 1000.0),
        "max_stance_reach_error_mm": float(stance_err.max() * 1000.0) if stance_err.size else 0.0,
        "params": params,
    }
    meta.update(sit_meta)
    return Motion(
        species=sp.name,
        fps=fps,
        root_positions=tr.root,
        rotations=sol.rotations,
        contacts=legs.contacts.copy(),
        metadata=meta,
    )


def draw_chain(
    species: str | Species, seed: int, options: GeneratorOptions | None = None
) -> list[tuple[str, float]]:
    """A random chain the species can make: 2–4 steps (``options.chain_steps``), each
    drawn among the allowed followers of the one before, each lasting its shortest plus
    a draw in ``options.chain_segment_s`` [s]. A pure function of (species, seed).

    Raises:
        UnknownSpeciesError: unknown species.
        GaitError: a seed that is not an integer.
    """
    sp = load_species(species)
    opts = resolve_generator(options)
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer):
        raise GaitError(f"seed must be an integer, got {seed!r}")
    rng = np.random.default_rng([int(seed), 48])
    allowed = allowed_transitions(sp)
    lo, hi = opts.chain_steps
    n = int(rng.integers(lo, hi + 1))
    starts = [a for a in allowed if a not in ("stop", "sit")]
    names = [str(rng.choice(starts))]
    while len(names) < n:
        nxt = _followers(allowed, names[-1], len(names) - 1)
        if not nxt:
            break
        names.append(str(rng.choice(nxt)))
    if names[-1] == "idle" and len(names) == 1:
        names.append(str(rng.choice(allowed["idle"])))  # a chain has two steps at least
    return [
        (a, round(chain_min_duration(sp, a, opts) + float(rng.uniform(*opts.chain_segment_s)), 2))
        for a in names
    ]
