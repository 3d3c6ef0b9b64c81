"""The stance-force QP: ground forces on the stance feet that realise a wanted wrench.

One implementation, shared by the trunk stabiliser
(:class:`~habitsim.controllers.stance.TrunkStabilizer`, through :func:`distribute_wrench`),
:class:`~habitsim.controllers.balance.BalanceController` and
:class:`~habitsim.controllers.mpc.MPCController` (the balance QP between MPC solves, with
the MPC's forces as its anchor). Over the forces ``f_i`` of k feet (world frame)::

    min_f ‖S (A f − b)‖² + α ‖f − f_anchor‖² + ε ‖f‖²
    s.t.  |f_x|, |f_y| ≤ μ f_z   (4-sided friction pyramid, z the ground normal)
          f_z,min ≤ f_z ≤ f_z,max on stance feet; f = 0 on swing feet
          τ_lo ≤ −Σ_i J_iᵀ f_i ≤ τ_hi on optional bounded joints

``A = [I … I; [r_i]× …]`` (:func:`wrench_matrix`, ``r_i`` the foot points minus the point
the wrench is taken about), ``S = diag(1, 1, 1, 1/L, 1/L, 1/L)`` so force and torque rows
are both in newtons. :class:`StanceQP` is built once per number of feet as a CasADi
``qpsol`` (plugin ``daqp`` by default) and evaluated through CasADi's zero-copy function
buffer; a result that is not finite or breaks the constraints is replaced by
:func:`clipped_least_squares` and counted as a failure. :func:`distribute_wrench` solves
one problem for any ground normal by expressing it in the frame of that normal.
"""

from __future__ import annotations

import time

import casadi
import numpy as np

from .base import ControllerError

__all__ = [
    "STANCE_SOLVERS",
    "StanceQP",
    "clipped_least_squares",
    "distribute_wrench",
    "ground_frame",
    "wrench_matrix",
]

#: CasADi conic plugins the stance QP accepts (dense active-set solvers first).
STANCE_SOLVERS = ("daqp", "qpoases", "proxqp", "osqp")

#: Levi-Civita symbol: ``Σ_i r_i × f_i = ε_ijk (rᵀf)_jk``.
_LEVI_CIVITA = np.zeros((3, 3, 3))
_LEVI_CIVITA[0, 1, 2] = _LEVI_CIVITA[1, 2, 0] = _LEVI_CIVITA[2, 0, 1] = 1.0
_LEVI_CIVITA[0, 2, 1] = _LEVI_CIVITA[2, 1, 0] = _LEVI_CIVITA[1, 0, 2] = -1.0


def _moment(r: np.ndarray, f: np.ndarray) -> np.ndarray:
    """(3,) total moment ``Σ_i r_i × f_i`` of (k, 3) forces at (k, 3) lever arms."""
    return np.einsum("ijk,fj,fk->i", _LEVI_CIVITA, r, f)


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def wrench_matrix(r: np.ndarray) -> np.ndarray:
    """(6, 3k) ``A`` mapping k foot forces to the wrench about the CoM; ``r`` (k, 3) are
    the foot points minus the CoM [m]."""
    r = np.asarray(r, dtype=float).reshape(-1, 3)
    a = np.zeros((6, 3 * len(r)))
    for i, ri in enumerate(r):
        a[:3, 3 * i : 3 * i + 3] = np.eye(3)
        a[3:, 3 * i : 3 * i + 3] = _skew(ri)
    return a


def ground_frame(up: np.ndarray) -> np.ndarray:
    """(3, 3) rotation whose rows are two unit tangents ``t1, t2`` and the unit normal
    ``up`` (right-handed, ``t2 = up × t1``); for ``up = +z`` it is the identity."""
    n = np.asarray(up, dtype=float)
    n = n / np.linalg.norm(n)
    helper = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    t1 = helper - n * (helper @ n)
    t1 /= np.linalg.norm(t1)
    return np.stack([t1, np.cross(n, t1), n])


