"""Optional root assistance: an EXTERNAL PD wrench on the free joint, always measured.

Root assistance is a force from outside the robot (a "hand of god" holding the trunk
toward the reference root pose). It bends physics, so it is never on by default: no
controller creates one, it exists only when the user constructs a :class:`RootAssist`
and passes it (``assist=`` of a controller, or calls :meth:`RootAssist.apply` itself).
Every application is recorded and :meth:`RootAssist.report` gives the figures that must
accompany any result obtained with assistance (``assist_force_mg`` …).

The wrench goes to ``data.qfrc_applied`` on the six free-joint dofs only:
``[F (world frame, at the free body's origin) ; τ (free body's local frame)]``, the
generalised-force convention of MuJoCo's free joint. It stays there (zero-order hold)
until the next call; :meth:`RootAssist.reset` and :meth:`RootAssist.remove` clear it.

Held explicitly over a step, the PD's damping adds to the stance-force feedback of the
``balance`` and ``mpc`` controllers on the same trunk error, and the sum passes the
explicit stability limit: on a cat's real walk the assistance then flipped sign every
2 ms step (about ±3.5 m·g and ±35 N·m) and read a mean 4.95 m·g where 0.25 m·g was
needed. :meth:`RootAssist.damped_model` moves the damping into the model's free-joint
``dof_damping``, which MuJoCo's implicit and implicitfast integrators, and Euler unless
the model disables its ``eulerdamp`` flag, integrate implicitly (unconditionally
stable; with ``eulerdamp`` off the damping is still evaluated at every step, not held
over a control period); :func:`habitsim.sim.track` does so for every run with
assistance. The record still holds the whole PD wrench, damping included.
"""

from __future__ import annotations

import mujoco
import numpy as np

from habitsim.mjutils import body_free_joint, free_body

from .base import ControllerError, Reference

__all__ = ["RootAssist"]


