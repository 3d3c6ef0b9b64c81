"""Balance-aware tracking without external force: the stance-force QP every control tick.

:class:`BalanceController` (name ``"balance"``) follows a reference motion on any MJCF
with a free joint and named feet, using only the joint actuators (Bledt et al. 2018, MIT
Cheetah 3's balance controller, in its whole-body form):

1. **Wanted trunk wrench** about the whole-body centre of mass ``c``::

       b = [m (c̈_des − g); I_c ω̇_des]
       c̈_des = c̈_ref + Kp (c_ref − c) + Kd (ċ_ref − ċ)
       ω̇_des = ω̇_ref + Kp_r e_R + Kd_r (ω_ref − ω)

   with ``e_R`` the trunk body's orientation error and ``ω`` its angular velocity (the
   MPC uses the whole body's centroidal one instead, see
   :attr:`BalanceController.centroidal_rate`), the reference from the motion
   (:class:`~habitsim.controllers.plan.MotionPlan`, or the current
   :class:`~habitsim.controllers.base.Reference` alone), ``I_c`` the
   centroidal inertia of the model at its current pose, gains scaled with the body
   (:class:`BalanceConfig`).
2. **Stance-force QP** (:class:`~habitsim.controllers.stance_qp.StanceQP`, shared with
   the trunk stabiliser and the MPC) over the ground forces ``f_i`` of the stance feet::

       min_f ‖S (A f − b)‖² + α ‖f − f_prev‖² + ε ‖f‖²
       s.t.  |f_x|, |f_y| ≤ μ f_z   (linear friction pyramid, flat ground, z up)
             f_z,min ≤ f_z ≤ f_z,max on stance feet; f = 0 on swing feet
             τ_lo ≤ −Σ_i J_iᵀ f_i ≤ τ_hi on every joint of a leg chain

   ``A = [I … I; [p_i − c]× …]``, ``S = diag(1, 1, 1, 1/L, 1/L, 1/L)`` (L the leg length)
   so force and torque rows are both in newtons; ``τ_lo, τ_hi`` are the actuator limits
   minus the torque the bias and swing terms already take, so the distribution never asks
   a weak joint (an abductor, the spine) for more than it has. Solved by a CasADi
   ``qpsol`` with the ``daqp`` plugin (or ``qpoases``), built once, evaluated through
   CasADi's zero-copy function buffer (CasADi's ordinary Python call converts every
   argument). A result that is not finite or breaks the constraints is replaced by a
   clipped least-squares solution and counted as a failure.
3. **Torques** (joint actuators only; nothing is ever applied to the free joint), in
   order of priority::

       τ = h + D q̇ + M q̈_ref|free + Σ_swing J_own,iᵀ F_i − Σ_stance J_iᵀ f_i + τ_posture

   ``h`` the bias forces (gravity, Coriolis; ``qfrc_bias``) of the actuated joints;
   ``D q̇`` the joints' own viscous damping (the model's ``dof_damping``), compensated so
   the stance forces are the ones the QP planned;
   ``M q̈_ref`` the inertial feed-forward of the reference accelerations of the swinging
   legs and of the joints on no leg chain (neck, head, tail); ``F_i`` the swing feet's
   Cartesian PD (:class:`~habitsim.controllers.swing.SwingLegs`); ``J_i`` the
   translational Jacobian, on the actuated joints of the foot's chain (spine joints
   included: they carry the front feet's load), of the point where foot i touches the
   ground (the mean of its body's contacts: a paw lying on its toe capsule or a
   plantigrade sole is pushed there, not at the foot sphere); ``τ_posture`` a joint PD
   to the reference — full on the joints outside the legs, projected into the null space
   of each foot Jacobian on the leg joints (``null_space_posture``) — plus light leg
   damping, clipped into whatever torque is left. The sum is clipped to the actuators'
   limits. ``f_i`` is the force the ground exerts on foot i; the leg pushes the ground
   with ``−f_i``, hence ``−J_iᵀ f_i``: a stance leg asked for an upward force extends and
   lifts the trunk (tested).
4. **Contacts** (:class:`~habitsim.controllers.contact_state.ContactTracker`): schedule from the
   motion, early touch-down switches a leg to stance, a lost contact zeroes its force.

Kinematic quantities are read from ``data`` as left by ``mj_step`` (the state at the
start of the last step: one step old), velocities from ``data.qvel``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import mujoco
import numpy as np

from habitsim.physics_constants import GRAVITY

from .base import BaseController, ControllerError, ControllerStats, Reference
from .contact_state import STANCE, SWING, ContactTracker
from .gains import critical_damping, max_stable_gains, stiffness_rule
from .legs import LegSet, model_leg_length
from .plan import MotionPlan, PlanSample, matrix_from_rpy, plan_from_qpos, rpy_from_matrix
from .stance_qp import STANCE_SOLVERS, StanceQP, _moment, wrench_matrix
from .swing import SwingLegs

__all__ = [
    "BalanceConfig",
    "StanceQP",
    "BalanceController",
    "centroidal_inertia",
    "wrench_matrix",
    "STANCE_SOLVERS",
]

#: Definition of a reported statistic: a joint torque at or above this share of its limit
#: counts as at the limit (``torque_at_limit_share`` in the controller's stats) [unitless].
AT_LIMIT_SHARE = 0.99


def centroidal_inertia(
    model: mujoco.MjModel, data: mujoco.MjData, bodies: np.ndarray, com: np.ndarray
) -> np.ndarray:
    """(3, 3) inertia [kg·m²] of ``bodies`` about ``com``, world frame, at ``data``'s pose."""
    r = data.xipos[bodies] - com
    rot = data.ximat[bodies].reshape(-1, 3, 3)
    inertia = np.einsum("bij,bj,bkj->ik", rot, model.body_inertia[bodies], rot)
    m = model.body_mass[bodies]
    rr = np.einsum("bi,bi->b", r, r)
    outer = r[:, :, None] * r[:, None, :]
    inertia += np.einsum("b,bij->ij", m, rr[:, None, None] * np.eye(3) - outer)
    return inertia


