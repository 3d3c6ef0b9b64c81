"""Animal motion on a legged robot: foot paths and trunk path mapped onto its joints.

:func:`retarget` maps a habitsim :class:`~habitsim.motion.Motion` (a synthetic gait, a
transfer, an imported BVH) onto a robot MJCF with a free joint and named feet:

1. **Source paths.** The motion is played on its species' model (MuJoCo FK): per frame
   the trunk (pelvis) position and orientation, the lowest point of each foot and the
   contact labels (the motion's own, else detected).
2. **Scaling.** Lengths are scaled by ``k = L_robot / L_species`` (leg lengths: the
   species' hind-leg length, the robot's trunk height over its feet at ``home``). The
   trunk keeps its path and its orientation relative to the standing pose::

       c_r,xy = k·c_s,xy      c_r,z = H_r + k·(c_s,z − c̄_s,z)
       (roll, pitch, yaw)_r = (roll − r̄oll, pitch − p̄itch, yaw)_s

   ``H_r`` the robot's standing trunk height, ``c̄_s,z`` the source's mean trunk height,
   r̄oll and p̄itch its mean trunk roll and pitch (a pelvis slopes; the robot's trunk
   stands level). Each foot keeps its scaled path, moved
   horizontally (in the trunk's heading frame) from the source's mean stance offset
   under the trunk to the robot's own::

       p_r,i = k·p_s,i + Rz(ψ)·(n_r,i − k·n̄_s,i)ₓᵧ

   and during every stance run of the labels it is held where it is at mid-stance, on
   the ground, so the robot's stance feet do not slide whatever the source's did.
3. **Leg IK** (:func:`leg_ik`) on the robot's own leg joints: damped least squares on
   the feet's translational Jacobians (``mujoco.mj_jac``), the trunk set to its pose,
   every joint kept inside its range, warm-started from the previous frame.

The result is a :class:`RobotClip` (qpos at the motion's frame rate, contact labels,
foot names, figures of the fit), saved atomically as ``.npz``; track it with
``habitsim.sim.track(clip.trajectory(), model=robot, feet=clip.feet,
contacts=clip.contacts, controller="mpc")`` (:func:`track_clip`).

:func:`trot` and :func:`stand` make a robot reference from nothing: trotting in place
or forward (the same IK), standing on ``home``.

Bad input raises :class:`RetargetError`; units are SI, world z up, ground at z = 0.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from .errors import HabitsimError
from .mjutils import foot_soles, free_body, home_qpos
from .motion import Motion
from .physics_constants import GRAVITY
from .stance.labels import runs
from .stance.planting import carriage_drop

__all__ = [
    "RetargetError",
    "RobotLegs",
    "RobotClip",
    "robot_legs",
    "find_robot_feet",
    "load_robot",
    "leg_ik",
    "leg_extension",
    "retarget",
    "trot",
    "stand",
    "track_clip",
    "load_robot_clip",
    "drawable",
]

#: File format version of a saved :class:`RobotClip`.
CLIP_VERSION = 1


class RetargetError(HabitsimError, ValueError):
    """Bad input to retargeting: a robot file that does not load, a robot without a free
    joint, unknown foot names (the message lists the valid ones), a foot count that does
    not match the motion's, bad sizes or rates, an unreadable robot clip file."""


