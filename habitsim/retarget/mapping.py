"""Animal motion mapped onto a robot: :func:`retarget` (see :mod:`habitsim.retarget`)."""

from __future__ import annotations

import math
from collections.abc import Sequence

import mujoco
import numpy as np

from ..mjutils import foot_soles, free_body
from ..motion import Motion
from ..stance.labels import runs
from ..stance.planting import carriage_drop
from .clip import RobotClip
from .errors import RetargetError
from .ik import _fit_figures, _solve_frames
from .legs import _at_home, _extensions, _need_feet, _stand_figures, robot_legs
from .options import RetargetOptions
from .robot import RobotLegs

__all__ = ["retarget"]


def _source_paths(motion: Motion) -> dict[str, np.ndarray]:
    """Per frame, the trunk position (T, 3) and rotation (T, 3, 3) and the feet's lowest
    points (T, 4, 3) of a motion played on its species' model."""
    from ..qpos import motion_to_qpos, species_model
    from ..sim import foot_geoms

    model = species_model(motion.species)
    q = motion_to_qpos(motion, model).qpos
    feet = foot_geoms(model)
    trunk = free_body(model)
    d = mujoco.MjData(model)
    t = len(q)
    pos, rot = np.empty((t, 3)), np.empty((t, 3, 3))
    for k in range(t):
        d.qpos[:] = q[k]
        mujoco.mj_kinematics(model, d)
        pos[k] = d.xpos[trunk]
        rot[k] = d.xmat[trunk].reshape(3, 3)
    return {"pos": pos, "rot": rot, "sole": foot_soles(model, q, feet)}


