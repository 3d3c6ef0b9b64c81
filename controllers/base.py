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
import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import mujoco
import numpy as np

from habitsim.errors import HabitsimError

__all__ = [
    "ControllerError",
    "Reference",
    "ControllerStats",
    "Controller",
    "JointActuatorMap",
    "actuated_joints",
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

    @property
    def mean_time_ms(self) -> float:
        return 1e3 * self.total_time_s / self.calls if self.calls else 0.0

    def to_dict(self) -> dict[str, float | int | list[str]]:
        return {
            "calls": self.calls,
            "mean_time_ms": round(self.mean_time_ms, 4),
            "max_time_ms": round(1e3 * self.max_time_s, 4),
            "failures": self.failures,
            "notes": list(self.notes[:20]),
        }


@dataclass(frozen=True)
class JointActuatorMap:
    """Which actuator drives which single-dof joint of a model.

    Attributes:
        names: joint names, in controller order.
        joint_ids, qpos_adr, dof_adr: per joint, MuJoCo indices.
        actuator_ids: per joint, the actuator with ``trntype`` joint driving it.
        gear: per joint, the actuator's gear ratio (torque = gear · ctrl for motors).
        ctrl_lo, ctrl_hi: per joint, the actuator's control range (±inf if unlimited).
    """

    names: tuple[str, ...]
    joint_ids: np.ndarray
    qpos_adr: np.ndarray
    dof_adr: np.ndarray
    actuator_ids: np.ndarray
    gear: np.ndarray
    ctrl_lo: np.ndarray
    ctrl_hi: np.ndarray

    @property
    def torque_limit(self) -> np.ndarray:
        """(n,) largest |torque| [N·m] each actuator can give (gear · ctrl range)."""
        return np.abs(self.gear) * np.maximum(np.abs(self.ctrl_lo), np.abs(self.ctrl_hi))


def actuated_joints(model: mujoco.MjModel, names: Sequence[str] | None = None) -> JointActuatorMap:
    """Map joints (by name; default: every hinge/slide joint with an actuator) to actuators.

    Raises:
        ControllerError: a named joint does not exist, is not a hinge/slide joint, or has
            no actuator driving it; the message lists the valid names.
    """
    driven: dict[int, int] = {}
    for a in range(model.nu):
        if model.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_JOINT:
            driven.setdefault(int(model.actuator_trnid[a, 0]), a)
    single = (mujoco.mjtJoint.mjJNT_HINGE, mujoco.mjtJoint.mjJNT_SLIDE)
    valid = [model.joint(j).name for j in sorted(driven) if model.jnt_type[j] in single]
    if names is None:
        names = valid
    jids, acts = [], []
    for n in names:
        jid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, n)
        if jid < 0 or jid not in driven or model.jnt_type[jid] not in single:
            raise ControllerError(
                f"joint {n!r} is not an actuated hinge/slide joint of the model; "
                f"valid: {', '.join(valid) or '(none)'}"
            )
        jids.append(jid)
        acts.append(driven[jid])
    jids_a, acts_a = np.array(jids, dtype=int), np.array(acts, dtype=int)
    limited = model.actuator_ctrllimited[acts_a].astype(bool)
    lo = np.where(limited, model.actuator_ctrlrange[acts_a, 0], -np.inf)
    hi = np.where(limited, model.actuator_ctrlrange[acts_a, 1], np.inf)
    return JointActuatorMap(
        names=tuple(names),
        joint_ids=jids_a,
        qpos_adr=model.jnt_qposadr[jids_a].copy(),
        dof_adr=model.jnt_dofadr[jids_a].copy(),
        actuator_ids=acts_a,
        gear=model.actuator_gear[acts_a, 0].copy(),
        ctrl_lo=lo,
        ctrl_hi=hi,
    )


class Controller(abc.ABC):
    """Base class: actuator controls from the state and a :class:`Reference`."""

    #: Short name used in reports and on the command line.
    name: str = "controller"

    def __init__(self) -> None:
        self.stats = ControllerStats()

    def reset(self, model: mujoco.MjModel, data: mujoco.MjData) -> None:  # noqa: B027
        """Called once before a run (clear internal state). Default: nothing."""

    def control(self, model: mujoco.MjModel, data: mujoco.MjData, ref: Reference) -> np.ndarray:
        """(nu,) actuator controls for this tick (timed into :attr:`stats`)."""
        t0 = time.perf_counter()
        u = self._control(model, data, ref)
        dt = time.perf_counter() - t0
        self.stats.calls += 1
        self.stats.total_time_s += dt
        self.stats.max_time_s = max(self.stats.max_time_s, dt)
        return u

    @abc.abstractmethod
    def _control(self, model: mujoco.MjModel, data: mujoco.MjData, ref: Reference) -> np.ndarray:
        """Subclasses compute the controls here."""


class PDController(Controller):
    """Explicit joint-space PD torque control for torque (motor) actuators.

    τ_i = kp_i (q_ref,i − q_i) + kd_i (q̇_ref,i − q̇_i) + τ_ff,i, converted to controls by
    the actuator's gear and clipped to its control range.

    Args:
        model: the MuJoCo model.
        kp: stiffness [N·m/rad] per joint (array) or one value for all.
        kd: damping [N·m·s/rad] per joint or one value.
        joints: joint names to control (default: every actuated hinge/slide joint).
        feedforward: optional callable ``(model, data, ref) -> (n,)`` torques added to the
            PD terms (e.g. inverse dynamics of the reference).

    Explicit PD is only stable when kd·dt / M_ii stays well below 2 for every joint
    (M_ii the joint-space inertia); use the gain rules of :mod:`habitsim.controllers.gains`
    or the in-engine servos of :mod:`habitsim.controllers.servo` for stiff, light joints.
    """

    name = "pd"

    def __init__(self, model: mujoco.MjModel, kp: float | np.ndarray, kd: float | np.ndarray,
                 joints: Sequence[str] | None = None, feedforward=None) -> None:
        super().__init__()
        self.map = actuated_joints(model, joints)
        n = len(self.map.names)
        self.kp = np.broadcast_to(np.asarray(kp, dtype=float), (n,)).copy()
        self.kd = np.broadcast_to(np.asarray(kd, dtype=float), (n,)).copy()
        if np.any(~np.isfinite(self.kp)) or np.any(self.kp < 0) or np.any(self.kd < 0):
            raise ControllerError("PD gains must be finite and non-negative")
        self.feedforward = feedforward

    def torques(self, data: mujoco.MjData, ref: Reference) -> np.ndarray:
        """(n,) unclipped PD torques [N·m] of the controlled joints."""
        m = self.map
        return self.kp * (ref.qpos[m.qpos_adr] - data.qpos[m.qpos_adr]) + self.kd * (
            ref.qvel[m.dof_adr] - data.qvel[m.dof_adr]
        )

    def _control(self, model: mujoco.MjModel, data: mujoco.MjData, ref: Reference) -> np.ndarray:
        tau = self.torques(data, ref)
        if self.feedforward is not None:
            tau = tau + self.feedforward(model, data, ref)
        u = np.array(data.ctrl, copy=True)
        u[self.map.actuator_ids] = np.clip(tau / self.map.gear, self.map.ctrl_lo, self.map.ctrl_hi)
        return u