def clipped_least_squares(
    r: np.ndarray,
    wrench: np.ndarray,
    stance: np.ndarray,
    mu: float,
    fz_min: float,
    fz_max: float,
    row_scale: np.ndarray,
) -> np.ndarray:
    """(n, 3) fallback forces: regularised least squares on the stance feet, each force
    then clipped into its friction pyramid and normal-force bounds (z the normal)."""
    r = np.asarray(r, dtype=float).reshape(-1, 3)
    idx = np.flatnonzero(stance)
    a = wrench_matrix(r[idx]) * row_scale[:, None]
    lhs, rhs = a.T @ a + 1e-6 * np.eye(a.shape[1]), a.T @ (wrench * row_scale)
    try:
        f = np.linalg.solve(lhs, rhs)
    except np.linalg.LinAlgError:
        # singular in floating point: feet kilometres from the CoM (an absurd reference)
        # drown the regularisation; least squares instead, no force if even that fails
        try:
            f = np.linalg.lstsq(lhs, rhs, rcond=None)[0]
        except np.linalg.LinAlgError:
            f = np.zeros(a.shape[1])
        if not np.all(np.isfinite(f)):
            f = np.zeros(a.shape[1])
    out = np.zeros((len(r), 3))
    for k, i in enumerate(idx):
        fi = f[3 * k : 3 * k + 3]
        fz = float(np.clip(fi[2], fz_min, fz_max))
        out[i] = (np.clip(fi[0], -mu * fz, mu * fz), np.clip(fi[1], -mu * fz, mu * fz), fz)
    return out


