"""The public synthetic gait generator: :func:`generate`.

Every clip is a pure function of (species, action, seed, fps, duration, overrides): all
randomness comes from ``np.random.default_rng(seed)`` and is drawn as dimensionless
parameters (``metadata["params"]``). Paired generation reuses those parameters for a
second species (same Froude number, dimensionless turn rate ω·sqrt(h/g), frames, fps,
start phase and heading), so the two clips are the "same" motion under dynamic
similarity.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..errors import GaitError
from ..motion import Motion
from ..physics_constants import GRAVITY
from ..species import FEET, Species, load_species
from .actions import ACTIONS, LOCOMOTION_ACTIONS, action_gait
from .jump import build_jump, min_jump_duration
from .locomotion import build_locomotion, gait_numbers
from .options import GeneratorOptions, resolve_generator
from .stationary import build_idle, build_sit

__all__ = ["generate", "draw_params", "GENERATOR_VERSION"]

#: Bumped whenever the same inputs (with the default options) would produce a
#: different clip.
GENERATOR_VERSION = 5


def draw_params(
    rng: np.random.Generator, options: GeneratorOptions | None = None
) -> dict[str, Any]:
    """Draw every per-clip random number (dimensionless, species-independent).

    The draws happen in a fixed order whatever the action, so a seed means the same
    parameters for every species and action (``options`` sets the turn-rate range).
    """
    opts = resolve_generator(options)
    p: dict[str, Any] = {}
    p["u_froude"] = float(rng.uniform(0.08, 0.92))
    p["u_duty_noise"] = float(rng.normal(0.0, 0.12))
    p["phase_jitter"] = {f: (0.0 if f == "LH" else float(rng.uniform(-0.01, 0.01))) for f in FEET}
    p["start_phase"] = float(rng.uniform(0.0, 1.0))
    p["heading"] = float(rng.uniform(-math.pi, math.pi))
    p["u_duration"] = float(rng.uniform(0.0, 1.0))
    p["turn_rate_nd"] = float(rng.uniform(*opts.turn_rate_nd_range))
    p["neck_offset"] = float(rng.uniform(-0.1, 0.1))
    p["head_offset"] = float(rng.uniform(-0.08, 0.08))
    p["tail_offset"] = float(rng.uniform(-0.15, 0.15))
    p["swing_scale"] = float(rng.uniform(0.85, 1.15))
    p["shift_start"] = float(rng.uniform(0.1, 0.5))
    p["shift_ramp"] = float(rng.uniform(3.0, 6.0))
    p["shift_hold"] = float(rng.uniform(0.1, 0.3))
    p["shift_side"] = float(rng.choice([-1.0, 1.0]))
    p["shift_fwd"] = float(rng.uniform(-1.0, 1.0))
    p["sit_start"] = float(rng.uniform(1.0, 2.5))
    p["sit_duration"] = float(rng.uniform(3.5, 5.5))
    p["sit_hip_frac"] = float(rng.uniform(0.28, 0.36))
    p["sit_foot_incl"] = float(rng.uniform(1.0, 1.25))
    p["jump_height_nd"] = float(rng.uniform(0.15, 0.35))
    p["jump_distance_nd"] = float(rng.uniform(0.6, 1.5))
    p["crouch_nd"] = float(rng.uniform(0.08, 0.13))
    p["jump_stand_nd"] = float(rng.uniform(1.0, 2.5))
    p["jump_crouch_nd"] = float(rng.uniform(2.0, 3.0))
    p["jump_recover_nd"] = float(rng.uniform(2.0, 3.0))
    p["detail_seed"] = int(rng.integers(0, 2**31 - 1))
    return p


def _duty_from(
    gait_band: tuple[float, float], u_froude: float, noise: float
) -> tuple[float, float]:
    """Duty factor in its band, falling with speed (u_froude) plus noise; returns (β, u)."""
    u = float(np.clip(1.0 - u_froude + noise, 0.08, 0.92))
    lo, hi = gait_band
    return lo + u * (hi - lo), u


def _metadata_base(
    sp: Species, action: str, gait: str, seed: int | None, fps: float, n: int
) -> dict[str, Any]:
    return {
        "generator": "habitsim.gaits",
        "generator_version": GENERATOR_VERSION,
        "species": sp.name,
        "action": action,
        "gait": gait,
        "seed": seed,
        "fps": fps,
        "frames": n,
        "duration_s": n / fps,
    }


def _build_cyclic(
    sp,
    action,
    gait,
    band,
    params,
    t,
    fps,
    froude,
    duty_factor,
    turn_rate,
    direction,
    trunk_sway,
    options,
    duty_shrink=1.0,
):
    """Build one cyclic clip for given speed and turn rate (validated here)."""
    if not (isinstance(froude, int | float) and math.isfinite(froude) and froude > 0):
        raise GaitError(f"froude must be a positive number for {action!r}, got {froude!r}")
    u_fr = (froude - band.froude[0]) / max(band.froude[1] - band.froude[0], 1e-12)
    if duty_factor is None:
        duty, _ = _duty_from(band.duty_factor, float(np.clip(u_fr, 0, 1)), params["u_duty_noise"])
        # a shorter stance (lower duty factor) sweeps the leg through a smaller angle
        duty = band.duty_factor[0] + (duty - band.duty_factor[0]) * duty_shrink
    else:
        if not (0.0 < duty_factor < 1.0):
            raise GaitError(f"duty_factor must lie in (0, 1), got {duty_factor!r}")
        duty = float(duty_factor)
    if not math.isfinite(turn_rate):
        raise GaitError(f"turn_rate must be finite, got {turn_rate!r}")
    if action == "turn_left" and turn_rate <= 0 or action == "turn_right" and turn_rate >= 0:
        raise GaitError(
            f"{action} needs a turn rate of the matching sign (left positive), got {turn_rate}"
        )
    phases = {f: (band.footfall[f] + params["phase_jitter"][f]) % 1.0 for f in FEET}
    if direction < 0:  # the walk run in reverse: the footfall sequence reverses
        phases = {f: (-v) % 1.0 for f, v in phases.items()}
    g = gait_numbers(
        sp,
        gait,
        float(froude),
        duty,
        phases,
        float(turn_rate),
        params["start_phase"],
        params["heading"],
        direction,
    )
    gain = sp.habits.trunk_sway if trunk_sway is None else float(trunk_sway)
    style = {k: params[k] for k in ("neck_offset", "head_offset", "tail_offset", "swing_scale")}
    tr, sol, plan = build_locomotion(sp, gait, g, t, fps, style, gain, options)
    return g, tr, sol, plan


def generate(
    species: str | Species,
    action: str | None = None,
    *,
    seed: int | None = None,
    fps: float = 30.0,
    duration_s: float | None = None,
    froude: float | None = None,
    turn_rate: float | None = None,
    like: Motion | None = None,
    duty_factor: float | None = None,
    trunk_sway: float | None = None,
    options: GeneratorOptions | None = None,
) -> Motion:
    """Generate one synthetic clip of a species performing an action.

    Args:
        species: catalog species name or :class:`~habitsim.species.Species`.
        action: one of :data:`ACTIONS` (may be omitted with ``like``: taken from it).
        seed: integer seed of ``np.random.default_rng`` (required unless ``like``).
        fps: frame rate [Hz].
        duration_s: clip length [s]; default drawn in ``options.duration_range_s`` (longer
            when a jump or a sit needs it).
        froude: Froude number v²/(g·h) for cyclic actions (jump: of the take-off
            horizontal speed); default drawn within the gait's band.
        turn_rate: yaw rate [rad/s] (left positive) for cyclic actions; default drawn
            (turns) or 0.
        like: a clip made by this generator (any species): produce the same action at
            the same Froude number, dimensionless turn rate ω·sqrt(h/g), number of
            frames, fps, start phase and heading, for ``species``.
        duty_factor: override the duty factor of a cyclic action (default: drawn within
            the band, falling with speed).
        trunk_sway: override the species' lateral trunk sway gain (0 disables it).
        options: the generator's knobs (:class:`~habitsim.gaits.options.GeneratorOptions`);
            default: today's values, the clips of ``GENERATOR_VERSION``.

    Returns:
        The :class:`~habitsim.motion.Motion`, with contacts = the planned stance and
        metadata: action, gait, speed_mps, froude, duty_factor, stride_frequency_hz,
        stride_length_m, turn_rate (rad/s), turn_rate_nd, seed, duration_s, fps, frames,
        species, footfall (phases used), start_phase, heading, params (all random draws),
        max_reach_error_mm, generator_version.

    Raises:
        UnknownSpeciesError: unknown species.
        GaitError: unknown or unavailable action (the message lists the species'
            available actions), missing seed, bad parameters, or a ``like`` clip that
            was not made by this generator.
    """
    sp = load_species(species)
    opts = resolve_generator(options)
    params: dict[str, Any]
    if like is not None:
        meta = like.metadata or {}
        if meta.get("generator") != "habitsim.gaits" or "params" not in meta:
            raise GaitError(
                "the 'like' motion was not made by habitsim.gaits (no generator metadata)"
            )
        if action is None:
            action = str(meta["action"])
        elif action != meta["action"]:
            raise GaitError(
                f"action {action!r} differs from the 'like' clip's action {meta['action']!r}"
            )
        params = dict(meta["params"])
        seed = meta.get("seed")
        fps = float(like.fps)
        n_frames = like.num_frames
        if froude is None and action in LOCOMOTION_ACTIONS:
            froude = float(meta["froude"])
        if turn_rate is None and "turn_rate_nd" in meta:
            turn_rate = float(meta["turn_rate_nd"]) * math.sqrt(GRAVITY / sp.hip_height)
    else:
        if action is None:
            raise GaitError(f"an action is needed; valid: {', '.join(ACTIONS)}")
        if seed is None or isinstance(seed, bool) or not isinstance(seed, int | np.integer):
            raise GaitError(f"seed must be an integer, got {seed!r}")
        params = draw_params(np.random.default_rng(int(seed)), opts)
        n_frames = None
    gait = action_gait(sp, action)  # raises GaitError listing the available actions
    if not (isinstance(fps, int | float) and math.isfinite(fps) and fps > 0):
        raise GaitError(f"fps must be positive, got {fps!r}")
    fps = float(fps)
    if duration_s is not None and like is None:
        if not (math.isfinite(duration_s) and duration_s > 0):
            raise GaitError(f"duration_s must be positive, got {duration_s!r}")
        n_frames = max(2, int(round(duration_s * fps)))
    if n_frames is None:
        lo, hi = opts.duration_range_s
        if action == "jump":
            lo = max(lo, 1.1 * min_jump_duration(sp, params))
        elif action == "sit":
            tau = math.sqrt(sp.hip_height / GRAVITY)
            lo = max(lo, 1.2 * (params["sit_start"] + params["sit_duration"]) * tau)
        hi = max(hi, lo)
        n_frames = max(2, int(round((lo + params["u_duration"] * (hi - lo)) * fps)))
    t = np.arange(n_frames) / fps
    meta_out = _metadata_base(sp, action, gait, None if seed is None else int(seed), fps, n_frames)
    detail_rng = np.random.default_rng(params["detail_seed"])

    if action in LOCOMOTION_ACTIONS:
        band = sp.gaits[gait]
        direction = -1.0 if action == "walk_backward" else 1.0
        froude_drawn, turn_drawn = froude is None, turn_rate is None
        for attempt in range(opts.max_attempts):
            # A drawn speed or turn rate that the legs cannot reach without leaving a
            # planted foot (the clip would skate) is drawn again closer to the slow end
            # of its range; explicit or paired values are kept and the error reported.
            shrink = opts.retry_shrink**attempt
            if froude_drawn:
                u = params["u_froude"] * shrink
                if action == "walk_backward":
                    u *= 0.5  # backward walking is slow: lower half of the band
                froude = band.froude[0] + u * (band.froude[1] - band.froude[0])
            if turn_drawn:
                lo_nd = opts.turn_rate_nd_range[0]
                w_nd = lo_nd + (params["turn_rate_nd"] - lo_nd) * shrink
                w_nd = w_nd if action == "turn_left" else (-w_nd if action == "turn_right" else 0.0)
                turn_rate = w_nd * math.sqrt(GRAVITY / sp.hip_height)
            built = _build_cyclic(
                sp,
                action,
                gait,
                band,
                params,
                t,
                fps,
                froude,
                duty_factor,
                turn_rate,
                direction,
                trunk_sway,
                opts,
                shrink,
            )
            g, tr, sol, plan = built
            err = sol.reach_error[plan.contacts]
            if (
                not (froude_drawn or turn_drawn)
                or err.size == 0
                or err.max() <= opts.feasible_stance_error_m
            ):
                break
        meta_out["attempts"] = attempt + 1
        meta_out.update(
            speed_mps=abs(g.speed_mps),
            velocity_mps=g.speed_mps,
            froude=g.froude,
            duty_factor=g.duty_factor,
            stride_frequency_hz=g.stride_frequency_hz,
            stride_length_m=g.stride_length_m,
            turn_rate=g.turn_rate,
            turn_rate_nd=g.turn_rate * math.sqrt(sp.hip_height / GRAVITY),
            footfall=g.phases,
            start_phase=g.start_phase,
            heading=g.heading,
            trunk_sway=sp.habits.trunk_sway if trunk_sway is None else float(trunk_sway),
        )
    else:
        heading = params["heading"]
        meta_out.update(
            speed_mps=0.0,
            velocity_mps=0.0,
            froude=0.0,
            duty_factor=1.0,
            stride_frequency_hz=0.0,
            stride_length_m=0.0,
            turn_rate=0.0,
            turn_rate_nd=0.0,
            start_phase=params["start_phase"],
            heading=heading,
        )
        if action == "idle":
            tr, sol, plan = build_idle(sp, t, fps, params, detail_rng, opts)
        elif action == "sit":
            tr, sol, plan, extra = build_sit(sp, t, fps, params, detail_rng, opts)
            meta_out.update(extra)
        else:
            tr, sol, plan, extra = build_jump(sp, t, fps, params, opts)
            vx = extra["takeoff_speed_mps"][0]
            meta_out.update(
                extra,
                speed_mps=vx,
                velocity_mps=vx,
                froude=vx * vx / (GRAVITY * sp.hip_height),
                duty_factor=float(plan.contacts.mean()),
            )
    stance_err = sol.reach_error[plan.contacts]
    meta_out["max_reach_error_mm"] = float(sol.reach_error.max() * 1000.0)
    meta_out["max_stance_reach_error_mm"] = (
        float(stance_err.max() * 1000.0) if stance_err.size else 0.0
    )
    meta_out["params"] = params
    return Motion(
        species=sp.name,
        fps=fps,
        root_positions=tr.root,
        rotations=sol.rotations,
        contacts=plan.contacts.copy(),
        metadata=meta_out,
    )
