"""Stance-leg trunk stabilisation without any external force (virtual model control).

Every tick, :class:`TrunkStabilizer`

1. computes a desired wrench on the robot about its centre of mass from PD on the
   reference free-joint pose and velocity (plus the reference acceleration),
   ``W = [m·(a_des − g); I_c·α_des]``,
2. distributes ``W`` over the stance feet (``ref.contacts``, or all feet) as ground
   reaction forces ``f_i`` with the shared stance-force QP
   (:func:`~habitsim.controllers.stance_qp.distribute_wrench`)::

       min_f  ‖S (A f − W)‖² + ε‖f‖²
       s.t.   |f·t1|, |f·t2| ≤ μ f·n   (4-sided friction pyramid per foot)
              0 ≤ f·n ≤ fz_max

   with ``A = [I … I; [p_i − c]× …]``, ``n`` the up direction (against gravity), ``S``
   scaling the torque rows by one over a body length so both halves are in newtons (one
   :class:`~habitsim.controllers.stance_qp.StanceQP` built per number of stance feet and
   reused); if the solver fails, a clipped regularised least squares solution is used and
   the failure counted in :attr:`TrunkStabilizer.stats`,
3. turns the forces into joint torques ``τ = −Σ_i J_iᵀ f_i`` (``J_i`` the foot point's
   translational Jacobian restricted to the leg joints). ``f_i`` is the force the ground
   must exert on foot ``i``; by reaction the foot must push the ground with ``−f_i``,
   which the legs do with ``τ = J_iᵀ(−f_i)``. A stance leg asked for an upward ground
   force therefore extends and lifts the trunk (tested).

Only actuator torques are produced: no force is ever applied to the free joint, gravity is
never changed. The stabiliser is a feed-forward component: add it on top of a
:class:`~habitsim.controllers.PDController` or
:class:`~habitsim.controllers.servo.ServoController` with :class:`StabilizedController`
(or pass it in their ``feedforward`` list).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import TYPE_CHECKING

import mujoco
import numpy as np

from habitsim.mjutils import body_free_joint, free_body, home_qpos

from .base import (
    BaseController,
    ControllerError,
    ControllerStats,
    PDController,
    Reference,
    actuated_joints,
    joint_torques,
)
from .gains import _point_body, _point_pos, _resolve_points
from .stance_qp import StanceQP, distribute_wrench

if TYPE_CHECKING:
    from .servo import ServoController

__all__ = ["TrunkStabilizer", "StabilizedController", "distribute_wrench", "StanceQP"]


class TrunkStabilizer:
    """Virtual-model trunk stabiliser: stance-leg joint torques realising a trunk wrench.

    Usable on any model with a free joint. Call it as a feed-forward component,
    ``stabilizer(model, data, ref) -> (n,)`` (same as :meth:`torques`), in the order of
    :attr:`joint_names`.

    Args:
        model: the MuJoCo model.
        feet: foot names in order (site, geom or body names; a site or geom gives the
            contact point, a body its origin); matches the order of ``ref.contacts``.
        trunk: body with the free joint (default: the model's free-joint body). The
            wrench is about the centre of mass of this body's subtree (the whole robot).
        joints: joints that receive torques (default: every actuated hinge/slide joint
            on the chain from the trunk to a foot).
        frequency_hz: natural frequency of the trunk PD [Hz]; translational gains are
            ``kp = m·ω²``, ``kd = 2ζ·m·ω``, rotational ones the same with the centroidal
            inertia (computed at the home pose) instead of ``m``.
        damping_ratio: ζ of the trunk PD.
        kp_pos, kd_pos, kp_rot, kd_rot: explicit per-unit-mass / per-unit-inertia gains
            [1/s², 1/s] overriding the frequency rule.
        mu: friction coefficient of the linear pyramid (4 sides).
        fz_max: largest normal force per foot [N] (default 1.5·m·g).
        regularization: ε of the QP.
        solver: CasADi conic plugin ("daqp" default; "qpoases", "osqp", "proxqp").

    Attributes:
        stats: :class:`ControllerStats` (calls, timing, ``failures`` = QP failures).
        last_forces: (n_feet, 3) ground forces of the last tick (zeros for swing feet).
        last_wrench: (6,) wanted wrench; last_achieved: (6,) wrench of ``last_forces``.
        last_torque: (n,) joint torques of the last tick.
    """

    name = "stance"

    def __init__(
        self,
        model: mujoco.MjModel,
        feet: Sequence[str],
        trunk: str | None = None,
        joints: Sequence[str] | None = None,
        *,
        frequency_hz: float = 1.5,
        damping_ratio: float = 1.0,
        kp_pos: float | None = None,
        kd_pos: float | None = None,
        kp_rot: float | None = None,
        kd_rot: float | None = None,
        mu: float = 0.8,
        fz_max: float | None = None,
        regularization: float = 1e-4,
        solver: str = "daqp",
    ) -> None:
        if not feet:
            raise ControllerError("TrunkStabilizer needs at least one foot name")
        self.points = _resolve_points(model, list(feet))
        self.feet = tuple(feet)
        if trunk is None:
            self.trunk = free_body(model)
            if self.trunk < 0:
                raise ControllerError("TrunkStabilizer needs a model with a free joint")
        else:
            self.trunk = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, trunk)
            if self.trunk < 0:
                names = [model.body(i).name for i in range(1, model.nbody)]
                raise ControllerError(f"unknown trunk body {trunk!r}; bodies: {', '.join(names)}")
        jnt = body_free_joint(model, self.trunk)
        if jnt < 0:
            raise ControllerError(f"trunk body {model.body(self.trunk).name!r} has no free joint")
        self._qa, self._da = int(model.jnt_qposadr[jnt]), int(model.jnt_dofadr[jnt])
        if joints is None:
            all_j = actuated_joints(model)
            foot_bodies = [_point_body(model, k, i) for k, i in self.points]
            joints = [
                n
                for n, j in zip(all_j.names, all_j.joint_ids, strict=True)
                if any(self._on_chain(model, int(model.jnt_bodyid[j]), fb) for fb in foot_bodies)
            ]
            if not joints:
                raise ControllerError("no actuated joint lies between the trunk and the feet")
        self.map = actuated_joints(model, joints)
        for name, val in (
            ("mu", mu),
            ("frequency_hz", frequency_hz),
            ("damping_ratio", damping_ratio),
            ("regularization", regularization),
        ):
            if not (np.isfinite(val) and val >= 0):
                raise ControllerError(f"{name} must be finite and >= 0, got {val}")
        for name, gain in (
            ("kp_pos", kp_pos),
            ("kd_pos", kd_pos),
            ("kp_rot", kp_rot),
            ("kd_rot", kd_rot),
        ):
            if gain is not None and not (np.isfinite(gain) and gain >= 0):
                raise ControllerError(f"{name} must be finite and >= 0, got {gain}")
        omega = 2 * np.pi * frequency_hz
        self.kp_pos = omega**2 if kp_pos is None else float(kp_pos)
        self.kd_pos = 2 * damping_ratio * omega if kd_pos is None else float(kd_pos)
        self.kp_rot = omega**2 if kp_rot is None else float(kp_rot)
        self.kd_rot = 2 * damping_ratio * omega if kd_rot is None else float(kd_rot)
        self.mu = float(mu)
        self.mass = float(model.body_subtreemass[self.trunk])
        self.gravity = np.array(model.opt.gravity, dtype=float)
        gnorm = float(np.linalg.norm(self.gravity))
        self.up = -self.gravity / gnorm if gnorm > 0 else np.array([0.0, 0.0, 1.0])
        self.fz_max = 1.5 * self.mass * max(gnorm, 1e-9) if fz_max is None else float(fz_max)
        if not self.fz_max > 0:
            raise ControllerError(f"fz_max must be > 0, got {fz_max}")
        self.regularization = float(regularization)
        self.solver = solver
        self._qps: dict[int, StanceQP] = {}
        StanceQP(1, solver)  # fail early if the plugin is missing
        self._inertia_body, self.length = self._centroidal(model)
        self._jacp = np.zeros((3, model.nv))
        self.stats = ControllerStats()
        n = len(self.map.names)
        self.last_forces = np.zeros((len(self.points), 3))
        self.last_wrench = np.zeros(6)
        self.last_achieved = np.zeros(6)
        self.last_torque = np.zeros(n)

    @property
    def joint_names(self) -> tuple[str, ...]:
        return self.map.names

    def _on_chain(self, model: mujoco.MjModel, body: int, foot_body: int) -> bool:
        """True if ``body`` is on the path trunk → foot (strictly below the trunk)."""
        b = foot_body
        while b > 0 and b != self.trunk:
            if b == body:
                return True
            b = int(model.body_parentid[b])
        return False

    def _centroidal(self, model: mujoco.MjModel) -> tuple[np.ndarray, float]:
        """Centroidal inertia in the trunk frame at home, and the mean foot–CoM distance."""
        d = mujoco.MjData(model)
        d.qpos[:] = home_qpos(model)
        mujoco.mj_forward(model, d)
        com = d.subtree_com[self.trunk].copy()
        inertia = np.zeros((3, 3))
        bodies = [b for b in range(model.nbody) if self._descends(model, b)]
        for b in bodies:
            r = d.xipos[b] - com
            rot = d.ximat[b].reshape(3, 3)
            inertia += rot @ np.diag(model.body_inertia[b]) @ rot.T
            inertia += model.body_mass[b] * (r @ r * np.eye(3) - np.outer(r, r))
        r_trunk = d.xmat[self.trunk].reshape(3, 3)
        dist = [np.linalg.norm(_point_pos(d, k, i) - com) for k, i in self.points]
        return r_trunk.T @ inertia @ r_trunk, float(max(np.mean(dist), 1e-3))

    def _descends(self, model: mujoco.MjModel, b: int) -> bool:
        while b > 0:
            if b == self.trunk:
                return True
            b = int(model.body_parentid[b])
        return False

    def reset(self, model: mujoco.MjModel, data: mujoco.MjData) -> None:
        self.last_forces[:] = 0.0
        self.last_torque[:] = 0.0

    def desired_wrench(
        self, model: mujoco.MjModel, data: mujoco.MjData, ref: Reference
    ) -> np.ndarray:
        """(6,) wanted [force N; torque N·m] about the CoM, world frame."""
        qa, da = self._qa, self._da
        pos, quat = data.qpos[qa : qa + 3], data.qpos[qa + 3 : qa + 7]
        rpos, rquat = ref.qpos[qa : qa + 3], ref.qpos[qa + 3 : qa + 7]
        rot9 = np.zeros(9)
        mujoco.mju_quat2Mat(rot9, quat)
        rot = rot9.reshape(3, 3)
        rrot9 = np.zeros(9)
        rquat_n = rquat / max(np.linalg.norm(rquat), 1e-12)
        mujoco.mju_quat2Mat(rrot9, rquat_n)
        rrot = rrot9.reshape(3, 3)
        a_des = (
            ref.qacc[da : da + 3]
            + self.kp_pos * (rpos - pos)
            + self.kd_pos * (ref.qvel[da : da + 3] - data.qvel[da : da + 3])
        )
        err_local = np.zeros(3)
        mujoco.mju_subQuat(err_local, rquat_n, quat / max(np.linalg.norm(quat), 1e-12))
        err = rot @ err_local
        omega = rot @ data.qvel[da + 3 : da + 6]
        omega_ref = rrot @ ref.qvel[da + 3 : da + 6]
        alpha = (
            rrot @ ref.qacc[da + 3 : da + 6] + self.kp_rot * err + self.kd_rot * (omega_ref - omega)
        )
        inertia = rot @ self._inertia_body @ rot.T
        return np.concatenate([self.mass * (a_des - self.gravity), inertia @ alpha])

    def torques(self, model: mujoco.MjModel, data: mujoco.MjData, ref: Reference) -> np.ndarray:
        """(n,) joint torques [N·m] ``−Σ J_iᵀ f_i`` for this tick (timed into stats).

        ``data`` must hold the current kinematics (``mj_forward`` / ``mj_step`` done).
        """
        t0 = time.perf_counter()
        nf = len(self.points)
        if ref.contacts is None:
            stance = np.ones(nf, dtype=bool)
        else:
            stance = np.asarray(ref.contacts, dtype=bool).reshape(-1)
            if stance.shape != (nf,):
                raise ControllerError(
                    f"ref.contacts has {stance.size} entries; the stabiliser has "
                    f"{nf} feet ({', '.join(self.feet)})"
                )
        wrench = self.desired_wrench(model, data, ref)
        self.last_wrench = wrench
        self.last_forces = np.zeros((nf, 3))
        tau = np.zeros(len(self.map.names))
        idx = np.flatnonzero(stance)
        if idx.size:
            pts = np.array([_point_pos(data, *self.points[i]) for i in idx])
            com = data.subtree_com[self.trunk]
            k = idx.size
            if k not in self._qps:
                self._qps[k] = StanceQP(k, self.solver)
            forces, ok = distribute_wrench(
                pts,
                com,
                wrench,
                mu=self.mu,
                fz_max=self.fz_max,
                up=self.up,
                length=self.length,
                regularization=self.regularization,
                qp=self._qps[k],
            )
            if not ok:
                self.stats.failures += 1
                self.stats.extra["qp_failures"] = self.stats.failures
                self.stats.note(f"QP failed at t={ref.time:.3f}s; used clipped least squares")
            achieved = np.zeros(6)
            for f, i, p in zip(forces, idx, pts, strict=True):
                self.last_forces[i] = f
                kind, oid = self.points[i]
                mujoco.mj_jac(model, data, self._jacp, None, p, _point_body(model, kind, oid))
                tau -= self._jacp[:, self.map.dof_adr].T @ f
                achieved[:3] += f
                achieved[3:] += np.cross(p - com, f)
            self.last_achieved = achieved
        self.last_torque = tau
        dt = time.perf_counter() - t0
        self.stats.calls += 1
        self.stats.total_time_s += dt
        self.stats.max_time_s = max(self.stats.max_time_s, dt)
        return tau

    __call__ = torques


class StabilizedController(BaseController):
    """A PD or servo controller plus a :class:`TrunkStabilizer` (torques summed).

    With a :class:`~habitsim.controllers.PDController` the stabiliser torques join the PD
    and feed-forward torques before clipping to the actuator limits; with a
    :class:`~habitsim.controllers.servo.ServoController` they join its feed-forward in
    ``data.qfrc_applied`` on the joint dofs (clipped so servo + extra stays in the motor's
    torque range, reported as actuator effort). The stabiliser's joints must be among the
    base controller's joints. The base's ``assist`` (default none) is used.

    ``stats.failures`` counts the stabiliser's QP failures; ``stats.extra`` holds the
    base's figures and ``stance_mean_time_ms``.
    """

    def __init__(self, base: PDController | ServoController, stabilizer: TrunkStabilizer) -> None:
        if not hasattr(base, "_control_with"):
            raise ControllerError(
                f"StabilizedController needs a PDController or ServoController base, got "
                f"{type(base).__name__}"
            )
        super().__init__(assist=base.assist)
        names = tuple(base.joint_names)
        missing = [n for n in stabilizer.joint_names if n not in names]
        if missing:
            raise ControllerError(
                f"stabiliser joints not driven by the base controller: {', '.join(missing)}"
            )
        self.base = base
        self.stabilizer = stabilizer
        self.name = f"{base.name}+stance"

    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(self.base.joint_names)

    def reset(self, model: mujoco.MjModel, data: mujoco.MjData) -> None:
        super().reset(model, data)
        base_assist, self.base.assist = self.base.assist, None  # reset the assist only once
        self.base.reset(model, data)
        self.base.assist = base_assist
        self.stabilizer.reset(model, data)

    def _control(self, model: mujoco.MjModel, data: mujoco.MjData, ref: Reference) -> np.ndarray:
        extra = joint_torques(self.stabilizer, model, data, ref, self.joint_names)
        u = self.base._control_with(model, data, ref, extra)
        self.stats.failures = self.stabilizer.stats.failures
        self.stats.extra.update(self.base.stats.extra)
        self.stats.extra["stance_mean_time_ms"] = self.stabilizer.stats.mean_time_ms
        for note in self.stabilizer.stats.notes:
            self.stats.note(note)
        return u
