"""Tracking runner: play a reference qpos trajectory through a controller in MuJoCo.

One clip goes ``Motion → motion_to_qpos → reference at the control rate → controller →
mj_step … → TrackResult`` (simulated qpos at the reference frames, foot contacts, falls,
metrics). The pieces, each usable alone:

* :func:`finite_differences` — (qvel, qacc) of a qpos trajectory at its frame rate
  (``mj_differentiatePos``, so the free joint's quaternion is handled correctly).
* :func:`build_reference` — the reference resampled at the simulation step: cubic Hermite
  for scalar coordinates and the root position, slerp for quaternions; velocities and
  accelerations are the frame-rate finite differences, interpolated linearly.
* :class:`FallDetector` — docs/metrics.md's fall rule, checked at every reference frame.
* :func:`track` — one clip, Python loop (any :class:`~habitsim.controllers.Controller`,
  optional root assistance) or, for in-engine servos without assistance, one
  ``mujoco.rollout`` call (no Python in the loop).
* :func:`track_many` — many clips: ``mujoco.rollout`` over threads when the PD lives in
  the actuators, else a thread pool over :func:`track`.

Failures are results, not exceptions: a fall or a numerically unstable run (NaN, any
MuJoCo warning) ends the clip and is reported (``fell``, ``unstable``, ``survival``).
Bad *inputs* (unknown species or controller, a model without the joints, NaN in the
reference) raise :class:`SimulationError` (or the motion's own typed errors).

Units: SI (m, s, rad, N, N·m); times in [s] from the clip's first frame.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any

import mujoco
import numpy as np

from . import mjutils
from .contacts import contacts_from_feet
from .controllers import CONTROLLERS, REGISTRY, ControllerError, make_controller
from .errors import InvalidMotionError, SimulationError, unknown_choice
from .mjutils import (
    HABITSIM_FEET,
    ModelLookupError,
    finite_differences,
    foot_soles,
    free_dofs,
    free_joints,
    home_qpos,
    leg_length,
    lowest_z,
)
from .mjutils import check_qpos as _check_qpos
from .motion import Motion
from .qpos import QposTrajectory, motion_to_qpos, qpos_to_motion, species_model
from .species import load_species

__all__ = [
    "SimulationError",
    "CONTROLLERS",
    "ReferenceTrajectory",
    "TrackResult",
    "FallDetector",
    "FALL_HEIGHT_RATIO",
    "FALL_TILT_DEG",
    "FALL_GROUND_CONTACT_S",
    "finite_differences",
    "build_reference",
    "foot_geoms",
    "FOOT_GEOMS",
    "MPC_CONTROL_HZ",
    "servo_model",
    "root_assist",
    "servo_targets",
    "track",
    "track_many",
]

#: docs/metrics.md fall rule: trunk height below this share of its reference height …
FALL_HEIGHT_RATIO = 0.5
#: … or trunk tilt (from the reference's trunk orientation) above this [deg] …
FALL_TILT_DEG = 60.0
#: … or a non-foot body touching the ground for longer than this [s].
FALL_GROUND_CONTACT_S = 0.2
#: A foot is "in contact" when its touch sensor reads more than this share of m·g.
TOUCH_THRESHOLD_MG = 0.01
#: A reference body counts as resting on the ground within this share of leg length.
GROUND_TOLERANCE_PER_LEG = 0.01

_FULL = mujoco.mjtState.mjSTATE_FULLPHYSICS


# --------------------------------------------------------------------------- reference
@dataclass(frozen=True)
class ReferenceTrajectory:
    """A reference sampled at the simulation step.

    Attributes:
        time: (N,) times [s] from the first frame (step i starts at i·dt).
        qpos: (N, nq) positions; qvel, qacc: (N, nv).
        dt: step [s].
    """

    time: np.ndarray
    qpos: np.ndarray
    qvel: np.ndarray
    qacc: np.ndarray
    dt: float


def _quat_slerp(q0: np.ndarray, q1: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Row-wise slerp of (N, 4) wxyz quaternions with weights a (N,)."""
    dot = np.sum(q0 * q1, axis=1)
    q1 = np.where(dot[:, None] < 0, -q1, q1)
    dot = np.abs(dot).clip(-1.0, 1.0)
    theta = np.arccos(dot)
    s = np.sin(theta)
    small = s < 1e-8
    w0 = np.where(small, 1.0 - a, np.sin((1.0 - a) * theta) / np.where(small, 1.0, s))
    w1 = np.where(small, a, np.sin(a * theta) / np.where(small, 1.0, s))
    out = w0[:, None] * q0 + w1[:, None] * q1
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def build_reference(
    model: mujoco.MjModel, qpos: np.ndarray, fps: float, dt: float | None = None
) -> ReferenceTrajectory:
    """Resample a frame-rate qpos trajectory at the simulation step.

    Scalar coordinates (hinges, slides, root position) use cubic Hermite interpolation
    with the finite-difference velocities as tangents; free/ball quaternions use slerp.
    qvel and qacc are the frame-rate finite differences, interpolated linearly.

    Args:
        model: the model.
        qpos: (T, nq) at ``fps``.
        fps: frame rate [Hz].
        dt: sampling step [s] (default ``model.opt.timestep``).

    Returns:
        The :class:`ReferenceTrajectory` covering [0, (T-1)/fps) in steps of ``dt``
        (one sample for a one-frame clip).
    """
    q = _check_qpos(model, qpos)
    if not (math.isfinite(fps) and fps > 0):
        raise SimulationError(f"fps must be positive, got {fps}")
    dt = float(model.opt.timestep if dt is None else dt)
    qvel, qacc = finite_differences(model, q, fps)
    t_frames = q.shape[0]
    n = max(1, int(round((t_frames - 1) / fps / dt)))
    times = np.arange(n) * dt
    s = np.clip(times * fps, 0.0, t_frames - 1)
    i0 = np.minimum(np.floor(s).astype(int), max(t_frames - 2, 0))
    i1 = np.minimum(i0 + 1, t_frames - 1)
    a = s - i0
    h = 1.0 / fps
    out_q = np.empty((n, model.nq))
    # velocity index of each scalar qpos coordinate (hinge/slide/free position)
    h00, h10 = 2 * a**3 - 3 * a**2 + 1, a**3 - 2 * a**2 + a
    h01, h11 = -2 * a**3 + 3 * a**2, a**3 - a**2
    for j in range(model.njnt):
        qa, va = model.jnt_qposadr[j], model.jnt_dofadr[j]
        jt = int(model.jnt_type[j])
        if jt == mujoco.mjtJoint.mjJNT_FREE:
            scal = [(qa + k, va + k) for k in range(3)]
            quat = qa + 3
        elif jt == mujoco.mjtJoint.mjJNT_BALL:
            scal, quat = [], qa
        else:
            scal, quat = [(qa, va)], None
        for qi, vi in scal:
            if t_frames == 1:
                out_q[:, qi] = q[0, qi]
                continue
            out_q[:, qi] = (
                h00 * q[i0, qi] + h10 * h * qvel[i0, vi] + h01 * q[i1, qi] + h11 * h * qvel[i1, vi]
            )
        if quat is not None:
            qa0, qa1 = q[i0, quat : quat + 4], q[i1, quat : quat + 4]
            out_q[:, quat : quat + 4] = _quat_slerp(qa0, qa1, a)
    out_v = (1 - a)[:, None] * qvel[i0] + a[:, None] * qvel[i1]
    out_a = (1 - a)[:, None] * qacc[i0] + a[:, None] * qacc[i1]
    return ReferenceTrajectory(times, out_q, out_v, out_a, dt)


