"""Convex model-predictive control on a single rigid body (Di Carlo et al. 2018).

:class:`MPCController` (name ``"mpc"``) plans the ground forces of the stance feet over a
horizon of at least one stride at 30–50 Hz, and again at once whenever the stance set
changes (touch-down, lift-off), and runs the stance-force QP of
:class:`~habitsim.controllers.balance.BalanceController` at every control tick between
the MPC solves, with the MPC's first-step forces as its anchor.

**Model** (:class:`ConvexMPC`): the 13-state single rigid body
``x = [Θ (roll, pitch, yaw), p (CoM), ω (world), ṗ, g]`` (Θ the trunk body's orientation,
ω the whole body's centroidal angular velocity ``I_c⁻¹ h_c``, p the whole-body centre of
mass) with the dynamics linearised about
the reference yaw ψ_k of each horizon step::

    Θ̇ = Rz(ψ_k)ᵀ ω          ṗ = v
    ω̇ = I_k⁻¹ Σ_i r_ik × f_ik,   I_k = Rz(ψ_k) I_ψ Rz(ψ_k)ᵀ
    v̇ = Σ_i f_ik / m − [0, 0, g]        ġ = 0

``I_ψ`` is the centroidal inertia of the model at its current pose (expressed in the
current yaw frame), ``r_ik`` the foot points minus the CoM: for a foot that stays on the
ground, where it is; for a foot that will land, its reference foothold plus the same
capture-point correction the swing controller uses. The model is nilpotent
(``A³ = 0``), so its zero-order-hold discretisation is exact in closed form::

    x_{k+1} = (I + A dt + A² dt²/2) x_k + (B dt + A B dt²/2) u_k

**QP** (sparse, variables ``[u_0, x_1, u_1, x_2, …, x_N]``)::

    min Σ_k (x_k − x_ref,k)ᵀ Q (x_k − x_ref,k) + Σ_k R ‖u_k‖²
    s.t. dynamics, |f_x|, |f_y| ≤ μ f_z, 0 ≤ f_z ≤ f_z,max on scheduled stance feet,
         f = 0 on swing feet

Built once per horizon length as a CasADi ``qpsol`` whose parameters are the state, the
reference, the lever arms, yaws and inertia (so nothing is rebuilt per solve), solved by
OSQP (default) or PROXQP, warm-started from the previous solution shifted by one step,
and evaluated through CasADi's zero-copy function buffer. Weights are dimensionless and
scaled by mass, leg length and gravity (:class:`MPCWeights`).

The reference trunk states and the contact table come from the motion's
:class:`~habitsim.controllers.plan.MotionPlan`; without a plan the current reference is
extrapolated at constant velocity and the current contacts are held.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass

import casadi
import mujoco
import numpy as np

from .balance import BalanceController
from .base import ControllerError, Reference
from .contact_state import STANCE
from .plan import PlanSample, matrix_from_rpy, rpy_from_matrix
from .stance_qp import _moment

__all__ = [
    "MPCWeights",
    "MPCSolution",
    "ConvexMPC",
    "MPCController",
    "srb_matrices",
    "MPC_SOLVERS",
]

#: CasADi conic plugins the MPC accepts (sparse solvers).
MPC_SOLVERS = ("osqp", "proxqp")
#: State size of the single rigid body (orientation, position, angular velocity,
#: velocity, gravity).
NX = 13


@dataclass(frozen=True)
class MPCWeights:
    """Dimensionless MPC weights; :meth:`scaled` turns them into SI weights.

    Errors are measured in natural units of the body: angles in rad, positions in leg
    lengths L, velocities in sqrt(g·L), angular velocities in sqrt(g/L), forces in m·g.
    The defaults start from the weights of the MIT Mini Cheetah's convex MPC (Di Carlo
    et al. 2018; Q = [0.25 0.25 10, 2 2 50, 0 0 0.3, 0.2 0.2 0.1], R = 4e-5 N⁻² for 9 kg
    and L ≈ 0.3 m) in these units, with small roll/pitch rate weights added for damping,
    horizontal position and velocity weights of 2 and a roll weight eight times theirs
    (why: docs/controllers.md, "Why the defaults").
    """

    roll: float = 2.0
    pitch: float = 0.25
    yaw: float = 10.0
    pos_xy: float = 2.0
    pos_z: float = 4.5
    omega_xy: float = 0.3
    omega_z: float = 10.0
    vel_xy: float = 2.0
    vel_z: float = 0.3
    force: float = 0.03

    def scaled(self, mass: float, leg_length: float, gravity: float) -> tuple[np.ndarray, float]:
        """(Q (13,), R) in SI units."""
        length, g = leg_length, gravity
        wo = length / g
        q = np.array(
            [
                self.roll,
                self.pitch,
                self.yaw,
                self.pos_xy / length**2,
                self.pos_xy / length**2,
                self.pos_z / length**2,
                self.omega_xy * wo,
                self.omega_xy * wo,
                self.omega_z * wo,
                self.vel_xy / (g * length),
                self.vel_xy / (g * length),
                self.vel_z / (g * length),
                0.0,
            ]
        )
        return q, self.force / (mass * g) ** 2


def srb_matrices(
    yaw: float, inertia_inv: np.ndarray, r: np.ndarray, mass: float, dt: float
) -> tuple[np.ndarray, np.ndarray]:
    """(A_d (13, 13), B_d (13, 3k)) of the exact discretisation (see module docstring).

    Args:
        yaw: ψ_k [rad]; inertia_inv: (3, 3) ``I_ψ⁻¹`` in the yaw frame; r: (k, 3) lever
        arms [m]; mass [kg]; dt [s].
    """
    c, s = math.cos(yaw), math.sin(yaw)
    rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    iw = rz @ inertia_inv @ rz.T
    k = len(r)
    a = np.zeros((NX, NX))
    a[0:3, 6:9] = rz.T
    a[3:6, 9:12] = np.eye(3)
    a[11, 12] = -1.0
    b = np.zeros((NX, 3 * k))
    for i, ri in enumerate(np.asarray(r).reshape(-1, 3)):
        skew = np.array([[0.0, -ri[2], ri[1]], [ri[2], 0.0, -ri[0]], [-ri[1], ri[0], 0.0]])
        b[6:9, 3 * i : 3 * i + 3] = iw @ skew
        b[9:12, 3 * i : 3 * i + 3] = np.eye(3) / mass
    ad = np.eye(NX) + a * dt + a @ a * (dt * dt / 2.0)
    bd = b * dt + a @ b * (dt * dt / 2.0)
    return ad, bd


@dataclass(frozen=True)
class MPCSolution:
    """One MPC solve.

    Attributes:
        time: the state's time [s]; dt: step [s].
        forces: (N, nf, 3) planned ground forces [N]; states: (N, 13) predicted states
            x_1 … x_N; x0: (13,) initial state.
        ok: the solver's answer passed the checks; solve_s: wall time of the solve [s].
    """

    time: float
    dt: float
    x0: np.ndarray
    forces: np.ndarray
    states: np.ndarray
    ok: bool
    solve_s: float


class ConvexMPC:
    """The convex MPC QP for ``horizon`` steps and ``n_feet`` feet (built once).

    Args:
        horizon: number of steps N.
        n_feet: number of feet.
        solver: "osqp" (default) or "proxqp".
        tolerance: absolute / relative tolerance of the solver.
        solver_options: extra options of the solver (OSQP / PROXQP names).

    Attributes:
        times: solve times [s] of the last up to 4096 solves (ring buffer); calls; failures.
    """

    def __init__(
        self,
        horizon: int,
        n_feet: int = 4,
        solver: str = "osqp",
        tolerance: float = 1e-4,
        solver_options: dict | None = None,
    ) -> None:
        if solver not in MPC_SOLVERS or not casadi.has_conic(solver):
            avail = [s for s in MPC_SOLVERS if casadi.has_conic(s)]
            raise ControllerError(
                f"MPC solver {solver!r} is not available; available: {', '.join(avail)}"
            )
        if horizon < 1 or n_feet < 1:
            raise ControllerError("the MPC needs horizon >= 1 and n_feet >= 1")
        self.n, self.nf, self.solver = int(horizon), int(n_feet), solver
        self.tolerance = float(tolerance)
        fn, layout = self._build(tolerance, solver_options or {})
        self._fn = fn
        self._layout = layout
        self._buf, self._eval = fn.buffer()
        self._in = [np.zeros(fn.nnz_in(i)) for i in range(fn.n_in())]
        self._out = [np.zeros(fn.nnz_out(i)) for i in range(fn.n_out())]
        for i, a in enumerate(self._in):
            self._buf.set_arg(i, a.data)
        for i, a in enumerate(self._out):
            self._buf.set_res(i, a.data)
        step = NX + 4 * self.nf  # constraint rows per step: dynamics, friction
        lbg = np.zeros(self.n * step)
        for k in range(self.n):
            lbg[k * step + NX : (k + 1) * step] = -np.inf
        self._in[4][:] = lbg  # dynamics rows: = 0; friction rows: ≤ 0
        self._in[5][:] = 0.0
        self._warm = False
        self.times = np.zeros(4096)
        self.calls = 0
        self.failures = 0

    # variables per step k: u_k (3nf) then x_{k+1} (13)
    def _build(self, tolerance: float, extra: dict):
        n, nf = self.n, self.nf
        nu = 3 * nf
        x0 = casadi.SX.sym("x0", NX)
        xref = casadi.SX.sym("xref", NX, n)
        r = casadi.SX.sym("r", nu, n)
        yaw = casadi.SX.sym("yaw", n)
        iinv = casadi.SX.sym("iinv", 3, 3)
        mass, dt, mu, rw = (casadi.SX.sym(s) for s in ("m", "dt", "mu", "R"))
        q = casadi.SX.sym("Q", NX)
        z: list[casadi.SX] = []
        g: list[casadi.SX] = []
        cost: casadi.SX | float = 0
        xk = x0
        fs = mass * x0[12]  # forces are decision variables in units of m·g
        for k in range(n):
            us = casadi.SX.sym(f"u{k}", nu)
            u = fs * us
            xn = casadi.SX.sym(f"x{k + 1}", NX)
            c, s = casadi.cos(yaw[k]), casadi.sin(yaw[k])
            rz = casadi.vertcat(
                casadi.horzcat(c, -s, 0), casadi.horzcat(s, c, 0), casadi.horzcat(0, 0, 1)
            )
            iw = rz @ iinv @ rz.T
            force = casadi.SX.zeros(3)
            torque = casadi.SX.zeros(3)
            for i in range(nf):
                fi = u[3 * i : 3 * i + 3]
                force += fi
                torque += casadi.cross(r[3 * i : 3 * i + 3, k], fi)
            wd = iw @ torque
            vd = force / mass - casadi.vertcat(0, 0, xk[12])
            nxt = casadi.vertcat(
                xk[0:3] + dt * (rz.T @ xk[6:9]) + 0.5 * dt * dt * (rz.T @ wd),
                xk[3:6] + dt * xk[9:12] + 0.5 * dt * dt * vd,
                xk[6:9] + dt * wd,
                xk[9:12] + dt * vd,
                xk[12],
            )
            g.append(xn - nxt)
            for i in range(nf):
                fi = us[3 * i : 3 * i + 3]
                g.append(
                    casadi.vertcat(
                        fi[0] - mu * fi[2],
                        -fi[0] - mu * fi[2],
                        fi[1] - mu * fi[2],
                        -fi[1] - mu * fi[2],
                    )
                )
            e = xn - xref[:, k]
            cost += casadi.sum1(q * e * e) + rw * casadi.sumsqr(u)
            z += [us, xn]
            xk = xn
        p = casadi.vertcat(
            x0, casadi.vec(xref), casadi.vec(r), yaw, casadi.vec(iinv), mass, dt, mu, rw, q
        )
        opts: dict = {"error_on_fail": False}
        if self.solver == "osqp":
            opts["osqp"] = {
                "verbose": False,
                "eps_abs": tolerance,
                "eps_rel": tolerance,
                "polish": False,
                "max_iter": 4000,
                **extra,
            }
        else:
            opts["proxqp"] = {"eps_abs": tolerance, **extra}
        fn = casadi.qpsol(
            f"srb_mpc_{n}_{nf}",
            self.solver,
            {"x": casadi.vertcat(*z), "p": p, "f": cost, "g": casadi.vertcat(*g)},
            opts,
        )
        layout = {"x0": 0, "xref": NX, "r": NX + NX * n, "yaw": NX + NX * n + nu * n}
        layout["iinv"] = layout["yaw"] + n
        layout["scal"] = layout["iinv"] + 9
        layout["q"] = layout["scal"] + 4
        return fn, layout

    def solve(
        self,
        x0: np.ndarray,
        xref: np.ndarray,
        r: np.ndarray,
        yaw: np.ndarray,
        inertia: np.ndarray,
        contacts: np.ndarray,
        *,
        mass: float,
        dt: float,
        mu: float,
        fz_max: float,
        q: np.ndarray,
        rw: float,
        t: float = 0.0,
    ) -> MPCSolution:
        """Solve for one horizon.

        Args:
            x0: (13,) current state. xref: (N, 13) reference x_1 … x_N.
            r: (N, nf, 3) lever arms foot − CoM [m]. yaw: (N,) ψ_k [rad].
            inertia: (3, 3) centroidal inertia in the yaw frame [kg·m²].
            contacts: (N, nf) bool stance per step (swing feet get no force).
            mass [kg], dt [s], mu, fz_max [N], q (13,), rw: model, bounds and weights.
            t: time stamp [s] stored in the solution.
        """
        t0 = time.perf_counter()
        n, nf, lay = self.n, self.nf, self._layout
        nu = 3 * nf
        p = self._in[1]
        # positions relative to the current CoM (conditioning); forces in units of m·g
        origin = np.array(x0[3:6], dtype=float)
        x0r = np.array(x0, dtype=float)
        x0r[3:6] = 0.0
        xr = np.array(xref, dtype=float).reshape(n, NX).copy()
        xr[:, 3:6] -= origin
        fscale = mass * float(x0[12])
        p[lay["x0"] : lay["x0"] + NX] = x0r
        p[lay["xref"] : lay["r"]] = xr.ravel()
        p[lay["r"] : lay["yaw"]] = np.asarray(r, dtype=float).reshape(n, nu).ravel()
        p[lay["yaw"] : lay["iinv"]] = yaw
        p[lay["iinv"] : lay["scal"]] = np.linalg.inv(inertia).T.ravel()  # column-major
        p[lay["scal"] : lay["q"]] = (mass, dt, mu, rw)
        p[lay["q"] :] = q
        st = np.asarray(contacts, dtype=bool).reshape(n, nf)
        fz_s = fz_max / fscale
        lo_u = np.where(st[:, :, None], np.array([-mu * fz_s, -mu * fz_s, 0.0]), 0.0).reshape(n, nu)
        hi_u = np.where(st[:, :, None], np.array([mu * fz_s, mu * fz_s, fz_s]), 0.0).reshape(n, nu)
        lbx = np.full((n, nu + NX), -np.inf)
        ubx = np.full((n, nu + NX), np.inf)
        lbx[:, :nu], ubx[:, :nu] = lo_u, hi_u
        self._in[2][:] = lbx.ravel()
        self._in[3][:] = ubx.ravel()
        if self._warm:  # shift the previous solution by one step
            for k_in, k_out in ((0, 0), (6, 3), (7, 4)):  # x, lam_x, lam_g
                prev = self._out[k_out].reshape(n, -1)
                self._in[k_in][:] = np.concatenate([prev[1:], prev[-1:]]).ravel()
        else:
            self._in[0][:] = np.concatenate([np.zeros((n, nu)), xr], axis=1).ravel()
            self._in[6][:] = 0.0
            self._in[7][:] = 0.0
        self._eval()
        sol = self._out[0].reshape(n, nu + NX)
        ok = bool(np.all(np.isfinite(sol)))
        raw = sol[:, :nu].reshape(n, nf, 3)
        # the solver meets the constraints to its tolerance: project onto them exactly
        fz = np.clip(raw[..., 2], 0.0, fz_s)
        forces = np.stack(
            [np.clip(raw[..., 0], -mu * fz, mu * fz), np.clip(raw[..., 1], -mu * fz, mu * fz), fz],
            axis=-1,
        )
        forces = np.where(st[:, :, None], forces, 0.0)
        ok = ok and float(np.max(np.abs(forces - raw), initial=0.0)) <= 50.0 * self.tolerance
        forces = forces * fscale
        states = sol[:, nu:].copy()
        states[:, 3:6] += origin
        self._warm = ok
        if not ok:
            self.failures += 1
        dt_s = time.perf_counter() - t0
        self.times[self.calls % self.times.size] = dt_s
        self.calls += 1
        return MPCSolution(float(t), float(dt), np.array(x0, dtype=float), forces, states, ok, dt_s)

    def reset(self) -> None:
        """Forget the warm start."""
        self._warm = False

    def median_ms(self) -> float:
        """Median solve time [ms] (NaN before the first solve)."""
        k = min(self.calls, self.times.size)
        return float(np.median(self.times[:k]) * 1e3) if k else float("nan")

    @staticmethod
    def predict(
        x0: np.ndarray,
        forces: np.ndarray,
        r: np.ndarray,
        yaw: np.ndarray,
        inertia: np.ndarray,
        *,
        mass: float,
        dt: float,
    ) -> np.ndarray:
        """(N, 13) states of the discrete model under ``forces`` (N, nf, 3) (numpy
        roll-out of the same equations the QP uses)."""
        iinv = np.linalg.inv(inertia)
        x = np.array(x0, dtype=float)
        out = []
        for k in range(len(forces)):
            ad, bd = srb_matrices(float(yaw[k]), iinv, r[k], mass, dt)
            x = ad @ x + bd @ np.asarray(forces[k]).reshape(-1)
            out.append(x.copy())
        return np.array(out)


def _unwrap_to(angle: float, target: float) -> float:
    """``angle`` plus the multiple of 2π that brings it nearest to ``target``."""
    return angle + 2.0 * math.pi * round((target - angle) / (2.0 * math.pi))


class MPCController(BalanceController):
    """Convex MPC (forces over a horizon ≥ one stride) + the stance QP every tick.

    Args:
        model, feet, plan, leg_length, config, solver, assist: as
            :class:`~habitsim.controllers.balance.BalanceController`.
        rate_hz: MPC solves per second (30–50 recommended).
        horizon_s: horizon [s] (default: one stride of the plan, at least 0.3 s).
        max_steps: most horizon steps; a longer horizon takes longer steps.
        mpc_solver: "osqp" (default) or "proxqp".
        mpc_tolerance, mpc_options: solver tolerance and extra options.
        weights: :class:`MPCWeights`.
        feedback_scale: share of the balance PD gains used between MPC solves to track
            the MPC's own prediction.
        integral_rate: gain k_i [1/s] of the integral action on the forward lag of the
            CoM (see :meth:`_integrate`; 0 turns it off; why its default:
            docs/controllers.md).
        integral_max: bound of the integral's shift of the reference [leg lengths].
        resolve_on_contact: solve again as soon as the stance set changes (touch-down,
            lift-off, early touch-down, lost contact) instead of waiting for the next
            periodic solve: the first step's forces were planned for the old set, and at
            30 Hz a trot's foot would lose (or miss) its planned force for up to 33 ms.
        **options: :class:`~habitsim.controllers.balance.BalanceConfig` overrides.

    ``stats.extra`` adds ``mpc_median_ms``, ``mpc_solves``, ``mpc_failures``,
    ``mpc_horizon_steps`` and ``mpc_dt_s``.
    """

    name = "mpc"
    #: The single-rigid-body model's ω is the rate the ground forces change: the whole
    #: body's centroidal angular velocity ``I_c⁻¹ h_c`` (True), not the trunk body's own
    #: (False; why: docs/controllers.md).
    centroidal_rate = True

    def __init__(
        self,
        model: mujoco.MjModel,
        feet: Sequence[str] | None = None,
        *,
        rate_hz: float = 30.0,
        horizon_s: float | None = None,
        max_steps: int = 24,
        mpc_solver: str = "osqp",
        weights: MPCWeights | None = None,
        feedback_scale: float = 1.0,
        mpc_tolerance: float = 1e-3,
        mpc_options: dict | None = None,
        resolve_on_contact: bool = True,
        integral_rate: float = 3.0,
        integral_max: float = 0.3,
        **kwargs,
    ) -> None:
        super().__init__(model, feet, **kwargs)
        if not (np.isfinite(rate_hz) and rate_hz > 0):
            raise ControllerError(f"rate_hz must be > 0, got {rate_hz}")
        if max_steps < 2:
            raise ControllerError(f"max_steps must be >= 2, got {max_steps}")
        if not (np.isfinite(feedback_scale) and feedback_scale >= 0):
            raise ControllerError(f"feedback_scale must be >= 0, got {feedback_scale}")
        self.rate_hz = float(rate_hz)
        self.horizon_s = horizon_s
        self.max_steps = int(max_steps)
        self.mpc_solver = mpc_solver
        self.mpc_tolerance = float(mpc_tolerance)
        self.mpc_options = {"scaling": 0, **(mpc_options or {})}
        self.weights = weights or MPCWeights()
        self.feedback_scale = float(feedback_scale)
        cfg = self.config
        self.q, self.rw = self.weights.scaled(cfg.mass, cfg.leg_length, cfg.gravity)
        self._mpcs: dict[int, ConvexMPC] = {}
        self.solution: MPCSolution | None = None
        self._next = 0.0
        self._solved_stance: np.ndarray | None = None
        self.resolve_on_contact = bool(resolve_on_contact)
        if not (
            np.isfinite(integral_rate)
            and integral_rate >= 0
            and np.isfinite(integral_max)
            and integral_max >= 0
        ):
            raise ControllerError(
                f"integral_rate and integral_max must be finite and >= 0, "
                f"got {integral_rate}, {integral_max}"
            )
        self.integral_rate = float(integral_rate)
        self.integral_max = float(integral_max)
        self.integral = np.zeros(2)
        self._t_int: float | None = None
        self._setup_horizon()
        ConvexMPC(2, self.legs.n_feet, mpc_solver)  # fail early on a missing plugin

    def _setup_horizon(self) -> None:
        stride = self.plan.stride_s if self.plan is not None else float("nan")
        span = (
            self.horizon_s
            if self.horizon_s is not None
            else (stride if np.isfinite(stride) else 0.5)
        )
        span = max(float(span), 0.3)
        dt = 1.0 / self.rate_hz
        steps = int(math.ceil(span / dt - 1e-9))
        if steps > self.max_steps:
            steps = self.max_steps
            dt = span / steps
        self.steps, self.dt_mpc = max(steps, 2), dt

    def set_plan(self, plan_or_qpos, fps=None, contacts=None) -> None:
        super().set_plan(plan_or_qpos, fps, contacts)
        self._setup_horizon()

    @property
    def mpc(self) -> ConvexMPC:
        if self.steps not in self._mpcs:
            self._mpcs[self.steps] = ConvexMPC(
                self.steps, self.legs.n_feet, self.mpc_solver, self.mpc_tolerance, self.mpc_options
            )
        return self._mpcs[self.steps]

    def reset(self, model: mujoco.MjModel, data: mujoco.MjData) -> None:
        super().reset(model, data)
        self.mpc.reset()
        self.solution = None
        self._solved_stance = None
        self._next = -np.inf
        self.integral = np.zeros(2)
        self._t_int = None

    # ------------------------------------------------------------------ MPC problem
    def _horizon(
        self,
        smp: PlanSample,
        hold: bool,
        com: np.ndarray,
        rpy_now: np.ndarray,
        p: np.ndarray,
        delta: np.ndarray,
    ):
        """(times, xref, r, yaw, contacts) of the horizon starting at ``smp.t``."""
        n = self.steps
        dt = self.dt_mpc
        tk = smp.t + dt * np.arange(n + 1)  # t_0 … t_N
        g = self.config.gravity
        if self.plan is not None and not hold:
            xs = self.plan.trunk_states(tk)
            sched = self.plan.contacts_at(tk[:n])
            feet_ref = self.plan.feet_at(tk[:n])
        else:  # constant-velocity extrapolation of the current reference
            xs = np.zeros((n + 1, NX))
            xs[:, 0:3] = smp.rpy + np.outer(tk - smp.t, _rpy_rate(smp.rpy, smp.omega))
            xs[:, 3:6] = smp.com + np.outer(tk - smp.t, smp.com_vel)
            xs[:, 6:9] = smp.omega
            xs[:, 9:12] = smp.com_vel
            sched = np.tile(smp.contacts, (n, 1))
            feet_ref = np.tile(smp.feet, (n, 1, 1)) + np.einsum(
                "k,ij->kij", tk[:n] - smp.t, np.where(smp.contacts[:, None], 0.0, smp.feet_vel)
            )
        xs[:, 12] = g
        xs[:, 3:5] += self.integral  # integral action (see _integrate)
        modes = self.last_modes
        stance_now = modes == STANCE
        contacts = sched.copy()
        contacts[0] = stance_now
        # early touch-down: keep the foot on the ground until the schedule agrees
        early = stance_now & ~sched[0]
        if early.any():
            for i in np.flatnonzero(early):
                k = 0
                while k < n and not sched[k, i]:
                    contacts[k, i] = True
                    k += 1
        # feet that stay on the ground from now on push where they are
        stay = np.logical_and.accumulate(contacts, axis=0) & stance_now[None, :]
        foot = feet_ref + delta[None, None, :]
        foot = np.where(stay[:, :, None], p[None, :, :], foot)
        offset = com - xs[0, 3:6]
        r = foot - (xs[:n, 3:6] + offset)[:, None, :]
        yaw = xs[:n, 2].copy()
        return tk, xs, r, yaw, contacts

    def _solve(
        self,
        model: mujoco.MjModel,
        data: mujoco.MjData,
        smp: PlanSample,
        hold: bool,
        com: np.ndarray,
        com_vel: np.ndarray,
        rot: np.ndarray,
        omega: np.ndarray,
        p: np.ndarray,
        delta: np.ndarray,
    ) -> None:
        rpy = rpy_from_matrix(rot)
        rpy[2] = _unwrap_to(float(rpy[2]), float(smp.rpy[2]))
        tk, xs, r, yaw, contacts = self._horizon(smp, hold, com, rpy, p, delta)
        x0 = np.concatenate([rpy, com, omega, com_vel, [self.config.gravity]])
        c, s = math.cos(rpy[2]), math.sin(rpy[2])
        rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        inertia_yaw = rz.T @ self._inertia @ rz
        cfg = self.config
        self._mpc_inputs = (x0, r, yaw, inertia_yaw)
        self._solved_stance = contacts[0].copy()
        self.solution = self.mpc.solve(
            x0,
            xs[1:],
            r,
            yaw,
            inertia_yaw,
            contacts,
            mass=cfg.mass,
            dt=self.dt_mpc,
            mu=cfg.mu,
            fz_max=cfg.fz_max,
            q=self.q,
            rw=self.rw,
            t=smp.t,
        )
        if not self.solution.ok:
            self.stats.note(f"MPC solve failed at t={smp.t:.3f}s; using the stance QP alone")

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
        hold = ref.time == 0.0 and not np.any(ref.qvel)
        t = smp.t
        # a touch-down or lift-off between solves makes the first step's forces wrong
        # (planned for the old stance set): solve again at once
        contact_event = (
            self.resolve_on_contact
            and self._solved_stance is not None
            and bool((stance != self._solved_stance).any())
        )
        if (
            t >= self._next
            or self.solution is None
            or hold
            and self.solution.time != t
            or contact_event
        ):
            p = r + com
            height = max(float(com[2] - np.min(p[:, 2])), 1e-3)
            delta = self.swing.correction(
                com, com_vel, smp.com, smp.com_vel, height, self.config.gravity, float(smp.rpy[2])
            )
            self._integrate(t, hold, com, smp.com, float(smp.rpy[2]))
            self._solve(model, data, smp, hold, com, com_vel, rot, omega, p, delta)
            self._next = (t if np.isfinite(self._next) else t) + 1.0 / self.rate_hz
            self._update_stats()
        sol = self.solution
        if sol is None or not sol.ok:
            return super()._wanted(model, data, ref, smp, com, com_vel, rot, omega, r, stance)
        f_mpc = np.where(stance[:, None], sol.forces[0], 0.0)
        # the MPC's own prediction at this time (between x0 and x1)
        a = min(max((t - sol.time) / sol.dt, 0.0), 1.0)
        x_pred = (1.0 - a) * sol.x0 + a * sol.states[0]
        fb = self.feedback_scale
        acc = fb * (self.kp_pos * (x_pred[3:6] - com) + self.kd_pos * (x_pred[9:12] - com_vel))
        e_rot = self._rotation_error(matrix_from_rpy(x_pred[0:3]), rot)
        alpha = fb * (self.kp_rot * e_rot + self.kd_rot * (x_pred[6:9] - omega))
        b = np.concatenate(
            [f_mpc.sum(axis=0) + self.config.mass * acc, _moment(r, f_mpc) + self._inertia @ alpha]
        )
        return b, f_mpc

    def _integrate(
        self, t: float, hold: bool, com: np.ndarray, com_ref: np.ndarray, heading: float
    ) -> None:
        """Integral action on the CoM's lag along the reference heading.

        The single rigid body does not see the losses of a fast gait (touch-down impacts,
        the inertia of the stance legs, sliding feet): the ground forces it plans are not
        all realised, and a position/velocity weight alone leaves a steady lag (the camel's
        pace trailed its reference by 0.3–0.45 m, 0.25 L, at 5.4 m/s, while its root-relative
        pose error stayed at 65 mm). The reference the MPC tracks is therefore shifted by
        ``k_i ∫ e_fwd dt`` along the heading, ``e_fwd`` the forward component of
        ``c_ref − c``, bounded by ``integral_max`` leg lengths. Only the forward axis:
        sideways, the narrow support line of a pace leaves little force authority and an
        integral there made the camel's pace drift off and fall.
        """
        if hold or self.integral_rate == 0.0:
            self._t_int = None
            return
        if self._t_int is None:
            self._t_int = t
            return
        dt = min(max(t - self._t_int, 0.0), 0.1)
        self._t_int = t
        h = np.array([math.cos(heading), math.sin(heading)])
        e = float(h @ (com_ref[:2] - com[:2]))
        self.integral += self.integral_rate * dt * e * h
        lim = self.integral_max * self.config.leg_length
        n = float(np.hypot(*self.integral))
        if n > lim:
            self.integral *= lim / n

    def _update_stats(self) -> None:
        ex = self.stats.extra
        ex["mpc_median_ms"] = self.mpc.median_ms()
        ex["mpc_solves"] = self.mpc.calls
        ex["mpc_failures"] = self.mpc.failures
        ex["mpc_horizon_steps"] = self.steps
        ex["mpc_dt_s"] = self.dt_mpc


def _rpy_rate(rpy: np.ndarray, omega: np.ndarray) -> np.ndarray:
    """Roll/pitch/yaw rates of a world angular velocity under the MPC's approximation."""
    c, s = math.cos(rpy[2]), math.sin(rpy[2])
    return np.array([c * omega[0] + s * omega[1], -s * omega[0] + c * omega[1], omega[2]])
