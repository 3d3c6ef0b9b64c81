"""In-engine PD servos: turn a model's torque motors into MuJoCo position / pid actuators.

An explicit PD law computes torques once per control tick and holds them over the step,
which limits how stiff and how damped it can be (see
:func:`habitsim.controllers.gains.max_stable_gains`). A MuJoCo position actuator computes
``force = kp·(ctrl − q) − kv·q̇`` inside every step, and with the ``implicitfast``
integrator its velocity term is integrated implicitly, so critical damping is stable
even on light joints (tails, heads, toes).

:func:`configure_servos` returns a COPY of the model in which the chosen joints' motors
have become such servos, keeping each motor's torque limit as the servo's force limit.
:class:`ServoController` then only writes the target joint angles to ``ctrl``.

Example::

    servo_model = configure_servos(model)              # kp = τmax/0.15, critical kv
    ctrl = ServoController(servo_model)
    data = mujoco.MjData(servo_model)
    data.ctrl[:] = ctrl.control(servo_model, data, ref)
"""

from __future__ import annotations

import copy
import functools
from collections.abc import Sequence
from dataclasses import dataclass

import mujoco
import numpy as np

from .base import (
    BaseController,
    ControllerError,
    JointActuatorMap,
    Reference,
    actuated_joints,
    joint_torques,
)
from .gains import effective_inertia, stiffness_rule

__all__ = ["ServoMap", "configure_servos", "servo_map", "ServoController", "has_pid_actuator"]

_KINDS = ("position", "pid")


def has_pid_actuator() -> bool:
    """True if the installed MuJoCo has the built-in pid actuator (gain, bias and dynamics
    types ``mjGAIN_PID`` / affine bias / ``mjDYN_PID``; MuJoCo 3.3.3 and later)."""
    return hasattr(mujoco.mjtGain, "mjGAIN_PID") and hasattr(mujoco.mjtDyn, "mjDYN_PID")