# --------------------------------------------------------------------------- model helpers
def _free_body(model: mujoco.MjModel) -> int:
    free = free_joints(model)
    if len(free) != 1:
        raise SimulationError(
            f"the model needs exactly one free joint (the trunk), found {len(free)}"
        )
    return int(model.jnt_bodyid[free[0]])


def foot_geoms(model: mujoco.MjModel, feet: Sequence[str] | None = None) -> np.ndarray:
    """(nf,) geom ids of the feet: ``lf_foot, rf_foot, lh_foot, rh_foot`` (habitsim's
    models), or the colliding geom of each of ``feet``, named as the robot names them
    (site, geom or body; :func:`habitsim.mjutils.foot_geoms`).

    Raises:
        SimulationError: a foot geom is missing (the message lists the model's geoms), an
            unknown foot name.
    """
    try:
        return mjutils.foot_geoms(model, feet)
    except ModelLookupError as e:
        raise SimulationError(str(e)) from e


def _touch_adr(model: mujoco.MjModel, feet: Sequence[str] | None = None) -> np.ndarray | None:
    """(4,) sensordata addresses of ``<leg>_touch`` sensors, or None if any is missing
    (always None for a robot's named ``feet``: their contact forces are summed)."""
    if feet is not None:
        return None
    adr = []
    for leg in ("lf", "rf", "lh", "rh"):
        s = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SENSOR, f"{leg}_touch")
        if s < 0:
            return None
        adr.append(model.sensor_adr[s])
    return np.array(adr)


def _foot_forces(model: mujoco.MjModel, data: mujoco.MjData, feet: np.ndarray) -> np.ndarray:
    """(nf,) normal contact force [N] on each foot geom (from the contact list)."""
    out = np.zeros(len(feet))
    f6 = np.zeros(6)
    for c in range(data.ncon):
        con = data.contact[c]
        for k, g in enumerate(feet):
            if con.geom1 == g or con.geom2 == g:
                mujoco.mj_contactForce(model, data, c, f6)
                out[k] += abs(f6[0])
    return out


def _total_mass(model: mujoco.MjModel) -> float:
    return float(mujoco.mj_getTotalmass(model))


def _state_offsets(model: mujoco.MjModel) -> dict[str, int]:
    """Offsets of time/qpos/qvel inside an mjSTATE_FULLPHYSICS vector."""
    off, out = 0, {}
    for name in ("TIME", "QPOS", "QVEL"):
        out[name] = off
        off += mujoco.mj_stateSize(model, getattr(mujoco.mjtState, f"mjSTATE_{name}"))
    return out


# --------------------------------------------------------------------------- servos
#: Foot geoms in the order of contact labels (LF, RF, LH, RH).
FOOT_GEOMS = HABITSIM_FEET


def servo_model(model: mujoco.MjModel) -> mujoco.MjModel:
    """A copy of ``model`` whose joint motors are in-engine position servos.

    :func:`habitsim.controllers.servo.configure_servos` with its default gain rule
    (kp = τmax / 0.15 rad, critical kv on M_ii); torque limits are kept as force limits.
    """
    from .controllers.servo import configure_servos

    return configure_servos(model)


def servo_targets(
    model: mujoco.MjModel, qpos: np.ndarray, qvel: np.ndarray | None = None
) -> np.ndarray:
    """(N, nu) controls of in-engine servos for reference positions (N, nq) and, for the
    velocity lead, velocities (N, nv).

    The law of :class:`habitsim.controllers.servo.ServoController`
    (:meth:`~habitsim.controllers.servo.ServoMap.position_targets`), vectorised, so the
    ``mujoco.rollout`` path and the Python loop apply identical controls. Actuators that
    are not servos keep 0.

    Raises:
        SimulationError: the model has no joint position servos.
    """
    from .controllers import ControllerError
    from .controllers.servo import servo_map

    try:
        sm = servo_map(model)
    except ControllerError as e:
        raise SimulationError(f"{e}") from e
    q = np.atleast_2d(qpos)
    u = np.zeros((q.shape[0], model.nu))
    u[:, sm.actuator_ids] = sm.position_targets(q, None if qvel is None else np.atleast_2d(qvel))
    return u


def _servo_power(
    model: mujoco.MjModel, q: np.ndarray, v: np.ndarray, v_next: np.ndarray, ctrl: np.ndarray
) -> np.ndarray:
    """(N,) Σ|τ·q̇| of the servos per step: torque at (q, v) under ``ctrl`` (vectorised
    :meth:`~habitsim.controllers.servo.ServoMap.predicted_torque`) times ``v_next``."""
    from .controllers.servo import servo_map

    sm = servo_map(model)
    g = sm.gear
    qj, vj = q[:, sm.qpos_adr], v[:, sm.dof_adr]
    force = sm.kp / g**2 * (ctrl[:, sm.actuator_ids] - g * qj) - sm.kv / g**2 * (g * vj)
    tau = np.clip(g * force, sm.torque_lo, sm.torque_hi)
    return np.abs(tau * v_next[:, sm.dof_adr]).sum(axis=1)


# --------------------------------------------------------------------------- controllers
def _make_controller(
    controller: Any,
    model: mujoco.MjModel,
    clip: _Clip | None = None,
    control_dt: float | None = None,
) -> Any:
    """A controller instance for a name (on ``model``, already servo-configured when the
    name asks for servos) or the given instance. The balance-aware controllers
    (``balance``, ``mpc``) get the clip's reference plan (qpos, fps, contact table)."""
    if not isinstance(controller, str):
        if not hasattr(controller, "control"):
            raise SimulationError(
                f"controller must be one of {', '.join(CONTROLLERS)} or a Controller, "
                f"got {type(controller).__name__}"
            )
        if clip is not None and hasattr(controller, "set_plan"):
            controller.set_plan(clip.qpos, clip.fps, clip.contacts)
        return controller
    if controller not in CONTROLLERS:
        raise SimulationError(unknown_choice("controller", controller, CONTROLLERS))
    spec = REGISTRY[controller]
    kw: dict[str, Any] = {}
    if spec.planned:
        if control_dt is not None:
            kw["control_dt"] = control_dt
        if clip is not None:
            kw.update(qpos=clip.qpos, fps=clip.fps, contacts=clip.contacts)
            kw["species"] = clip.species if clip.feet is None else None
    if (spec.planned or controller.endswith("+stance")) and clip is not None:
        kw["feet"] = clip.feet
    try:
        return make_controller(controller, model, **kw)
    except ControllerError as e:
        raise SimulationError(f"controller {controller!r} does not fit the model: {e}") from e


