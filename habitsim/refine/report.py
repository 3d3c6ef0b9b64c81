"""The refinement's JSON report.

Keys (all values JSON types; lengths in mm where the key says so):

==============================  ==========================================================
``status`` / ``success``        IPOPT's status of the last window solved (or of the failing
                                one), ``fallback: <status>`` after a fallback
``stage``                       ``"A"`` (kinematic) or ``"B"`` (centroidal dynamics)
``species``, ``frames``, ``fps``
``iterations``                  IPOPT iterations summed over the windows
``solve_time_s``                IPOPT wall time summed over the windows [s]
``build_time_s``                time spent building problems in this call (0 when cached)
``wall_time_s``                 the whole call including metrics [s]
``windows``                     per window: start, stop, n_fixed, status, hessian
                                (``gauss-newton`` / ``exact``), iterations and
                                solve_time_s (summed over a retry; ``retry_of`` = the
                                status of the failed Gauss-Newton attempt), objective
``window_plan``                 the planned windows (start, stop, n_fixed, commit_stop)
``cost`` / ``cost_input``       each weighted term of :data:`~.problem.COST_TERMS` on the
                                whole clip and their ``total`` (= the sum of the terms),
                                for the result / for the initial guess (the input
                                filtered, aligned, clipped to the joint ranges)
``weights``                     the weights used
``max_constraint_violation``    largest violation of any constraint row or bound on the
                                whole clip, in its unit (m for rows, rad for joint limits)
``constraint_violation``        the same per block: ``sole``, ``ground``, ``pin``,
                                ``com`` (stage B), ``joint_limits``
``checks``                      MuJoCo-FK checks of the result: ``stance_drift_max_mm``,
                                ``stance_sole_height_max_mm``, ``penetration_max_mm``,
                                ``joint_limit_excess_max_rad`` (after a window failure: of
                                the input; after ``Verification_Failed``: of the rejected
                                result)
``contacts``                    ``source`` (input / detected / given), per-foot
                                ``stance_share`` of the labels planted and
                                ``stance_share_input`` of the labels given,
                                ``cleaning`` (what :func:`~.solve.clean_contact_labels`
                                changed, None when off), ``swing_clearance_mm``
``metrics_before/after``        docs/metrics.md kinematic metrics (and dynamic ones when
                                :mod:`habitsim.metrics.dynamic` is available) of the
                                input and of the result (when ``options.metrics``), by
                                the metrics' literal definitions (contact = toe height
                                < 2 % L), not by the refinement's labels
``verdict``                     always (None after a failure): ``before`` / ``after``
                                ``skate_mm``, ``jerk`` and ``penetration_mm`` (the
                                metric functions), ``worse`` (the keys the result makes
                                worse beyond ``tolerance``: mm, relative for the jerk)
                                and ``ok`` (nothing worse)
``guard``                       the solves redone with smoother weights because the
                                result was worse (``options.guard``): per retry the
                                ``worse`` keys, the ``after`` values, ``iterations`` and
                                ``solve_time_s`` of the discarded attempt, ``status``
                                (``retried``; ``bisected, kept`` / ``bisected, dropped``
                                for a solve at the weights halfway, ``guard_bisect``)
``reg_reference``               what ``w_reg`` pulls the hinges towards:
                                ``reading_gap_per_leg`` (how far the model's reading of
                                the input's angles lies from the input), ``applied``
                                (refitted to the model's closest poses,
                                ``reg_fit_above``) with the fit's ``status``,
                                ``iterations`` and ``solve_time_s``
``filter``                      the jitter pre-filter: ``applied`` and the input's
                                ``jitter_autocorr`` (None: filter off)
``change_per_leg``              how far the result lies from the input in leg lengths
                                (:func:`~.verdict.input_change`): per frame the mean
                                joint position change, its ``max`` and ``median`` over
                                the frames, and ``joint_max`` (one joint, one frame)
``ground_offset_mm``            mean and largest ground-alignment shift
``residual_mg``                 stage B: the model's root residual force / (m·g): mean, max
                                and ``per_frame`` (0 at the first and last frame)
==============================  ==========================================================
"""

from __future__ import annotations

import math
import time
from typing import Any

import mujoco
import numpy as np

from .problem import COST_TERMS, STAGE_A_TERMS, RefinementProblem, clip_evaluator
from .verdict import WORSE_TOLERANCE, input_change

__all__ = ["build_report", "clean_json"]