@dataclass(frozen=True)
class ServoMap:
    """The in-engine servos of a configured model, one entry per controlled joint.

    Attributes:
        names, joint_ids, qpos_adr, dof_adr, actuator_ids: as in
            :class:`~habitsim.controllers.JointActuatorMap`.
        kind: "position" or "pid" per joint.
        kp: stiffness [N·m/rad]; kv: damping [N·m·s/rad]; ki: integral gain [N·m/(rad·s)]
            (0 for position servos). All in joint units (gear folded in).
        gear: actuator gear (ctrl = gear · target angle; torque = gear · force).
        ctrl_lo, ctrl_hi: control range (±inf if unlimited), actuator units.
        torque_lo, torque_hi: joint torque range the servo can give [N·m] (±inf if not
            force-limited).
        ctrl_ids: index in ``data.ctrl`` of each position target.
        vel_ctrl_ids: index in ``data.ctrl`` of each velocity target (MuJoCo ≥ 4 pid
            actuators take one), −1 where the servo has none (D acts on −q̇ only).
    """

    names: tuple[str, ...]
    joint_ids: np.ndarray
    qpos_adr: np.ndarray
    dof_adr: np.ndarray
    actuator_ids: np.ndarray
    kind: tuple[str, ...]
    kp: np.ndarray
    kv: np.ndarray
    ki: np.ndarray
    gear: np.ndarray
    ctrl_lo: np.ndarray
    ctrl_hi: np.ndarray
    torque_lo: np.ndarray
    torque_hi: np.ndarray
    ctrl_ids: np.ndarray | None = None
    vel_ctrl_ids: np.ndarray | None = None

    @property
    def ctrl_index(self) -> np.ndarray:
        """(n,) index in ``data.ctrl`` of each servo's position target."""
        return self.actuator_ids if self.ctrl_ids is None else self.ctrl_ids

    @property
    def has_vel_target(self) -> np.ndarray:
        """(n,) bool, servo takes a velocity target control."""
        if self.vel_ctrl_ids is None:
            return np.zeros(len(self.names), dtype=bool)
        return self.vel_ctrl_ids >= 0

    def position_targets(self, qpos: np.ndarray, qvel: np.ndarray | None = None) -> np.ndarray:
        """Position-target controls ``gear · q_target`` (…, n) of reference positions
        ``qpos`` (…, nq), clipped to the control range.

        With the reference velocities ``qvel`` (…, nv), servos without a velocity target
        get a velocity lead, ``q_target = q_ref + (kv/kp)·q̇_ref``: a position actuator's
        D term acts on −q̇ alone, and ``kp·(q_ref + kv/kp·q̇_ref − q) − kv·q̇ =
        kp·(q_ref − q) + kv·(q̇_ref − q̇)`` turns it into damping of the velocity ERROR,
        inside the actuator and under its own force limit. Without the lead a servo
        brakes every fast reference motion by kv·q̇_ref (a swinging fore leg lags by
        10–15° and its foot drags on the ground).
        """
        q = np.asarray(qpos)[..., self.qpos_adr]
        if qvel is not None:
            q = q + self.lead_rate * np.asarray(qvel)[..., self.dof_adr]
        return np.clip(self.gear * q, self.ctrl_lo, self.ctrl_hi)

    @functools.cached_property
    def lead_rate(self) -> np.ndarray:
        """(n,) kv/kp [s] of the velocity lead (0 where a servo takes a velocity target
        or has no stiffness)."""
        kp = self.kp
        return np.where(self.has_vel_target | (kp <= 0), 0.0, self.kv / np.where(kp > 0, kp, 1.0))

    @property
    def torque_limit(self) -> np.ndarray:
        """(n,) largest |torque| [N·m] each servo can give."""
        return np.maximum(np.abs(self.torque_lo), np.abs(self.torque_hi))

    def predicted_torque(
        self,
        model: mujoco.MjModel,
        data: mujoco.MjData,
        ctrl: np.ndarray,
        vel_ctrl: np.ndarray | None = None,
    ) -> np.ndarray:
        """(n,) joint torque the servos will give for position targets ``ctrl`` (n,) (and
        velocity targets ``vel_ctrl`` where a servo takes one) at the current state.

        Exact up to the implicit velocity term of the coming step; pid servos use the
        current integral state.
        """
        q = data.qpos[self.qpos_adr]
        qd = data.qvel[self.dof_adr]
        g = self.gear
        vt = np.zeros_like(q) if vel_ctrl is None else np.where(self.has_vel_target, vel_ctrl, 0.0)
        force = self.kp / g**2 * (ctrl - g * q) + self.kv / g**2 * (vt - g * qd)
        pid = self.ki != 0
        if np.any(pid):
            adr = model.actuator_actadr[self.actuator_ids[pid]]
            force[pid] += self.ki[pid] / g[pid] ** 2 * data.act[adr]
        return np.clip(g * force, self.torque_lo, self.torque_hi)


