"""A forward jump: stand, crouch, push-off, ballistic flight, landing, recovery.

Internal module used by :func:`habitsim.gaits.generate`. Phases (heading frame, root =
pelvis):

* stand, then crouch: the root lowers by ``crouch_depth`` (minimum-jerk);
* push-off (feet planted): constant upward acceleration a = v_z²/(2·c) from rest over the
  crouch depth c, reaching the take-off height with vertical speed v_z = sqrt(2·g·H)
  (H the jump height); the horizontal speed rises linearly to v_x;
* flight (every contact false): z(t) = z_to + v_z·t − g·t²/2, x(t) = x_to + v_x·t with
  g = :data:`~habitsim.physics_constants.GRAVITY`, lasting 2·v_z/g; the feet follow the
  body, tucked;
* landing (feet planted at new footholds): the mirror image of the push-off;
* recovery: back to the take-off height (minimum-jerk), then stand.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import GaitError
from ..physics_constants import GRAVITY
from ..species import Species
from ._pose import (
    LegPlan,
    Solved,
    Trunk,
    min_jerk,
    required_lowering,
    solve,
    standing_info,
)
from .options import GeneratorOptions


def jump_timing(sp: Species, p: dict) -> dict[str, float]:
    """Phase boundaries [s] and kinematic numbers of a jump from its dimensionless parameters."""
    h = sp.hip_height
    tau = math.sqrt(h / GRAVITY)
    height = p["jump_height_nd"] * h
    dist = p["jump_distance_nd"] * h
    crouch = p["crouch_nd"] * h
    vz = math.sqrt(2 * GRAVITY * height)
    t_flight = 2 * vz / GRAVITY
    vx = dist / t_flight
    t_push = 2 * crouch / vz
    t_stand = p["jump_stand_nd"] * tau
    t_crouch = p["jump_crouch_nd"] * tau
    t_rec = p["jump_recover_nd"] * tau
    out = {
        "jump_height_m": height,
        "jump_distance_m": dist,
        "crouch_m": crouch,
        "vz": vz,
        "vx": vx,
        "t_flight": t_flight,
        "t_push": t_push,
    }
    out["t0"] = t_stand
    out["t1"] = out["t0"] + t_crouch
    out["t_takeoff"] = out["t1"] + t_push
    out["t_land"] = out["t_takeoff"] + t_flight
    out["t3"] = out["t_land"] + t_push
    out["t_end"] = out["t3"] + t_rec
    return out


def min_jump_duration(sp: Species, p: dict) -> float:
    """Shortest clip [s] that holds the whole jump including recovery."""
    return jump_timing(sp, p)["t_end"] + 0.1


def _trajectory(tm: dict, t: np.ndarray, z_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Root x, z (heading frame) and pitch offset at times t."""
    c, vz, vx, tp = tm["crouch_m"], tm["vz"], tm["vx"], tm["t_push"]
    az, ax = vz / tp, vx / tp
    g = GRAVITY
    t0, t1, tto, tl = tm["t0"], tm["t1"], tm["t_takeoff"], tm["t_land"]
    t3, te = tm["t3"], tm["t_end"]
    z_c = z_s - c
    x = np.zeros_like(t)
    z = np.full_like(t, z_s)
    # crouch
    m = (t >= t0) & (t < t1)
    z[m] = z_s - c * min_jerk((t[m] - t0) / (t1 - t0))
    # push-off
    m = (t >= t1) & (t < tto)
    s = t[m] - t1
    z[m] = z_c + 0.5 * az * s**2
    x[m] = 0.5 * ax * s**2
    x_to = 0.5 * vx * tp
    # flight
    m = (t >= tto) & (t < tl)
    s = t[m] - tto
    z[m] = z_s + vz * s - 0.5 * g * s**2
    x[m] = x_to + vx * s
    x_l = x_to + vx * tm["t_flight"]
    # landing
    m = (t >= tl) & (t < t3)
    s = t[m] - tl
    z[m] = z_s - vz * s + 0.5 * az * s**2
    x[m] = x_l + vx * s - 0.5 * ax * s**2
    x_end = x_l + 0.5 * vx * tp
    # recovery and rest
    m = t >= t3
    z[m] = z_c + c * min_jerk((t[m] - t3) / (te - t3))
    x[m] = x_end
    # pitch: nose up through push-off, level in flight, nose down on landing
    pitch = 0.08 * (min_jerk((t - t1) / (tto - t1)) - min_jerk((t - tto) / (tl - tto))) - 0.05 * (
        min_jerk((t - tl) / max(t3 - tl, 1e-6)) - min_jerk((t - t3) / (te - t3))
    )
    return x, z, pitch