# --------------------------------------------------------------------------- the robot
@dataclass(frozen=True)
class RobotLegs:
    """A robot's legs as retargeting sees them.

    Attributes:
        model: the robot (with a floor or without).
        feet: foot names in the order of the contact labels (LF, RF, LH, RH for a
            habitsim motion).
        legs: the controllers' :class:`~habitsim.controllers.legs.LegSet` (foot points,
            the joints each leg owns).
        home: (nq,) the standing pose (:func:`robot_legs`: keyframe ``home``, else
            ``qpos0``, crouched when its legs are straight).
        height: trunk height over the ground when standing [m].
        nominal: (nf, 3) foot points in the trunk frame when standing [m].
        radius: (nf,) foot sphere radius [m] (the foot point is its centre).
        leg_length: L [m], the trunk origin's height over the foot points at home.
        qadr, dadr, lo, hi: per foot, the qpos / dof addresses of the leg's own joints
            and the leg IK's bounds: the joint ranges, narrowed to half a turn about the
            standing angle (:data:`HINGE_SPAN`) and, for the knee, to the side it bends
            to when standing (±inf for an unlimited slide joint).
        home_source: where ``home`` comes from (``keyframe 'home'``, ``qpos0``, or
            ``qpos0`` crouched).
    """

    model: mujoco.MjModel
    feet: tuple[str, ...]
    legs: Any
    home: np.ndarray
    height: float
    nominal: np.ndarray
    radius: np.ndarray
    leg_length: float
    qadr: tuple[np.ndarray, ...]
    dadr: tuple[np.ndarray, ...]
    lo: tuple[np.ndarray, ...]
    hi: tuple[np.ndarray, ...]
    home_source: str = "keyframe 'home'"

    @property
    def trunk_qadr(self) -> int:
        return int(self.legs.qadr)


def load_robot(path: str | Path) -> mujoco.MjModel:
    """A robot MJCF (its scene, with a floor, for simulation).

    Raises:
        RetargetError: the file is missing or does not compile.
    """
    p = Path(path)
    if not p.is_file():
        raise RetargetError(f"robot model {str(p)!r} does not exist")
    try:
        return mujoco.MjModel.from_xml_path(str(p))
    except ValueError as e:
        raise RetargetError(f"robot model {str(p)!r} does not load: {e}") from e


#: A pose whose legs all but reach their full length (:func:`leg_extension` above this
#: on any leg) is straight-legged: ANYmal C's ``qpos0`` in
#: MuJoCo Menagerie (no keyframe). Straight legs are a singular pose for the leg IK (no
#: joint moves the foot vertically) and for the stance forces, so such a model stands
#: on a crouched pose instead (:func:`robot_legs`).
STRAIGHT_REACH = 0.97
#: Trunk height of the crouched standing pose, share of the straight-legged height.
CROUCH_HEIGHT = 0.85
#: Knee bend [rad] that starts the crouch's leg IK off the straight-leg singularity.
CROUCH_BEND = 0.5
#: The leg IK keeps every hinge of a leg within half a turn [rad] of its standing angle
#: (inside the joint's own range): robots that leave their leg joints unlimited
#: (Menagerie's ANYmal B) or give them ±3π (ANYmal C) otherwise let a foot target out
#: of reach spin a joint by whole turns (ANYmal B's dog trot: 47.7 rad in one frame).
HINGE_SPAN = math.pi
#: Largest change of one joint in one damped-least-squares step of the leg IK [rad].
MAX_IK_STEP = 0.3
#: Passes of lowering the trunk where a stance leg would be straighter than
#: :data:`STRAIGHT_REACH` or its foot short of the ground (:func:`retarget`).
LOWER_PASSES = 4


