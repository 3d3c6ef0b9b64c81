"""The controller interface shared by every habitsim controller and the tracking runner.

A controller turns the simulation state and a reference (the wanted generalised position,
velocity and acceleration at the current control time, plus the reference foot
contacts) into actuator controls. Controllers work on ANY MuJoCo model: they address
joints by name and find the actuators that drive them, so a user's robot works as well as
a habitsim species model.

The runner (:mod:`habitsim.sim`) calls :meth:`Controller.reset` once and then
:meth:`Controller.control` at every control tick, writing the result to ``data.ctrl``.
"""

from __future__ import annotations

import abc
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import mujoco
import numpy as np

from habitsim.errors import HabitsimError

__all__ = [
    "ControllerError",
    "Reference",
    "ControllerStats",
    "Controller",
    "BaseController",
    "JointActuatorMap",
    "actuated_joints",
    "check_reference",
    "ctrl_adr",
    "joint_torques",
    "n_actuators",
    "PDController",
]


class ControllerError(HabitsimError, ValueError):
    """A controller asked for joints or actuators the model does not have, or bad gains."""


@dataclass(frozen=True)
class Reference:
    """The reference at one control tick.

    Attributes:
        time: reference time [s].
        qpos: (nq,) wanted generalised positions.
        qvel: (nv,) wanted generalised velocities.
        qacc: (nv,) wanted generalised accelerations (finite differences of the reference).
        contacts: optional (n_feet,) bool, which feet the reference has on the ground.
    """

    time: float
    qpos: np.ndarray
    qvel: np.ndarray
    qacc: np.ndarray
    contacts: np.ndarray | None = None


@dataclass
class ControllerStats:
    """Timing and failure counts a controller reports after a run."""

    calls: int = 0
    total_time_s: float = 0.0
    max_time_s: float = 0.0
    failures: int = 0
    notes: list[str] = field(default_factory=list)
    #: Named running figures a controller adds (e.g. feed-forward effort), SI units.
    extra: dict[str, float] = field(default_factory=dict)

    @property
    def mean_time_ms(self) -> float:
        return 1e3 * self.total_time_s / self.calls if self.calls else 0.0

    def note(self, text: str) -> None:
        """Record a note once (the list is capped at 100 entries)."""
        if text not in self.notes and len(self.notes) < 100:
            self.notes.append(text)

    def to_dict(self) -> dict[str, float | int | list[str]]:
        out: dict[str, float | int | list[str]] = {
            "calls": self.calls,
            "mean_time_ms": round(self.mean_time_ms, 4),
            "max_time_ms": round(1e3 * self.max_time_s, 4),
            "failures": self.failures,
            "notes": list(self.notes[:20]),
        }
        out.update({k: float(v) for k, v in self.extra.items()})
        return out


@dataclass(frozen=True)
class JointActuatorMap:
    """Which actuator drives which single-dof joint of a model.

    Attributes:
        names: joint names, in controller order.
        joint_ids, qpos_adr, dof_adr: per joint, MuJoCo indices.
        actuator_ids: per joint, the actuator with ``trntype`` joint driving it.
        gear: per joint, the actuator's gear ratio (torque = gear · ctrl for motors).
        ctrl_lo, ctrl_hi: per joint, the actuator's control range (±inf if unlimited).
        gain: per joint, ``gainprm[0]`` of a fixed-gain actuator (1 for ``<motor>``; a
            ``<general>`` actuator gives force = gain · ctrl).
        force_lo, force_hi: per joint, the actuator's force range (±inf if not
            force-limited), in actuator units (torque = gear · force).
        biased: per joint, True if the actuator has a bias (a position / pid servo).
        ctrl_ids: per joint, index of the actuator's first control in ``data.ctrl``
            (MuJoCo ≥ 4 actuators may take several controls, e.g. a pid actuator a
            position and a velocity target); equal to ``actuator_ids`` for motors.
    """

    names: tuple[str, ...]
    joint_ids: np.ndarray
    qpos_adr: np.ndarray
    dof_adr: np.ndarray
    actuator_ids: np.ndarray
    gear: np.ndarray
    ctrl_lo: np.ndarray
    ctrl_hi: np.ndarray
    gain: np.ndarray | None = None
    force_lo: np.ndarray | None = None
    force_hi: np.ndarray | None = None
    biased: np.ndarray | None = None
    ctrl_ids: np.ndarray | None = None

    @property
    def ctrl_index(self) -> np.ndarray:
        """(n,) index in ``data.ctrl`` of each actuator's (first) control."""
        return self.actuator_ids if self.ctrl_ids is None else self.ctrl_ids

    @property
    def torque_per_ctrl(self) -> np.ndarray:
        """(n,) joint torque per unit control of a torque actuator (gear · gain)."""
        gain = np.ones_like(self.gear) if self.gain is None else self.gain
        return self.gear * gain

    @property
    def torque_limit(self) -> np.ndarray:
        """(n,) largest |torque| [N·m] each actuator can give.

        A torque actuator (no bias): the smaller of |gear·gain|·max|ctrl range| and
        |gear|·max|force range|. A servo (biased actuator, its control is a target
        position): |gear|·max|force range|.
        """
        by_force = np.full(self.gear.shape, np.inf)
        if self.force_lo is not None and self.force_hi is not None:
            by_force = np.abs(self.gear) * np.maximum(np.abs(self.force_lo), np.abs(self.force_hi))
        ctrl_max = np.maximum(np.abs(self.ctrl_lo), np.abs(self.ctrl_hi))
        by_ctrl = np.abs(self.torque_per_ctrl) * ctrl_max
        if self.biased is None:
            return np.minimum(by_force, by_ctrl)
        return np.where(self.biased, by_force, np.minimum(by_force, by_ctrl))