def build_jump(
    sp: Species, t: np.ndarray, fps: float, p: dict, options: GeneratorOptions
) -> tuple[Trunk, Solved, LegPlan, dict]:
    """Build a jump clip (see the module docstring)."""
    n = t.shape[0]
    tm = jump_timing(sp, p)
    if t[-1] < tm["t3"]:
        raise GaitError(
            f"a {sp.name} jump needs at least {tm['t3'] + 1.0 / fps:.2f} s to land; "
            f"the clip has {n} frames at {fps:g} fps"
        )
    info = standing_info(sp)
    neutral = np.asarray(info["neutral"])
    heading = p["heading"]
    c, s = math.cos(heading), math.sin(heading)

    def world(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return c * x - s * y, s * x + c * y

    lower = 0.0
    span = tm["vx"] * (tm["t_push"] + tm["t_flight"])  # footholds move this far
    tto, tl = tm["t_takeoff"], tm["t_land"]
    flight = (t > tto) & (t < tl)
    sig = np.clip((t - tto) / (tl - tto), 0.0, 1.0)
    tuck = 0.2 * sp.leg_length * np.sin(np.pi * sig) * flight
    for _ in range(6):
        z_s = info["root_z"] - lower
        x, z, pitch = _trajectory(tm, t, z_s)
        tr = Trunk.standing(sp, n)
        rx, ry = world(x, np.zeros_like(x))
        tr.root[:, 0], tr.root[:, 1], tr.root[:, 2] = rx, ry, z
        tr.yaw[:] = heading
        tr.pitch += pitch
        tr.spine_pitch += (0.5 * sp.habits.spine_flex / 3.0 * np.sin(np.pi * sig) * flight)[:, None]
        tr.neck_pitch += p["neck_offset"] - 0.5 * pitch
        tr.head_pitch += p["head_offset"]
        tr.tail_pitch[:, 0] += p["tail_offset"] + 0.3 * np.sin(np.pi * sig) * flight
        # feet (heading frame)
        fx = np.zeros((n, 4))
        fy = np.broadcast_to(neutral[:, 1], (n, 4)).copy()
        fz = np.zeros((n, 4))
        after = t >= tl
        fx[:] = neutral[:, 0]
        fx[after] += span
        x_to = 0.5 * tm["vx"] * tm["t_push"]
        x_l = x_to + tm["vx"] * tm["t_flight"]
        r0 = neutral[:, 0] - x_to  # foot relative to the root at take-off (x)
        r1 = neutral[:, 0] + span - x_l
        ms = min_jerk(sig)[:, None]
        fx[flight] = (x[:, None] + r0 + (r1 - r0) * ms)[flight]
        fz[flight] = (z[:, None] - z_s + tuck[:, None])[flight]
        wx, wy = world(fx, fy)
        targets = np.stack([wx, wy, fz], -1)
        contacts = np.broadcast_to(~flight[:, None], (n, 4)).copy()
        swing = np.broadcast_to((sig * flight)[:, None], (n, 4)).copy()
        plan = LegPlan(targets=targets, contacts=contacts, swing_s=swing)
        plan.sweep_gain = 0.5
        sol = solve(sp, tr, plan, options)
        low = required_lowering(sp, sol.legs, options)
        need = float(low[~flight].max()) if (~flight).any() else 0.0
        if need < 1e-7:
            break
        lower += 1.05 * need + 1e-6
    extra = {
        "jump_height_m": tm["jump_height_m"],
        "jump_distance_m": tm["jump_distance_m"],
        "takeoff_time_s": tto,
        "landing_time_s": tl,
        "flight_time_s": tm["t_flight"],
        "takeoff_speed_mps": [tm["vx"], tm["vz"]],
        "takeoff_lowering_m": lower,
    }
    return tr, sol, plan, extra


__all__ = ["build_jump", "jump_timing", "min_jump_duration"]