def robot_legs(model: mujoco.MjModel, feet: Sequence[str], home: str = "home") -> RobotLegs:
    """The legs of ``model`` ending at ``feet`` (site, geom or body names; a body is its
    foot sphere, :func:`habitsim.mjutils.resolve_feet`).

    The standing pose is the keyframe named ``home`` (default ``"home"``; Menagerie's
    ``anymal_c_mjx.xml`` calls it ``"standing"``); without a keyframe ``"home"``, ``qpos0``,
    crouched when its legs are straight (:data:`STRAIGHT_REACH`): the trunk lowered to
    :data:`CROUCH_HEIGHT` of its height with the feet kept where they stand, the legs
    solved by :func:`leg_ik` from knees bent so that each foot moves forward (the knees
    point backward, as on most legged robots). :attr:`RobotLegs.home_source` says which.

    Raises:
        RetargetError: no free joint, an unknown foot (the message lists the model's
            sites, geoms and bodies), a foot without joints of its own, a keyframe name
            ``home`` other than ``"home"`` that the model does not have (the message lists
            its keyframes), a straight-legged ``qpos0`` the crouch cannot solve (add a
            ``home`` keyframe).
    """
    from .controllers import ControllerError
    from .controllers.legs import LegSet

    feet = tuple(str(f) for f in feet)
    if not feet:
        raise RetargetError("no feet given; name the robot's feet, e.g. --feet FL,FR,RL,RR")
    if len(set(feet)) != len(feet):
        raise RetargetError(f"a foot is named twice: {', '.join(feet)}")
    if free_body(model) < 0:
        raise RetargetError(
            "the robot has no free joint: retargeting moves its trunk, which "
            "needs a <freejoint/> on the trunk body"
        )
    valid = _point_names(model)
    unknown = [f for f in feet if f not in valid]
    if unknown:
        raise RetargetError(
            f"unknown foot name(s) {', '.join(map(repr, unknown))}; the "
            f"robot's sites, geoms and bodies: {', '.join(valid)}"
        )
    try:
        legs = LegSet(model, feet)
    except ControllerError as e:
        raise RetargetError(str(e)) from e
    if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_KEY, str(home)) >= 0:
        return _legs_at(model, feet, legs, home_qpos(model, str(home)), f"keyframe {home!r}")
    if home != "home":
        keys = [model.key(k).name or f"#{k}" for k in range(model.nkey)]
        raise RetargetError(
            f"the robot has no keyframe {home!r}; its keyframes: {', '.join(keys) or '(none)'}"
        )
    rl = _legs_at(model, feet, legs, model.qpos0.copy(), "qpos0")
    if float(leg_extension(rl).max()) <= STRAIGHT_REACH:
        return rl
    crouched = _crouch(rl)
    return _legs_at(
        model, feet, legs, crouched, f"qpos0 crouched to {CROUCH_HEIGHT:.0%} of its height"
    )


def _legs_at(
    model: mujoco.MjModel, feet: tuple[str, ...], legs: Any, home: np.ndarray, source: str
) -> RobotLegs:
    """The :class:`RobotLegs` standing on ``home``."""
    d = mujoco.MjData(model)
    d.qpos[:] = home
    mujoco.mj_kinematics(model, d)
    tr = legs.trunk
    rot = d.xmat[tr].reshape(3, 3)
    pts = np.array(legs.positions(d))
    sole = pts[:, 2] - legs.radius
    ground = float(sole.min())
    nominal = (pts - d.xpos[tr]) @ rot
    jm = legs.jmap
    qadr, dadr, lo, hi = [], [], [], []
    for i in range(len(feet)):
        own = legs.own[i]
        jid = jm.joint_ids[own]
        lim = model.jnt_limited[jid].astype(bool)
        qadr.append(jm.qpos_adr[own].copy())
        dadr.append(jm.dof_adr[own].copy())
        lo.append(np.where(lim, model.jnt_range[jid, 0], -np.inf))
        hi.append(np.where(lim, model.jnt_range[jid, 1], np.inf))
    rl = RobotLegs(
        model=model,
        feet=feet,
        legs=legs,
        home=home,
        height=float(d.xpos[tr, 2] - ground),
        nominal=nominal,
        radius=legs.radius.copy(),
        leg_length=float(max(d.xpos[tr, 2] - pts[:, 2].mean(), 1e-3)),
        qadr=tuple(qadr),
        dadr=tuple(dadr),
        lo=tuple(lo),
        hi=tuple(hi),
        home_source=source,
    )
    return _bounded(rl)