class StanceQP:
    """The stance-force QP for up to ``n_feet`` feet (built once; see module docstring).

    Decision variables: all feet's forces (3·n_feet, world frame); swing feet are held
    at zero by their bounds, so one problem serves every stance set.

    With ``n_joints > 0`` the torques the forces need are kept inside given bounds,
    ``τ_lo ≤ −Σ_i J_iᵀ f_i ≤ τ_hi`` (``J_i`` (3, n_joints) the foot Jacobians on those
    joints): the controller passes the actuator limits minus the torque the other terms
    already use, so the distribution never asks a weak joint (an abductor, the spine) for
    more than it has.

    Args:
        n_feet: number of feet.
        solver: CasADi conic plugin (:data:`STANCE_SOLVERS`; "daqp" default).
        n_joints: number of joints with torque bounds (0: none).

    Attributes:
        times: solve times [s] of the last up to 4096 calls (ring buffer), for medians.
        failures: number of solves whose result was replaced by the fallback.
    """

    def __init__(self, n_feet: int, solver: str = "daqp", n_joints: int = 0) -> None:
        if solver not in STANCE_SOLVERS or not casadi.has_conic(solver):
            avail = [s for s in STANCE_SOLVERS if casadi.has_conic(s)]
            raise ControllerError(
                f"stance QP solver {solver!r} is not available; available: {', '.join(avail)}"
            )
        if n_feet < 1:
            raise ControllerError("the stance QP needs at least one foot")
        self.n = int(n_feet)
        self.nj = int(n_joints)
        self.solver = solver
        nx = 3 * self.n
        f = casadi.SX.sym("f", nx)
        # parameters: r (3n), b (6), anchor (3n), S (6), alpha, eps, mu, Jᵀ (nj × 3n, by column)
        p = casadi.SX.sym("p", 3 * self.n + 6 + 3 * self.n + 6 + 3 + self.nj * nx)
        r = p[0:nx]
        b = p[nx : nx + 6]
        anchor = p[nx + 6 : 2 * nx + 6]
        s = p[2 * nx + 6 : 2 * nx + 12]
        alpha, eps, mu = p[2 * nx + 12], p[2 * nx + 13], p[2 * nx + 14]
        force = casadi.SX.zeros(3)
        torque = casadi.SX.zeros(3)
        g = []
        for i in range(self.n):
            fi, ri = f[3 * i : 3 * i + 3], r[3 * i : 3 * i + 3]
            force += fi
            torque += casadi.cross(ri, fi)
            g += [fi[0] - mu * fi[2], -fi[0] - mu * fi[2], fi[1] - mu * fi[2], -fi[1] - mu * fi[2]]
        if self.nj:
            jt = casadi.reshape(p[2 * nx + 15 :], self.nj, nx)
            g += casadi.vertsplit(-(jt @ f))
        res = s * (casadi.vertcat(force, torque) - b)
        obj = casadi.sumsqr(res) + alpha * casadi.sumsqr(f - anchor) + eps * casadi.sumsqr(f)
        opts: dict = {"error_on_fail": False}
        if solver == "qpoases":
            opts["printLevel"] = "none"
        elif solver == "osqp":
            opts["osqp"] = {"verbose": False, "eps_abs": 1e-6, "eps_rel": 1e-6}
        self._fn = casadi.qpsol(
            f"stance_qp_{self.n}", solver, {"x": f, "p": p, "f": obj, "g": casadi.vertcat(*g)}, opts
        )
        self._buf, self._eval = self._fn.buffer()
        self._in = [np.zeros(self._fn.nnz_in(i)) for i in range(self._fn.n_in())]
        self._out = [np.zeros(self._fn.nnz_out(i)) for i in range(self._fn.n_out())]
        for i, a in enumerate(self._in):
            self._buf.set_arg(i, a.data)  # type: ignore[call-arg]  # size: from the buffer
        for i, a in enumerate(self._out):
            self._buf.set_res(i, a.data)  # type: ignore[call-arg]  # size: from the buffer
        self._in[4][:] = -np.inf  # lbg
        self._in[5][:] = 0.0  # ubg
        self._np = 2 * nx + 15
        self.times = np.zeros(4096)
        self.calls = 0
        self.failures = 0
        self._bits = 1 << np.arange(self.n)
        self._bounds: dict = {}

    def solve(
        self,
        r: np.ndarray,
        wrench: np.ndarray,
        stance: np.ndarray,
        *,
        mu: float,
        fz_min: float,
        fz_max: float,
        row_scale: np.ndarray,
        anchor: np.ndarray | None = None,
        smooth: float = 1e-3,
        regularization: float = 1e-6,
        jac: np.ndarray | None = None,
        tau_lo: np.ndarray | None = None,
        tau_hi: np.ndarray | None = None,
    ) -> tuple[np.ndarray, bool]:
        """Ground forces ``(n, 3)`` [N] and whether the QP solution was used.

        Args:
            r: (n, 3) foot points minus CoM [m] (world frame).
            wrench: (6,) wanted [force N; torque about the CoM N·m].
            stance: (n,) bool, feet allowed to carry force.
            mu, fz_min, fz_max: friction coefficient and normal-force bounds [N].
            row_scale: (6,) S.
            anchor: (n, 3) forces the smoothing term pulls towards (f_prev); default 0.
            smooth, regularization: α and ε.
            jac: (n, 3, n_joints) foot Jacobians on the bounded joints; tau_lo, tau_hi:
                (n_joints,) bounds of ``−Σ J_iᵀ f_i`` [N·m] (widened to include 0, so
                ``f = 0`` is always feasible). Needed when built with ``n_joints > 0``.
        """
        t0 = time.perf_counter()
        n, nj = self.n, self.nj
        st = np.asarray(stance, dtype=bool)
        prm, lbg, ubg = self._in[1], self._in[4], self._in[5]
        prm[0 : 3 * n] = np.ravel(r)
        prm[3 * n : 3 * n + 6] = wrench
        prm[3 * n + 6 : 6 * n + 6] = 0.0 if anchor is None else np.ravel(anchor)
        prm[6 * n + 6 : 6 * n + 12] = row_scale
        prm[6 * n + 12 : 6 * n + 15] = (smooth, regularization, mu)
        if nj:
            if jac is None or tau_lo is None or tau_hi is None:
                raise ControllerError(
                    "this stance QP has joint torque bounds: pass jac, tau_lo, tau_hi"
                )
            # column-major (nj × 3n) Jᵀ: entry (j, 3i+k) = jac[i, k, j]
            prm[self._np :] = np.ravel(jac)
            np.minimum(tau_lo, 0.0, out=lbg[4 * n :])
            np.maximum(tau_hi, 0.0, out=ubg[4 * n :])
        key = (int(st @ self._bits), fz_min, fz_max)
        bounds = self._bounds.get(key)
        if bounds is None:
            big = 10.0 * fz_max
            bounds = (
                np.where(st[:, None], np.array([-big, -big, fz_min]), 0.0).ravel(),
                np.where(st[:, None], np.array([big, big, fz_max]), 0.0).ravel(),
            )
            if len(self._bounds) < 256:
                self._bounds[key] = bounds
        lbx, ubx = bounds
        self._in[2][:] = lbx
        self._in[3][:] = ubx
        ok = True
        if st.any():
            x, g = self._evaluate()
            viol = max((x - ubx).max(), (lbx - x).max(), (g - ubg).max(), (lbg - g).max())
            ok = viol <= 1e-5 * max(fz_max, 1.0)  # False for NaN as well
            if not ok:
                self.failures += 1
                x = clipped_least_squares(r, wrench, st, mu, fz_min, fz_max, row_scale).ravel()
            x.reshape(n, 3)[~st] = 0.0  # exactly (the solver leaves ~1e-15 on fixed bounds)
        else:
            x = np.zeros(3 * n)
        self.times[self.calls % self.times.size] = time.perf_counter() - t0
        self.calls += 1
        return x.reshape(n, 3), ok

    def _evaluate(self) -> tuple[np.ndarray, np.ndarray]:
        """Run the solver on the buffers: (x copy, constraint values g)."""
        self._eval()
        return self._out[0].copy(), self._out[2]

    def median_ms(self) -> float:
        """Median solve time [ms] over the recorded calls (NaN before the first)."""
        k = min(self.calls, self.times.size)
        return float(np.median(self.times[:k]) * 1e3) if k else float("nan")


