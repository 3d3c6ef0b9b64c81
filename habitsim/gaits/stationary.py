"""Actions without steps: ``idle`` (standing) and ``sit``.

Internal module used by :func:`habitsim.gaits.generate`. All four feet stay planted at
their standing footholds; the trunk moves above them and the legs follow by IK.

Times of these actions scale with sqrt(h/g) (dynamic similarity), so a giraffe sits
down more slowly than a cat.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import GaitError
from ..ik import LEGS, axial_frames, leg_geometry
from ..physics_constants import GRAVITY
from ..species import Species
from ._pose import LegPlan, Solved, Trunk, fix_reach, min_jerk, smooth_noise, standing_info
from .options import GeneratorOptions


def _planted_plan(sp: Species, t: int, heading: float) -> LegPlan:
    neutral = np.asarray(standing_info(sp)["neutral"])
    c, s = math.cos(heading), math.sin(heading)
    holds = np.stack(
        [c * neutral[:, 0] - s * neutral[:, 1], s * neutral[:, 0] + c * neutral[:, 1]], -1
    )
    targets = np.zeros((t, 4, 3))
    targets[:, :, :2] = holds[None]
    return LegPlan(targets=targets, contacts=np.ones((t, 4), dtype=bool), swing_s=np.zeros((t, 4)))


def breathing_rate_hz(sp: Species) -> float:
    """Resting breathing rate [Hz] from body mass (Stahl 1967: 53.5·M^-0.26 per minute)."""
    return 53.5 * sp.mass_kg**-0.26 / 60.0


def _idle_motion(
    sp: Species, tr: Trunk, t: np.ndarray, rng: np.random.Generator, amount: float
) -> None:
    """Breathing, head and tail motion in place (modifies ``tr``)."""
    h = sp.hip_height
    fb = breathing_rate_hz(sp)
    ph = rng.uniform(0, 2 * math.pi)
    tr.root[:, 2] -= 0.004 * h * 0.5 * (1 - np.cos(2 * math.pi * fb * t + ph))
    tr.pitch += 0.004 * np.sin(2 * math.pi * fb * t + ph)
    look = 0.15 * math.sqrt(GRAVITY / h) / (2 * math.pi)  # slow head movements [Hz]
    tr.neck_yaw += amount * 0.3 * smooth_noise(rng, t, look)
    tr.neck_pitch += amount * 0.1 * smooth_noise(rng, t, look)
    tr.head_yaw += amount * 0.1 * smooth_noise(rng, t, look)
    tr.head_pitch += amount * 0.08 * smooth_noise(rng, t, look)
    tr.tail_yaw[:, 0] += amount * 0.5 * sp.habits.tail_sway * smooth_noise(rng, t, 2 * look)
    tr.tail_yaw[:, 1] += amount * 0.4 * sp.habits.tail_sway * smooth_noise(rng, t, 2 * look)


def build_idle(
    sp: Species,
    t: np.ndarray,
    fps: float,
    p: dict,
    rng: np.random.Generator,
    options: GeneratorOptions,
) -> tuple[Trunk, Solved, LegPlan]:
    """Standing with breathing, head and tail motion and one slow weight shift."""
    n = t.shape[0]
    heading = p["heading"]
    plan = _planted_plan(sp, n, heading)
    tr = Trunk.standing(sp, n)
    tr.yaw[:] = heading
    tr.neck_pitch += p["neck_offset"]
    tr.head_pitch += p["head_offset"]
    tr.tail_pitch[:, 0] += p["tail_offset"]
    _idle_motion(sp, tr, t, rng, 1.0)
    # One weight shift: sideways (and a little fore-aft), rise, hold, return.
    dur = t[-1] if n > 1 else 0.0
    t0 = p["shift_start"] * dur
    ramp = max(p["shift_ramp"] * math.sqrt(sp.hip_height / GRAVITY), 1.0 / fps)
    hold = p["shift_hold"] * dur
    bump = min_jerk((t - t0) / ramp) - min_jerk((t - t0 - ramp - hold) / ramp)
    width = 0.5 * (sp.segments["trunk_width_fore"] + sp.segments["trunk_width_hind"])
    lat = p["shift_side"] * 0.25 * width * bump
    fwd = p["shift_fwd"] * 0.03 * sp.hip_height * bump
    c, s = math.cos(heading), math.sin(heading)
    tr.root[:, 0] += c * fwd - s * lat
    tr.root[:, 1] += s * fwd + c * lat
    tr.root[:, :2] += 0.0
    tr2, sol = fix_reach(sp, tr, plan, max(3, int(round(0.3 * fps))), options=options)
    return tr2, sol, plan


def _sit_pose(
    sp: Species, heading: float, hip_frac: float, hind_foot_incl: float
) -> dict[str, float]:
    """Final sitting trunk (in the heading frame, root xy relative to standing).

    The fore legs straighten (shoulder 96 % of the fore reach above the planted fore
    wrist, leaning 0.1 rad back); the trunk pitches up about that shoulder until the hip
    joint is down at ``hip_frac`` × hip height.
    """
    info = standing_info(sp)
    neutral = np.asarray(info["neutral"])
    gf = leg_geometry(sp, "LF")
    # planted fore wrist (standing foot inclination), heading frame x-z
    wrist_x = neutral[0, 0] - gf.foot * math.sin(gf.foot_inclination0)
    wrist_z = gf.foot * math.cos(gf.foot_inclination0)
    rho = 0.96 * gf.max_reach
    gam = 0.1
    sh = np.array([wrist_x - rho * math.sin(gam), wrist_z + rho * math.cos(gam)])
    # scan trunk pitches
    d_th = np.linspace(0.0, 1.1, 111)
    m = d_th.shape[0]
    tr = Trunk.standing(sp, m)
    tr.root[:] = 0.0
    tr.pitch += d_th
    fr = axial_frames(sp, tr.root, tr.rotations())
    rg = np.array(
        [
            [math.cos(gf.girdle_flex0), 0, math.sin(gf.girdle_flex0)],
            [0, 1, 0],
            [-math.sin(gf.girdle_flex0), 0, math.cos(gf.girdle_flex0)],
        ]
    )
    shoulder = fr.girdle_root[:, 0] + np.einsum(
        "tij,j->ti", fr.parent_rotation[:, 0] @ rg, [0, 0, -gf.girdle]
    )
    gh = leg_geometry(sp, "LH")
    rh = np.array(
        [
            [math.cos(gh.girdle_flex0), 0, math.sin(gh.girdle_flex0)],
            [0, 1, 0],
            [-math.sin(gh.girdle_flex0), 0, math.cos(gh.girdle_flex0)],
        ]
    )
    hip = fr.girdle_root[:, 2] + np.einsum(
        "tij,j->ti", fr.parent_rotation[:, 2] @ rh, [0, 0, -gh.girdle]
    )
    root_x = sh[0] - shoulder[:, 0]
    root_z = sh[1] - shoulder[:, 2]
    hip_z = root_z + hip[:, 2]
    hip_x = root_x + hip[:, 0]
    target = hip_frac * sp.hip_height
    # Hind hock target from the planted toe and the sitting foot inclination; when the
    # drawn inclination admits no reachable posture (long-legged species), it is
    # relaxed step by step toward the standing inclination.
    for incl in np.linspace(hind_foot_incl, gh.foot_inclination0, 9):
        hock_x = neutral[2, 0] - gh.foot * math.sin(incl)
        hock_z = gh.foot * math.cos(incl)
        dist = np.hypot(hip_x - hock_x, hip_z - hock_z)
        ok = (dist < 0.97 * gh.max_reach) & (dist > gh.min_reach + 0.05 * gh.max_reach)
        below = ok & (hip_z <= target)
        if below.any():
            i = int(np.argmax(below))
        elif ok.any():
            i = int(np.flatnonzero(ok)[np.argmin(hip_z[ok])])
        else:
            continue
        return {
            "d_pitch": float(d_th[i]),
            "root_x": float(root_x[i]),
            "root_z": float(root_z[i]),
            "foot_incl": float(incl),
        }
    raise GaitError(f"species {sp.name!r}: no reachable sitting posture")


def build_sit(
    sp: Species,
    t: np.ndarray,
    fps: float,
    p: dict,
    rng: np.random.Generator,
    options: GeneratorOptions,
) -> tuple[Trunk, Solved, LegPlan, dict]:
    """Stand, lower the hind quarters (hind feet planted, fore legs straighten), hold."""
    n = t.shape[0]
    h = sp.hip_height
    tau = math.sqrt(h / GRAVITY)
    heading = p["heading"]
    plan = _planted_plan(sp, n, heading)
    info = standing_info(sp)
    gh = leg_geometry(sp, "LH")
    foot1 = p["sit_foot_incl"]
    fin = _sit_pose(sp, heading, p["sit_hip_frac"], foot1)
    foot1 = fin["foot_incl"]
    t0 = p["sit_start"] * tau
    dur = p["sit_duration"] * tau
    s = min_jerk((t - t0) / dur)
    tr = Trunk.standing(sp, n)
    tr.yaw[:] = heading
    c, si = math.cos(heading), math.sin(heading)
    tr.root[:, 0] += s * fin["root_x"] * c
    tr.root[:, 1] += s * fin["root_x"] * si
    tr.root[:, 2] += s * (fin["root_z"] - info["root_z"])
    dp = s * fin["d_pitch"]
    tr.pitch += dp
    tr.neck_pitch += 0.8 * dp + p["neck_offset"]
    tr.head_pitch += p["head_offset"]
    # Tail: keep its standing elevation unless the tip would touch the ground.
    loc = info["loc"]
    stand_elev = loc["tail_pitch"] - info["pitch"]  # global elevation of the tail when standing
    tail_len = sp.segments["tail"]
    z_base = info["root_z"] + s * (fin["root_z"] - info["root_z"])
    min_elev = -np.arcsin(np.clip(0.85 * z_base / tail_len, 0.0, 1.0))
    elev = np.maximum(stand_elev + p["tail_offset"], min_elev)
    tr.tail_pitch[:, 0] = elev + tr.pitch
    hold = np.clip((t - t0 - dur) / tau, 0.0, 1.0)
    _idle_motion(sp, tr, t, rng, 0.5 * hold)
    plan.foot_extra[:, 2:] = (s * (foot1 - gh.foot_inclination0))[:, None]
    plan.sweep_gain = 0.0
    tr2, sol = fix_reach(sp, tr, plan, max(3, int(round(0.2 * fps))), options=options)
    extra = {"sit_start_s": t0, "sit_duration_s": dur, "sit_pitch_rad": fin["d_pitch"]}
    return tr2, sol, plan, extra


__all__ = ["build_idle", "build_sit", "breathing_rate_hz"]
_ = LEGS