def _bounded(rl: RobotLegs) -> RobotLegs:
    """``rl`` with the leg IK's bounds: every hinge within :data:`HINGE_SPAN` of its
    standing angle, and each knee (the outermost own hinge about the trunk's lateral
    axis) on the side it bends to when standing, up to the straight leg, so that a foot
    target out of reach straightens the leg instead of folding the knee the other way
    (not for a leg standing straight, :data:`STRAIGHT_REACH`: the crouch bends it first).
    """
    m = rl.model
    d, knees = _at_home(rl)
    straight = _extensions(rl, d, knees) > STRAIGHT_REACH
    hinge = mujoco.mjtJoint.mjJNT_HINGE
    lo, hi = [], []
    for i in range(len(rl.feet)):
        jid = rl.legs.jmap.joint_ids[rl.legs.own[i]]
        h = rl.home[rl.qadr[i]]
        turn = m.jnt_type[jid] == hinge
        a = np.where(turn, np.maximum(rl.lo[i], h - HINGE_SPAN), rl.lo[i])
        b = np.where(turn, np.minimum(rl.hi[i], h + HINGE_SPAN), rl.hi[i])
        hk = knees[i]
        if hk is not None and not straight[i]:
            k = int(np.flatnonzero(jid == hk[1])[0])
            flat = _straight_angle(rl, knees, i, int(rl.qadr[i][k]), float(a[k]), float(b[k]))
            if h[k] > flat:
                a[k] = max(a[k], flat)
            else:
                b[k] = min(b[k], flat)
        lo.append(a)
        hi.append(b)
    return replace(rl, lo=tuple(lo), hi=tuple(hi))


def _at_home(rl: RobotLegs) -> tuple[mujoco.MjData, list]:
    """Data at the standing pose (kinematics done) and its (hip, knee) joints per foot
    (:func:`_knee_joints`)."""
    d = mujoco.MjData(rl.model)
    d.qpos[:] = rl.home
    mujoco.mj_kinematics(rl.model, d)
    return d, _knee_joints(rl, d)


def _straight_angle(rl: RobotLegs, knees: list, i: int, adr: int, lo: float, hi: float) -> float:
    """The angle of the knee at qpos address ``adr`` in [lo, hi] (finite) that makes leg
    i straightest (:func:`leg_extension`, the rest of the standing pose kept; ``knees``:
    :func:`_knee_joints` at it): a 5° scan, then 0.25° about its best."""
    d = mujoco.MjData(rl.model)
    d.qpos[:] = rl.home

    def best(grid: np.ndarray) -> float:
        ext = np.empty(len(grid))
        for n, v in enumerate(grid):
            d.qpos[adr] = v
            mujoco.mj_kinematics(rl.model, d)
            ext[n] = _extensions(rl, d, knees)[i]
        return float(grid[int(np.argmax(ext))])

    coarse = best(np.linspace(lo, hi, max(2, int(math.ceil((hi - lo) / math.radians(5.0))) + 1)))
    step = math.radians(5.0)
    return best(np.clip(np.arange(coarse - step, coarse + step, math.radians(0.25)), lo, hi))


def _leg_chain(rl: RobotLegs, i: int) -> np.ndarray:
    """Joint ids of foot i's own joints, from the trunk outward (MuJoCo numbers bodies,
    and their joints, depth first: along one chain the ids grow outward)."""
    return np.sort(np.asarray(rl.legs.jmap.joint_ids[rl.legs.own[i]]))


def _knee_joints(rl: RobotLegs, d: mujoco.MjData) -> list[tuple[int, int] | None]:
    """Per foot (hip, knee): the first and the outermost own hinge turning about the
    trunk's lateral axis at ``d``'s pose (None for a leg with fewer than two)."""
    m = rl.model
    rot = d.xmat[rl.legs.trunk].reshape(3, 3)
    out: list[tuple[int, int] | None] = []
    for i in range(len(rl.feet)):
        lateral = [
            int(j)
            for j in _leg_chain(rl, i)
            if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE
            and abs(float(d.xaxis[j] @ rot[:, 1])) > 0.7
        ]
        out.append((lateral[0], lateral[-1]) if len(lateral) >= 2 else None)
    return out


def leg_extension(rl: RobotLegs, qpos: np.ndarray | None = None) -> np.ndarray:
    """(nf,) how straight each leg is at ``qpos`` (default the standing pose): in the
    trunk's sagittal plane, the hip-to-foot distance over the summed hip-to-knee and
    knee-to-foot lengths (hip and knee: the first and the outermost own joint turning
    about the trunk's lateral axis). 1 is a straight leg; 0 for a leg without a knee."""
    m = rl.model
    d = mujoco.MjData(m)
    d.qpos[:] = rl.home if qpos is None else qpos
    mujoco.mj_kinematics(m, d)
    return _extensions(rl, d, _knee_joints(rl, d))


