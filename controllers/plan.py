"""The reference motion seen as a plan (:class:`MotionPlan`, :func:`plan_from_qpos`).

Per frame the whole-body centre of mass (position, velocity, acceleration), trunk
roll/pitch/yaw (yaw unwrapped) and angular velocity, foot positions and velocities, and
the contact table; per foot and frame the lift-off and touch-down times and the
touch-down foothold. :meth:`MotionPlan.sample` interpolates it at any time
(:class:`PlanSample`). :func:`rpy_from_matrix` / :func:`matrix_from_rpy` convert trunk
orientations (ZYX).

Units: SI (m, s, kg, N, N·m, rad); world frame z up.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import mujoco
import numpy as np

from habitsim.physics_constants import CONTACT_HEIGHT_PER_LEG
from habitsim.stance.labels import stance_runs, swing_bounds

from .base import ControllerError
from .legs import LegSet, model_leg_length

__all__ = ["MotionPlan", "PlanSample", "plan_from_qpos", "rpy_from_matrix", "matrix_from_rpy"]


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
    # Lookup tables of :meth:`sample`, derived by ``__post_init__``.
    _pack: np.ndarray = field(init=False, repr=False, compare=False)
    _foothold: np.ndarray = field(init=False, repr=False, compare=False)
    _t_lo: np.ndarray = field(init=False, repr=False, compare=False)
    _t_td: np.ndarray = field(init=False, repr=False, compare=False)
    _feet_idx: np.ndarray = field(init=False, repr=False, compare=False)

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


def _mean_stride(contacts: np.ndarray) -> float:
    """Mean interval between successive touch-downs of a foot, over all feet [frames]
    (NaN when no foot touches down twice); a stance at frame 0 is not a touch-down."""
    strides: list[int] = []
    for foot_runs in stance_runs(contacts):
        tds = [a for a, _ in foot_runs if a > 0]
        strides += np.diff(tds).tolist()
    return float(np.mean(strides)) if strides else float("nan")


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
        cont = low < low.min() + CONTACT_HEIGHT_PER_LEG * leg
    else:
        cont = np.asarray(contacts, dtype=bool)
        if cont.shape != (t, nf):
            raise ControllerError(f"plan contacts must have shape ({t}, {nf}), got {cont.shape}")
    liftoff, touchdown = swing_bounds(cont)
    stride = _mean_stride(cont)
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