def clean_json(v: Any) -> Any:
    """Numpy scalars/arrays → Python; NaN / inf → None (valid JSON)."""
    if isinstance(v, dict):
        return {str(k): clean_json(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [clean_json(x) for x in v]
    if isinstance(v, np.ndarray):
        return clean_json(v.tolist())
    if isinstance(v, (np.bool_, bool)):
        return bool(v)
    if isinstance(v, (np.integer, int)):
        return int(v)
    if isinstance(v, (np.floating, float)):
        f = float(v)
        return f if math.isfinite(f) else None
    return v


_EVALUATORS: dict[tuple, tuple[mujoco.MjModel, RefinementProblem]] = {}


def _evaluator(model: mujoco.MjModel, n_frames: int, dynamics: bool) -> RefinementProblem:
    """The clip-length evaluator, cached for the last few (model, T, stage)."""
    key = (id(model), int(n_frames), bool(dynamics))
    hit = _EVALUATORS.get(key)
    if hit is not None and hit[0] is model:
        return hit[1]
    if len(_EVALUATORS) >= 8:
        _EVALUATORS.pop(next(iter(_EVALUATORS)))
    ev = clip_evaluator(model, n_frames, dynamics)
    _EVALUATORS[key] = (model, ev)
    return ev


def _metrics(motion: Any, contacts: np.ndarray, model: mujoco.MjModel) -> dict[str, float]:
    from ..metrics.kinematic import kinematic_metrics

    out = dict(kinematic_metrics(motion))
    try:
        from ..metrics.dynamic import dynamic_metrics
    except ImportError:  # pragma: no cover - the dynamic metrics are optional
        return out
    out.update(dynamic_metrics(motion, model, contacts))
    return out


def _cost(values: np.ndarray, dynamics: bool) -> dict[str, float]:
    names = COST_TERMS if dynamics else COST_TERMS[:STAGE_A_TERMS]
    out = {n: float(values[i]) for i, n in enumerate(names)}
    out["total"] = float(sum(out.values()))
    return out


def build_report(
    *,
    motion_in: Any,
    motion_out: Any,
    x: np.ndarray,
    prep: Any,
    opts: Any,
    plan: list,
    log: list[dict],
    status: str,
    success: bool,
    build_s: float,
    checks: dict[str, float],
    model: mujoco.MjModel,
    info: Any,
    wall0: float,
    verdict: dict[str, Any] | None = None,
    guard: list[dict[str, Any]] | None = None,
) -> dict[str, Any]:
    """Assemble the report of one :func:`~habitsim.refine.refine` call (module docstring)."""
    t = motion_in.num_frames
    ev = _evaluator(model, t, bool(opts.dynamics))
    p = ev.parameters(prep.targets, prep.qref, prep.href, prep.glob)
    terms, g, res = (np.asarray(v) for v in ev.evaluator(ev.pack(x), p))
    terms0 = np.asarray(ev.evaluator(ev.pack(prep.x0), p)[0]).ravel()
    lbx, ubx, lbg, ubg = ev.bounds(
        prep.contacts, swing_floor=prep.swing_floor, clearance=prep.clearance, pins=prep.pins
    )
    g = g.ravel()
    viol_rows = np.maximum(np.maximum(lbg - g, g - ubg), 0.0)
    violation = {
        name: float(viol_rows[a:b].max(initial=0.0)) for name, (a, b) in ev.ng_blocks.items()
    }
    xf = ev.pack(x)
    vx = np.maximum(np.maximum(lbx - xf, xf - ubx), 0.0)
    violation["joint_limits"] = float(vx.max(initial=0.0))
    report: dict[str, Any] = {
        "status": status,
        "success": success,
        "stage": "B" if opts.dynamics else "A",
        "species": motion_in.species,
        "frames": t,
        "fps": motion_in.fps,
        "iterations": int(sum(e["iterations"] for e in log)),
        "solve_time_s": float(sum(e["solve_time_s"] for e in log)),
        "build_time_s": float(build_s),
        "windows": log,
        "window_plan": [
            {"start": w.start, "stop": w.stop, "n_fixed": w.n_fixed, "commit_stop": w.commit_stop}
            for w in plan
        ],
        "cost": _cost(terms.ravel(), opts.dynamics),
        "cost_input": _cost(terms0, opts.dynamics),
        "weights": opts.weights,
        "max_constraint_violation": float(max(violation.values())),
        "constraint_violation": violation,
        "checks": checks,
        "contacts": {
            "source": prep.labels_input.source.value,
            "stance_share": prep.contacts.mean(axis=0).tolist(),
            "stance_share_input": prep.labels_input.array.mean(axis=0).tolist(),
            "cleaning": prep.cleaning,
            "swing_clearance_mm": None
            if opts.swing_clearance is None
            else float(opts.swing_clearance * motion_in.species_info.leg_length * 1000.0),
        },
        "filter": {"applied": bool(prep.filtered), "jitter_autocorr": prep.jitter},
        "change_per_leg": input_change(motion_in, motion_out),
        "ground_offset_mm": {
            "mean": float(prep.offset.mean() * 1000.0),
            "max_abs": float(np.abs(prep.offset).max() * 1000.0),
        },
    }
    if opts.dynamics:
        per = np.linalg.norm(res[:3], axis=0)
        inner = per[1:-1] if t > 2 else per
        report["residual_mg"] = {
            "mean": float(inner.mean()),
            "max": float(inner.max()),
            "per_frame": per.tolist(),
        }
    if opts.metrics:
        report["metrics_before"] = _metrics(motion_in, prep.contacts, model)
        report["metrics_after"] = _metrics(motion_out, prep.contacts, model)
    report["guard"] = list(guard or [])
    if verdict is not None:
        report["verdict"] = {
            "worse": list(verdict["worse"]),
            "ok": bool(verdict["ok"]),
            "before": verdict["before"],
            "after": verdict["after"],
            "tolerance": dict(WORSE_TOLERANCE),
        }
    else:
        report["verdict"] = None
    report["wall_time_s"] = time.perf_counter() - wall0
    return clean_json(report)
