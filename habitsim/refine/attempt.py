"""One attempt at a clip: its windows solved in turn, assembled and checked by MuJoCo."""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import Any

import mujoco
import numpy as np

from ..motion import Motion
from ..qpos import (
    qpos_to_motion,
)
from ..rotations import quat_mul, quat_normalize
from ..stance.labels import StanceLabels, runs
from ..threads import one_thread
from . import cache
from .cache import get_problem
from .options import RefineOptions
from .prepare import _Prepared
from .problem import (
    FEET,
    ModelInfo,
)
from .windows import Window

__all__ = ["RefineAttempt", "SUCCESS_STATUSES"]
#: IPOPT return statuses counted as success.
SUCCESS_STATUSES = ("Solve_Succeeded", "Solved_To_Acceptable_Level")


def _gibbs_quat(g: np.ndarray) -> np.ndarray:
    return quat_normalize(np.concatenate([np.ones(g.shape[:-1] + (1,)), g], axis=-1))


def _assemble_qpos(prep: _Prepared, info: Any, x: np.ndarray) -> np.ndarray:
    q = prep.qpos_in.copy()
    fa = info.free_qposadr
    q[:, fa : fa + 3] = x[:, :3]
    q[:, fa + 3 : fa + 7] = quat_normalize(quat_mul(prep.qref, _gibbs_quat(x[:, 3:6])))
    q[:, info.hinge_qposadr] = x[:, 6 : 6 + len(info.hinge_qposadr)]
    return q


def _solve_windows(
    prep: _Prepared,
    motion: Motion,
    opts: RefineOptions,
    plan: list[Window],
    model_arg: mujoco.MjModel | None,
    info: ModelInfo,
    x_init: np.ndarray | None = None,
) -> tuple[np.ndarray, list[dict], str, float]:
    """Solve the windows of ``plan`` in turn from ``prep.x0``, or from ``x_init`` (a
    guard retry, :data:`GUARD_WEIGHTS`: the previous attempt's solution, solved with the
    exact Hessian only)."""
    x = (prep.x0 if x_init is None else x_init).copy()
    log: list[dict] = []
    build_s = 0.0
    status = "not solved"
    for win in plan:
        sl = slice(win.start, win.stop)
        fixed = np.zeros(win.length, bool)
        fixed[: win.n_fixed] = True
        x_start = x[sl].copy()
        # Gauss-Newton first (fast); if IPOPT fails with it, the exact Hessian (robust
        # from far-off starts, e.g. inputs well outside the joint ranges)
        settings = [opts.settings]
        if opts.settings.hessian == "gauss-newton":
            exact = replace(opts.settings, hessian="exact", max_iter=int(opts.max_iter))
            read = prep.href_read[sl]
            excess = np.maximum(info.lower - read, read - info.upper).max()
            start_exact = excess > opts.exact_first_excess_rad or x_init is not None
            settings = [exact] if start_exact else [opts.settings, exact]
        for k, st_k in enumerate(settings):
            built = cache.builds()
            pr = get_problem(motion.species, win.length, opts.dynamics, st_k, model=model_arg)
            if cache.builds() > built:
                build_s += pr.build_time_s
            p = pr.parameters(prep.targets[sl], prep.qref[sl], prep.href[sl], prep.glob)
            lbx, ubx, lbg, ubg = pr.bounds(
                prep.contacts[sl],
                fixed,
                x_start,
                clearance=None if prep.clearance is None else prep.clearance[sl],
                pins=prep.pins[win.start : win.stop - 1],
            )
            solver = pr.solver
            assert solver is not None  # get_problem builds the solver
            t0 = time.perf_counter()
            with one_thread():  # the same solution on every machine (habitsim.threads)
                sol = solver(x0=pr.pack(x_start), p=p, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg)
            dt = time.perf_counter() - t0
            st = solver.stats()
            status = str(st["return_status"])
            xw = pr.unpack(np.asarray(sol["x"]).ravel())
            ok = status in SUCCESS_STATUSES and bool(np.all(np.isfinite(xw)))
            if k == 0:
                entry: dict[str, Any] = {
                    "start": win.start,
                    "stop": win.stop,
                    "n_fixed": win.n_fixed,
                    "status": status,
                    "hessian": st_k.hessian,
                    "iterations": 0,
                    "solve_time_s": 0.0,
                    "objective": float(sol["f"]),
                }
                log.append(entry)
            else:
                entry["retry_of"] = entry["status"]
                entry.update(status=status, hessian=st_k.hessian, objective=float(sol["f"]))
            entry["iterations"] += int(st["iter_count"])
            entry["solve_time_s"] += dt
            if ok:
                break
        if not ok:
            raise _WindowFailed(status, (win.start, win.stop), log, build_s)
        # committed up to commit_stop; beyond it the solution is the next window's warm start
        x[sl] = xw
    return x, log, status, build_s


