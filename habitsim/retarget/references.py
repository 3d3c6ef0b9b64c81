"""Robot references made from nothing: :func:`trot` and :func:`stand`."""

from __future__ import annotations

import math
from collections.abc import Sequence

import mujoco
import numpy as np

from ..physics_constants import GRAVITY
from .clip import RobotClip
from .errors import RetargetError
from .ik import _fit_figures, _solve_frames
from .legs import _need_feet, _stand_figures, robot_legs
from .options import RetargetOptions
from .robot import RobotLegs

__all__ = ["trot", "stand"]


def trot(
    robot: mujoco.MjModel | RobotLegs,
    feet: Sequence[str] | None = None,
    *,
    speed: float = 0.0,
    duration_s: float = 10.0,
    fps: float = 100.0,
    period_s: float | None = None,
    duty: float = 0.6,
    step_height: float | None = None,
    stand_s: float = 0.5,
    ramp_s: float = 1.0,
    options: RetargetOptions | None = None,
) -> RobotClip:
    """A trot reference for a robot: stand, then trot at ``speed`` (0: in place).

    The trunk stays at its standing height and orientation and moves forward (its x
    axis at home) at ``speed``, reached by a smooth ramp over ``ramp_s`` after standing
    ``stand_s``. The diagonal pairs (feet 0 and 3, then 1 and 2: LF+RH, RF+LH) swing in
    turn; each swing runs from where the foot stands to the foothold under its hip at the
    trunk's mid-stance position (symmetric stance, as Raibert's rule), on a smooth arc of
    ``step_height``. Joint angles by :func:`leg_ik`.

    Args:
        robot: the robot (then ``feet`` in the order LF, RF, LH, RH) or its legs.
        speed: forward speed [m/s]; duration_s: length of the clip [s]; fps [Hz].
        period_s: stride period [s] (default ``2.4·sqrt(L/g)``, 0.4 s on a Go1).
        duty: stance share of a stride (> 0.5 keeps a double support at each switch).
        step_height: swing clearance [m] (default 0.25·L).
        options: the knobs of the legs and the leg IK (default
            :class:`~habitsim.retarget.options.RetargetOptions`).

    Raises:
        RetargetError: not four feet, non-positive durations or rates, duty outside
            (0.5, 1).
    """
    rl = (
        robot
        if isinstance(robot, RobotLegs)
        else robot_legs(robot, _need_feet(feet, robot, options=options), options=options)
    )
    if len(rl.feet) != 4:
        raise RetargetError(
            f"a trot needs 4 feet in the order LF, RF, LH, RH; got {', '.join(rl.feet)}"
        )
    g = float(np.linalg.norm(rl.model.opt.gravity)) or GRAVITY
    period = 2.4 * math.sqrt(rl.leg_length / g) if period_s is None else float(period_s)
    height = 0.25 * rl.leg_length if step_height is None else float(step_height)
    for name, v in (("duration_s", duration_s), ("fps", fps), ("period_s", period)):
        if not (math.isfinite(v) and v > 0):
            raise RetargetError(f"{name} must be > 0, got {v}")
    if not 0.5 < duty < 1.0:
        raise RetargetError(f"duty must be in (0.5, 1), got {duty}")
    if not (math.isfinite(speed) and math.isfinite(height) and height >= 0):
        raise RetargetError("speed and step_height must be finite (step_height >= 0)")
    n = int(round(duration_s * fps)) + 1
    t = np.arange(n) / fps

    def trunk_x(time: np.ndarray) -> np.ndarray:
        # speed · ∫ ramp, ramp a smoothstep from 0 to 1 over [stand_s, stand_s + ramp_s]
        u = np.clip((np.asarray(time) - stand_s) / max(ramp_s, 1e-9), 0.0, 1.0)
        ramp_int = ramp_s * (u**3 - 0.5 * u**4)  # ∫ (3u² − 2u³) dt
        after = np.maximum(np.asarray(time) - stand_s - ramp_s, 0.0)
        return speed * (ramp_int + after)

    a = rl.trunk_qadr
    x0 = rl.home[a : a + 3].copy()
    x0[2] = rl.height
    quat0 = rl.home[a + 3 : a + 7] / np.linalg.norm(rl.home[a + 3 : a + 7])
    rot9 = np.zeros(9)
    mujoco.mju_quat2Mat(rot9, quat0)
    rot0 = rot9.reshape(3, 3)
    fwd = rot0[:, 0] * np.array([1.0, 1.0, 0.0])
    fwd /= max(float(np.linalg.norm(fwd)), 1e-9)
    trunk = x0[None, :] + trunk_x(t)[:, None] * fwd[None, :]
    quat = np.tile(quat0, (n, 1))
    stand = (x0[:, None] + rot0 @ rl.nominal.T).T  # (4, 3) foot centres when standing
    stand[:, 2] = rl.radius
    swing_len = (1.0 - duty) * period
    offsets = (0.0, 0.5, 0.5, 0.0)  # LF+RH, then RF+LH
    contacts = np.ones((n, 4), bool)
    target = np.tile(stand, (n, 1, 1))
    for i in range(4):
        start = stand_s + offsets[i] * period
        lift = start
        pos = stand[i].copy()
        while lift < t[-1]:
            land = lift + swing_len
            mid_stance = land + 0.5 * duty * period
            hold = stand[i] + (trunk_x(np.array([mid_stance]))[0]) * fwd
            sel = (t >= lift) & (t < land)
            ph = (t[sel] - lift) / swing_len
            s = ph * ph * (3.0 - 2.0 * ph)
            target[sel, i] = pos + s[:, None] * (hold - pos)
            target[sel, i, 2] = rl.radius[i] + height * 16.0 * ph**2 * (1.0 - ph) ** 2
            contacts[sel, i] = False
            after = t >= land
            target[after, i] = hold
            pos = hold
            lift = land + duty * period
    qpos, res = _solve_frames(rl, trunk, quat, target, options)
    return RobotClip(
        qpos=qpos,
        fps=float(fps),
        contacts=contacts,
        feet=rl.feet,
        metadata=_fit_figures(
            rl,
            qpos,
            res,
            {
                "source": "habitsim.retarget.trot",
                "speed_m_s": float(speed),
                "period_s": period,
                "duty": float(duty),
                "step_height_m": height,
                "frames": n,
                "robot_stand": _stand_figures(rl),
            },
        ),
    )


def stand(
    robot: mujoco.MjModel | RobotLegs,
    feet: Sequence[str] | None = None,
    *,
    duration_s: float = 10.0,
    fps: float = 100.0,
    options: RetargetOptions | None = None,
) -> RobotClip:
    """A standing reference: the ``home`` pose with the feet on the ground, held.

    Raises:
        RetargetError: see :func:`robot_legs`; non-positive duration or rate.
    """
    rl = (
        robot
        if isinstance(robot, RobotLegs)
        else robot_legs(robot, _need_feet(feet, robot, options=options), options=options)
    )
    for name, v in (("duration_s", duration_s), ("fps", fps)):
        if not (math.isfinite(v) and v > 0):
            raise RetargetError(f"{name} must be > 0, got {v}")
    n = int(round(duration_s * fps)) + 1
    q = rl.home.copy()
    q[rl.trunk_qadr + 2] = rl.height
    qpos = np.tile(q, (n, 1))
    return RobotClip(
        qpos=qpos,
        fps=float(fps),
        contacts=np.ones((n, len(rl.feet)), bool),
        feet=rl.feet,
        metadata={"source": "habitsim.retarget.stand", "frames": n},
    )