def _extensions(rl: RobotLegs, d: mujoco.MjData, knees: list) -> np.ndarray:
    """:func:`leg_extension` at ``d``'s pose (kinematics done) for (hip, knee) ``knees``."""
    rot = d.xmat[rl.legs.trunk].reshape(3, 3)
    pts = np.array(rl.legs.positions(d))
    out = np.zeros(len(rl.feet))
    for i, hk in enumerate(knees):
        if hk is None:
            continue
        hip, knee, foot = ((p @ rot)[[0, 2]] for p in (d.xanchor[hk[0]], d.xanchor[hk[1]], pts[i]))
        full = float(np.linalg.norm(knee - hip) + np.linalg.norm(foot - knee))
        out[i] = float(np.linalg.norm(foot - hip)) / full if full > 0 else 0.0
    return out


def _crouch(rl: RobotLegs) -> np.ndarray:
    """A standing pose off the straight-leg singularity (see :func:`robot_legs`)."""
    m = rl.model
    d = mujoco.MjData(m)
    q = rl.home.copy()
    d.qpos[:] = q
    mujoco.mj_kinematics(m, d)
    feet = np.array(rl.legs.positions(d))
    rot = d.xmat[rl.legs.trunk].reshape(3, 3)
    for i, hk in enumerate(_knee_joints(rl, d)):
        if hk is None:
            continue
        adr = int(m.jnt_qposadr[hk[1]])
        k = int(np.flatnonzero(rl.qadr[i] == adr)[0])
        best, ahead = q[adr], -np.inf
        for sign in (1.0, -1.0):
            trial = q.copy()
            trial[adr] = np.clip(q[adr] + sign * CROUCH_BEND, rl.lo[i][k], rl.hi[i][k])
            d.qpos[:] = trial
            mujoco.mj_kinematics(m, d)
            x = float((rl.legs.positions(d)[i] - d.xpos[rl.legs.trunk]) @ rot[:, 0])
            if x > ahead:
                best, ahead = trial[adr], x
        q[adr] = best
    q[rl.trunk_qadr + 2] -= (1.0 - CROUCH_HEIGHT) * rl.height
    q, res = leg_ik(rl, q, feet, iterations=300, data=d)
    if float(res.max()) > 0.01 * rl.leg_length:
        raise RetargetError(
            f"the robot has no 'home' keyframe and its qpos0 stands on straight legs; "
            f"crouching it left a foot {1000 * float(res.max()):.1f} mm from the ground "
            'point: add a <key name="home" qpos="..."/> standing pose to the model'
        )
    return q


def _point_names(model: mujoco.MjModel) -> list[str]:
    """Names of the sites, geoms and bodies that could be feet (none on the world body)."""
    names: list[str] = []
    for n, get, body in (
        (model.nsite, model.site, model.site_bodyid),
        (model.ngeom, model.geom, model.geom_bodyid),
        (model.nbody, model.body, np.arange(model.nbody)),
    ):
        for i in range(n):
            nm = get(i).name
            if nm and nm not in names and body[i] != 0:
                names.append(nm)
    return names