#: Default torque-layer rate of the ``"mpc"`` controller [Hz] (MPC solves at 30 Hz).
#: Measured with ``habitsim bench balance --refine``: survival 100 % of 33 training
#: species × walk/trot/pace/turn at both 250 and 500 Hz, median sim MPJPE 0.036 vs 0.035
#: of leg length, 5.4× vs 3.5× real time. ``balance`` loses survival at 250 Hz and keeps
#: the full rate.
MPC_CONTROL_HZ = 250.0


#: Natural frequency of the default root assistance [Hz].
ASSIST_FREQUENCY_HZ = 5.0


def root_assist(model: mujoco.MjModel, frequency_hz: float = ASSIST_FREQUENCY_HZ) -> Any:
    """:class:`~habitsim.controllers.assist.RootAssist` with gains for the WHOLE body.

    Translation: ``kp = M·ω²``, ``kd = 2M·ω`` (ω = 2π·frequency, M the total mass).
    Rotation: the same with ``I = min(I_max, I_0 / (2ω·dt))``: I_max is the largest
    diagonal entry of the joint-space inertia of the free joint's rotational dofs at home
    (the whole body's inertia about the trunk origin), I_0 = 1/``dof_invweight0`` the
    effective rotational inertia with the other joints free (a lower bound). The
    assist's torque is explicit (held over a step), so its damping must stay below the
    stability limit ``kd·dt < 2·I_eff``; the cap keeps ``kd·dt/I_0 ≤ 1``. Axes with
    more inertia then run at a lower frequency than ω. (The assist's own default uses the
    trunk BODY's inertia, tens of times too small for a quadruped: a dog held in the air
    pitches nose-down.)
    """
    from .controllers.assist import RootAssist

    trunk = _free_body(model)
    dof = int(model.jnt_dofadr[model.body_jntadr[trunk]])
    d = mujoco.MjData(model)
    d.qpos[:] = home_qpos(model)
    mujoco.mj_forward(model, d)
    full = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, d, full)
    rot = np.diag(full)[dof + 3 : dof + 6]
    mass = float(model.body_subtreemass[trunk])
    w = 2.0 * math.pi * frequency_hz
    i0 = 1.0 / float(model.dof_invweight0[dof + 3 : dof + 6].max())
    inertia = float(min(rot.max(), i0 / (2.0 * w * model.opt.timestep)))
    return RootAssist(model, kp=(mass * w**2, inertia * w**2), kd=(2 * mass * w, 2 * inertia * w))


def _make_assist(assist: Any, model: mujoco.MjModel) -> Any:
    """None, or a :class:`~habitsim.controllers.assist.RootAssist` (or the given object)."""
    if assist is False or assist is None:
        return None
    if assist is True or assist == "root":
        return root_assist(model)
    if isinstance(assist, str):
        raise SimulationError(unknown_choice("assist", assist, ("root",)))
    if not (hasattr(assist, "apply") and hasattr(assist, "report")):
        raise SimulationError("assist must be 'root', True/False or a RootAssist-like object")
    return assist