def fit_reference(
    prep: _Prepared,
    motion: Motion,
    opts: RefineOptions,
    plan: list[Window],
    model_arg: mujoco.MjModel | None,
    info: ModelInfo,
) -> tuple[_Prepared, dict[str, Any]]:
    """``prep`` with ``href`` (what ``w_reg`` pulls the hinges towards) the hinges of the
    model's closest poses to the targets: the windows solved with the tracking term alone
    (no labels, clearance, pins, smoothing or regularisation; joint ranges and the floor
    kept). The regularisation then measures the change from the input as the model best
    takes it, not from a reading of its rotations several % of leg length away. On a
    failure ``prep`` comes back unchanged. Returns the prepared clip and the report's
    entry (``applied``, ``status``, ``iterations``, ``solve_time_s``)."""
    t = len(prep.href)
    zero = {k: 0.0 for k in opts.weights if k != "w_track"}
    free = replace(
        prep,
        glob={**prep.glob, **zero},
        labels=StanceLabels(np.zeros((t, 4), bool), prep.labels.source),
        clearance=None,
        pins=np.zeros_like(prep.pins),
    )
    entry: dict[str, Any] = {"applied": False}
    try:
        x, log, status, _ = _solve_windows(free, motion, opts, plan, model_arg, info)
    except _WindowFailed as e:
        entry.update(status=e.status)
        return prep, entry
    entry.update(
        applied=True,
        status=status,
        iterations=int(sum(e["iterations"] for e in log)),
        solve_time_s=float(sum(e["solve_time_s"] for e in log)),
    )
    nh = len(info.hinge_qposadr)
    return replace(prep, href=x[:, 6 : 6 + nh].copy(), reading=prep.href), entry


@dataclass(frozen=True)
class RefineAttempt:
    """One solve of every window of a clip, assembled and checked (:func:`_solve_checked`).

    Attributes:
        x: (T, nx) the solution (the initial guess after a window failure).
        log: per window what IPOPT did (the report's ``windows``).
        status: IPOPT's status of the last window solved or of the failing one, or
            ``Verification_Failed``.
        failure: what failed; None when every window was solved and the result passed
            the MuJoCo check.
        checks: the MuJoCo-FK checks of the result (:func:`_verify`; of the input after
            a window failure).
        qpos: (T, nq) the result (the input after a failure).
        motion: the result as a motion carrying the labels (the input after a failure).
        build_s: time spent building problems during the attempt [s].
    """

    x: np.ndarray
    log: list[dict[str, Any]]
    status: str
    failure: _WindowFailed | None
    checks: dict[str, float]
    qpos: np.ndarray
    motion: Motion
    build_s: float


def _solve_checked(
    prep: _Prepared,
    motion: Motion,
    opts: RefineOptions,
    plan: list[Window],
    model_arg: mujoco.MjModel | None,
    info: ModelInfo,
    m: mujoco.MjModel,
    x_init: np.ndarray | None = None,
) -> RefineAttempt:
    """Solve every window (from ``x_init`` if given, :func:`_solve_windows`), assemble,
    check with MuJoCo; the output motion is the input (with the labels) after a
    failure."""
    t = motion.num_frames
    failure: _WindowFailed | None = None
    try:
        x, log, status, build_s = _solve_windows(prep, motion, opts, plan, model_arg, info, x_init)
    except _WindowFailed as e:
        failure = e
        x, log, status, build_s = prep.x0, e.log, e.status, e.build_s
    qpos = _assemble_qpos(prep, info, x) if failure is None else prep.qpos_in.copy()
    checks = _verify(m, info, qpos, prep.contacts)
    if (
        failure is None
        and max(
            checks["stance_drift_max_mm"],
            checks["penetration_max_mm"],
            checks["stance_sole_height_max_mm"],
        )
        > opts.verify_tol_mm
    ):
        failure = _WindowFailed("Verification_Failed", (0, t), log, build_s)
        status = failure.status
    if failure is None:
        out = qpos_to_motion(m, qpos, motion.species, motion.fps)
        out.contacts = prep.contacts.copy()
        out.metadata = dict(motion.metadata)
    else:
        out = motion.slice(0)
        out.contacts = prep.contacts.copy()
        qpos = prep.qpos_in.copy()
    return RefineAttempt(x, log, status, failure, checks, qpos, out, build_s)


class _WindowFailed(Exception):
    def __init__(self, status: str, window: tuple[int, int], log: list[dict], build_s: float):
        self.status, self.window, self.log, self.build_s = status, window, log, build_s


def _verify(
    model: mujoco.MjModel, info: Any, qpos: np.ndarray, contacts: np.ndarray
) -> dict[str, float]:
    """MuJoCo-FK checks of a qpos trajectory: stance drift, penetration, limits [mm/rad]."""
    d = mujoco.MjData(model)
    toes = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, f"{leg}_toe") for leg in FEET]
    sole = np.empty((len(qpos), 4))
    toe = np.empty((len(qpos), 4, 3))
    low = np.empty(len(qpos))
    for k, q in enumerate(qpos):
        d.qpos[:] = q
        mujoco.mj_kinematics(model, d)
        sole[k] = d.geom_xpos[info.foot_geoms, 2] - info.foot_radius
        toe[k] = d.site_xpos[toes]
        low[k] = min(d.xpos[1:, 2].min(), d.site_xpos[:, 2].min())
    drift = 0.0
    for f in range(4):
        for a, b in runs(contacts[:, f]):
            seg = toe[a:b, f, :2]
            drift = max(drift, float(np.linalg.norm(seg - seg[0], axis=1).max()))
    stance_height = float(np.abs(sole[contacts]).max()) if contacts.any() else 0.0
    h = qpos[:, info.hinge_qposadr]
    excess = np.maximum(info.lower - h, 0) + np.maximum(h - info.upper, 0)
    return {
        "stance_drift_max_mm": drift * 1000.0,
        "stance_sole_height_max_mm": stance_height * 1000.0,
        "penetration_max_mm": float(max(0.0, -sole.min(), -low.min())) * 1000.0,
        "joint_limit_excess_max_rad": float(excess.max()),
    }