def n_actuators(model: mujoco.MjModel) -> int:
    """Number of actuators (``nactuator`` in MuJoCo ≥ 4, where ``nu`` counts controls)."""
    return int(getattr(model, "nactuator", model.nu))


def ctrl_adr(model: mujoco.MjModel) -> np.ndarray:
    """(nactuator,) index of each actuator's first control in ``data.ctrl``."""
    if hasattr(model, "actuator_ctrladr"):
        return np.asarray(model.actuator_ctrladr, dtype=int).copy()
    return np.arange(model.nu)


def actuator_force_range(model: mujoco.MjModel, actuators: np.ndarray) -> np.ndarray:
    """(n, 2) force range of each actuator in its own units (±inf where unlimited): its
    ``forcerange`` when force-limited, intersected with its joint's ``actuatorfrcrange``
    divided by |gear| (MuJoCo clamps the actuators' summed force on a joint there;
    Menagerie's Spot limits its servos only that way)."""
    a = np.asarray(actuators, dtype=int)
    out = np.tile([-np.inf, np.inf], (len(a), 1))
    lim = model.actuator_forcelimited[a].astype(bool)
    out[lim] = model.actuator_forcerange[a[lim]]
    on_joint = model.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_JOINT
    for k in np.flatnonzero(on_joint):
        j = int(model.actuator_trnid[a[k], 0])
        gear = abs(float(model.actuator_gear[a[k], 0]))
        if model.jnt_actfrclimited[j] and gear > 0:
            lo, hi = model.jnt_actfrcrange[j] / gear
            out[k] = [max(out[k, 0], lo), min(out[k, 1], hi)]
    return out


def actuated_joints(model: mujoco.MjModel, names: Sequence[str] | None = None) -> JointActuatorMap:
    """Map joints (by name; default: every hinge/slide joint with an actuator) to actuators.

    Raises:
        ControllerError: a named joint does not exist, is not a hinge/slide joint, or has
            no actuator driving it; the message lists the valid names.
    """
    driven: dict[int, int] = {}
    for a in range(n_actuators(model)):
        if model.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_JOINT:
            driven.setdefault(int(model.actuator_trnid[a, 0]), a)
    # ints: pybind11 enums do not compare equal to numpy ints inside `in`
    single = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))
    valid = [model.joint(j).name for j in sorted(driven) if int(model.jnt_type[j]) in single]
    if names is None:
        names = valid
    jids, acts = [], []
    for n in names:
        jid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, n)
        if jid < 0 or jid not in driven or int(model.jnt_type[jid]) not in single:
            raise ControllerError(
                f"joint {n!r} is not an actuated hinge/slide joint of the model; "
                f"valid: {', '.join(valid) or '(none)'}"
            )
        jids.append(jid)
        acts.append(driven[jid])
    jids_a, acts_a = np.array(jids, dtype=int), np.array(acts, dtype=int)
    cadr = ctrl_adr(model)[acts_a]
    limited = model.actuator_ctrllimited[cadr].astype(bool)
    lo = np.where(limited, model.actuator_ctrlrange[cadr, 0], -np.inf)
    hi = np.where(limited, model.actuator_ctrlrange[cadr, 1], np.inf)
    frange = actuator_force_range(model, acts_a)
    fixed = model.actuator_gaintype[acts_a] == mujoco.mjtGain.mjGAIN_FIXED
    return JointActuatorMap(
        names=tuple(names),
        joint_ids=jids_a,
        qpos_adr=model.jnt_qposadr[jids_a].copy(),
        dof_adr=model.jnt_dofadr[jids_a].copy(),
        actuator_ids=acts_a,
        gear=model.actuator_gear[acts_a, 0].copy(),
        ctrl_lo=lo,
        ctrl_hi=hi,
        gain=np.where(fixed, model.actuator_gainprm[acts_a, 0], 1.0),
        force_lo=frange[:, 0],
        force_hi=frange[:, 1],
        biased=model.actuator_biastype[acts_a] != mujoco.mjtBias.mjBIAS_NONE,
        ctrl_ids=cadr,
    )