def distribute_wrench(
    points: np.ndarray,
    com: np.ndarray,
    wrench: np.ndarray,
    *,
    mu: float = 0.8,
    fz_max: float = np.inf,
    up: np.ndarray | None = None,
    length: float = 0.3,
    regularization: float = 1e-4,
    qp: StanceQP | None = None,
    solver: str = "daqp",
) -> tuple[np.ndarray, bool]:
    """Ground forces ``(k, 3)`` on ``k`` stance points giving ``wrench`` about ``com``.

    The :class:`StanceQP` problem without smoothing (α = 0), every point in stance, posed
    in the frame of the ground normal ``up`` (:func:`ground_frame`) and rotated back.

    Args:
        points: (k, 3) stance foot positions [m], world frame.
        com: (3,) point the wrench's torque is taken about [m].
        wrench: (6,) wanted [force N, torque N·m], world frame.
        mu: friction coefficient of the 4-sided pyramid.
        fz_max: largest normal force per foot [N].
        up: (3,) ground normal (default +z).
        length: body length [m] scaling torque rows against force rows.
        regularization: ε on ‖f‖² (in units of the scaled residual).
        qp: a prebuilt :class:`StanceQP` for k feet (else one is built).
        solver: the QP plugin when ``qp`` is not given.

    Returns:
        (forces (k, 3), solved): ``solved`` is False when the QP failed and the clipped
        least-squares fallback was used.
    """
    pts = np.asarray(points, dtype=float).reshape(-1, 3)
    k = len(pts)
    if k == 0:
        return np.zeros((0, 3)), True
    rot = ground_frame(np.array([0.0, 0.0, 1.0]) if up is None else up)
    w = np.asarray(wrench, dtype=float)
    r_local = (pts - np.asarray(com, dtype=float)) @ rot.T
    w_local = np.concatenate([rot @ w[:3], rot @ w[3:]])
    fmax = float(fz_max) if np.isfinite(fz_max) else 1e9
    solver_qp = qp if qp is not None else StanceQP(k, solver)
    s = 1.0 / length
    forces, ok = solver_qp.solve(
        r_local,
        w_local,
        np.ones(k, dtype=bool),
        mu=mu,
        fz_min=0.0,
        fz_max=fmax,
        row_scale=np.array([1.0, 1.0, 1.0, s, s, s]),
        smooth=0.0,
        regularization=regularization,
    )
    return forces @ rot, ok