@dataclass(frozen=True)
class BalanceConfig:
    """Parameters of the balance and MPC controllers, scaled to the body.

    Build with :meth:`scaled` (every default follows from mass m, leg length L and
    gravity g, so one set of dimensionless numbers serves a 2 kg rabbit and a 3.5 t
    elephant); override any field by keyword.

    Attributes:
        mass: total mass m [kg]; leg_length: L [m]; gravity: g [m/s²].
        trunk_omega: natural frequency of the CoM PD [rad/s] (default 2·sqrt(g/L), at
            most ``omega_cap`` of :meth:`scaled`).
        rot_omega: of the trunk orientation PD [rad/s] (same default).
        damping_ratio: ζ of both.
        mu: friction coefficient of the pyramid (keep below the floor's).
        fz_min, fz_max: normal force bounds per stance foot [N] (default 0, 1.5·m·g).
        smooth: α on ‖f − f_prev‖² (relative to the scaled wrench residual).
        regularization: ε on ‖f‖².
        swing_omega: swing-foot PD natural frequency [rad/s] (default 8·sqrt(g/L));
            Cartesian gains ``kp = m_leg ω²``, ``kd = 2 m_leg ω`` per leg, capped at half
            the explicit-integration stability limit of the leg's joints.
        capture_gain, capture_pos_gain: foothold stepping-feedback gains (velocity
            error × sqrt(h/g); CoM position error), on top of the footholds following
            the body (:meth:`~habitsim.controllers.swing.SwingLegs.correction`).
        capture_max: bound of the stepping feedback [m] (default 0.15·L).
        seek_depth: a lost-contact foot aims this far below its reference point [m]
            (default 0.03·L).
        posture_body: scale of the joint PD on non-leg joints (1 = kp = τmax/0.15 rad,
            capped at half the explicit stability limit; kd critical, capped).
        posture_leg: scale of the posture PD of the leg joints.
        null_space_posture: project the leg posture PD into the null space of each foot
            Jacobian (default), so it never changes a redundant leg's foot force; off, the
            plain joint PD acts on the legs as well (stiffer posture, foot forces a little
            off the QP's plan — it keeps the fox standing).
        leg_damping: scale of the (unprojected) damping of the leg joints.
        early_phase: swing phase after which a touch-down switches to stance [share of
            the swing] (why 0.75: docs/controllers.md).
        early_reach: ... only when the foot is within this horizontal distance of its
            swing target [m] (default 0.1·L); farther behind, the foot is scuffing, not
            landing (:class:`~habitsim.controllers.contact_state.ContactTracker`).
        lost_s: grace time before a stance foot without contact loses its force [s].
    """

    mass: float
    leg_length: float
    gravity: float = GRAVITY
    trunk_omega: float = 0.0
    rot_omega: float = 0.0
    damping_ratio: float = 1.0
    mu: float = 0.6
    fz_min: float = 0.0
    fz_max: float = 0.0
    smooth: float = 1e-3
    regularization: float = 1e-6
    swing_omega: float = 0.0
    capture_gain: float = 1.0
    capture_pos_gain: float = 0.3
    capture_max: float = 0.0
    seek_depth: float = 0.0
    posture_body: float = 1.0
    posture_leg: float = 0.3
    leg_damping: float = 0.1
    early_phase: float = 0.75
    early_reach: float = 0.0
    lost_s: float = 0.01
    null_space_posture: bool = True
    extra: dict = field(default_factory=dict)

    @classmethod
    def scaled(
        cls,
        mass: float,
        leg_length: float,
        gravity: float = GRAVITY,
        omega_cap: float = 10.0,
        **overrides: Any,
    ) -> BalanceConfig:
        """The defaults for a body of ``mass`` [kg] and ``leg_length`` [m].

        ``omega_cap`` bounds the default trunk PD natural frequencies [rad/s] (why 10:
        docs/controllers.md).

        Raises:
            ControllerError: non-positive mass, leg length or gravity; unknown field.
        """
        for name, v in (("mass", mass), ("leg_length", leg_length), ("gravity", gravity)):
            if not (np.isfinite(v) and v > 0):
                raise ControllerError(f"{name} must be finite and > 0, got {v}")
        w0 = float(np.sqrt(gravity / leg_length))
        cfg = cls(
            mass=float(mass),
            leg_length=float(leg_length),
            gravity=float(gravity),
            trunk_omega=min(2.0 * w0, omega_cap),
            rot_omega=min(2.0 * w0, omega_cap),
            fz_max=1.5 * mass * gravity,
            swing_omega=8.0 * w0,
            capture_max=0.15 * leg_length,
            seek_depth=0.03 * leg_length,
            early_reach=0.1 * leg_length,
        )
        known = set(cls.__dataclass_fields__) - {"mass", "leg_length", "gravity"}
        bad = sorted(set(overrides) - known)
        if bad:
            raise ControllerError(
                f"unknown balance option(s) {', '.join(bad)}; valid: {', '.join(sorted(known))}"
            )
        changes: dict[str, Any] = {
            k: (v if isinstance(v, (dict, bool)) else float(v)) for k, v in overrides.items()
        }
        cfg = replace(cfg, **changes)
        for name in known - {
            "extra",
            "null_space_posture",
            "fz_min",
            "capture_gain",
            "capture_pos_gain",
            "posture_body",
            "posture_leg",
            "leg_damping",
            "regularization",
            "smooth",
        }:
            v = getattr(cfg, name)
            if not (np.isfinite(v) and v > 0):
                raise ControllerError(f"balance option {name} must be > 0, got {v}")
        for name in (
            "fz_min",
            "capture_gain",
            "capture_pos_gain",
            "posture_body",
            "posture_leg",
            "leg_damping",
            "regularization",
            "smooth",
        ):
            v = getattr(cfg, name)
            if not (np.isfinite(v) and v >= 0):
                raise ControllerError(f"balance option {name} must be >= 0, got {v}")
        if cfg.fz_min >= cfg.fz_max:
            raise ControllerError("fz_min must be below fz_max")
        return cfg