def check_reference(model: mujoco.MjModel, ref: Reference) -> None:
    """Raise :class:`ControllerError` unless ``ref`` fits ``model`` and is finite."""
    for name, arr, size in (
        ("qpos", ref.qpos, model.nq),
        ("qvel", ref.qvel, model.nv),
        ("qacc", ref.qacc, model.nv),
    ):
        a = np.asarray(arr)
        if a.shape != (size,):
            raise ControllerError(f"reference {name} has shape {a.shape}, model needs ({size},)")
        if math.isfinite(float(a.sum())):  # fast path: then every entry is finite
            continue
        if not np.all(np.isfinite(a)):  # a NaN or inf (not merely an overflowing sum)
            bad = np.flatnonzero(~np.isfinite(a))[:5].tolist()
            raise ControllerError(f"reference {name} is not finite at index {bad} (t={ref.time})")
    if not np.isfinite(ref.time):
        raise ControllerError(f"reference time is not finite: {ref.time}")


def joint_torques(
    component, model: mujoco.MjModel, data: mujoco.MjData, ref: Reference, names: Sequence[str]
) -> np.ndarray:
    """(n,) torques of a feed-forward ``component`` in the joint order ``names``.

    ``component`` is a callable ``(model, data, ref) -> (k,)``, or a list of them (summed).
    A component that has a ``joint_names`` attribute is re-ordered by name (its joints must
    all be among ``names``); one without must return exactly ``len(names)`` values in
    ``names`` order.
    """
    n = len(names)
    if isinstance(component, (list, tuple)):
        total = np.zeros(n)
        for c in component:
            total += joint_torques(c, model, data, ref, names)
        return total
    tau = np.asarray(component(model, data, ref), dtype=float)
    own = getattr(component, "joint_names", None)
    if own is None or tuple(own) == tuple(names):
        if tau.shape != (n,):
            raise ControllerError(f"feed-forward returned shape {tau.shape}, expected ({n},)")
        return tau
    index = {nm: i for i, nm in enumerate(names)}
    missing = [nm for nm in own if nm not in index]
    if missing:
        raise ControllerError(
            f"feed-forward drives joints the controller does not: {', '.join(missing)}; "
            f"controller joints: {', '.join(names)}"
        )
    out = np.zeros(n)
    out[[index[nm] for nm in own]] = tau
    return out


@runtime_checkable
class Controller(Protocol):
    """What the tracking runner needs of a controller (any object with these members).

    Every habitsim controller is one (they derive from :class:`BaseController`); a
    user's own needs no base class. A controller that plans with the whole clip also has
    ``set_plan(qpos, fps, contacts)``, which the runner calls before :meth:`reset`.
    """

    #: Short name used in reports and on the command line.
    name: str
    #: Timing and failure counts of the run so far.
    stats: ControllerStats

    def reset(self, model: mujoco.MjModel, data: mujoco.MjData) -> None:
        """Called once before a run."""
        ...

    def control(self, model: mujoco.MjModel, data: mujoco.MjData, ref: Reference) -> np.ndarray:
        """(nu,) actuator controls for this tick."""
        ...


class BaseController(abc.ABC):
    """Base class of habitsim's controllers (a :class:`Controller`): timing, reference
    checks and the optional root assist around :meth:`_control`."""

    #: Short name used in reports and on the command line.
    name: str = "controller"

    def __init__(self, assist=None) -> None:
        self.stats = ControllerStats()
        #: Optional :class:`~habitsim.controllers.assist.RootAssist` (an external force on
        #: the free joint). ``None`` by default: no controller ever adds outside force
        #: unless the user passes one, and then it is recorded in ``assist.report()``.
        self.assist = assist

    def reset(self, model: mujoco.MjModel, data: mujoco.MjData) -> None:
        """Called once before a run (clear internal state and the assist's record)."""
        if self.assist is not None:
            self.assist.reset(model, data)

    def control(self, model: mujoco.MjModel, data: mujoco.MjData, ref: Reference) -> np.ndarray:
        """(nu,) actuator controls for this tick (timed into :attr:`stats`).

        Raises:
            ControllerError: the reference does not fit the model or is not finite.
        """
        t0 = time.perf_counter()
        check_reference(model, ref)
        u = self._control(model, data, ref)
        if self.assist is not None:
            self.assist.apply(model, data, ref)
        dt = time.perf_counter() - t0
        self.stats.calls += 1
        self.stats.total_time_s += dt
        self.stats.max_time_s = max(self.stats.max_time_s, dt)
        return u

    @abc.abstractmethod
    def _control(self, model: mujoco.MjModel, data: mujoco.MjData, ref: Reference) -> np.ndarray:
        """Subclasses compute the controls here."""