def retarget(
    motion: Motion,
    robot: mujoco.MjModel | RobotLegs,
    feet: Sequence[str] | None = None,
    home: str = "home",
    options: RetargetOptions | None = None,
) -> RobotClip:
    """Map a habitsim motion onto a legged robot (see :mod:`habitsim.retarget`).

    Args:
        motion: the motion (four feet, LF, RF, LH, RH).
        robot: the robot model (or its :class:`RobotLegs`).
        feet: the robot's four foot names in the order LF, RF, LH, RH (e.g.
            ``["FL", "FR", "RL", "RR"]``); not needed with a :class:`RobotLegs`; ``None``:
            found by :func:`find_robot_feet` (``metadata["feet_found"]`` says so).
        home: the keyframe the robot stands on (:func:`robot_legs`).
        options: the knobs (default :class:`~habitsim.retarget.options.RetargetOptions`;
            a given :class:`RobotLegs` keeps the bounds it was built with).

    Returns:
        The :class:`RobotClip` at the motion's frame rate; ``metadata`` holds the scale,
        the IK residual (max and mean [m]) and the share of joint values at a range limit.

    Raises:
        RetargetError: see :func:`robot_legs`; not four feet.
    """
    from ..controllers.plan import matrix_from_rpy, rpy_from_matrix

    opts = options or RetargetOptions()

    if isinstance(robot, RobotLegs):
        rl = robot
    else:
        rl = robot_legs(robot, _need_feet(feet, robot, home, opts), home, opts)
    if len(rl.feet) != 4:
        raise RetargetError(
            f"a habitsim motion has 4 feet (LF, RF, LH, RH); got "
            f"{len(rl.feet)}: {', '.join(rl.feet)}"
        )
    src = _source_paths(motion)
    contacts = (
        np.asarray(motion.contacts, bool)
        if motion.contacts is not None
        else motion.detect_contacts()
    )
    k_scale = rl.leg_length / float(motion.species_info.leg_length)
    pos, rot, sole = src["pos"], src["rot"], src["sole"]
    t = len(pos)
    rpy = rpy_from_matrix(rot)
    rpy[:, 2] = np.unwrap(rpy[:, 2])
    mean_rp = rpy[:, :2].mean(axis=0)
    # trunk: scaled path, height moved to the robot's, roll/pitch relative to the mean
    trunk = k_scale * pos
    trunk[:, 2] = rl.height + k_scale * (pos[:, 2] - pos[:, 2].mean())
    quat = np.empty((t, 4))
    for k in range(t):
        r = matrix_from_rpy(np.array([rpy[k, 0] - mean_rp[0], rpy[k, 1] - mean_rp[1], rpy[k, 2]]))
        mujoco.mju_mat2Quat(quat[k], r.ravel())
    quat[1:] *= np.sign(np.einsum("ij,ij->i", quat[1:], quat[:-1]))[:, None]
    # feet: scaled paths, moved from the source's mean stance offset to the robot's
    heading = [_yaw_matrix(a) for a in rpy[:, 2]]
    off_s = np.zeros((4, 3))
    for i in range(4):
        st = contacts[:, i] if contacts[:, i].any() else np.ones(t, bool)
        rel = np.array([heading[k].T @ (sole[k, i] - pos[k]) for k in np.flatnonzero(st)])
        off_s[i] = rel.mean(axis=0)
    sole_r = rl.nominal.copy()
    sole_r[:, 2] -= rl.radius
    target = np.empty((t, 4, 3))
    for k in range(t):
        shift = heading[k] @ (sole_r - k_scale * off_s).T  # (3, 4)
        target[k] = k_scale * sole[k] + shift.T * np.array([1.0, 1.0, 0.0])
    target[:, :, 2] = np.maximum(k_scale * sole[:, :, 2], 0.0)
    for i in range(4):  # stance feet stay put, on the ground
        for a, b in runs(contacts[:, i]):
            mid = (a + b - 1) // 2
            target[a:b, i, :2] = target[mid, i, :2]
            target[a:b, i, 2] = 0.0
    target[:, :, 2] += rl.radius[None, :]  # foot point = sphere centre
    qpos, res = _solve_frames(rl, trunk, quat, target, opts)
    drop = np.zeros(t)
    for _ in range(int(opts.lower_passes)):
        short = _stance_shortfall(rl, qpos, target, contacts, opts.straight_reach)
        if float(short.max()) <= 0.002 * rl.leg_length:
            break
        drop += carriage_drop(short, float(motion.fps))
        lowered = trunk.copy()
        lowered[:, 2] -= drop
        qpos, res = _solve_frames(rl, lowered, quat, target, opts)
    return RobotClip(
        qpos=qpos,
        fps=float(motion.fps),
        contacts=contacts.copy(),
        feet=rl.feet,
        metadata=_fit_figures(
            rl,
            qpos,
            res,
            {
                "source": "habitsim.retarget.retarget",
                "species": motion.species,
                "scale": k_scale,
                "frames": t,
                "feet_found": feet is None and not isinstance(robot, RobotLegs),
                "trunk_lowered_max_m": float(drop.max()),
                "robot_stand": _stand_figures(rl),
            },
        ),
    )


def _stance_shortfall(
    rl: RobotLegs,
    qpos: np.ndarray,
    target: np.ndarray,
    contacts: np.ndarray,
    straight_reach: float,
) -> np.ndarray:
    """(T,) per frame, the most a stance foot falls short [m]: how far it hangs above its
    target, or how much its leg is straighter than ``straight_reach`` (extension
    beyond it times the leg's hip-to-knee plus knee-to-foot length)."""
    m = rl.model
    d, knees = _at_home(rl)
    full = np.zeros(len(rl.feet))
    for i, hk in enumerate(knees):
        if hk is not None:
            full[i] = float(
                np.linalg.norm(d.xanchor[hk[1]] - d.xanchor[hk[0]])
                + np.linalg.norm(np.array(rl.legs.positions(d))[i] - d.xanchor[hk[1]])
            )
    out = np.zeros(len(qpos))
    for k, q in enumerate(qpos):
        if not contacts[k].any():
            continue
        d.qpos[:] = q
        mujoco.mj_kinematics(m, d)
        hang = np.array(rl.legs.positions(d))[:, 2] - target[k, :, 2]
        stretch = (_extensions(rl, d, knees) - straight_reach) * full
        short = np.maximum(np.maximum(hang, 0.0), np.maximum(stretch, 0.0))
        out[k] = float(short[contacts[k]].max())
    return out


def _yaw_matrix(yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