# --------------------------------------------------------------------------- IK
def leg_ik(
    robot: RobotLegs,
    qpos: np.ndarray,
    targets: np.ndarray,
    *,
    iterations: int = 30,
    tolerance: float = 1e-5,
    damping: float | None = None,
    data: mujoco.MjData | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Leg joint angles putting each foot point at its target, trunk as in ``qpos``.

    Damped least squares per leg on the leg's own joints,
    ``Δq = Jᵀ (J Jᵀ + λ² I)⁻¹ (p* − p)`` with ``J`` the foot point's translational
    Jacobian (``mujoco.mj_jac``), each step scaled to at most :data:`MAX_IK_STEP` per
    joint and clipped into the leg's bounds (:attr:`RobotLegs.lo` / ``hi``), until every
    foot is within ``tolerance`` [m] or after ``iterations`` steps.

    Args:
        robot: the :class:`RobotLegs`.
        qpos: (nq,) start (trunk pose and initial leg angles).
        targets: (nf, 3) wanted foot points (world) [m].
        damping: λ [m] (default 1 % of the leg length).

    Returns:
        (qpos (nq,), residual (nf,) [m] distance of each foot from its target).
    """
    m = robot.model
    d = mujoco.MjData(m) if data is None else data
    q = np.array(qpos, dtype=float)
    lam2 = (0.01 * robot.leg_length if damping is None else float(damping)) ** 2
    legs = robot.legs
    jac = np.zeros((3, m.nv))
    eye = np.eye(3)
    err = np.zeros((len(robot.feet), 3))
    for _ in range(max(int(iterations), 1)):
        d.qpos[:] = q
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        pts = np.array(legs.positions(d))
        err = targets - pts
        if float(np.abs(err).max()) < tolerance:
            break
        for i, b in enumerate(legs.bodies):
            mujoco.mj_jac(m, d, jac, None, pts[i], int(b))
            j = jac[:, robot.dadr[i]]
            step = j.T @ np.linalg.solve(j @ j.T + lam2 * eye, err[i])
            big = float(np.abs(step).max(initial=0.0))
            if big > MAX_IK_STEP:  # near a singularity DLS steps grow as |err|/λ
                step *= MAX_IK_STEP / big
            qa = robot.qadr[i]
            q[qa] = np.clip(q[qa] + step, robot.lo[i], robot.hi[i])
    d.qpos[:] = q
    mujoco.mj_kinematics(m, d)
    res = np.linalg.norm(targets - np.array(legs.positions(d)), axis=1)
    return q, res


def _solve_frames(
    robot: RobotLegs, trunk_pos: np.ndarray, trunk_quat: np.ndarray, feet: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(qpos (T, nq), residual (T, nf)) of trunk poses and foot targets per frame."""
    t = len(trunk_pos)
    m = robot.model
    d = mujoco.MjData(m)
    a = robot.trunk_qadr
    q = robot.home.copy()
    out = np.empty((t, m.nq))
    res = np.empty((t, len(robot.feet)))
    for k in range(t):
        q[a : a + 3] = trunk_pos[k]
        q[a + 3 : a + 7] = trunk_quat[k]
        q, res[k] = leg_ik(robot, q, feet[k], iterations=60 if k == 0 else 30, data=d)
        out[k] = q
    return out, res


# --------------------------------------------------------------------------- clips
@dataclass
class RobotClip:
    """A reference for a robot: qpos at a frame rate, contact labels, foot names.

    Attributes:
        qpos: (T, nq) frames; fps: frame rate [Hz]; contacts: (T, nf) bool stance labels
        in the order of ``feet``; feet: the robot's foot names.
        metadata: JSON-ready figures (source, scale, IK residual, clipped joints, …).
    """

    qpos: np.ndarray
    fps: float
    contacts: np.ndarray
    feet: tuple[str, ...]
    metadata: dict[str, Any] = field(default_factory=dict)

    @property
    def duration(self) -> float:
        return (len(self.qpos) - 1) / self.fps if len(self.qpos) > 1 else 0.0

    def trajectory(self) -> Any:
        """The frames as a :class:`~habitsim.qpos.QposTrajectory` (for
        :func:`habitsim.sim.track`)."""
        from .qpos import QposTrajectory

        return QposTrajectory(
            qpos=self.qpos, fps=self.fps, residual_rad=np.zeros(len(self.qpos)), missing=()
        )

    def save(self, path: str | Path) -> Path:
        """Write the clip as ``.npz`` atomically (a temporary file renamed over ``path``)."""
        from .fileio import atomic_write, json_safe

        path = Path(path)
        with atomic_write(path) as fh:
            np.savez_compressed(
                fh,
                version=np.array(CLIP_VERSION),
                qpos=self.qpos,
                fps=np.array(self.fps),
                contacts=self.contacts,
                feet=np.array(self.feet),
                metadata=np.array(json.dumps(json_safe(self.metadata))),
            )
        return path


def load_robot_clip(path: str | Path) -> RobotClip:
    """Read a clip written by :meth:`RobotClip.save`.

    Raises:
        RetargetError: missing file, not a robot clip, wrong version.
    """
    p = Path(path)
    try:
        with np.load(p, allow_pickle=False) as z:
            if "qpos" not in z or "feet" not in z:
                raise RetargetError(f"{str(p)!r} is not a robot clip (no qpos/feet arrays)")
            if int(z["version"]) != CLIP_VERSION:
                raise RetargetError(
                    f"{str(p)!r} has robot clip version {int(z['version'])}, "
                    f"this habitsim reads {CLIP_VERSION}"
                )
            return RobotClip(
                qpos=z["qpos"].astype(float),
                fps=float(z["fps"]),
                contacts=z["contacts"].astype(bool),
                feet=tuple(str(f) for f in z["feet"]),
                metadata=json.loads(str(z["metadata"])),
            )
    except (OSError, ValueError, KeyError) as e:
        raise RetargetError(f"cannot read robot clip {str(p)!r}: {e}") from e


# --------------------------------------------------------------------------- retarget
def _source_paths(motion: Motion) -> dict[str, np.ndarray]:
    """Per frame, the trunk position (T, 3) and rotation (T, 3, 3) and the feet's lowest
    points (T, 4, 3) of a motion played on its species' model."""
    from .qpos import motion_to_qpos, species_model
    from .sim import foot_geoms

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
) -> RobotClip:
    """Map a habitsim motion onto a legged robot (see the module docstring).

    Args:
        motion: the motion (four feet, LF, RF, LH, RH).
        robot: the robot model (or its :class:`RobotLegs`).
        feet: the robot's four foot names in the order LF, RF, LH, RH (e.g.
            ``["FL", "FR", "RL", "RR"]``); not needed with a :class:`RobotLegs`; ``None``:
            found by :func:`find_robot_feet` (``metadata["feet_found"]`` says so).
        home: the keyframe the robot stands on (:func:`robot_legs`).

    Returns:
        The :class:`RobotClip` at the motion's frame rate; ``metadata`` holds the scale,
        the IK residual (max and mean [m]) and the share of joint values at a range limit.

    Raises:
        RetargetError: see :func:`robot_legs`; not four feet.
    """
    from .controllers.plan import matrix_from_rpy, rpy_from_matrix

    if isinstance(robot, RobotLegs):
        rl = robot
    else:
        rl = robot_legs(robot, _need_feet(feet, robot, home), home)
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
    qpos, res = _solve_frames(rl, trunk, quat, target)
    drop = np.zeros(t)
    for _ in range(LOWER_PASSES):
        short = _stance_shortfall(rl, qpos, target, contacts)
        if float(short.max()) <= 0.002 * rl.leg_length:
            break
        drop += carriage_drop(short, float(motion.fps))
        lowered = trunk.copy()
        lowered[:, 2] -= drop
        qpos, res = _solve_frames(rl, lowered, quat, target)
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
            },
        ),
    )


