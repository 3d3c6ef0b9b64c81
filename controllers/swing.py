"""Swing-leg control (:class:`SwingLegs`), and the pieces it is built on, re-exported.

Swing feet follow the motion's own foot path, bent so that it starts where the foot
really lifted off and ends at a corrected foothold (the reference foothold moved with the
body, plus a bounded capture-point correction), tracked by a Cartesian PD
``F = Kp (p_des − p) + Kd (v_des − v)`` applied as ``τ = J_legᵀ F``; gravity and bias
compensation (``qfrc_bias``) and the joints' damping are added by the torque layer for
every joint.

Shared by the balance (:mod:`~habitsim.controllers.balance`) and MPC
(:mod:`~habitsim.controllers.mpc`) controllers; usable on any MJCF with a free joint and
named feet (sites, geoms or bodies). The legs (:mod:`~habitsim.controllers.legs`), the
plan (:mod:`~habitsim.controllers.plan`) and the contact state machine
(:mod:`~habitsim.controllers.contact_state`) live in their own modules; their names are
importable from here as well.

Units: SI (m, s, kg, N, N·m, rad); world frame z up.
"""

from __future__ import annotations

import math

import numpy as np

from .contact_state import SEEK, STANCE, SWING, ContactTracker
from .legs import HABITSIM_FEET, LegSet, default_feet, model_leg_length
from .plan import MotionPlan, PlanSample, matrix_from_rpy, plan_from_qpos, rpy_from_matrix

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