class PDController(BaseController):
    """Explicit joint-space PD torque control for torque (motor) actuators.

    τ_i = kp_i (q_ref,i − q_i) + kd_i (q̇_ref,i − q̇_i) + τ_ff,i, converted to controls by
    the actuator's torque per control (gear · gain) and clipped to its control range (and
    force range), so the applied torque never exceeds the actuator's limit.

    Args:
        model: the MuJoCo model.
        kp: stiffness [N·m/rad] per joint (array) or one value for all.
        kd: damping [N·m·s/rad] per joint or one value.
        joints: joint names to control (default: every actuated hinge/slide joint).
        feedforward: optional callable ``(model, data, ref) -> (n,)`` torques added to the
            PD terms (e.g. :class:`~habitsim.controllers.feedforward.InverseDynamicsFeedforward`,
            :class:`~habitsim.controllers.stance.TrunkStabilizer`), or a list of them.
        assist: optional :class:`~habitsim.controllers.assist.RootAssist`; ``None`` (the
            default) means no external force, ever.

    Explicit PD is only stable when kd·dt / M_ii stays well below 2 for every joint
    (M_ii the joint-space inertia); use the gain rules of :mod:`habitsim.controllers.gains`
    or the in-engine servos of :mod:`habitsim.controllers.servo` for stiff, light joints.

    After each tick :attr:`last_torque` holds the (n,) joint torques [N·m] sent.

    Raises:
        ControllerError: unknown joints, negative / non-finite gains, or an actuator that
            is not a torque actuator (a biased position / pid servo).
    """

    name = "pd"

    def __init__(
        self,
        model: mujoco.MjModel,
        kp: float | np.ndarray,
        kd: float | np.ndarray,
        joints: Sequence[str] | None = None,
        feedforward=None,
        *,
        assist=None,
    ) -> None:
        super().__init__(assist=assist)
        self.map = actuated_joints(model, joints)
        n = len(self.map.names)
        try:
            self.kp = np.broadcast_to(np.asarray(kp, dtype=float), (n,)).copy()
            self.kd = np.broadcast_to(np.asarray(kd, dtype=float), (n,)).copy()
        except ValueError as exc:
            raise ControllerError(f"PD gains must be scalars or have {n} entries: {exc}") from None
        if (
            np.any(~np.isfinite(self.kp))
            or np.any(~np.isfinite(self.kd))
            or np.any(self.kp < 0)
            or np.any(self.kd < 0)
        ):
            raise ControllerError("PD gains must be finite and non-negative")
        flags = self.map.biased if self.map.biased is not None else [False] * len(self.map.names)
        biased = [nm for nm, b in zip(self.map.names, flags, strict=True) if b]
        if biased:
            raise ControllerError(
                f"PDController needs torque actuators; these joints have servo (biased) "
                f"actuators: {', '.join(biased)}; use ServoController instead"
            )
        self.feedforward = feedforward
        self.last_torque = np.zeros(n)

    @property
    def joint_names(self) -> tuple[str, ...]:
        return self.map.names

    def torques(self, data: mujoco.MjData, ref: Reference) -> np.ndarray:
        """(n,) unclipped PD torques [N·m] of the controlled joints."""
        m = self.map
        return self.kp * (ref.qpos[m.qpos_adr] - data.qpos[m.qpos_adr]) + self.kd * (
            ref.qvel[m.dof_adr] - data.qvel[m.dof_adr]
        )

    def _control(self, model: mujoco.MjModel, data: mujoco.MjData, ref: Reference) -> np.ndarray:
        return self._control_with(model, data, ref, None)

    def _control_with(
        self, model: mujoco.MjModel, data: mujoco.MjData, ref: Reference, extra: np.ndarray | None
    ) -> np.ndarray:
        """Controls with ``extra`` (n,) joint torques added to PD + feed-forward."""
        m = self.map
        tau = self.torques(data, ref)
        if self.feedforward is not None:
            tau = tau + joint_torques(self.feedforward, model, data, ref, m.names)
        if extra is not None:
            tau = tau + extra
        limit = m.torque_limit
        tau = np.clip(tau, -limit, limit)
        u = np.array(data.ctrl, copy=True)
        u[m.ctrl_index] = np.clip(tau / m.torque_per_ctrl, m.ctrl_lo, m.ctrl_hi)
        self.last_torque = u[m.ctrl_index] * m.torque_per_ctrl
        return u