class RootAssist:
    """PD wrench on the free joint toward the reference root pose.

    Args:
        model: the MuJoCo model (must have a free joint).
        kp: (translational, rotational) stiffness [N/m, N·m/rad] or one pair; default
            ``m·ω²`` and ``I·ω²`` with ``ω = 2π·5 Hz`` (m the subtree mass of the free body,
            I the largest principal inertia of the free body).
        kd: (translational, rotational) damping [N·s/m, N·m·s/rad]; default critical.
        body: name of the free-joint body (default: the model's first free joint).

    Attributes:
        last_wrench: (6,) the assist's generalised force at the last call (the whole PD
            wrench; on the model :meth:`damped_model` returned, its damping part acts
            through the model).
    """

    name = "root_assist"

    def __init__(
        self,
        model: mujoco.MjModel,
        kp: float | tuple[float, float] | None = None,
        kd: float | tuple[float, float] | None = None,
        *,
        body: str | None = None,
    ) -> None:
        if body is None:
            self.body = free_body(model)
        else:
            self.body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, body)
        jnt = body_free_joint(model, self.body)
        if jnt < 0:
            raise ControllerError("RootAssist needs a body with a free joint")
        self._qa, self._da = int(model.jnt_qposadr[jnt]), int(model.jnt_dofadr[jnt])
        self.mass = float(model.body_subtreemass[self.body])
        self.weight = self.mass * float(np.linalg.norm(model.opt.gravity))
        inertia = float(np.max(model.body_inertia[self.body]))
        omega = 2 * np.pi * 5.0
        kp_t, kp_r = self._pair(kp, (self.mass * omega**2, inertia * omega**2), "kp")
        kd_t, kd_r = self._pair(kd, (2 * self.mass * omega, 2 * inertia * omega), "kd")
        if kp is not None and kd is None:  # critical damping for the given stiffness
            kd_t, kd_r = 2 * np.sqrt(kp_t * self.mass), 2 * np.sqrt(kp_r * inertia)
        self.kp_t, self.kp_r, self.kd_t, self.kd_r = kp_t, kp_r, kd_t, kd_r
        self.last_wrench = np.zeros(6)
        self._damped: mujoco.MjModel | None = None  # the model damped_model returned
        self._reset_record()

    @staticmethod
    def _pair(value, default: tuple[float, float], name: str) -> tuple[float, float]:
        if value is None:
            return default
        arr = np.broadcast_to(np.asarray(value, dtype=float).ravel(), (2,))
        if not np.all(np.isfinite(arr)) or np.any(arr < 0):
            raise ControllerError(f"RootAssist {name} must be finite and non-negative, got {value}")
        return float(arr[0]), float(arr[1])

    def _reset_record(self) -> None:
        self._calls = 0
        self._force_sum = 0.0
        self._force_max = 0.0
        self._torque_sum = 0.0
        self._torque_max = 0.0
        self._impulse = 0.0
        self._angular_impulse = 0.0
        self._t_last: float | None = None

    def reset(self, model: mujoco.MjModel, data: mujoco.MjData) -> None:
        """Clear the record and the assist's entries of ``qfrc_applied``."""
        self._reset_record()
        self.remove(data)

    def remove(self, data: mujoco.MjData) -> None:
        """Zero the free-joint entries of ``qfrc_applied`` (stop assisting)."""
        data.qfrc_applied[self._da : self._da + 6] = 0.0
        self.last_wrench = np.zeros(6)

    def damped_model(self, model: mujoco.MjModel) -> mujoco.MjModel:
        """A copy of ``model`` whose free-joint dofs carry this assist's damping.

        ``dof_damping`` of the three translational dofs gets ``kd`` (translational) added,
        that of the three rotational dofs ``kd`` (rotational): the same ``−kd·q̇`` as the
        PD's damping term (MuJoCo's free joint has its linear velocity in the world frame
        and its angular velocity in the body frame, as the PD uses them), but integrated
        implicitly (by Euler only with its ``eulerdamp`` flag on, MuJoCo's default).
        :meth:`apply` on the returned model writes only the stiffness and the
        ``kd·q̇_ref`` feed-forward (on any other model, the whole wrench as before).
        ``model`` itself is not changed.

        Raises:
            ControllerError: the model integrates with RK4, which treats damping
                explicitly (nothing would be gained).
        """
        import copy

        if model.opt.integrator == mujoco.mjtIntegrator.mjINT_RK4:
            raise ControllerError(
                "RootAssist.damped_model needs the Euler, implicit or implicitfast "
                "integrator (RK4 integrates damping explicitly)"
            )
        out = copy.copy(model)
        da = self._da
        out.dof_damping[da : da + 3] += self.kd_t
        out.dof_damping[da + 3 : da + 6] += self.kd_r
        self._damped = out
        return out

    def _damping(self, data: mujoco.MjData) -> np.ndarray:
        """(6,) the PD's damping term ``−kd·q̇`` on the free joint at this state."""
        v = data.qvel[self._da : self._da + 6]
        return np.concatenate([-self.kd_t * v[:3], -self.kd_r * v[3:]])

    def wrench(self, data: mujoco.MjData, ref: Reference) -> np.ndarray:
        """(6,) the assist's generalised force on the free joint for this state."""
        qa, da = self._qa, self._da
        force = self.kp_t * (ref.qpos[qa : qa + 3] - data.qpos[qa : qa + 3]) + self.kd_t * (
            ref.qvel[da : da + 3] - data.qvel[da : da + 3]
        )
        err = np.zeros(3)
        rq = ref.qpos[qa + 3 : qa + 7] / max(np.linalg.norm(ref.qpos[qa + 3 : qa + 7]), 1e-12)
        q = data.qpos[qa + 3 : qa + 7] / max(np.linalg.norm(data.qpos[qa + 3 : qa + 7]), 1e-12)
        mujoco.mju_subQuat(err, rq, q)  # body-frame rotation vector current → reference
        # reference angular velocity is in the reference body frame; close enough near
        # the reference pose (the assist is a PD, not an exact tracker)
        torque = self.kp_r * err + self.kd_r * (
            ref.qvel[da + 3 : da + 6] - data.qvel[da + 3 : da + 6]
        )
        return np.concatenate([force, torque])

    def apply(self, model: mujoco.MjModel, data: mujoco.MjData, ref: Reference) -> np.ndarray:
        """Write the wrench to ``data.qfrc_applied`` (free dofs only; without its damping
        term on the model :meth:`damped_model` returned) and record the whole wrench."""
        if self._t_last is not None:  # the previous wrench acted from _t_last until now
            dt = max(float(data.time) - self._t_last, 0.0)
            self._impulse += float(np.linalg.norm(self.last_wrench[:3])) * dt
            self._angular_impulse += float(np.linalg.norm(self.last_wrench[3:])) * dt
        w = self.wrench(data, ref)
        # with implicit damping the model applies −kd·q̇ (at the end-of-step velocity)
        written = w - self._damping(data) if model is self._damped else w
        data.qfrc_applied[self._da : self._da + 6] = written
        self.last_wrench = w
        f, t = float(np.linalg.norm(w[:3])), float(np.linalg.norm(w[3:]))
        self._calls += 1
        self._force_sum += f
        self._force_max = max(self._force_max, f)
        self._torque_sum += t
        self._torque_max = max(self._torque_max, t)
        self._t_last = float(data.time)
        return w

    def report(self, data: mujoco.MjData | None = None) -> dict[str, float | int | bool]:
        """Figures of the assistance so far.

        Args:
            data: if given, the last wrench's impulse up to ``data.time`` is included.

        Returns:
            dict with ``assist_on`` (True), ``assist_calls``, ``assist_force_mg`` (mean
            |F| / (m·g)), ``assist_force_max_mg``, ``assist_force_mean_N``,
            ``assist_force_max_N``, ``assist_impulse_Ns`` (∫|F|dt), ``assist_torque_mean_Nm``,
            ``assist_torque_max_Nm``, ``assist_angular_impulse_Nms``.
        """
        impulse, ang = self._impulse, self._angular_impulse
        if data is not None and self._t_last is not None:
            dt = max(float(data.time) - self._t_last, 0.0)
            impulse += float(np.linalg.norm(self.last_wrench[:3])) * dt
            ang += float(np.linalg.norm(self.last_wrench[3:])) * dt
        n = max(self._calls, 1)
        mg = max(self.weight, 1e-12)
        return {
            "assist_on": True,
            "assist_calls": self._calls,
            "assist_force_mg": self._force_sum / n / mg,
            "assist_force_max_mg": self._force_max / mg,
            "assist_force_mean_N": self._force_sum / n,
            "assist_force_max_N": self._force_max,
            "assist_impulse_Ns": impulse,
            "assist_torque_mean_Nm": self._torque_sum / n,
            "assist_torque_max_Nm": self._torque_max,
            "assist_angular_impulse_Nms": ang,
        }