# --------------------------------------------------------------------------- falls
class FallDetector:
    """docs/metrics.md's fall rule, evaluated at the reference frames.

    A run has fallen at frame k when (a) the trunk (free-joint body) is lower than
    :data:`FALL_HEIGHT_RATIO` × the reference trunk height at k, (b) the angle between
    the simulated and the reference trunk "up" axes exceeds :data:`FALL_TILT_DEG` (tilt is
    measured from the reference orientation, so a giraffe's sloping back or a sit does not
    count), or (c) a non-foot body has touched the ground for more than
    :data:`FALL_GROUND_CONTACT_S` (bodies that the reference itself rests on the ground at
    that frame, within 1 % of leg length, are allowed: e.g. the haunches of a sit).

    Args:
        model: the simulated model (with a floor: geoms of the world body).
        ref_qpos: (T, nq) reference frames.
        fps: frame rate [Hz].
        leg_length: normalising length [m].
        feet: foot names of a robot (default habitsim's foot geoms, see :func:`foot_geoms`).
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        ref_qpos: np.ndarray,
        fps: float,
        leg_length: float,
        feet: Sequence[str] | None = None,
    ) -> None:
        self.model = model
        self.fps = float(fps)
        self.trunk = _free_body(model)
        feet = foot_geoms(model, feet)
        self.foot_bodies = set(int(model.geom_bodyid[g]) for g in feet)
        self.ground = set(int(g) for g in np.flatnonzero(model.geom_bodyid == 0))
        q = _check_qpos(model, ref_qpos)
        # reference trunk height, up axis and bodies resting on the ground per frame
        colliding = np.flatnonzero(
            ((model.geom_contype != 0) | (model.geom_conaffinity != 0)) & (model.geom_bodyid != 0)
        )
        tol = GROUND_TOLERANCE_PER_LEG * leg_length
        d = mujoco.MjData(model)
        self.ref_height = np.empty(len(q))
        self.ref_up = np.empty((len(q), 3))
        pos = np.empty((len(q), len(colliding), 3))
        mat = np.empty((len(q), len(colliding), 9))
        for k in range(len(q)):
            d.qpos[:] = q[k]
            mujoco.mj_kinematics(model, d)
            self.ref_height[k] = d.xpos[self.trunk, 2]
            self.ref_up[k] = d.xmat[self.trunk, [2, 5, 8]]
            pos[k], mat[k] = d.geom_xpos[colliding], d.geom_xmat[colliding]
        near = lowest_z(model, colliding, pos, mat) < tol  # (T, n)
        bodies = model.geom_bodyid[colliding]
        self.ref_ground = [set(int(b) for b in bodies[row]) for row in near]
        self.contact_frames = 0

    def _ground_bodies(self, data: mujoco.MjData) -> set[int]:
        out = set()
        for c in range(data.ncon):
            con = data.contact[c]
            g1, g2 = int(con.geom1), int(con.geom2)
            if g1 in self.ground and g2 not in self.ground:
                out.add(int(self.model.geom_bodyid[g2]))
            elif g2 in self.ground and g1 not in self.ground:
                out.add(int(self.model.geom_bodyid[g1]))
        return out

    def reset(self) -> None:
        self.contact_frames = 0

    def check(self, k: int, data: mujoco.MjData) -> str | None:
        """The fall reason at frame k (``data`` after mj_step/mj_forward), or None."""
        k = min(k, len(self.ref_height) - 1)
        h = data.xpos[self.trunk, 2]
        if h < FALL_HEIGHT_RATIO * self.ref_height[k]:
            ref = self.ref_height[k]
            return f"trunk height {h:.3f} m < {FALL_HEIGHT_RATIO:.0%} of reference {ref:.3f} m"
        up = data.xmat[self.trunk, [2, 5, 8]]
        tilt = math.degrees(math.acos(float(np.clip(up @ self.ref_up[k], -1.0, 1.0))))
        if tilt > FALL_TILT_DEG:
            return f"trunk tilt {tilt:.0f} deg > {FALL_TILT_DEG:.0f} deg"
        touching = self._ground_bodies(data) - self.foot_bodies - self.ref_ground[k]
        if touching:
            self.contact_frames += 1
            if self.contact_frames / self.fps > FALL_GROUND_CONTACT_S:
                names = ", ".join(sorted(self.model.body(b).name for b in touching))
                return f"non-foot body on the ground > {FALL_GROUND_CONTACT_S} s ({names})"
        else:
            self.contact_frames = 0
        return None


# --------------------------------------------------------------------------- results
@dataclass
class TrackResult:
    """The outcome of tracking one clip.

    Attributes:
        species: species name (or the model name for a user model).
        fps: frame rate [Hz] of the reference and of the recorded frames.
        model: the simulated MuJoCo model (for the shipped species models a per-process
            cached instance shared by every run: copy it before modifying).
        qpos: (K, nq) simulated qpos at the reference frames that were reached (K ≤ T;
            K < T when the run stopped at a fall or instability).
        reference_qpos: (T, nq) reference frames.
        contacts: (K, 4) bool simulated foot contacts (touch > 1 % m·g), LF, RF, LH, RH.
        touch: (K, 4) foot normal forces [N].
        reference_contacts: (T, 4) bool reference contacts.
        fell: a fall by docs/metrics.md's rule; fall_time [s] and fall_reason say when/why.
        unstable: the simulation produced NaN or a MuJoCo warning (a failed run).
        survival: share of the clip completed before a fall or instability.
        controller: controller name; controller_stats: its ``stats.to_dict()``.
        assist: the assistance report (``{"assist_force_mg": 0.0}`` when off).
        work_j: Σ|τ·q̇|·dt over the survived part [J].
        wall_time_s: wall-clock time of the simulation loop [s].
        metrics: :data:`habitsim.metrics.simulated.SIMULATED_KEYS` → value.
    """

    species: str
    fps: float
    model: mujoco.MjModel
    qpos: np.ndarray
    reference_qpos: np.ndarray
    contacts: np.ndarray
    touch: np.ndarray
    reference_contacts: np.ndarray
    fell: bool
    fall_time: float | None
    fall_reason: str | None
    unstable: bool
    unstable_reason: str | None
    survival: float
    controller: str
    controller_stats: dict[str, Any]
    assist: dict[str, Any]
    work_j: float
    wall_time_s: float
    sim_time_s: float
    metrics: dict[str, Any] = field(default_factory=dict)

    @property
    def failed(self) -> bool:
        return self.fell or self.unstable

    def motion(self) -> Motion:
        """The simulated frames as a habitsim Motion (with simulated contacts)."""
        m = qpos_to_motion(self.model, self.qpos, self.species, self.fps)
        m.contacts = self.contacts.copy()
        m.metadata = {
            "source": "habitsim.sim.track",
            "controller": self.controller,
            "fell": self.fell,
            "fall_time": self.fall_time,
            "unstable": self.unstable,
            "survival": self.survival,
        }
        return m

    def report(self) -> dict[str, Any]:
        """JSON-ready report: every metric, failure info, controller stats, assist report."""
        return _clean(
            {
                "species": self.species,
                "fps": self.fps,
                "frames": int(self.reference_qpos.shape[0]),
                "frames_simulated": int(self.qpos.shape[0]),
                "duration_s": (self.reference_qpos.shape[0] - 1) / self.fps,
                "controller": self.controller,
                "timestep_s": float(self.model.opt.timestep),
                "fell": self.fell,
                "fall_time_s": self.fall_time,
                "fall_reason": self.fall_reason,
                "unstable": self.unstable,
                "unstable_reason": self.unstable_reason,
                "metrics": self.metrics,
                "controller_stats": self.controller_stats,
                "assist": self.assist,
                "mujoco_version": mujoco.__version__,
            }
        )


def _clean(v: Any) -> Any:
    if isinstance(v, dict):
        return {str(k): _clean(x) for k, x in v.items()}
    if isinstance(v, list | tuple):
        return [_clean(x) for x in v]
    if isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


# --------------------------------------------------------------------------- inputs
@dataclass
class _Clip:
    species: str
    base: mujoco.MjModel  # the model the reference was mapped on (torque motors or servos)
    qpos: np.ndarray  # (T, nq)
    fps: float
    contacts: np.ndarray  # (T, nf) bool reference contact labels
    leg_length: float
    feet: tuple[str, ...] | None = None  # a robot's foot names (None: habitsim's)


def _check_contacts(contacts: Any, n_frames: int, n_feet: int = 4) -> np.ndarray:
    """Explicit reference contact labels as (T, nf) bool."""
    c = np.asarray(contacts)
    if c.shape != (n_frames, n_feet):
        order = "feet LF, RF, LH, RH" if n_feet == 4 else f"{n_feet} feet"
        raise SimulationError(
            f"contacts must have shape ({n_frames}, {n_feet}) ({order}), got {c.shape}"
        )
    if c.dtype != bool and not np.isin(c, (0, 1)).all():
        raise SimulationError("contacts must be booleans (or 0/1)")
    return c.astype(bool)


def _resolve(
    motion_or_qpos: Motion | QposTrajectory | np.ndarray,
    species: str | None,
    model: mujoco.MjModel | None,
    fps: float | None = None,
    contacts: np.ndarray | None = None,
    feet: Sequence[str] | None = None,
) -> _Clip:
    """Reference qpos, contacts and sizes of one input clip (explicit ``contacts`` labels
    win over a motion's own and over detection). ``feet`` names a robot's feet: the
    clip is then a qpos trajectory of that robot (a Motion is retargeted first, see
    :mod:`habitsim.retarget`)."""
    if feet is not None:
        feet = tuple(feet)
        if not feet:
            raise SimulationError("feet=[] names no foot")
        if isinstance(motion_or_qpos, Motion):
            raise SimulationError(
                "a Motion is tracked on habitsim's own models; for a robot (feet=...) "
                "retarget it first (habitsim.retarget.retarget or `habitsim retarget`) and "
                "track the qpos trajectory"
            )
        if model is None:
            raise SimulationError("feet=... names a robot's feet: pass the robot as model=")
    if isinstance(motion_or_qpos, Motion):
        motion = motion_or_qpos
        if species is not None and load_species(species).name != motion.species:
            raise SimulationError(
                f"species {species!r} given but the motion is of {motion.species!r}"
            )
        base = _species_model(motion.species, False) if model is None else model
        try:
            traj = motion_to_qpos(motion, base)
        except InvalidMotionError as e:
            raise SimulationError(f"the motion does not fit the model: {e}") from e
        if contacts is not None:
            contacts = _check_contacts(contacts, motion.num_frames)
        elif motion.contacts is not None:
            contacts = motion.contacts
        else:
            contacts = motion.detect_contacts()
        sp = motion.species_info
        return _Clip(
            sp.name,
            base,
            _check_qpos(base, traj.qpos),
            motion.fps,
            np.asarray(contacts, bool),
            sp.leg_length,
        )
    if isinstance(motion_or_qpos, QposTrajectory | np.ndarray):
        if species is None and model is None:
            raise SimulationError("a qpos trajectory needs species= (or model=)")
        sp = load_species(species) if species is not None else None
        base = _species_model(sp.name, False) if model is None else model
        if isinstance(motion_or_qpos, QposTrajectory):
            q, f = motion_or_qpos.qpos, motion_or_qpos.fps
        else:
            if fps is None:
                raise SimulationError("a bare qpos array needs fps=")
            q, f = motion_or_qpos, fps
        q = _check_qpos(base, q)
        leg = sp.leg_length if sp is not None else _model_leg_length(base, feet)
        nf = 4 if feet is None else len(feet)
        if contacts is not None:
            contacts = _check_contacts(contacts, len(q), nf)
        else:
            contacts = contacts_from_feet(_foot_points(base, q, feet), f, leg)
        name = sp.name if sp is not None else "model"
        if sp is None and feet is not None:
            name = bytes(base.names).split(b"\0", 1)[0].decode() or "robot"
        return _Clip(name, base, q, float(f), contacts, leg, feet)
    raise SimulationError(
        f"expected a Motion or a QposTrajectory, got {type(motion_or_qpos).__name__}"
    )


def _model_leg_length(model: mujoco.MjModel, feet: Sequence[str] | None = None) -> float:
    """Normalising length of a user model without a species: the trunk's height above
    its feet at home (:func:`habitsim.mjutils.leg_length`)."""
    _free_body(model)
    foot_geoms(model, feet)  # a model without the feet fails here, naming its geoms
    try:
        return leg_length(model, feet)
    except ModelLookupError as e:
        raise SimulationError(str(e)) from e


def _foot_points(
    model: mujoco.MjModel, qpos: np.ndarray, names: Sequence[str] | None = None
) -> np.ndarray:
    """(T, nf, 3) lowest points of the foot spheres."""
    return foot_soles(model, qpos, foot_geoms(model, names))


def _species_model(species: str, servos: bool) -> mujoco.MjModel:
    """The shipped model of a species (:func:`habitsim.qpos.species_model`, the shared
    per-process cache; never mutated here)."""
    return species_model(species, servos)


def _has_servos(model: mujoco.MjModel) -> bool:
    from .controllers import ControllerError
    from .controllers.servo import servo_map

    try:
        servo_map(model)
    except ControllerError:
        return False
    return True


def _sim_model(controller: Any, clip: _Clip, given: mujoco.MjModel | None) -> mujoco.MjModel:
    """The model to simulate: servos for the servo controllers (unless already there);
    torque motors for ``pd``, ``balance`` and ``mpc`` by name on a model with position
    servos (a robot's: :func:`habitsim.controllers.robot.torque_model`, same limits)."""
    if (
        isinstance(controller, str)
        and REGISTRY.get(controller) is not None
        and REGISTRY[controller].actuators == "servo"
    ):
        if given is None:
            return _species_model(clip.species, True)
        return given if _has_servos(given) else servo_model(given)
    if isinstance(controller, str) and given is not None and _has_position_servos(given):
        from .controllers import ControllerError
        from .controllers.robot import torque_model

        try:
            return torque_model(given)
        except ControllerError as e:
            raise SimulationError(f"controller {controller!r} does not fit the model: {e}") from e
    return clip.base


def _has_position_servos(model: mujoco.MjModel) -> bool:
    from .controllers.robot import is_position_servo

    return any(
        is_position_servo(model, a) for a in range(int(getattr(model, "nactuator", model.nu)))
    )


# --------------------------------------------------------------------------- running
def _frame_steps(n_frames: int, fps: float, dt: float) -> np.ndarray:
    """Number of mj_steps after which frame k is recorded (frame 0: 0 steps)."""
    return np.round(np.arange(n_frames) / fps / dt).astype(int)


def _init_data(model: mujoco.MjModel, q0: np.ndarray, v0: np.ndarray) -> mujoco.MjData:
    d = mujoco.MjData(model)
    d.qpos[:] = q0
    d.qvel[:] = v0
    mujoco.mj_forward(model, d)
    return d


def _warnings(data: mujoco.MjData) -> int:
    return int(sum(w.number for w in data.warning))


def _warning_names(data: mujoco.MjData) -> str:
    names = [mujoco.mjtWarning(i).name for i, w in enumerate(data.warning) if w.number]
    return ", ".join(names) or "NaN state"


def _touch(
    model: mujoco.MjModel, data: mujoco.MjData, adr: np.ndarray | None, feet: np.ndarray
) -> np.ndarray:
    if adr is not None:
        return np.asarray(data.sensordata[adr], dtype=float).copy()
    return _foot_forces(model, data, feet)


def _joint_dofs(model: mujoco.MjModel) -> np.ndarray:
    """Every dof except the free joint's."""
    keep = np.ones(model.nv, bool)
    keep[free_dofs(model)] = False
    return np.flatnonzero(keep)


@dataclass
class _Run:
    """Raw outcome of one simulated clip, before metrics."""

    qpos: np.ndarray  # (K, nq) recorded frames
    touch: np.ndarray  # (K, 4)
    fall_frame: int | None
    fall_reason: str | None
    unstable_frame: int | None
    unstable_reason: str | None
    work_j: float  # Σ|τ·q̇|dt up to the end of the survived part
    wall_time_s: float
    sim_time_s: float
    assist_report: dict[str, Any] = field(default_factory=dict)


def _run_python(
    model: mujoco.MjModel,
    clip: _Clip,
    ctl: Any,
    assist: Any,
    control_every: int,
    settle_s: float,
    stop_on_fall: bool,
    detector: FallDetector,
) -> _Run:
    """Step-by-step loop with the controller (and assistance) called in Python."""
    from .controllers import Reference

    dt = model.opt.timestep
    ref = build_reference(model, clip.qpos, clip.fps, dt)
    fsteps = _frame_steps(len(clip.qpos), clip.fps, dt)
    n_total = int(fsteps[-1])
    adr, feet = _touch_adr(model, clip.feet), foot_geoms(model, clip.feet)
    jdofs = _joint_dofs(model)
    data = _init_data(model, clip.qpos[0], ref.qvel[0] if settle_s <= 0 else np.zeros(model.nv))
    # the assist rides on the controller when it can (Controller.control applies it)
    external_assist = None
    if assist is not None:
        if hasattr(ctl, "assist"):
            ctl.assist = assist
        else:
            external_assist = assist
    ctl.reset(model, data)
    if external_assist is not None:
        external_assist.reset(model, data)
    zeros = np.zeros(model.nv)

    def reference(i: int, hold: bool) -> Any:
        if hold:
            return Reference(0.0, ref.qpos[0], zeros, zeros, clip.contacts[0])
        k = min(int(ref.time[i] * clip.fps + 0.5), len(clip.contacts) - 1)
        return Reference(
            float(ref.time[i]), ref.qpos[i], ref.qvel[i], ref.qacc[i], clip.contacts[k]
        )

    def tick(r: Any) -> None:
        data.ctrl[:] = ctl.control(model, data, r)
        if external_assist is not None:
            external_assist.apply(model, data, r)

    wall0 = time.perf_counter()
    qs = [data.qpos.copy()]
    touches = [_touch(model, data, adr, feet)]
    fall = unstable = None
    fall_reason = unstable_reason = None
    for i in range(int(round(settle_s / dt))):  # optional hold of the first frame
        if i % control_every == 0:
            tick(reference(0, True))
        mujoco.mj_step(model, data)
    if settle_s > 0:
        if _warnings(data) or not np.all(np.isfinite(data.qpos)):
            unstable, unstable_reason = 0, f"unstable while settling: {_warning_names(data)}"
            n_total = 0
        qs[0] = data.qpos.copy()
        touches[0] = _touch(model, data, adr, feet)
        data.time = 0.0
    work = 0.0
    work_at_end = 0.0
    k = 1
    for i in range(n_total):
        if i % control_every == 0:
            tick(reference(i, False))
        mujoco.mj_step(model, data)
        tau = data.qfrc_actuator[jdofs] + data.qfrc_applied[jdofs]
        work += float(np.abs(tau * data.qvel[jdofs]).sum()) * dt
        while k < len(fsteps) and fsteps[k] == i + 1:
            if _warnings(data) or not np.all(np.isfinite(data.qpos)):
                unstable, unstable_reason = k, f"unstable: {_warning_names(data)}"
                break
            # mj_step leaves kinematics and sensors of the pre-step state: refresh them
            # (no effect on the next step) so frames, falls and touch match the state
            mujoco.mj_forward(model, data)
            qs.append(data.qpos.copy())
            touches.append(_touch(model, data, adr, feet))
            reason = detector.check(k, data)
            if reason is not None and fall is None:
                fall, fall_reason = k, reason
            if fall is None:
                work_at_end = work
            k += 1
        if unstable is not None or (fall is not None and stop_on_fall):
            break
    wall = time.perf_counter() - wall0
    rep: dict[str, Any] = {}
    if assist is not None:
        rep = dict(assist.report(data))
    return _Run(
        np.array(qs),
        np.array(touches).reshape(-1, len(feet)),
        fall,
        fall_reason,
        unstable,
        unstable_reason,
        work_at_end,
        wall,
        float(data.time),
        rep,
    )


def _run_rollout(
    model: mujoco.MjModel,
    clips: Sequence[_Clip],
    threads: int,
    settle_s: float,
    stop_on_fall: bool,
    detectors: Sequence[FallDetector],
) -> list[_Run]:
    """All clips of one servo model in one ``mujoco.rollout`` call (no Python per step).

    Controls are :func:`servo_targets` of the reference at every step. Rollout freezes a
    clip's state after a MuJoCo warning, so a stalled clock or a NaN marks instability.
    Falls are found afterwards on the recorded frames (same :class:`FallDetector`).
    """
    from mujoco import rollout

    dt = model.opt.timestep
    refs = [build_reference(model, c.qpos, c.fps, dt) for c in clips]
    fsteps = [_frame_steps(len(c.qpos), c.fps, dt) for c in clips]
    n_settle = int(round(settle_s / dt))
    nstep = max(1, max(int(f[-1]) for f in fsteps) + n_settle)
    wall0 = time.perf_counter()
    ctrl = np.empty((len(clips), nstep, model.nu))
    x0 = np.empty((len(clips), mujoco.mj_stateSize(model, _FULL)))
    for b, (c, r) in enumerate(zip(clips, refs, strict=True)):
        u = servo_targets(model, r.qpos, r.qvel)
        n = len(u)
        if n_settle:
            ctrl[b, :n_settle] = servo_targets(model, r.qpos[:1])[0]  # held at rest: no lead
        ctrl[b, n_settle : n_settle + n] = u
        ctrl[b, n_settle + n :] = u[-1]
        d = _init_data(model, c.qpos[0], r.qvel[0] if n_settle == 0 else np.zeros(model.nv))
        mujoco.mj_getState(model, d, x0[b], _FULL)
    datas = [mujoco.MjData(model) for _ in range(max(1, threads))]
    state, _ = rollout.rollout(model, datas, x0, ctrl)
    off = _state_offsets(model)
    scratch = mujoco.MjData(model)
    runs = []
    for b, c in enumerate(clips):
        adr, feet = _touch_adr(model, c.feet), foot_geoms(model, c.feet)
        st = state[b]
        expect = x0[b, off["TIME"]] + dt * np.arange(1, nstep + 1)
        bad = ~np.isfinite(st).all(axis=1) | (np.abs(st[:, off["TIME"]] - expect) > 0.5 * dt)
        first_bad = int(np.argmax(bad)) if bad.any() else None
        start = x0[b] if n_settle == 0 else st[n_settle - 1]
        mujoco.mj_setState(model, scratch, start, _FULL)
        scratch.ctrl[:] = 0.0 if n_settle == 0 else ctrl[b, n_settle - 1]
        mujoco.mj_forward(model, scratch)
        qs = [scratch.qpos.copy()]
        touches = [_touch(model, scratch, adr, feet)]
        fall = unstable = None
        fall_reason = unstable_reason = None
        end_step = n_settle  # steps simulated up to the end of the survived part
        if first_bad is not None and first_bad < n_settle:
            unstable, unstable_reason = 0, "unstable while settling (NaN or MuJoCo warning)"
        detectors[b].reset()
        for k in range(1, len(fsteps[b])):
            if unstable is not None or (fall is not None and stop_on_fall):
                break
            s = n_settle + int(fsteps[b][k]) - 1
            if first_bad is not None and first_bad <= s:
                unstable, unstable_reason = k, "unstable: NaN or MuJoCo warning in rollout"
                break
            mujoco.mj_setState(model, scratch, st[s], _FULL)
            scratch.ctrl[:] = ctrl[b, s]  # the state holds no controls: the last applied
            mujoco.mj_forward(model, scratch)
            qs.append(scratch.qpos.copy())
            touches.append(_touch(model, scratch, adr, feet))
            reason = detectors[b].check(k, scratch)
            if reason is not None and fall is None:
                fall, fall_reason = k, reason
            if fall is None:
                end_step = s + 1
        # power of step i: servo torque at the state before the step (as MuJoCo's
        # qfrc_actuator in the Python loop) times the velocity after it
        sl = slice(n_settle, end_step)
        before = np.concatenate([start[None], st[:nstep]])[sl]
        q_pre = before[:, off["QPOS"] : off["QPOS"] + model.nq]
        v_pre = before[:, off["QVEL"] : off["QVEL"] + model.nv]
        v_post = st[sl, off["QVEL"] : off["QVEL"] + model.nv]
        work = float(_servo_power(model, q_pre, v_pre, v_post, ctrl[b, sl]).sum() * dt)
        sim_t = (n_settle + int(fsteps[b][len(qs) - 1]) - n_settle) * dt
        runs.append(
            _Run(
                np.array(qs),
                np.array(touches),
                fall,
                fall_reason,
                unstable,
                unstable_reason,
                work,
                0.0,
                sim_t,
            )
        )
    # wall time per clip: the shared rollout and all pre/post-processing, split evenly
    per_clip = (time.perf_counter() - wall0) / len(clips)
    for r in runs:
        r.wall_time_s = per_clip
    return runs


def _finish(
    clip: _Clip,
    model: mujoco.MjModel,
    run: _Run,
    controller: str,
    stats: dict[str, Any],
) -> TrackResult:
    from .metrics.simulated import simulated_metrics

    mg = _total_mass(model) * float(np.linalg.norm(model.opt.gravity))
    n_ref = len(clip.qpos)
    duration = (n_ref - 1) / clip.fps if n_ref > 1 else 0.0
    fall_t = None if run.fall_frame is None else run.fall_frame / clip.fps
    end = [f for f in (run.fall_frame, run.unstable_frame) if f is not None]
    survival = min(end) / clip.fps / duration if end and duration > 0 else 1.0
    if end and duration == 0:
        survival = 0.0
    contacts = run.touch > TOUCH_THRESHOLD_MG * mg
    report = dict(run.assist_report) if run.assist_report else {"assist_on": False}
    report.setdefault("assist_force_mg", 0.0)
    res = TrackResult(
        species=clip.species,
        fps=clip.fps,
        model=model,
        qpos=run.qpos,
        reference_qpos=clip.qpos,
        contacts=contacts,
        touch=run.touch,
        reference_contacts=clip.contacts,
        fell=run.fall_frame is not None,
        fall_time=fall_t,
        fall_reason=run.fall_reason,
        unstable=run.unstable_frame is not None,
        unstable_reason=run.unstable_reason,
        survival=float(survival),
        controller=controller,
        controller_stats=stats,
        assist=report,
        work_j=run.work_j,
        wall_time_s=run.wall_time_s,
        sim_time_s=run.sim_time_s,
    )
    res.metrics = simulated_metrics(
        model,
        res.qpos,
        clip.qpos,
        res.contacts,
        clip.contacts,
        leg_length=clip.leg_length,
        survival=res.survival,
        fell=res.failed,
        work_j=run.work_j,
        assist_force_mg=float(report["assist_force_mg"]),
        sim_time_s=run.sim_time_s,
        wall_time_s=run.wall_time_s,
    )
    return res


def _rollout_stats(threads: int) -> dict[str, Any]:
    return {
        "calls": 0,
        "mean_time_ms": 0.0,
        "max_time_ms": 0.0,
        "failures": 0,
        "notes": [f"in-engine servos via mujoco.rollout ({threads} thread(s))"],
    }


def _control_every(model: mujoco.MjModel, control_hz: float | None) -> int:
    if control_hz is None:
        return 1
    if not (math.isfinite(control_hz) and control_hz > 0):
        raise SimulationError(f"control_hz must be positive, got {control_hz}")
    every = int(round(1.0 / (control_hz * model.opt.timestep)))
    if every < 1:
        raise SimulationError(
            f"control_hz {control_hz} is above the simulation rate {1 / model.opt.timestep:g} Hz"
        )
    return every


def _check_settle(settle_s: float) -> None:
    if not (math.isfinite(settle_s) and settle_s >= 0):
        raise SimulationError(f"settle_s must be finite and >= 0, got {settle_s}")


def track(
    motion_or_qpos: Motion | QposTrajectory,
    *,
    species: str | None = None,
    controller: str | Any = "servo",
    assist: bool | str | Any = False,
    model: mujoco.MjModel | None = None,
    control_hz: float | None = None,
    settle_s: float = 0.0,
    stop_on_fall: bool = True,
    seed: int | None = None,
    use_rollout: bool | None = None,
    contacts: np.ndarray | None = None,
    feet: Sequence[str] | None = None,
) -> TrackResult:
    """Track a reference motion in MuJoCo with a controller.

    The simulation starts at the reference's first frame (position and velocity; feet on
    the ground as the reference has them), the controller is called every
    ``1/control_hz`` s with the reference interpolated at that time
    (:func:`build_reference`), and the state is recorded at every reference frame, where
    falls (:class:`FallDetector`) and instability (NaN, any MuJoCo warning) are checked.

    Args:
        motion_or_qpos: a :class:`~habitsim.motion.Motion` or a
            :class:`~habitsim.qpos.QposTrajectory` (then ``species`` or ``model``).
        species: catalog species (checked against a Motion's).
        controller: a name of :data:`CONTROLLERS` — ``"servo"`` (in-engine position
            servos, ``ctrl`` = target angle), ``"pd"`` (explicit PD torques on the motors),
            ``"servo+stance"`` (plus the stance-leg trunk stabiliser, no external force),
            ``"balance"`` (stance-force QP every tick + swing-leg control on the torque
            motors) and ``"mpc"`` (convex single-rigid-body MPC feeding that QP), both
            planned from the clip's reference and contact table,
            ``"servo+id"`` / ``"servo+id+stance"`` (plus inverse-dynamics feed-forward) —
            or a :class:`~habitsim.controllers.Controller` instance for ``model``.
        assist: ``False``; ``True`` or ``"root"`` for
            :class:`~habitsim.controllers.assist.RootAssist` (an external wrench on the
            trunk, reported in ``assist``); or such an object.
        model: the model (default: the species' shipped model). Named servo controllers
            configure servos on it unless it has them already.
        control_hz: control rate [Hz] (default: every simulation step; for ``"mpc"`` by
            name without assistance :data:`MPC_CONTROL_HZ` — its torque layer holds a walk
            or trot as well at 250 Hz as at 500 Hz and runs 1.5× faster).
        settle_s: seconds to hold the first frame (from rest) before the clip starts.
        stop_on_fall: stop at the first fall (else simulate to the end; metrics still
            use the survived part only).
        seed: accepted for a uniform signature; every stage here is deterministic.
        use_rollout: force (True) or forbid (False) the ``mujoco.rollout`` path; by
            default it is used for ``"servo"`` without assistance at the full rate.
        contacts: (T, 4) bool reference contact labels (LF, RF, LH, RH): the contact
            schedule of ``balance`` / ``mpc`` and the reference of ``contact_f1``.
            Default: a Motion's own labels, else contacts detected on the reference
            (for a qpos trajectory always detected). Pass the labels an earlier stage
            decided (refinement's) so they are not detected again. With ``feet``:
            (T, nf) in the order of ``feet``.
        feet: a robot's foot names (sites, geoms or bodies, as the robot names them,
            e.g. ``["FL", "FR", "RL", "RR"]`` on Menagerie's Unitree robots) when
            ``model`` is not a habitsim species model: the controllers' feet, the touch
            and contact labels, and the fall rule's allowed ground contacts. The input is
            then a qpos trajectory of the robot (:func:`habitsim.retarget.retarget` makes
            one from a Motion). A robot with position servos is simulated with torque
            motors of the same strength for ``pd``, ``balance`` and ``mpc``
            (:func:`habitsim.controllers.robot.torque_model`).

    Returns:
        The :class:`TrackResult` (metrics in :attr:`TrackResult.metrics`).

    Raises:
        SimulationError: unknown controller or assist, bad rates, a reference that does
            not fit the model (joints, nq) or is not finite, contacts of the wrong shape.
        UnknownSpeciesError: unknown species.
    """
    del seed
    _check_settle(settle_s)
    clip = _resolve(motion_or_qpos, species, model, contacts=contacts, feet=feet)
    sim_model = _sim_model(controller, clip, model)
    asst = _make_assist(assist, sim_model)
    if control_hz is None and controller == "mpc" and asst is None:
        # (a root assist is an explicit wrench held over a control period: its gains are
        # set for one simulation step, so assisted runs keep the full rate)
        control_hz = MPC_CONTROL_HZ
    every = _control_every(sim_model, control_hz)
    fast = controller == "servo" and asst is None and every == 1
    if use_rollout and not fast:
        raise SimulationError("use_rollout needs controller='servo', no assist, full rate")
    detector = FallDetector(sim_model, clip.qpos, clip.fps, clip.leg_length, clip.feet)
    if use_rollout if use_rollout is not None else fast:
        run = _run_rollout(sim_model, [clip], 1, settle_s, stop_on_fall, [detector])[0]
        return _finish(clip, sim_model, run, "servo", _rollout_stats(1))
    ctl = _make_controller(
        controller, sim_model, clip, None if every == 1 else every * sim_model.opt.timestep
    )
    run = _run_python(sim_model, clip, ctl, asst, every, settle_s, stop_on_fall, detector)
    name = controller if isinstance(controller, str) else str(getattr(ctl, "name", "custom"))
    return _finish(clip, sim_model, run, name, ctl.stats.to_dict())


def track_many(
    motions: Sequence[Motion | QposTrajectory],
    *,
    species: str | None = None,
    controller: str | Callable[[mujoco.MjModel], Any] = "servo",
    assist: bool | str = False,
    control_hz: float | None = None,
    settle_s: float = 0.0,
    stop_on_fall: bool = True,
    threads: int | None = None,
) -> list[TrackResult]:
    """Track many clips in parallel threads.

    With ``controller="servo"``, no assistance and the full control rate, the clips of
    each species run in ONE ``mujoco.rollout`` call over ``threads`` threads (the PD lives
    in the actuators, no Python per step). Otherwise a thread pool runs :func:`track` per
    clip (MuJoCo releases the GIL while stepping, the controllers' Python does not).

    Args:
        motions: the clips.
        species: species of QposTrajectory inputs.
        controller: a controller name, or a factory ``model -> Controller`` called once
            per clip with the model to simulate (controllers keep state).
        assist, control_hz, settle_s, stop_on_fall: as in :func:`track`.
        threads: worker threads (default: the CPU count).

    Returns:
        One :class:`TrackResult` per clip, in input order.
    """
    import os

    threads = int(threads or os.cpu_count() or 1)
    if threads < 1:
        raise SimulationError(f"threads must be >= 1, got {threads}")
    _check_settle(settle_s)
    if isinstance(controller, str) and controller not in CONTROLLERS:
        raise SimulationError(unknown_choice("controller", controller, CONTROLLERS))
    if not motions:
        return []
    fast = controller == "servo" and not assist and control_hz is None
    if not fast:

        def one(m: Motion | QposTrajectory) -> TrackResult:
            ctl: Any = controller
            mdl = None
            if not isinstance(controller, str):
                mdl = _resolve(m, species, None).base
                ctl = controller(mdl)
            return track(
                m,
                species=species,
                controller=ctl,
                assist=assist,
                model=mdl,
                control_hz=control_hz,
                settle_s=settle_s,
                stop_on_fall=stop_on_fall,
                use_rollout=False,
            )

        with ThreadPoolExecutor(max_workers=threads) as ex:
            return list(ex.map(one, motions))
    clips = [_resolve(m, species, None) for m in motions]
    results: list[TrackResult | None] = [None] * len(clips)
    groups: dict[str, list[int]] = {}
    for i, c in enumerate(clips):
        groups.setdefault(c.species, []).append(i)
    for idx in groups.values():
        sim_model = _sim_model("servo", clips[idx[0]], None)
        group = [clips[i] for i in idx]
        dets = [FallDetector(sim_model, c.qpos, c.fps, c.leg_length) for c in group]
        runs = _run_rollout(sim_model, group, threads, settle_s, stop_on_fall, dets)
        for i, c, r in zip(idx, group, runs, strict=True):
            results[i] = _finish(c, sim_model, r, "servo", _rollout_stats(threads))
    return [r for r in results if r is not None]