def _stance_shortfall(
    rl: RobotLegs, qpos: np.ndarray, target: np.ndarray, contacts: np.ndarray
) -> np.ndarray:
    """(T,) per frame, the most a stance foot falls short [m]: how far it hangs above its
    target, or how much its leg is straighter than :data:`STRAIGHT_REACH` (extension
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
        stretch = (_extensions(rl, d, knees) - STRAIGHT_REACH) * full
        short = np.maximum(np.maximum(hang, 0.0), np.maximum(stretch, 0.0))
        out[k] = float(short[contacts[k]].max())
    return out


def _yaw_matrix(yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _need_feet(
    feet: Sequence[str] | None, model: mujoco.MjModel | None = None, home: str = "home"
) -> Sequence[str]:
    if feet is not None:
        return feet
    if model is None:
        raise RetargetError(
            "name the robot's feet (feet=[...], --feet FL,FR,RL,RR) in the order LF, RF, LH, RH"
        )
    return find_robot_feet(model, home)


def find_robot_feet(model: mujoco.MjModel, home: str = "home") -> tuple[str, ...]:
    """The robot's four feet in the order LF, RF, LH, RH when nobody names them: the
    usual names (:func:`habitsim.mjutils.known_feet`: ``FL``, ``FL_foot``, ``LF_FOOT``
    …), else the four legs standing on the ground at the standing pose (keyframe
    ``home``, else ``qpos0``; :func:`habitsim.mjutils.standing_feet`).

    Raises:
        RetargetError: not four legs standing on the ground, or a foot that is an
            unnamed geom other than a sphere (the message says what was found).
    """
    from .mjutils import ModelLookupError, known_feet, standing_feet

    names = known_feet(model)
    if names is not None:
        return tuple(names)
    try:
        return standing_feet(model, home_qpos(model, home))
    except ModelLookupError as e:
        raise RetargetError(
            f"{e}; name them (feet=[...], --feet FL,FR,RL,RR) in the order LF, RF, LH, RH"
        ) from e


def _fit_figures(
    rl: RobotLegs, qpos: np.ndarray, res: np.ndarray, extra: dict[str, Any]
) -> dict[str, Any]:
    at_limit = []
    for i in range(len(rl.feet)):
        v = qpos[:, rl.qadr[i]]
        span = np.where(np.isfinite(rl.hi[i] - rl.lo[i]), rl.hi[i] - rl.lo[i], np.inf)
        at_limit.append(((v - rl.lo[i] < 1e-3 * span) | (rl.hi[i] - v < 1e-3 * span)).mean())
    return {
        **extra,
        "ik_residual_max_m": float(res.max()),
        "ik_residual_mean_m": float(res.mean()),
        "joints_at_limit_share": float(np.mean(at_limit)),
        "robot_leg_length_m": rl.leg_length,
        "robot_home": rl.home_source,
    }


# --------------------------------------------------------------------------- trot
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

    Raises:
        RetargetError: not four feet, non-positive durations or rates, duty outside
            (0.5, 1).
    """
    rl = robot if isinstance(robot, RobotLegs) else robot_legs(robot, _need_feet(feet, robot))
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
    qpos, res = _solve_frames(rl, trunk, quat, target)
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
            },
        ),
    )


