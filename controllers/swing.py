"""Legs, the motion's contact schedule and foot paths, and swing-leg control.

Shared by the balance (:mod:`~habitsim.controllers.balance`) and MPC
(:mod:`~habitsim.controllers.mpc`) controllers; usable on any MJCF with a free joint and
named feet (sites, geoms or bodies).

* :class:`LegSet` — the feet of a model and the joints that move them: every actuated
  joint on the chain trunk → foot (the Jacobian ``Jᵢ`` of the foot point is non-zero only
  there, so ``τ = −Jᵢᵀ fᵢ`` loads exactly that chain, spine joints included), and the
  joints that belong to one leg alone (:attr:`LegSet.own`, used for swing and posture).
* :class:`MotionPlan` — the reference motion seen as a plan: per frame the whole-body
  centre of mass (position, velocity, acceleration), trunk roll/pitch/yaw (yaw
  unwrapped) and angular velocity, foot positions and velocities, and the contact table;
  per foot and frame the lift-off and touch-down times and the touch-down foothold.
  :meth:`MotionPlan.sample` interpolates it at any time.
* :class:`ContactTracker` — the contact state machine: the schedule comes from the
  motion; a swing foot that touches the ground in the last quarter of its swing, near
  its swing target, switches to stance early (*early touch-down*; earlier or farther
  behind it is scuffing and keeps swinging); a scheduled stance foot that does not touch the
  ground carries no force (*lost contact*, :data:`SEEK`) and reaches down until it does.
* :class:`SwingLegs` — swing feet follow the motion's own foot path, bent so that it
  starts where the foot really lifted off and ends at a corrected foothold (the reference
  foothold moved with the body, plus a bounded capture-point correction), tracked by a
  Cartesian PD ``F = Kp (p_des − p) + Kd (v_des − v)`` applied as ``τ = J_legᵀ F``;
  gravity and bias compensation (``qfrc_bias``) and the joints' damping are added by the
  torque layer for every joint.

Units: SI (m, s, kg, N, N·m, rad); world frame z up.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import mujoco
import numpy as np

from habitsim.mjutils import (
    HABITSIM_FEET,
    ROBOT_FEET,
    ModelLookupError,
    free_body,
    known_feet,
    leg_length,
    point_pos,
)

from .base import ControllerError, JointActuatorMap, actuated_joints
from .gains import _point_body, _resolve_points

__all__ = [
    "STANCE",
    "SWING",
    "SEEK",
    "HABITSIM_FEET",
    "default_feet",
    "LegSet",
    "MotionPlan",
    "PlanSample",
    "plan_from_qpos",
    "ContactTracker",
    "SwingLegs",
    "model_leg_length",
    "rpy_from_matrix",
    "matrix_from_rpy",
]

#: Leg modes of :class:`ContactTracker`: on the ground and carrying force …
STANCE = 0
#: … in the air, following the swing path …
SWING = 1
#: … scheduled on the ground but not touching it: no force, reaching down.
SEEK = 2


def default_feet(model: mujoco.MjModel) -> tuple[str, ...]:
    """The model's feet in the order LF, RF, LH, RH, found by the usual names
    (:func:`habitsim.mjutils.known_feet`).

    Raises:
        ControllerError: no known naming matches (pass ``feet=`` explicitly).
    """
    names = known_feet(model)
    if names is None:
        raise ControllerError(
            "cannot find the feet of the model by name (tried "
            + "; ".join(", ".join(n) for n in (HABITSIM_FEET, *ROBOT_FEET))
            + "); pass feet=[...] (site, geom or body names in the order LF, RF, LH, RH)"
        )
    return names


def model_leg_length(model: mujoco.MjModel, feet: Sequence[str] | None = None) -> float:
    """A model's leg length [m] when no species says it (:func:`habitsim.mjutils.leg_length`:
    the height of the trunk above the mean of the feet at the home pose)."""
    if free_body(model) < 0:
        raise ControllerError("the model has no free joint")
    try:
        return leg_length(model, feet or default_feet(model))
    except ModelLookupError as e:
        raise ControllerError(str(e)) from e


def rpy_from_matrix(rot: np.ndarray) -> np.ndarray:
    """(…, 3) roll, pitch, yaw (ZYX: R = Rz(yaw) Ry(pitch) Rx(roll)) of (…, 3, 3)."""
    r = np.asarray(rot)
    roll = np.arctan2(r[..., 2, 1], r[..., 2, 2])
    pitch = -np.arcsin(np.clip(r[..., 2, 0], -1.0, 1.0))
    yaw = np.arctan2(r[..., 1, 0], r[..., 0, 0])
    return np.stack([roll, pitch, yaw], axis=-1)


def matrix_from_rpy(rpy: np.ndarray) -> np.ndarray:
    """(3, 3) rotation ``Rz(yaw) Ry(pitch) Rx(roll)`` of roll, pitch, yaw."""
    cr, sr = np.cos(rpy[0]), np.sin(rpy[0])
    cp, sp = np.cos(rpy[1]), np.sin(rpy[1])
    cy, sy = np.cos(rpy[2]), np.sin(rpy[2])
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


# --------------------------------------------------------------------------- legs
class LegSet:
    """The feet of a model and the joints that move them.

    Args:
        model: the MuJoCo model (one free joint: the trunk).
        feet: foot names (site, geom or body), default :func:`default_feet`; the order is
            the order of contact labels (LF, RF, LH, RH for habitsim motions).

    Attributes:
        feet: the names; points: ``(kind, id)`` per foot; bodies: (nf,) foot bodies.
        trunk: free-joint body; qadr, dadr: its qpos / dof addresses.
        jmap: every actuated hinge/slide joint (the controller's joint order).
        own: (nf, n) bool, joint k belongs to foot i's leg alone (on its chain, on no
            other foot's chain).
        body: (n,) bool, joints on no foot's chain or on several (spine, neck, tail).
        radius: (nf,) foot sphere radius [m] (0 for sites/bodies without a sphere geom).
        mass: total mass [kg]; leg_mass: (nf,) mass of each leg's own bodies [kg].
    """

    def __init__(self, model: mujoco.MjModel, feet: Sequence[str] | None = None) -> None:
        self.feet = tuple(feet) if feet is not None else default_feet(model)
        if not self.feet:
            raise ControllerError("at least one foot is needed")
        self.points = _resolve_points(model, list(self.feet))
        self.trunk = free_body(model)
        if self.trunk < 0:
            raise ControllerError("balance control needs a model with a free joint (the trunk)")
        jnt = int(model.body_jntadr[self.trunk])
        self.qadr, self.dadr = int(model.jnt_qposadr[jnt]), int(model.jnt_dofadr[jnt])
        self.bodies = np.array([_point_body(model, k, i) for k, i in self.points], dtype=int)
        self.jmap: JointActuatorMap = actuated_joints(model)
        nf, n = len(self.feet), len(self.jmap.names)
        on_chain = np.zeros((nf, n), dtype=bool)
        for i, fb in enumerate(self.bodies):
            chain = set()
            b = int(fb)
            while b > 0 and b != self.trunk:
                chain.add(b)
                b = int(model.body_parentid[b])
            if b != self.trunk:
                raise ControllerError(f"foot {self.feet[i]!r} is not below the trunk body")
            for k, j in enumerate(self.jmap.joint_ids):
                on_chain[i, k] = int(model.jnt_bodyid[j]) in chain
        shared = on_chain.sum(axis=0) > 1
        self.own = on_chain & ~shared[None, :]
        self.on_chain = on_chain
        self.body = ~self.own.any(axis=0)
        for i in range(nf):
            if not self.own[i].any():
                raise ControllerError(f"foot {self.feet[i]!r} has no actuated joint of its own")
        self.mass = float(model.body_subtreemass[self.trunk])
        # each leg's own bodies: subtree of the highest body carrying one of its own joints
        self.leg_mass = np.zeros(nf)
        for i in range(nf):
            tops = [int(model.jnt_bodyid[j]) for j in self.jmap.joint_ids[self.own[i]]]
            depth = [self._depth(model, b) for b in tops]
            self.leg_mass[i] = float(model.body_subtreemass[tops[int(np.argmin(depth))]])
        self.radius = np.zeros(nf)
        self.geom_lut = np.full(model.ngeom, -1, dtype=int)
        for i, (kind, oid) in enumerate(self.points):
            if kind == "geom" and int(model.geom_type[oid]) == int(mujoco.mjtGeom.mjGEOM_SPHERE):
                self.radius[i] = float(model.geom_size[oid, 0])
            # every colliding geom of the foot's body is "the foot" (a paw's toe capsule
            # or a plantigrade sole touches the ground as well as the foot sphere)
            geoms = [
                g
                for g in range(model.ngeom)
                if model.geom_bodyid[g] == self.bodies[i]
                and (model.geom_contype[g] or model.geom_conaffinity[g])
            ]
            if kind == "geom":
                geoms.append(oid)
            self.geom_lut[geoms] = i
        # padded index of each leg's own joints (for batched null-space projection)
        width = int(self.own.sum(axis=1).max())
        self.own_idx = np.full((nf, width), n, dtype=int)  # n = a zero column
        for i in range(nf):
            k = np.flatnonzero(self.own[i])
            self.own_idx[i, : k.size] = k
        kinds = {k for k, _ in self.points}
        self._kind = kinds.pop() if len(kinds) == 1 else "mixed"
        self._ids = np.array([i for _, i in self.points], dtype=int)
        self._foot_range = np.arange(nf)
        self._body_list = [int(b) for b in self.bodies]

    @staticmethod
    def _depth(model: mujoco.MjModel, b: int) -> int:
        d = 0
        while b > 0:
            b = int(model.body_parentid[b])
            d += 1
        return d

    @property
    def n_feet(self) -> int:
        return len(self.feet)

    def positions(self, data: mujoco.MjData) -> np.ndarray:
        """(nf, 3) foot points [m], world frame (from ``data``'s kinematics)."""
        if self._kind == "geom":
            return data.geom_xpos[self._ids]
        if self._kind == "site":
            return data.site_xpos[self._ids]
        return np.array([point_pos(data, k, i) for k, i in self.points])

    def jacobians(
        self,
        model: mujoco.MjModel,
        data: mujoco.MjData,
        points: np.ndarray,
        out: np.ndarray | None = None,
    ) -> np.ndarray:
        """(nf, 3, nv) translational Jacobians of the foot points (into ``out``)."""
        if out is None:
            out = np.empty((self.n_feet, 3, model.nv))
        for i, b in enumerate(self._body_list):
            mujoco.mj_jac(model, data, out[i], None, points[i], b)
        return out

    def touching(self, data: mujoco.MjData) -> np.ndarray:
        """(nf,) bool: the foot has an active contact (any colliding geom of its body)."""
        return self.contact_points(data)[0]

    def contact_points(self, data: mujoco.MjData) -> tuple[np.ndarray, np.ndarray]:
        """(touching (nf,) bool, points (nf, 3)): per foot whether any geom of its body
        has a contact, and the mean position of those contacts (NaN without contact) —
        where the ground really pushes, which for a paw lying on its toe capsule or a
        plantigrade sole is not the foot sphere's centre."""
        nf = self.n_feet
        if not data.ncon:
            return np.zeros(nf, dtype=bool), np.full((nf, 3), np.nan)
        con = data.contact
        geoms = con.geom
        foot = np.maximum(self.geom_lut[geoms[:, 0]], self.geom_lut[geoms[:, 1]])
        onehot = (foot[:, None] == self._foot_range).astype(float)  # (ncon, nf); -1: none
        count = onehot.sum(axis=0)
        touch = count > 0
        pts = (onehot.T @ con.pos) / np.maximum(count, 1.0)[:, None]
        pts[~touch] = np.nan
        return touch, pts


# --------------------------------------------------------------------------- plan
@dataclass(frozen=True)
class PlanSample:
    """The plan at one time (see :meth:`MotionPlan.sample`); all world frame, SI.

    Attributes:
        t: time [s]. com, com_vel, com_acc: (3,) whole-body centre of mass.
        rpy: (3,) trunk roll, pitch, yaw (yaw unwrapped). omega, omega_dot: (3,) trunk
            angular velocity / acceleration. feet, feet_vel: (nf, 3) reference foot points.
        contacts: (nf,) bool scheduled stance. phase: (nf,) swing phase in [0, 1] (NaN in
            stance or when unknown). t_liftoff, t_touchdown: (nf,) times [s] of the current
            swing's lift-off and touch-down (NaN in stance). foothold: (nf, 3) reference
            foot point at the next touch-down (the current point in stance).
    """

    t: float
    com: np.ndarray
    com_vel: np.ndarray
    com_acc: np.ndarray
    rpy: np.ndarray
    omega: np.ndarray
    omega_dot: np.ndarray
    feet: np.ndarray
    feet_vel: np.ndarray
    contacts: np.ndarray
    phase: np.ndarray
    t_liftoff: np.ndarray
    t_touchdown: np.ndarray
    foothold: np.ndarray


@dataclass(frozen=True)
class MotionPlan:
    """A reference motion as a plan for balance control (build with :func:`plan_from_qpos`).

    Attributes:
        fps: frame rate [Hz]; T frames, frame k at time k / fps.
        com, com_vel, com_acc: (T, 3) whole-body centre of mass along the reference.
        rpy: (T, 3) trunk roll, pitch, yaw (ZYX), yaw unwrapped.
        omega, omega_dot: (T, 3) trunk angular velocity / acceleration, world frame.
        feet, feet_vel: (T, nf, 3) reference foot points.
        contacts: (T, nf) bool stance labels of the frames.
        liftoff, touchdown: (T, nf) int first swing frame of the current swing / first
            stance frame after it (-1 in stance; touch-down ``T`` when the clip ends in
            the air).
        stride_s: mean time between touch-downs of a foot [s] (NaN if no foot steps twice).

    **Schedule between frames.** The reference the controllers track is interpolated
    between frames, so a foot labelled swing at frame k−1 and stance at k reaches the
    ground at frame k, and one labelled stance at k and swing at k+1 leaves it right after
    frame k. A foot is therefore scheduled in stance at time t when the frames on both
    sides of t are stance frames (:meth:`contacts_at`), and a swing runs from the last
    stance frame to the next stance frame. (The nearest-frame rule would put every
    touch-down half a frame before the reference foot lands and every lift-off half a
    frame after it leaves: at 30 fps a fast trot's stance would be planned a whole frame
    too long and its flight phase a frame too short.)
    """

    fps: float
    com: np.ndarray
    com_vel: np.ndarray
    com_acc: np.ndarray
    rpy: np.ndarray
    omega: np.ndarray
    omega_dot: np.ndarray
    feet: np.ndarray
    feet_vel: np.ndarray
    contacts: np.ndarray
    liftoff: np.ndarray
    touchdown: np.ndarray
    stride_s: float

    @property
    def n_frames(self) -> int:
        return int(self.com.shape[0])

    @property
    def duration(self) -> float:
        return (self.n_frames - 1) / self.fps

    def _interp(self, arr: np.ndarray, s: np.ndarray | float) -> np.ndarray:
        s = np.clip(s, 0.0, self.n_frames - 1)
        i0 = np.minimum(np.floor(s).astype(int), max(self.n_frames - 2, 0))
        i1 = np.minimum(i0 + 1, self.n_frames - 1)
        a = np.asarray(s - i0)
        a = a.reshape(a.shape + (1,) * (arr.ndim - 1))
        return (1.0 - a) * arr[i0] + a * arr[i1]

    def frame(self, t: float | np.ndarray) -> np.ndarray | int:
        """Nearest frame index of time(s) ``t`` [s] (the runner's contact rule)."""
        k = np.floor(np.asarray(t, dtype=float) * self.fps + 0.5).astype(int)
        k = np.clip(k, 0, self.n_frames - 1)
        return int(k) if k.ndim == 0 else k

    def trunk_states(self, times: np.ndarray) -> np.ndarray:
        """(n, 13) single-rigid-body states ``[rpy, com, omega, com_vel, g]`` at ``times``
        (the last entry is left 0; the caller sets gravity)."""
        s = np.asarray(times, dtype=float) * self.fps
        out = np.zeros((len(s), 13))
        out[:, 0:3] = self._interp(self.rpy, s)
        out[:, 3:6] = self._interp(self.com, s)
        out[:, 6:9] = self._interp(self.omega, s)
        out[:, 9:12] = self._interp(self.com_vel, s)
        return out

    def contacts_at(self, times: np.ndarray) -> np.ndarray:
        """(n, nf) bool scheduled stance at ``times``: the frames on both sides are
        stance frames (see the class docstring)."""
        s = np.clip(np.asarray(times, dtype=float) * self.fps, 0.0, self.n_frames - 1)
        i0 = np.floor(s).astype(int)
        i1 = np.minimum(np.ceil(s).astype(int), self.n_frames - 1)
        return self.contacts[i0] & self.contacts[i1]

    def feet_at(self, times: np.ndarray) -> np.ndarray:
        """(n, nf, 3) reference foot points at ``times``."""
        return self._interp(self.feet, np.asarray(times, dtype=float) * self.fps)

    def __post_init__(self) -> None:
        # every interpolated per-frame quantity packed in one (T, D) array, so a sample
        # is one interpolation (the controllers sample the plan at every tick)
        t = self.n_frames
        pack = np.concatenate(
            [
                self.com,
                self.com_vel,
                self.com_acc,
                self.rpy,
                self.omega,
                self.omega_dot,
                self.feet.reshape(t, -1),
                self.feet_vel.reshape(t, -1),
            ],
            axis=1,
        )
        object.__setattr__(self, "_pack", pack)
        nf = self.contacts.shape[1]
        swing = ~self.contacts
        td = np.minimum(self.touchdown, t - 1)
        hold_ = np.where(swing[:, :, None], self.feet[np.maximum(td, 0), np.arange(nf)], np.nan)
        object.__setattr__(self, "_foothold", hold_)
        # per swing frame: lift-off right after the last stance frame, touch-down at the
        # next stance frame [s] (NaN in stance)
        object.__setattr__(self, "_t_lo", np.where(swing, (self.liftoff - 1) / self.fps, np.nan))
        object.__setattr__(self, "_t_td", np.where(swing, self.touchdown / self.fps, np.nan))
        object.__setattr__(self, "_feet_idx", np.arange(nf))

    def sample(self, t: float, hold: bool = False) -> PlanSample:
        """The plan at time ``t`` [s] (clamped to the clip); ``hold`` freezes the first
        frame with zero velocities (the runner's settling phase)."""
        nfr = self.n_frames
        s = 0.0 if hold else min(max(float(t) * self.fps, 0.0), nfr - 1.0)
        i0 = min(int(s), max(nfr - 2, 0))
        i1 = min(i0 + 1, nfr - 1)
        a = s - i0
        v = self._pack[i0] * (1.0 - a) + self._pack[i1] * a if a else self._pack[i0].copy()
        c0 = self.contacts[i0]
        if a:  # stance between two stance frames; a swing's frame is i1 right after lift-off
            contacts = c0 & self.contacts[i1]
            k = np.where(c0, i1, i0)
        else:
            contacts = c0.copy()
            k = np.full(c0.size, i0)
        nf = contacts.size
        now = 0.0 if hold else float(t)
        feet_idx = self._feet_idx
        swing = ~contacts
        t_lo = np.where(swing, self._t_lo[k, feet_idx], np.nan)
        t_td = np.where(swing, self._t_td[k, feet_idx], np.nan)
        phase = np.full(nf, np.nan)
        if swing.any():
            a_, b_ = t_lo[swing], t_td[swing]
            phase[swing] = np.clip((now - a_) / np.maximum(b_ - a_, 1e-6), 0.0, 1.0)
        feet = v[18 : 18 + 3 * nf].reshape(nf, 3)
        foothold = np.where(swing[:, None], self._foothold[k, feet_idx], feet)
        if hold:
            v[3:9] = 0.0
            v[12:18] = 0.0
            v[18 + 3 * nf :] = 0.0
        return PlanSample(
            t=now,
            com=v[0:3],
            com_vel=v[3:6],
            com_acc=v[6:9],
            rpy=v[9:12],
            omega=v[12:15],
            omega_dot=v[15:18],
            feet=feet,
            feet_vel=v[18 + 3 * nf :].reshape(nf, 3),
            contacts=contacts,
            phase=phase,
            t_liftoff=t_lo,
            t_touchdown=t_td,
            foothold=foothold,
        )


def _segments(contacts: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Per frame and foot the lift-off and next touch-down frame; mean stride [frames]."""
    t, nf = contacts.shape
    liftoff = np.full((t, nf), -1, dtype=int)
    touchdown = np.full((t, nf), -1, dtype=int)
    strides = []
    for f in range(nf):
        c = contacts[:, f]
        last_lo = 0
        for k in range(t):
            if not c[k] and (k == 0 or c[k - 1]):
                last_lo = k
            if not c[k]:
                liftoff[k, f] = last_lo
        nxt = t
        for k in range(t - 1, -1, -1):
            if c[k] and (k == 0 or not c[k - 1]):
                nxt = k
            if not c[k]:
                touchdown[k, f] = nxt
        tds = [k for k in range(1, t) if c[k] and not c[k - 1]]
        strides += list(np.diff(tds))
    return liftoff, touchdown, float(np.mean(strides)) if strides else float("nan")


def plan_from_qpos(
    model: mujoco.MjModel,
    qpos: np.ndarray,
    fps: float,
    contacts: np.ndarray | None = None,
    feet: Sequence[str] | None = None,
    *,
    legs: LegSet | None = None,
    leg_length: float | None = None,
    smooth_s: float = 0.08,
    smooth_fast_s: float = 0.05,
) -> MotionPlan:
    """Build a :class:`MotionPlan` from a reference qpos trajectory.

    Args:
        model: the model the reference is for.
        qpos: (T, nq) reference frames at ``fps``.
        fps: frame rate [Hz].
        contacts: (T, nf) bool contact labels in the order of ``feet`` (default: a foot
            is in contact when its lowest point is within 2 % of the leg length of the
            lowest foot point of the clip).
        feet: foot names (default :func:`default_feet`); ignored when ``legs`` is given.
        legs: a prebuilt :class:`LegSet`.
        leg_length: for the default contact rule (default :func:`model_leg_length`).
        smooth_s: standard deviation [s] of a Gaussian smoothing of the horizontal CoM
            path before it is differentiated. Kinematic motions are not dynamically
            smooth (synthetic walks, for instance, move the root by up to 4 m/s for single
            frames), and twice-differentiated positions would ask for accelerations of
            several g. 0 disables it.
        smooth_fast_s: the same for the CoM height, roll/pitch/yaw and angular velocity,
            kept short so the vertical bounce and pitching of fast gaits survive.
            Foot paths are never smoothed.

    Raises:
        ControllerError: shapes do not fit, non-finite values, fps ≤ 0.
    """
    legs = LegSet(model, feet) if legs is None else legs
    q = np.atleast_2d(np.asarray(qpos, dtype=float))
    if q.ndim != 2 or q.shape[1] != model.nq or q.shape[0] < 1:
        raise ControllerError(f"plan qpos must have shape (T, {model.nq}), got {q.shape}")
    if not np.all(np.isfinite(q)):
        raise ControllerError("plan qpos is not finite")
    if not (np.isfinite(fps) and fps > 0):
        raise ControllerError(f"plan fps must be > 0, got {fps}")
    t, nf = q.shape[0], legs.n_feet
    d = mujoco.MjData(model)
    com = np.empty((t, 3))
    rot = np.empty((t, 3, 3))
    feet_pos = np.empty((t, nf, 3))
    for k in range(t):
        d.qpos[:] = q[k]
        mujoco.mj_kinematics(model, d)
        mujoco.mj_comPos(model, d)
        com[k] = d.subtree_com[legs.trunk]
        rot[k] = d.xmat[legs.trunk].reshape(3, 3)
        feet_pos[k] = legs.positions(d)
    rpy = rpy_from_matrix(rot)
    rpy[:, 2] = np.unwrap(rpy[:, 2])
    dt = 1.0 / fps
    for name, v in (("smooth_s", smooth_s), ("smooth_fast_s", smooth_fast_s)):
        if not (np.isfinite(v) and v >= 0):
            raise ControllerError(f"{name} must be finite and >= 0, got {v}")

    def smooth(x: np.ndarray, seconds: float) -> np.ndarray:
        sigma = float(seconds) * fps
        if sigma <= 0.1 or t < 3:
            return x
        from scipy.ndimage import gaussian_filter1d

        # pad by point reflection (2·x0 − x_k) so a linear trend is kept at the ends
        pad = min(int(np.ceil(4 * sigma)), t - 1)
        head = 2.0 * x[0] - x[pad:0:-1]
        tail = 2.0 * x[-1] - x[-2 : -pad - 2 : -1]
        y = gaussian_filter1d(np.concatenate([head, x, tail]), sigma, axis=0, mode="nearest")
        return y[pad : pad + t]

    def deriv(x: np.ndarray) -> np.ndarray:
        return np.gradient(x, dt, axis=0) if t > 1 else np.zeros_like(x)

    # angular velocity from consecutive rotations (world frame): log(R_{k+1} R_kᵀ)/dt
    omega = np.zeros((t, 3))
    if t > 1:
        rel = np.einsum("kij,klj->kil", rot[1:], rot[:-1])
        w = np.zeros((t - 1, 3))
        for k in range(t - 1):
            quat = np.zeros(4)
            mujoco.mju_mat2Quat(quat, rel[k].ravel())
            vel = np.zeros(3)
            mujoco.mju_quat2Vel(vel, quat, dt)
            w[k] = vel
        omega[1:-1] = 0.5 * (w[1:] + w[:-1])
        omega[0], omega[-1] = w[0], w[-1]
    if contacts is None:
        leg = model_leg_length(model, legs.feet) if leg_length is None else float(leg_length)
        low = feet_pos[:, :, 2] - legs.radius[None, :]
        cont = low < low.min() + 0.02 * leg
    else:
        cont = np.asarray(contacts, dtype=bool)
        if cont.shape != (t, nf):
            raise ControllerError(f"plan contacts must have shape ({t}, {nf}), got {cont.shape}")
    liftoff, touchdown, stride = _segments(cont)
    com = np.concatenate([smooth(com[:, :2], smooth_s), smooth(com[:, 2:], smooth_fast_s)], axis=1)
    rpy, omega = smooth(rpy, smooth_fast_s), smooth(omega, smooth_fast_s)
    com_vel = deriv(com)
    feet_vel = deriv(feet_pos)
    return MotionPlan(
        fps=float(fps),
        com=com,
        com_vel=com_vel,
        com_acc=deriv(com_vel),
        rpy=rpy,
        omega=omega,
        omega_dot=deriv(omega),
        feet=feet_pos,
        feet_vel=feet_vel,
        contacts=cont.copy(),
        liftoff=liftoff,
        touchdown=touchdown,
        stride_s=stride / fps if np.isfinite(stride) else float("nan"),
    )


# --------------------------------------------------------------------------- contacts
class ContactTracker:
    """Leg modes (:data:`STANCE`, :data:`SWING`, :data:`SEEK`) from schedule and touch.

    * scheduled stance and touching → STANCE;
    * scheduled stance, not touching → SEEK (no force, reach down) — a foot that was in
      STANCE keeps it for ``lost_s`` first, so a one-step bounce does not drop its force;
    * scheduled swing → SWING, except when the foot touches the ground after
      ``early_phase`` of its swing *near where it is meant to be* (``near``, see
      :meth:`update`): then STANCE until the schedule agrees (early touch-down). A touch
      earlier in the swing, or far from the swing target, is a scuff (a leg at a joint
      limit under a trunk a little low, a foot lagging its path), not a landing: planted
      there, half a step short, the foot would carry the body on a support polygon the
      plan never had. Across the bench every real early landing came after 88 % of the
      swing within 0.1 L of the target; with ``early_phase`` 0.5 a pig's trot planted
      its scuffing front feet at mid-swing, 0.5 L short, and pitched over;

    Args:
        n_feet: number of feet.
        lost_s: grace time [s] before a stance foot without contact loses its force.
        early_phase: swing phase after which a touch-down counts as early stance.
    """

    def __init__(self, n_feet: int, lost_s: float = 0.01, early_phase: float = 0.75) -> None:
        self.n = n_feet
        self.lost_s = float(lost_s)
        self.early_phase = float(early_phase)
        self.reset()

    def reset(self) -> None:
        self.mode = np.full(self.n, STANCE, dtype=int)
        self.early = [False] * self.n
        self.last_touch = [-math.inf] * self.n
        self.events = {"early_touchdown": 0, "lost_contact": 0}

    def update(
        self,
        t: float,
        scheduled: np.ndarray,
        touching: np.ndarray,
        phase: np.ndarray,
        near: np.ndarray | None = None,
    ) -> np.ndarray:
        """(nf,) modes at time ``t`` [s] from the scheduled stance, actual touch and swing
        phase (NaN in stance or unknown); ``near`` (nf,) bool: the swing foot is close to
        its swing target, so a touch counts as an early touch-down (default: all)."""
        mode, early, last = self.mode, self.early, self.last_touch
        new = [SWING] * self.n
        for i in range(self.n):
            touch = bool(touching[i])
            if touch:
                last[i] = t
            if scheduled[i]:
                early[i] = False
                if touch or (mode[i] == STANCE and t - last[i] <= self.lost_s):
                    new[i] = STANCE
                else:
                    new[i] = SEEK
                    if mode[i] == STANCE:
                        self.events["lost_contact"] += 1
            elif early[i]:
                new[i] = STANCE
            elif (
                touch
                and phase[i] >= self.early_phase  # NaN compares False
                and (near is None or near[i])
            ):
                early[i] = True
                new[i] = STANCE
                self.events["early_touchdown"] += 1
        self.mode = np.array(new)
        return self.mode


# --------------------------------------------------------------------------- swing
class SwingLegs:
    """Cartesian PD of the swing feet along the motion's own, corrected foot path.

    The wanted point of swing foot i at phase ``φ`` (``s = 3φ² − 2φ³``)::

        p_des = p_ref(t) + (1 − s)·δ_lo + s·Δ

    where ``δ_lo`` is the actual minus the reference foot point at lift-off and ``Δ`` the
    horizontal correction of the foothold (:meth:`correction`); ``v_des`` is its time
    derivative, and in the last 30 % of the swing the target sinks (quadratically) to
    ``seek_depth`` below the path, so a foot that lags still touches down on time. A
    :data:`SEEK` foot aims at its reference point pushed ``seek_depth`` into the ground,
    moving down at ``seek_speed``. Force ``F = Kp (p_des − p) + Kd (v_des − v)``, torques
    ``τ = J_ownᵀ F`` on the leg's own joints.

    Args:
        legs: the :class:`LegSet`.
        kp: (nf,) or scalar Cartesian stiffness [N/m].
        kd: (nf,) or scalar Cartesian damping [N·s/m].
        capture_gain: gain on the capture-point offset of the CoM velocity error,
            ``(ċ − ċ_ref)·sqrt(h/g)``.
        capture_pos_gain: gain on the horizontal CoM position error beyond following
            the body (see :meth:`correction`).
        capture_max: bound of the stepping feedback in ``Δ`` [m].
        seek_depth: how far below its reference point a SEEK foot aims [m].
        seek_speed: downward speed wanted of a SEEK foot [m/s].
    """

    def __init__(
        self,
        legs: LegSet,
        kp: float | np.ndarray,
        kd: float | np.ndarray,
        *,
        capture_gain: float = 1.0,
        capture_pos_gain: float = 0.3,
        capture_max: float = 0.1,
        seek_depth: float = 0.02,
        seek_speed: float = 0.3,
    ) -> None:
        nf = legs.n_feet
        self.legs = legs
        self.kp = np.broadcast_to(np.asarray(kp, dtype=float), (nf,)).copy()
        self.kd = np.broadcast_to(np.asarray(kd, dtype=float), (nf,)).copy()
        self.capture_gain = float(capture_gain)
        self.capture_pos_gain = float(capture_pos_gain)
        self.capture_max = float(capture_max)
        self.seek_depth = float(seek_depth)
        self.seek_speed = float(seek_speed)
        self.last_target = np.zeros((nf, 3))
        self.d_lo = np.zeros((nf, 3))

    def correction(
        self,
        com: np.ndarray,
        com_vel: np.ndarray,
        com_ref: np.ndarray,
        com_vel_ref: np.ndarray,
        height: float,
        gravity: float,
        heading: float | None = None,
    ) -> np.ndarray:
        """(3,) horizontal foothold correction Δ [m]::

            Δ = e + clip(k_v·ė·sqrt(h/g) + k_p·e, capture_max),   e = c − c_ref

        The first term places the foothold relative to the body, as Raibert's heuristic
        does (relative to the hip): a reference foothold kept in the world while the CoM
        is off by ``e`` is off by −e relative to the body, which pushes the CoM further
        away (the stance leg of an inverted pendulum accelerates the CoM away from the
        foot). The bounded second term is the stepping feedback: the capture point of
        the velocity error plus a share of the position error, so both decay.

        The stepping feedback is bounded per axis of the direction of travel, forward
        and sideways each by ``capture_max``, as Raibert's controller places the foot
        per body axis. A bound on the norm let the forward error of a fast gait (a lag
        of 0.3 m at 5 m/s) use up the budget, and the sideways feedback went with it:
        the camel's pace, standing on the feet of one side like a biped, drifted
        0.2–0.35 m sideways (tracking error 0.149 L; 0.120 L with the per-axis bound).
        The direction of travel is that of the reference CoM velocity when it exceeds
        ``0.1·sqrt(g·h)`` (the trunk's yaw sways in a pace: bounded along it, the same
        clip tracked at 0.169 L), else ``heading`` (reference yaw [rad]), else the
        world x/y axes.
        """
        w = math.sqrt(max(height, 1e-3) / max(gravity, 1e-9))
        kv, kp = self.capture_gain * w, self.capture_pos_gain
        ex, ey = float(com[0] - com_ref[0]), float(com[1] - com_ref[1])
        dx = kv * float(com_vel[0] - com_vel_ref[0]) + kp * ex
        dy = kv * float(com_vel[1] - com_vel_ref[1]) + kp * ey
        m = self.capture_max
        vr = (float(com_vel_ref[0]), float(com_vel_ref[1]))
        if math.hypot(*vr) > 0.1 * math.sqrt(gravity * height):
            heading = math.atan2(vr[1], vr[0])
        if heading is None:
            dx, dy = min(max(dx, -m), m), min(max(dy, -m), m)
        else:
            c, s = math.cos(heading), math.sin(heading)
            df = min(max(c * dx + s * dy, -m), m)  # forward
            dl = min(max(-s * dx + c * dy, -m), m)  # sideways (left)
            dx, dy = c * df - s * dl, s * df + c * dl
        return np.array([ex + dx, ey + dy, 0.0])

    def reset(self) -> None:
        self.d_lo[:] = 0.0
        self.last_target[:] = 0.0

    def lift_off(self, feet: np.ndarray, actual: np.ndarray, reference: np.ndarray) -> None:
        """Record ``δ_lo = actual − reference`` foot point for the feet (indices) that
        just lifted off."""
        self.d_lo[feet] = actual[feet] - reference[feet]

    def targets(
        self, sample: PlanSample, modes: np.ndarray, delta: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """(p_des, v_des), each (nf, 3), for the SWING and SEEK feet (others: reference).

        Without swing timing (NaN phase: no plan) the swing foot follows its reference
        point shifted by ``Δ``.
        """
        p = sample.feet.copy()
        v = sample.feet_vel.copy()
        for i, m in enumerate(modes.tolist()):
            if m == SWING:
                ph = float(sample.phase[i])
                if ph != ph:  # NaN: no swing timing (no plan)
                    p[i] += delta
                    continue
                s = ph * ph * (3.0 - 2.0 * ph)
                span = max(float(sample.t_touchdown[i] - sample.t_liftoff[i]), 1e-3)
                ds = 6.0 * ph * (1.0 - ph) / span
                d_lo = self.d_lo[i]
                p[i] += (1.0 - s) * d_lo + s * delta
                v[i] += ds * (delta - d_lo)
                if ph > 0.7:  # reach slightly into the ground so touch-down is not late
                    w = (ph - 0.7) / 0.3
                    p[i, 2] -= self.seek_depth * w * w
                    v[i, 2] -= self.seek_depth * 2.0 * w / (0.3 * span)
            elif m == SEEK:
                p[i] = sample.feet[i] + delta
                p[i, 2] = sample.feet[i, 2] - self.seek_depth
                v[i] = 0.0
                v[i, 2] = -self.seek_speed
        self.last_target = p
        return p, v

    def forces(
        self, p: np.ndarray, v: np.ndarray, p_des: np.ndarray, v_des: np.ndarray
    ) -> np.ndarray:
        """(nf, 3) Cartesian PD forces [N] on the feet (applied by the leg)."""
        return self.kp[:, None] * (p_des - p) + self.kd[:, None] * (v_des - v)