def _torque_limits(jmap: JointActuatorMap) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) joint torque range of the original actuators (motor: gear·gain·ctrl range)."""
    a = jmap.torque_per_ctrl * jmap.ctrl_lo
    b = jmap.torque_per_ctrl * jmap.ctrl_hi
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    lo = np.where(np.isnan(lo), -np.inf, lo)
    hi = np.where(np.isnan(hi), np.inf, hi)
    g = np.abs(jmap.gear)
    if jmap.force_lo is not None and jmap.force_hi is not None:
        if jmap.biased is not None:  # servo being re-configured: only its force range counts
            lo = np.where(jmap.biased, -np.inf, lo)
            hi = np.where(jmap.biased, np.inf, hi)
        lo = np.maximum(lo, -g * np.maximum(np.abs(jmap.force_lo), np.abs(jmap.force_hi)))
        hi = np.minimum(hi, g * np.maximum(np.abs(jmap.force_lo), np.abs(jmap.force_hi)))
    return lo, hi


def _check_convertible(model: mujoco.MjModel, jmap: JointActuatorMap) -> None:
    bad = []
    for name, a in zip(jmap.names, jmap.actuator_ids, strict=True):
        motor = (
            model.actuator_gaintype[a] == mujoco.mjtGain.mjGAIN_FIXED
            and model.actuator_biastype[a] == mujoco.mjtBias.mjBIAS_NONE
        )
        servo = model.actuator_biastype[a] == mujoco.mjtBias.mjBIAS_AFFINE
        dyn_ok = (int(mujoco.mjtDyn.mjDYN_NONE), int(getattr(mujoco.mjtDyn, "mjDYN_PID", -1)))
        if not (motor or servo) or int(model.actuator_dyntype[a]) not in dyn_ok:
            bad.append(name)
    if bad:
        raise ControllerError(
            "configure_servos converts torque motors (fixed gain, no bias, no activation "
            f"dynamics) or existing servos; these joints have other actuators: {', '.join(bad)}"
        )


def _gains(
    model: mujoco.MjModel,
    jmap: JointActuatorMap,
    kp,
    dampratio: float,
    inertia: str,
    lo: np.ndarray,
    hi: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    n = len(jmap.names)
    if kp is None:
        limited = np.isfinite(lo) & np.isfinite(hi)
        mode = "torque" if np.all(limited) else "gravity"
        if mode == "torque":
            # the original motors' limits: kp = τmax / 0.15 rad (see gains module)
            kp_a = np.maximum(np.abs(lo), np.abs(hi)) / 0.15
        else:
            kp_a = stiffness_rule(model, jmap.names, mode="gravity")
    else:
        try:
            kp_a = np.broadcast_to(np.asarray(kp, dtype=float), (n,)).copy()
        except ValueError:
            raise ControllerError(f"kp must be a scalar or have {n} entries") from None
    if not np.all(np.isfinite(kp_a)) or np.any(kp_a <= 0):
        raise ControllerError("servo kp must be finite and > 0")
    if not (np.isfinite(dampratio) and dampratio >= 0):
        raise ControllerError(f"dampratio must be finite and >= 0, got {dampratio}")
    m_eff = effective_inertia(model, jmap.names, method=inertia)
    kv = dampratio * 2.0 * np.sqrt(kp_a * m_eff)
    return kp_a, kv


def configure_servos(
    model: mujoco.MjModel | mujoco.MjSpec,
    joints: Sequence[str] | None = None,
    *,
    kp: float | np.ndarray | None = None,
    dampratio: float = 1.0,
    kind: str = "position",
    ki: float | np.ndarray = 0.0,
    imax: float | np.ndarray | None = None,
    inertia: str = "fullM",
) -> mujoco.MjModel:
    """A copy of ``model`` whose joint motors are in-engine PD servos.

    Each chosen actuator becomes ``force = kp·(ctrl − q) − kv·q̇`` (``kind="position"``:
    gain type fixed with ``gainprm[0] = kp``, bias affine with ``biasprm[:3] = [0, −kp,
    −kv]``, gear 1, so ``ctrl`` is the target angle [rad]) or MuJoCo's built-in pid
    actuator (``kind="pid"``: additionally ``ki·∫(ctrl − q)dt`` kept in an activation
    state, clamped to ``imax``). The control range becomes the joint range (if the joint
    is limited), and the force range becomes the original motor's torque range
    (gear · gain · ctrl range, intersected with any force range it had), so torque limits
    are preserved: the servos are force-limited exactly like the motors were.

    ``kv = dampratio · 2 · sqrt(kp · m_eff)``; ``m_eff`` by default is the joint-space
    inertia diagonal ``M_ii`` (``mj_fullM``, armature included) at the home keyframe, or
    ``qpos0`` if the model has none (``inertia="fullM"``): the inertia with all other
    joints held, an upper bound, so ``dampratio = 1`` is at least critical.
    ``inertia="invweight0"`` uses MuJoCo's ``1/dof_invweight0`` instead (other joints
    free, smaller, what MuJoCo's own ``dampratio`` attribute uses).

    The input is never modified.

    Args:
        model: a compiled ``MjModel`` (kind "position") or an ``MjSpec`` (either kind).
        joints: joint names (default: every hinge/slide joint driven by a joint
            actuator).
        kp: stiffness [N·m/rad] per joint or one value; default
            ``τmax / 0.15 rad`` (:func:`~habitsim.controllers.gains.stiffness_rule` mode
            "torque") when every motor is torque-limited, else the gravity rule.
        dampratio: damping ratio ζ (1 = critical).
        kind: "position" or "pid".
        ki: pid only, integral gain [N·m/(rad·s)] per joint or one value.
        imax: pid only, clamp of the integral term [N·m]; default none.
        inertia: "fullM" or "invweight0", see above.

    Returns:
        The configured compiled ``MjModel`` (a new object).

    Raises:
        ControllerError: unknown joints (the message lists the valid ones), bad gains, an
            actuator that is neither a torque motor nor a servo, an unknown kind, or
            ``kind="pid"`` on a compiled model (the pid actuator adds one activation state
            per actuator, which only the model compiler can add: pass an ``MjSpec``) or on
            a MuJoCo without the pid actuator.
    """
    if kind not in _KINDS:
        raise ControllerError(f"unknown servo kind {kind!r}; valid: {', '.join(_KINDS)}")
    if kind == "pid" and not has_pid_actuator():
        raise ControllerError(
            f"kind='pid' needs MuJoCo's built-in pid actuator (mjGAIN_PID / mjDYN_PID), "
            f"which mujoco {mujoco.__version__} does not expose; use kind='position'"
        )
    if isinstance(model, mujoco.MjSpec):
        return _configure_spec(
            model, joints, kp=kp, dampratio=dampratio, kind=kind, ki=ki, imax=imax, inertia=inertia
        )
    if kind == "pid":
        raise ControllerError(
            "kind='pid' adds an integral (activation) state to each actuator, which cannot "
            "be added to an already compiled MjModel; pass a mujoco.MjSpec instead, e.g. "
            "configure_servos(mujoco.MjSpec.from_file(path), kind='pid', ki=...)"
        )
    jmap = actuated_joints(model, joints)
    _check_convertible(model, jmap)
    if np.any(model.actuator_actnum[jmap.actuator_ids] > 0):
        raise ControllerError("re-configuring pid servos of a compiled model needs an MjSpec")
    lo, hi = _torque_limits(jmap)
    kp_a, kv = _gains(model, jmap, kp, dampratio, inertia, lo, hi)
    out = _copy(model)
    for k, a in enumerate(jmap.actuator_ids):
        j = jmap.joint_ids[k]
        out.actuator_gaintype[a] = mujoco.mjtGain.mjGAIN_FIXED
        out.actuator_gainprm[a, :] = 0.0
        out.actuator_gainprm[a, 0] = kp_a[k]
        out.actuator_biastype[a] = mujoco.mjtBias.mjBIAS_AFFINE
        out.actuator_biasprm[a, :] = 0.0
        out.actuator_biasprm[a, 1] = -kp_a[k]
        out.actuator_biasprm[a, 2] = -kv[k]
        out.actuator_gear[a, :] = 0.0
        out.actuator_gear[a, 0] = 1.0
        out.actuator_dyntype[a] = mujoco.mjtDyn.mjDYN_NONE
        c = jmap.ctrl_index[k]  # ctrl-indexed arrays (MuJoCo >= 4: nu counts controls)
        if model.jnt_limited[j]:
            out.actuator_ctrllimited[c] = 1
            out.actuator_ctrlrange[c] = model.jnt_range[j]
        else:
            out.actuator_ctrllimited[c] = 0
        if hasattr(out, "actuator_ctrlspec"):  # MuJoCo >= 4: what the control means
            out.actuator_ctrlspec[a] = 1  # as a <position> actuator: a position target
        limited = bool(np.isfinite(lo[k]) and np.isfinite(hi[k]))
        out.actuator_forcelimited[a] = int(limited)
        if limited:
            out.actuator_forcerange[a] = (lo[k], hi[k])
    return out


def _copy(model: mujoco.MjModel) -> mujoco.MjModel:
    """A deep copy of a compiled model (``MjModel.__copy__`` copies all arrays)."""
    out = copy.copy(model)
    if np.shares_memory(out.actuator_gainprm, model.actuator_gainprm):  # pragma: no cover
        raise ControllerError("this mujoco version's MjModel copy shares memory")
    return out


def _configure_spec(
    spec: mujoco.MjSpec, joints, *, kp, dampratio, kind, ki, imax, inertia
) -> mujoco.MjModel:
    work = spec.copy()
    model = work.compile()
    jmap = actuated_joints(model, joints)
    _check_convertible(model, jmap)
    lo, hi = _torque_limits(jmap)
    kp_a, kv = _gains(model, jmap, kp, dampratio, inertia, lo, hi)
    n = len(jmap.names)
    try:
        ki_a = np.broadcast_to(np.asarray(ki, dtype=float), (n,)).copy()
        imax_a = None if imax is None else np.broadcast_to(np.asarray(imax, dtype=float), (n,))
    except ValueError:
        raise ControllerError(f"ki and imax must be scalars or have {n} entries") from None
    if not np.all(np.isfinite(ki_a)) or np.any(ki_a < 0):
        raise ControllerError("servo ki must be finite and >= 0")
    if imax_a is not None and (not np.all(np.isfinite(imax_a)) or np.any(imax_a <= 0)):
        raise ControllerError("servo imax must be finite and > 0")
    acts = work.actuators
    for k, a in enumerate(jmap.actuator_ids):
        j = jmap.joint_ids[k]
        act = acts[int(a)]
        act.gear = [1.0, 0, 0, 0, 0, 0]
        act.gainprm = np.zeros(10)
        act.biasprm = np.zeros(10)
        act.dynprm = np.zeros(10)
        act.biastype = mujoco.mjtBias.mjBIAS_AFFINE
        act.biasprm = [0.0, -kp_a[k], -kv[k]] + [0.0] * 7
        if kind == "position":
            act.gaintype = mujoco.mjtGain.mjGAIN_FIXED
            act.gainprm = [kp_a[k]] + [0.0] * 9
            act.dyntype = mujoco.mjtDyn.mjDYN_NONE
            act.actdim = -1
            if hasattr(act, "ctrlspec"):
                act.ctrlspec = 1  # one control: the position target
        else:
            act.gaintype = mujoco.mjtGain.mjGAIN_PID
            act.gainprm = [ki_a[k]] + [0.0] * 9
            act.dyntype = mujoco.mjtDyn.mjDYN_PID
            act.dynprm = [0.0 if imax_a is None else imax_a[k]] + [0.0] * 9
            act.actdim = -1
            if hasattr(act, "ctrlspec"):
                act.ctrlspec = 3  # MuJoCo >= 4 pid: position and velocity targets
        if model.jnt_limited[j]:
            act.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
            act.ctrlrange = model.jnt_range[j].copy()
        else:
            act.ctrllimited = mujoco.mjtLimited.mjLIMITED_FALSE
        if np.isfinite(lo[k]) and np.isfinite(hi[k]):
            act.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
            act.forcerange = [lo[k], hi[k]]
        else:
            act.forcelimited = mujoco.mjtLimited.mjLIMITED_FALSE
    return work.compile()


def servo_map(model: mujoco.MjModel, joints: Sequence[str] | None = None) -> ServoMap:
    """Read the in-engine servos of ``model`` (configured by :func:`configure_servos` or
    written by hand as ``<position>`` / ``<pid>`` actuators).

    Raises:
        ControllerError: unknown joints, or a joint whose actuator is not a servo
            (a biased actuator with ``biasprm[1] = −kp``); the message says to call
            :func:`configure_servos` first.
    """
    jmap = actuated_joints(model, joints)
    a = jmap.actuator_ids
    pid_type = getattr(mujoco.mjtGain, "mjGAIN_PID", -99)
    is_pid = model.actuator_gaintype[a] == pid_type
    is_pos = model.actuator_gaintype[a] == mujoco.mjtGain.mjGAIN_FIXED
    affine = model.actuator_biastype[a] == mujoco.mjtBias.mjBIAS_AFFINE
    kp_act = -model.actuator_biasprm[a, 1]
    matched = is_pos & np.isclose(model.actuator_gainprm[a, 0], kp_act)
    ok = affine & (is_pid | matched) & (kp_act > 0)
    if not np.all(ok):
        bad = [n for n, good in zip(jmap.names, ok, strict=True) if not good]
        raise ControllerError(
            f"joints without a position/pid servo: {', '.join(bad)}; "
            "call configure_servos(model) first (or use PDController for torque motors)"
        )
    g = jmap.gear
    vel_ids = np.full(len(a), -1, dtype=int)
    if hasattr(model, "actuator_ctrlnum"):
        two = model.actuator_ctrlnum[a] >= 2
        vel_ids[two] = jmap.ctrl_index[two] + 1
    flim = model.actuator_forcelimited[a].astype(bool)
    f_lo = np.where(flim, model.actuator_forcerange[a, 0], -np.inf)
    f_hi = np.where(flim, model.actuator_forcerange[a, 1], np.inf)
    t1, t2 = g * f_lo, g * f_hi
    return ServoMap(
        names=jmap.names,
        joint_ids=jmap.joint_ids,
        qpos_adr=jmap.qpos_adr,
        dof_adr=jmap.dof_adr,
        actuator_ids=a,
        kind=tuple("pid" if p else "position" for p in is_pid),
        kp=kp_act * g**2,
        kv=-model.actuator_biasprm[a, 2] * g**2,
        ki=np.where(is_pid, model.actuator_gainprm[a, 0], 0.0) * g**2,
        gear=g,
        ctrl_lo=jmap.ctrl_lo,
        ctrl_hi=jmap.ctrl_hi,
        torque_lo=np.nan_to_num(np.minimum(t1, t2), nan=-np.inf),
        torque_hi=np.nan_to_num(np.maximum(t1, t2), nan=np.inf),
        ctrl_ids=jmap.ctrl_index,
        vel_ctrl_ids=vel_ids,
    )


class ServoController(BaseController):
    """Drive in-engine servos: ``ctrl = gear · (q_ref + kv/kp · q̇_ref)`` (clipped to the
    control range; :meth:`ServoMap.position_targets`), so the D term of a position
    actuator damps the velocity error instead of braking the reference's own motion.

    Servos that take a velocity target (MuJoCo ≥ 4 pid actuators) get ``gear · q_ref``
    and ``gear · q̇_ref`` instead, so their D term acts on the velocity error directly.

    PD runs inside MuJoCo (see :func:`configure_servos`). A position actuator cannot add
    a torque, so feed-forward torques (``feedforward``, e.g.
    :class:`~habitsim.controllers.feedforward.InverseDynamicsFeedforward` or a
    :class:`~habitsim.controllers.stance.TrunkStabilizer`) are written to
    ``data.qfrc_applied`` on the controlled JOINT dofs only, never on a free joint. They
    stand for torque the same motor supplies, so each is clipped such that the predicted
    servo torque plus feed-forward stays inside the actuator's torque range, and they are
    reported as actuator effort: :attr:`last_feedforward` (n,) [N·m] after every tick,
    :meth:`joint_torques` (servo + feed-forward per joint) and in ``stats.extra``
    (``ff_mean_abs_Nm``, ``ff_max_abs_Nm``, ``ff_clipped_ticks``). Without feed-forward
    ``qfrc_applied`` is never touched.

    The written ``qfrc_applied`` entries persist until the next tick (MuJoCo keeps
    ``qfrc_applied``), which is the same zero-order hold as ``ctrl``.

    Args:
        model: a model configured by :func:`configure_servos` (or with hand-written
            position / pid actuators).
        joints: joint names (default: every actuated hinge/slide joint).
        feedforward: optional callable ``(model, data, ref) -> (n,)`` or a list of them.
        assist: optional :class:`~habitsim.controllers.assist.RootAssist` (default none).
        velocity_lead: add the velocity lead (default); False gives the plain
            ``ctrl = gear · q_ref`` whose D term acts on −q̇ only.
    """

    name = "servo"

    def __init__(
        self,
        model: mujoco.MjModel,
        joints: Sequence[str] | None = None,
        feedforward=None,
        *,
        assist=None,
        velocity_lead: bool = True,
    ) -> None:
        super().__init__(assist=assist)
        self.map = servo_map(model, joints)
        self.velocity_lead = bool(velocity_lead)
        self.feedforward = feedforward
        n = len(self.map.names)
        self.last_feedforward = np.zeros(n)
        self._ff_sum = 0.0
        self._ff_ticks = 0
        self._wrote = False

    @property
    def joint_names(self) -> tuple[str, ...]:
        return self.map.names

    def reset(self, model: mujoco.MjModel, data: mujoco.MjData) -> None:
        super().reset(model, data)
        if self._wrote:
            data.qfrc_applied[self.map.dof_adr] = 0.0
        self.last_feedforward[:] = 0.0

    def joint_torques(self, model: mujoco.MjModel, data: mujoco.MjData) -> np.ndarray:
        """(n,) torque [N·m] the motors give now: servo force (``actuator_force``, last
        step) plus the feed-forward written at the last tick."""
        return self.map.gear * data.actuator_force[self.map.actuator_ids] + self.last_feedforward

    def _control(self, model: mujoco.MjModel, data: mujoco.MjData, ref: Reference) -> np.ndarray:
        return self._control_with(model, data, ref, None)

    def _control_with(
        self, model: mujoco.MjModel, data: mujoco.MjData, ref: Reference, extra: np.ndarray | None
    ) -> np.ndarray:
        m = self.map
        u = np.array(data.ctrl, copy=True)
        target = m.position_targets(ref.qpos, ref.qvel if self.velocity_lead else None)
        u[m.ctrl_index] = target
        vel_target = None
        if np.any(m.has_vel_target):
            assert m.vel_ctrl_ids is not None  # has_vel_target is all False without them
            vel_target = m.gear * ref.qvel[m.dof_adr]
            ids = m.vel_ctrl_ids[m.has_vel_target]
            lim = model.actuator_ctrllimited[ids].astype(bool)
            vt = vel_target[m.has_vel_target]
            vt = np.where(
                lim,
                np.clip(vt, model.actuator_ctrlrange[ids, 0], model.actuator_ctrlrange[ids, 1]),
                vt,
            )
            u[ids] = vt
            vel_target[m.has_vel_target] = vt
        if self.feedforward is None and extra is None:
            return u
        tau = np.zeros(len(m.names))
        if self.feedforward is not None:
            tau += joint_torques(self.feedforward, model, data, ref, m.names)
        if extra is not None:
            tau += extra
        servo = m.predicted_torque(model, data, target, vel_target)
        clipped = np.clip(tau, m.torque_lo - servo, m.torque_hi - servo)
        if np.any(clipped != tau):
            self.stats.extra["ff_clipped_ticks"] = self.stats.extra.get("ff_clipped_ticks", 0) + 1
        data.qfrc_applied[m.dof_adr] = clipped
        self._wrote = True
        self.last_feedforward = clipped
        mean_abs = float(np.mean(np.abs(clipped)))
        self._ff_sum += mean_abs
        self._ff_ticks += 1
        self.stats.extra["ff_mean_abs_Nm"] = self._ff_sum / self._ff_ticks
        self.stats.extra["ff_max_abs_Nm"] = max(
            self.stats.extra.get("ff_max_abs_Nm", 0.0), float(np.max(np.abs(clipped), initial=0.0))
        )
        return u