def _posture_gains(
    model: mujoco.MjModel, names: Sequence[str], dt: float | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """(kp, kd): torque rule (τmax / 0.15 rad) and critical damping, both capped at half
    the explicit-integration stability limit for a control period ``dt`` (the runner's
    default PD rule)."""
    kp_max, kd_max = max_stable_gains(model, dt, joints=names)
    try:
        kp = stiffness_rule(model, names, mode="torque")
    except ControllerError:
        kp = stiffness_rule(model, names, mode="gravity")
    kp = np.minimum(kp, kp_max)
    kd = np.minimum(critical_damping(model, kp, names), kd_max)
    return kp, kd


@dataclass
class _LiveStats(ControllerStats):
    """Controller stats whose running figures are filled in when read."""

    refresh: Callable[[], None] | None = None

    def to_dict(self) -> dict[str, float | int | list[str]]:
        if self.refresh is not None:
            self.refresh()
        return super().to_dict()


class BalanceController(BaseController):
    """Stance-force QP + swing legs + posture: balance-aware tracking, no external force.

    Args:
        model: the MuJoCo model (one free joint; torque motors or position servos on the
            joints: a servo is given the target that makes it exert the wanted torque,
            see :class:`~habitsim.controllers.robot.ServoTorque`).
        feet: foot names in contact-label order (default: ``lf_foot, rf_foot, lh_foot,
            rh_foot`` or the usual robot names, see
            :func:`~habitsim.controllers.legs.default_feet`).
        plan: a :class:`~habitsim.controllers.plan.MotionPlan` of the clip to track
            (or set it later with :meth:`set_plan`). Without a plan the controller still
            works from each tick's :class:`Reference` (current CoM and feet by forward
            kinematics, contacts from ``ref.contacts``), but swing feet then follow their
            reference point without lift-off / touch-down bending.
        leg_length: L [m] for scaling (default: the model's trunk height over the feet).
        config: a :class:`BalanceConfig` (default: :meth:`BalanceConfig.scaled` of the
            model's mass and ``leg_length`` with ``options`` as overrides).
        solver: stance QP solver (:data:`STANCE_SOLVERS`).
        control_dt: period [s] at which the runner calls the controller (default: the
            model's time step); the explicit-integration gain caps use it.
        assist: optional root assistance (off by default; never used by the benchmarks).
        **options: overrides of :class:`BalanceConfig` fields.

    A runner gives the clip with :meth:`set_plan` (reference qpos, fps, contact labels)
    before :meth:`reset`; with ``settle_s`` the first frame is held while ``ref.time`` is 0
    and ``ref.qvel`` is zero.

    Attributes:
        stats: timing and failures; ``stats.to_dict()`` adds ``stance_qp_median_ms``,
            ``qp_failures``, ``early_touchdowns``, ``lost_contacts``,
            ``torque_clipped_share`` (ticks whose wanted torque was beyond a joint's
            limit and cut to it) and ``torque_at_limit_share`` (ticks with a joint's
            torque sent at ≥ :data:`AT_LIMIT_SHARE` of its limit: the stance QP keeps its
            own torques inside the limits, so a leg working at its limit shows here, not
            in the clipped share).
        last_forces (nf, 3) ground forces; last_wrench (6,) wanted; last_achieved (6,)
        achieved by the forces; last_modes (nf,) leg modes; last_torque (n,) joint
        torques sent.

    Raises:
        ControllerError: no free joint, unknown feet, a foot without joints of its own,
            biased actuators other than position servos, bad options, a missing solver
            plugin.
    """

    name = "balance"
    #: Feed back the whole body's centroidal angular velocity ``I_c⁻¹ h_c`` instead of the
    #: trunk body's own (see :meth:`_trunk_state`).
    centroidal_rate = False

    def __init__(
        self,
        model: mujoco.MjModel,
        feet: Sequence[str] | None = None,
        *,
        plan: MotionPlan | None = None,
        leg_length: float | None = None,
        config: BalanceConfig | None = None,
        solver: str = "daqp",
        assist=None,
        control_dt: float | None = None,
        **options: Any,
    ) -> None:
        super().__init__(assist=assist)
        self.control_dt = float(model.opt.timestep if control_dt is None else control_dt)
        if not (np.isfinite(self.control_dt) and self.control_dt > 0):
            raise ControllerError(f"control_dt must be > 0, got {control_dt}")
        self.legs = LegSet(model, feet)
        legs = self.legs
        jm = legs.jmap
        # position servos (a robot's usual actuators) give the wanted torques through the
        # inverse of their law (controllers.robot.ServoTorque); torque motors as they are
        self._servo = None
        if jm.biased is not None and jm.biased.any():
            from .robot import ServoTorque

            self._servo = ServoTorque(model, jm)
        gnorm = float(np.linalg.norm(model.opt.gravity))
        if config is None:
            length = model_leg_length(model, legs.feet) if leg_length is None else float(leg_length)
            config = BalanceConfig.scaled(
                legs.mass, length, gnorm if gnorm > 0 else GRAVITY, **options
            )
        elif options:
            config = replace(config, **options)
        self.config = config
        self.gravity_vec = np.array(model.opt.gravity, dtype=float)
        self._chain = np.flatnonzero(legs.on_chain.any(axis=0))
        self.qp = StanceQP(legs.n_feet, solver, n_joints=self._chain.size)
        self.tracker = ContactTracker(legs.n_feet, config.lost_s, config.early_phase)
        self._reach2 = config.early_reach**2
        kp_sw, kd_sw = self._swing_gains(model)
        self.swing = SwingLegs(
            legs,
            kp_sw,
            kd_sw,
            capture_gain=config.capture_gain,
            capture_pos_gain=config.capture_pos_gain,
            capture_max=config.capture_max,
            seek_depth=config.seek_depth,
            seek_speed=0.3 * float(np.sqrt(config.gravity * config.leg_length)),
        )
        kp, kd = _posture_gains(model, jm.names, self.control_dt)
        leg = legs.own.any(axis=0)
        self.kp_post = np.where(leg, config.posture_leg, config.posture_body) * kp
        self.kd_post = np.where(leg, config.posture_leg, config.posture_body) * kd
        self.kd_damp = np.where(leg, config.leg_damping * kd, 0.0)
        self.leg_joint = leg
        self.leg_free = ~legs.on_chain.any(axis=0)  # neck, head, tail: on no foot's chain
        self._qacc_buf = np.zeros(model.nv)
        self._mq_buf = np.zeros(model.nv)
        w, z = config.trunk_omega, config.damping_ratio
        self.kp_pos, self.kd_pos = w * w, 2.0 * z * w
        w = config.rot_omega
        self.kp_rot, self.kd_rot = w * w, 2.0 * z * w
        length = config.leg_length
        self.row_scale = np.array([1.0, 1.0, 1.0, 1.0 / length, 1.0 / length, 1.0 / length])
        self._bodies = np.array([b for b in range(1, model.nbody) if self._below_trunk(model, b)])
        self._model = model
        self._scratch = mujoco.MjData(model)
        self._jcom = np.zeros((3, model.nv))
        self.plan = plan
        nf, n = legs.n_feet, len(jm.names)
        self.last_forces = np.zeros((nf, 3))
        self.last_wrench = np.zeros(6)
        self.last_modes = np.full(nf, STANCE)
        self.last_torque = np.zeros(n)
        self._inertia: np.ndarray = np.eye(3)
        self._inertia_inv = np.eye(3)
        self._ticks = 0
        self._clipped = 0
        self._at_limit = 0
        # per-tick caches (see _control / _other_torques)
        self._dof = jm.dof_adr
        self._qadr = jm.qpos_adr
        self._limit = jm.torque_limit
        self._neg_limit = -self._limit
        self._joint_damping = np.array(model.dof_damping[jm.dof_adr], dtype=float)
        self._limit_ch = self._limit[self._chain]
        self._tpc = jm.torque_per_ctrl
        self._ctrl_idx = jm.ctrl_index
        self._jac_all = np.zeros((nf, 3, model.nv))
        self._jc = np.zeros((nf, 3, n + 1))
        self._own_any = legs.own.any(axis=0).astype(float)
        self._body_mask = (~leg).astype(float)
        self._leg_mask = leg.astype(float)
        self._feet_col = np.arange(nf)[:, None]
        self._own_idx = legs.own_idx
        self._own_valid = legs.own_idx < n
        self._own_flat = legs.own_idx[self._own_valid]
        self._eps3 = 1e-6 * np.eye(3)
        self._eye_w = np.eye(legs.own_idx.shape[1])[None]
        self._proj: np.ndarray | None = None
        self._proj_every = 5
        self._r = np.zeros((nf, 3))
        self._bits = 1 << np.arange(nf)
        self._moving: dict[int, np.ndarray] = {}
        self.stats = _LiveStats(refresh=self._refresh_stats)
        self.debug = False
        self._dbg: dict = {}

    # ------------------------------------------------------------------ set-up
    def _below_trunk(self, model: mujoco.MjModel, b: int) -> bool:
        while b > 0:
            if b == self.legs.trunk:
                return True
            b = int(model.body_parentid[b])
        return False

    def _swing_gains(self, model: mujoco.MjModel) -> tuple[np.ndarray, np.ndarray]:
        """Cartesian swing gains per leg, capped at half the stability limit of its joints."""
        legs, cfg = self.legs, self.config
        w = cfg.swing_omega
        kp = legs.leg_mass * w * w
        kd = 2.0 * legs.leg_mass * w
        d = mujoco.MjData(model)
        from .gains import home_qpos, joint_space_inertia

        d.qpos[:] = home_qpos(model)
        mujoco.mj_forward(model, d)
        mdiag = np.diag(joint_space_inertia(model, d.qpos))
        dt = self.control_dt
        pts = legs.positions(d)
        jac = legs.jacobians(model, d, pts)
        for i in range(legs.n_feet):
            dofs = legs.jmap.dof_adr[legs.own[i]]
            lever2 = np.maximum((jac[i][:, dofs] ** 2).sum(axis=0), 1e-12)
            kd_lim = 0.5 * float(np.min(2.0 * mdiag[dofs] / dt / lever2))
            kp_lim = 0.5 * float(np.min(4.0 * mdiag[dofs] / dt**2 / lever2))
            kd[i] = min(kd[i], kd_lim)
            kp[i] = min(kp[i], kp_lim)
        return kp, kd

    def set_plan(
        self,
        plan_or_qpos: MotionPlan | np.ndarray | None,
        fps: float | None = None,
        contacts: np.ndarray | None = None,
    ) -> None:
        """Give the controller the clip it will track (before :meth:`reset`).

        Args:
            plan_or_qpos: a :class:`MotionPlan`, or the (T, nq) reference qpos at ``fps``
                (then ``contacts`` (T, nf) are the contact labels, default: from the
                foot heights); ``None`` removes the plan.
        """
        if plan_or_qpos is None or isinstance(plan_or_qpos, MotionPlan):
            self.plan = plan_or_qpos
            return
        if fps is None:
            raise ControllerError("set_plan with a qpos array needs fps")
        self.plan = plan_from_qpos(
            self._model,
            plan_or_qpos,
            fps,
            contacts,
            legs=self.legs,
            leg_length=self.config.leg_length,
        )

    def reset(self, model: mujoco.MjModel, data: mujoco.MjData) -> None:
        super().reset(model, data)
        self.tracker.reset()
        self.swing.reset()
        self.last_forces[:] = 0.0
        self.last_modes[:] = STANCE
        self._proj = None
        self._ticks = 0
        self._clipped = 0
        self._at_limit = 0
        self._refresh_inertia(model, data)

    def _refresh_inertia(self, model: mujoco.MjModel, data: mujoco.MjData) -> None:
        """Centroidal inertia ``I_c`` at the current pose and its inverse."""
        self._inertia = centroidal_inertia(
            model, data, self._bodies, data.subtree_com[self.legs.trunk]
        )
        self._inertia_inv = np.linalg.inv(self._inertia)

    @property
    def joint_names(self) -> tuple[str, ...]:
        return self.legs.jmap.names

    # ------------------------------------------------------------------ per tick
    def _sample(self, model: mujoco.MjModel, ref: Reference) -> PlanSample:
        """The plan at ``ref.time`` (or, without a plan, from ``ref`` by forward kinematics)."""
        hold = ref.time == 0.0 and not np.any(ref.qvel)
        if self.plan is not None:
            return self.plan.sample(ref.time, hold=hold)
        legs, d = self.legs, self._scratch
        d.qpos[:] = ref.qpos
        mujoco.mj_kinematics(model, d)
        mujoco.mj_comPos(model, d)
        tr = legs.trunk
        mujoco.mj_jacSubtreeCom(model, d, self._jcom, tr)
        feet = legs.positions(d)
        jac = legs.jacobians(model, d, feet)
        rot = d.xmat[tr].reshape(3, 3)
        da = legs.dadr
        nf = legs.n_feet
        contacts = (
            np.ones(nf, dtype=bool)
            if ref.contacts is None
            else np.asarray(ref.contacts, dtype=bool).reshape(-1)
        )
        if contacts.shape != (nf,):
            raise ControllerError(
                f"ref.contacts has {contacts.size} entries, the controller "
                f"has {nf} feet ({', '.join(legs.feet)})"
            )
        nan = np.full(nf, np.nan)
        return PlanSample(
            t=float(ref.time),
            com=d.subtree_com[tr].copy(),
            com_vel=self._jcom @ ref.qvel,
            com_acc=np.array(ref.qacc[da : da + 3]),
            rpy=rpy_from_matrix(rot),
            omega=rot @ ref.qvel[da + 3 : da + 6],
            omega_dot=rot @ ref.qacc[da + 3 : da + 6],
            feet=feet,
            feet_vel=jac @ ref.qvel,
            contacts=contacts,
            phase=nan,
            t_liftoff=nan,
            t_touchdown=nan,
            foothold=feet.copy(),
        )

    def _trunk_state(self, model: mujoco.MjModel, data: mujoco.MjData):
        """(CoM, CoM velocity, trunk rotation, angular velocity), world frame.

        The angular velocity is the trunk body's own (:attr:`centroidal_rate` False: the
        rate of the orientation error the PD feeds back) or the whole body's average
        one, ``I_c⁻¹ h_c`` (``h_c`` the angular momentum about the CoM; True).
        """
        tr = self.legs.trunk
        mujoco.mj_subtreeVel(model, data)
        com = data.subtree_com[tr].copy()
        com_vel = data.subtree_linvel[tr].copy()
        rot = data.xmat[tr].reshape(3, 3).copy()
        if self.centroidal_rate:
            omega = self._inertia_inv @ data.subtree_angmom[tr]
        else:
            da = self.legs.dadr
            omega = rot @ data.qvel[da + 3 : da + 6]
        return com, com_vel, rot, omega

    @staticmethod
    def _rotation_error(rot_des: np.ndarray, rot: np.ndarray) -> np.ndarray:
        """World-frame rotation vector taking ``rot`` to ``rot_des``."""
        quat = np.zeros(4)
        mujoco.mju_mat2Quat(quat, (rot_des @ rot.T).ravel())
        err = np.zeros(3)
        mujoco.mju_quat2Vel(err, quat, 1.0)
        return err

    def _wanted(
        self,
        model: mujoco.MjModel,
        data: mujoco.MjData,
        ref: Reference,
        smp: PlanSample,
        com: np.ndarray,
        com_vel: np.ndarray,
        rot: np.ndarray,
        omega: np.ndarray,
        r: np.ndarray,
        stance: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        """(wanted wrench b (6,), anchor forces (nf, 3)) of this tick."""
        acc = smp.com_acc + self.kp_pos * (smp.com - com) + self.kd_pos * (smp.com_vel - com_vel)
        e_rot = self._rotation_error(matrix_from_rpy(smp.rpy), rot)
        alpha = smp.omega_dot + self.kp_rot * e_rot + self.kd_rot * (smp.omega - omega)
        b = np.concatenate([self.config.mass * (acc - self.gravity_vec), self._inertia @ alpha])
        return b, self.last_forces

    def _control(self, model: mujoco.MjModel, data: mujoco.MjData, ref: Reference) -> np.ndarray:
        legs, cfg = self.legs, self.config
        if self._ticks % 10 == 0:
            self._refresh_inertia(model, data)
        self._ticks += 1
        com, com_vel, rot, omega = self._trunk_state(model, data)
        p = legs.positions(data)
        touch, p_contact = legs.contact_points(data)
        smp = self._sample(model, ref)
        prev = self.last_modes
        # a touch counts as an early touch-down only near the swing target (last tick's)
        off = p[:, :2] - self.swing.last_target[:, :2]
        near = (off * off).sum(axis=1) <= self._reach2
        modes = self.tracker.update(smp.t, smp.contacts, touch, smp.phase, near)
        lifted = (modes == SWING) & (prev != SWING)
        if lifted.any():
            self.swing.lift_off(np.flatnonzero(lifted), p, smp.feet)
        self.last_modes = modes
        stance = modes == STANCE
        # stance feet push where their contacts are; swing feet are steered by the foot point
        use = stance & touch
        p_force = np.where(use[:, None], p_contact, p) if use.any() else p
        jac = legs.jacobians(model, data, p_force, out=self._jac_all)
        v = jac @ data.qvel  # for swing feet: the foot point's velocity
        r = p_force - com
        # swing feet
        height = max(float(com[2] - p[:, 2].min()), 1e-3)
        delta = self.swing.correction(
            com, com_vel, smp.com, smp.com_vel, height, cfg.gravity, float(smp.rpy[2])
        )
        p_des, v_des = self.swing.targets(smp, modes, delta)
        force_sw = self.swing.forces(p, v, p_des, v_des)
        force_sw[stance] = 0.0
        jc = self._jc
        jc[:, :, :-1] = jac[:, :, self._dof]  # (nf, 3, n + 1), last column zero
        tau0, post = self._other_torques(model, data, ref, jc, force_sw, modes)
        # stance forces, within what the actuators have left after bias and swing
        b, anchor = self._wanted(model, data, ref, smp, com, com_vel, rot, omega, r, stance)
        ch = self._chain
        t0 = tau0[ch]
        forces, ok = self.qp.solve(
            r,
            b,
            stance,
            mu=cfg.mu,
            fz_min=cfg.fz_min,
            fz_max=cfg.fz_max,
            row_scale=self.row_scale,
            anchor=anchor,
            smooth=cfg.smooth,
            regularization=cfg.regularization,
            jac=jc[:, :, ch],
            tau_lo=-self._limit_ch - t0,
            tau_hi=self._limit_ch - t0,
        )
        if not ok:
            self.stats.failures += 1
            self.stats.note(f"stance QP failed at t={ref.time:.3f}s; used clipped least squares")
        self.last_forces = forces
        self.last_wrench = b
        self._r = r
        tau = tau0 - np.einsum("fkn,fk->n", jc[:, :, :-1], forces)
        # posture last, within the torque that is left (balance comes first)
        post = np.minimum(np.maximum(post, -self._limit - tau), self._limit - tau)
        if self.debug:
            self._dbg["stance"] = tau - tau0
            self._dbg["posture"] = post
        return self._to_ctrl(data, tau + post)

    @property
    def last_achieved(self) -> np.ndarray:
        """(6,) wrench about the CoM of :attr:`last_forces` (at the last tick's lever arms)."""
        f = self.last_forces
        return np.concatenate([f.sum(axis=0), _moment(self._r, f)])

    def _other_torques(
        self,
        model: mujoco.MjModel,
        data: mujoco.MjData,
        ref: Reference,
        jc: np.ndarray,
        force_sw: np.ndarray,
        modes: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        """(base, posture), each (n,): every torque but the stance forces' — ``base`` the
        bias, joint-damping compensation, inertial feed-forward and swing PD,
        ``posture`` the joint PD (null-space projected on the legs) and damping. ``jc``
        is (nf, 3, n + 1), last column zero."""
        legs = self.legs
        dof = self._dof
        tau = data.qfrc_bias[dof]  # a copy (fancy index)
        # the joints' own viscous damping (MJCF ``damping``), which the engine applies on
        # top of the actuators: uncompensated, a stance leg sweeping back under a fast
        # trunk brakes it (a horse's trotting leg by ~0.2 m·g per foot)
        tau += self._joint_damping * data.qvel[dof]
        # inertial feed-forward of the reference joint accelerations of the swinging legs
        # and of the joints outside the legs: M[j, j'] q̈_ref[j'] over those joints only
        key = int((modes == SWING) @ self._bits)
        moving = self._moving.get(key)
        if moving is None:
            moving = self._moving[key] = (
                self.leg_free | legs.own[modes == SWING].any(axis=0)
            ).astype(float)
        vec = self._qacc_buf
        vec[dof] = ref.qacc[dof] * moving
        mujoco.mj_mulM(model, data, self._mq_buf, vec)
        tau += self._mq_buf[dof] * moving
        t_sw = np.einsum("fkn,fk->n", jc[:, :, :-1], force_sw * 1.0) * self._own_any
        if self.debug:
            self._dbg = {"bias": tau.copy(), "swing": t_sw}
        tau += t_sw
        e_q = ref.qpos[self._qadr] - data.qpos[self._qadr]
        e_v = ref.qvel[dof] - data.qvel[dof]
        pd = self.kp_post * e_q + self.kd_post * e_v
        post = self._body_mask * pd + self.kd_damp * e_v
        if not self.config.null_space_posture:
            post += self._leg_mask * pd
            return tau, post
        # leg posture in the null space of each foot Jacobian on the leg's own joints;
        # the projector I − J⁺J changes slowly and is refreshed every few ticks
        if self._ticks % self._proj_every == 1 or self._proj is None:
            jo = jc[self._feet_col, :, self._own_idx]  # (nf, w, 3) = J_ownᵀ
            jjt = np.einsum("fwk,fwl->fkl", jo, jo) + self._eps3
            pinv_t = np.linalg.solve(jjt, jo.transpose(0, 2, 1))  # (nf, 3, w) = (J⁺)ᵀ
            self._proj = self._eye_w - np.einsum("fwk,fkv->fwv", jo, pinv_t)
        pd_pad = np.append(pd, 0.0)[self._own_idx]  # (nf, w)
        proj = np.einsum("fwv,fv->fw", self._proj, pd_pad)
        post[self._own_flat] += proj[self._own_valid]  # each joint belongs to one leg
        return tau, post

    def _to_ctrl(self, data: mujoco.MjData, tau: np.ndarray) -> np.ndarray:
        jm = self.legs.jmap
        clipped = np.minimum(np.maximum(tau, self._neg_limit), self._limit)
        if (clipped != tau).any():
            self._clipped += 1
        if (np.abs(clipped) >= AT_LIMIT_SHARE * self._limit).any():
            self._at_limit += 1
        u = np.array(data.ctrl)
        u[self._ctrl_idx] = np.minimum(np.maximum(clipped / self._tpc, jm.ctrl_lo), jm.ctrl_hi)
        self.last_torque = u[self._ctrl_idx] * self._tpc
        if self._servo is not None:
            ctrl, torque = self._servo.controls(data, clipped)
            sv = self._servo.servo
            u[self._ctrl_idx[sv]] = ctrl[sv]
            self.last_torque = np.where(sv, torque, self.last_torque)
        return u

    def _refresh_stats(self) -> None:
        """Fill ``stats.extra`` (called by ``stats.to_dict()``)."""
        ex = self.stats.extra
        ex["stance_qp_median_ms"] = self.qp.median_ms()
        ex["qp_failures"] = self.qp.failures
        ex["early_touchdowns"] = self.tracker.events["early_touchdown"]
        ex["lost_contacts"] = self.tracker.events["lost_contact"]
        ex["torque_clipped_share"] = self._clipped / max(self._ticks, 1)
        ex["torque_at_limit_share"] = self._at_limit / max(self._ticks, 1)