def stand(
    robot: mujoco.MjModel | RobotLegs,
    feet: Sequence[str] | None = None,
    *,
    duration_s: float = 10.0,
    fps: float = 100.0,
) -> RobotClip:
    """A standing reference: the ``home`` pose with the feet on the ground, held.

    Raises:
        RetargetError: see :func:`robot_legs`; non-positive duration or rate.
    """
    rl = robot if isinstance(robot, RobotLegs) else robot_legs(robot, _need_feet(feet, robot))
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


def track_clip(
    clip: RobotClip, robot: mujoco.MjModel, *, controller: str | Any = "mpc", **options: Any
):
    """Track a :class:`RobotClip` on ``robot`` with :func:`habitsim.sim.track` (its feet,
    its contact labels; ``options`` are passed on, e.g. ``stop_on_fall``)."""
    from .sim import track

    return track(
        clip.trajectory(),
        model=robot,
        feet=clip.feet,
        contacts=clip.contacts,
        controller=controller,
        **options,
    )


def drawable(model: mujoco.MjModel) -> mujoco.MjModel:
    """A copy of ``model`` whose colliding geoms are drawn (for videos): a collision-only
    robot (Menagerie's style) keeps them in geom group 3, which MuJoCo's renderer hides
    by default. Physics is untouched."""
    import copy

    out = copy.copy(model)
    colliding = (out.geom_contype != 0) | (out.geom_conaffinity != 0)
    out.geom_group[colliding & (out.geom_group > 2)] = 0
    return out
