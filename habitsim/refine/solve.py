"""Solve the refinement of a clip: :func:`refine`.

``refine(motion)`` maps the motion onto its species' model
(:func:`habitsim.qpos.motion_to_qpos`), prepares targets, contact labels and an initial
guess, solves the windows of :func:`~habitsim.refine.windows.plan_windows` in order with
the cached problem of :func:`~habitsim.refine.problem.build_refinement_problem`,
assembles the qpos trajectory, checks the result with MuJoCo's own forward kinematics,
and writes the report (:mod:`habitsim.refine.report`).

Preparation, in this order:

0. **Targets**: the input's own joint positions (what the model's hinges cannot
   represent, e.g. a twist of a real animal's limb, is not taken for its pose).
1. **Jitter pre-filter** (``filter_cutoff``), only on a clip that jitters (the median
   lag-1 autocorrelation of what the filter would remove below ``jitter_autocorr``;
   the targets then get the filter's change of the model's joint positions): every
   coordinate of the input qpos (root position, root quaternion, hinges) is smoothed by
   the zero-phase second-difference
   filter ``argmin ‖y − x‖² + λ‖Δ²y‖²`` (a banded solve per coordinate, microseconds),
   with the cutoff scaled to the species' natural frequency √(g/L), so a cat and an
   elephant are smoothed alike in dimensionless time. A leg's hinges are not smoothed
   at the corners of its own touchdowns and lift-offs (the foot's velocity legitimately
   jumps there; smoothing across them makes the foot glide over the ground).
2. **Ground alignment** (``align_ground``): the targets are shifted vertically by a
   smooth per-frame offset, the mean height of the toes the labels put in contact
   (interpolated through flight phases, moving average over 0.25 s, at most
   ``max_align_per_leg`` × L). A
   clip that hovers or sinks as a whole is then tracked at the right height instead of
   being pulled against its stance constraints.
3. **Initial guess**: the filtered, aligned input with hinges clipped into their ranges
   and, frame by frame, the feet in contact put on the floor; stage B adds the body
   weight shared among the feet in contact and the CoM.
4. **Contact-label cleaning** (``clean_contacts``, :func:`clean_contact_labels`): stance
   runs are trimmed at their ends where the input's toe has moved more than
   ``stance_slip_per_leg`` × L from where it rests (at most ``max_trim_share``
   of a run at each end, uncapped by default), one-frame swing gaps whose two
   stance runs rest at the same place are filled, and stance runs shorter than
   ``min_run_s`` are dropped. Planting a label the input does not follow bends the
   whole leg for its duration and kinks it at the lift-off. Each step is an edit of
   the :class:`~habitsim.stance.labels.StanceLabels` under its reason code; the report
   lists the changes (``contacts.cleaning``, :func:`cleaning_summary`).
5. **Swing clearance** (:func:`swing_clearance`): docs/metrics.md counts a foot as in contact
   whenever its toe is below :data:`CONTACT_HEIGHT_PER_LEG` × L, labelled or not, so a
   swing foot skimming the ground while it moves reads as skating. Each swing phase
   gets a minimum toe height that rises linearly from the ground at the lift-off (and
   falls to it at the touch-down) over ``swing_ramp_s`` to ``swing_clearance`` × L
   (2.5 %: the contact height plus a margin); the swing frames whose minimum is still
   below the contact height are pinned horizontally to the foothold they leave or
   reach, and so are those next to a lift-off or touch-down whose input toe is still
   down (below the contact height, within ``swing_still_per_leg`` × L of the foothold):
   a foot is not lifted where the input does not move it. A foot therefore either rests
   (planted) or rises vertically, or clears the contact height while it moves: it never
   slides where the metric looks.

Each window is solved first with the Gauss-Newton Hessian (at most
``gauss_newton_max_iter`` iterations), and if IPOPT fails with it, again from the
same start with the exact Hessian; windows whose input leaves the joint ranges by more
than ``exact_first_excess_rad`` start with the exact Hessian.

Failure is never silent: a window on which IPOPT does not report success, or a result
that fails the MuJoCo check (stance drift or penetration beyond ``verify_tol_mm``),
raises :class:`~habitsim.refine.errors.RefineConvergenceError` — or, with
``fallback=True``, returns the input unchanged with ``success=False`` and the status in
the report. The knobs named here are fields of :class:`RefineOptions`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import Any

import mujoco
import numpy as np

from ..motion import Motion
from ..qpos import (
    QposTrajectory,
    motion_to_qpos,
)
from ..stance.labels import StanceLabels
from .attempt import SUCCESS_STATUSES, RefineAttempt, _solve_checked, fit_reference
from .cache import _species_model, clear_cache, get_problem
from .cleaning import (
    CLEANED_BY,
    _resolve_contacts,
    clean_contact_labels,
    cleaning_summary,
)
from .clearance import swing_clearance
from .errors import RefineConvergenceError, RefineInputError
from .options import (
    MIN_RUN_S,
    STANCE_SLIP_PER_LEG,
    SWING_CLEARANCE_PER_LEG,
    SWING_RAMP_S,
    RefineOptions,
)
from .prepare import _prepare, _preplant
from .verdict import VERDICT_METRICS, WORSE_TOLERANCE, compare_metrics

__all__ = [
    "RefineOptions",
    "RefineResult",
    "refine",
    "get_problem",
    "clear_cache",
    "SUCCESS_STATUSES",
    "SWING_CLEARANCE_PER_LEG",
    "SWING_RAMP_S",
    "STANCE_SLIP_PER_LEG",
    "MIN_RUN_S",
    "WORSE_TOLERANCE",
    "VERDICT_METRICS",
    "compare_metrics",
    "RefineAttempt",
    "clean_contact_labels",
    "cleaning_summary",
    "CLEANED_BY",
    "swing_clearance",
]


@dataclass(frozen=True)
class RefineResult:
    """Outcome of :func:`refine`.

    Attributes:
        motion: the refined motion (the input itself, with the labels, after a fallback),
            carrying the contact labels used and ``metadata["refine"]``.
        qpos: (T, nq) refined qpos trajectory of the species' model.
        fps: frame rate [Hz].
        status: IPOPT's status of the last window solved (``Solve_Succeeded`` …), or
            ``fallback: <status>``.
        success: False only after a fallback.
        contacts: (T, 4) the contact labels used (LF, RF, LH, RH).
        residual_mg: (T,) stage B's root residual force per frame / (m·g), else None.
        report: the JSON-ready report (:func:`habitsim.refine.report.build_report`).
        labels: the labels used as :class:`~habitsim.stance.labels.StanceLabels`, with
            the cleaning's and the preplanting's edits (None: not recorded).
    """

    motion: Motion
    qpos: np.ndarray
    fps: float
    status: str
    success: bool
    contacts: np.ndarray
    residual_mg: np.ndarray | None
    report: dict[str, Any] = field(default_factory=dict)
    labels: StanceLabels | None = None

    @property
    def trajectory(self) -> QposTrajectory:
        """The qpos as a :class:`~habitsim.qpos.QposTrajectory` (for tracking)."""
        return QposTrajectory(self.qpos, self.fps, np.zeros(len(self.qpos)), ())


# --------------------------------------------------------------------------- inputs
def _check_motion(motion: Any) -> Motion:
    if not isinstance(motion, Motion):
        raise RefineInputError(f"refine() needs a habitsim Motion, got {type(motion).__name__}")
    rp, rot = np.asarray(motion.root_positions), np.asarray(motion.rotations)
    t = rot.shape[0] if rot.ndim == 3 else -1
    if rot.ndim != 3 or rot.shape[1:] != (30, 4) or rp.shape != (t, 3):
        raise RefineInputError(
            f"motion arrays have wrong shapes: root_positions {rp.shape}, rotations {rot.shape}"
        )
    if not (np.all(np.isfinite(rp)) and np.all(np.isfinite(rot))):
        raise RefineInputError("motion contains NaN or inf")
    if t < 3:
        raise RefineInputError(f"refinement needs at least 3 frames, got {t}")
    if not (np.isfinite(motion.fps) and motion.fps > 0):
        raise RefineInputError(f"fps must be positive, got {motion.fps}")
    motion.species_info  # noqa: B018 - raises UnknownSpeciesError with the list
    return motion


def refine(
    motion: Motion,
    options: RefineOptions | None = None,
    *,
    contacts: np.ndarray | None = None,
    dynamics: bool | None = None,
    fallback: bool | None = None,
    model: mujoco.MjModel | None = None,
) -> RefineResult:
    """Make a motion physically plausible on its species' MuJoCo model.

    Args:
        motion: the motion (any length ≥ 3 frames).
        options: settings (default :class:`RefineOptions`).
        contacts: (T, 4) bool foot contact labels (LF, RF, LH, RH); default the motion's
            own labels, else :func:`habitsim.contacts.detect_contacts`.
        dynamics: shortcut for ``options.dynamics`` (stage B).
        fallback: shortcut for ``options.fallback``.
        model: a habitsim-named MuJoCo model to use instead of the species' shipped one.

    Returns:
        The :class:`RefineResult` (refined motion, qpos, status, report).

    Raises:
        RefineInputError: bad motion (NaN, shapes, < 3 frames), contacts or options.
        UnknownSpeciesError: the motion's species is not in the catalog.
        RefineConvergenceError: IPOPT failed on a window (unless ``fallback``).
        RefineError: the model lacks the habitsim structure.
    """
    from .report import build_report

    wall0 = time.perf_counter()
    opts = options or RefineOptions()
    if not isinstance(opts, RefineOptions):
        raise RefineInputError(f"options must be RefineOptions, got {type(opts).__name__}")
    if dynamics is not None:
        opts = replace(opts, dynamics=bool(dynamics))
    if fallback is not None:
        opts = replace(opts, fallback=bool(fallback))
    motion = _check_motion(motion)
    labels = _resolve_contacts(motion, contacts)  # bad labels fail before a problem is built
    motion_in = motion
    m = _species_model(motion.species) if model is None else model
    t = motion.num_frames
    plan = opts.plan(t)
    pr0 = get_problem(motion.species, plan[0].length, opts.dynamics, opts.settings, model=model)
    info = pr0.info
    pre = None
    if opts.preplant:
        motion, labels, pre = _preplant(motion, labels, opts)
    prep = _prepare(motion, labels, opts, m, pr0)
    if pre is not None:  # how the labels came and were cleaned, as given by the caller
        prep = replace(prep, **pre)
    refit: dict[str, Any] = {"applied": False, "reading_gap_per_leg": prep.reading_gap}
    if opts.reg_fit_above is not None and prep.reading_gap > opts.reg_fit_above:
        prep, entry = fit_reference(prep, motion, opts, plan, model, info)
        refit.update(entry)
    guard: list[dict[str, Any]] = []
    build_total = 0.0
    previous: tuple[RefineAttempt, dict[str, Any], RefineOptions] | None = None
    while True:
        warm = None if previous is None else previous[0].x  # a retry: the last solution
        attempt = _solve_checked(prep, motion, opts, plan, model, info, m, warm)
        build_total += attempt.build_s
        verdict = compare_metrics(motion_in, attempt.motion) if attempt.failure is None else None
        if verdict is None and previous is not None:  # a guard retry failed: keep the last
            attempt, verdict, opts = previous
            guard[-1]["status"] = "failed"
            break
        if verdict is None or verdict["ok"] or len(guard) >= int(opts.guard):
            break
        # worse than the input (in practice: jerkier): again with smoother weights
        log0 = attempt.log
        guard.append(
            {
                "worse": verdict["worse"],
                "after": verdict["after"],
                "iterations": int(sum(e["iterations"] for e in log0)),
                "solve_time_s": float(sum(e["solve_time_s"] for e in log0)),
                "status": "retried",
            }
        )
        previous = (attempt, verdict, opts)
        opts = opts.escalated()
        prep.glob.update(opts.weights)
    if previous is not None and verdict is not None and verdict["ok"]:
        # the guard's step overshoots: between the last worse weights and the first good
        # ones, the weights halfway (geometric) are tried, the good ones kept, so the
        # result is smoothed just enough to be no jerkier than its input
        lo = previous[2]
        for _ in range(int(opts.guard_bisect)):
            mid = opts.between(lo)
            prep.glob.update(mid.weights)
            trial = _solve_checked(prep, motion, mid, plan, model, info, m, attempt.x)
            build_total += trial.build_s
            good = compare_metrics(motion_in, trial.motion) if trial.failure is None else None
            guard.append(
                {
                    "worse": [] if good is None else good["worse"],
                    "after": None if good is None else good["after"],
                    "iterations": int(sum(e["iterations"] for e in trial.log)),
                    "solve_time_s": float(sum(e["solve_time_s"] for e in trial.log)),
                    "status": "bisected, kept" if good and good["ok"] else "bisected, dropped",
                }
            )
            if good is not None and good["ok"]:
                attempt, verdict, opts = trial, good, mid
            else:
                lo = mid
    status, failure, checks = attempt.status, attempt.failure, attempt.checks
    qpos, out = attempt.qpos, attempt.motion
    prep.glob.update(opts.weights)
    build_s = build_total
    success = failure is None
    report = build_report(
        motion_in=motion_in,
        motion_out=out,
        x=attempt.x,
        prep=prep,
        opts=opts,
        plan=plan,
        log=attempt.log,
        status=status if success else f"fallback: {status}" if opts.fallback else status,
        success=success,
        build_s=build_s,
        checks=checks,
        model=m,
        info=info,
        wall0=wall0,
        verdict=verdict,
        guard=guard,
    )
    residual = None
    if success and opts.dynamics and "residual_mg" in report:
        residual = np.asarray(report["residual_mg"]["per_frame"])
    if failure is not None:
        msg = (
            f"IPOPT did not converge on frames {failure.window[0]}:{failure.window[1]} "
            f"of the {t}-frame {motion.species} clip (status {failure.status}); "
            "use fallback=True (--fallback) to get the input back"
        )
        if failure.status == "Verification_Failed":
            msg = (
                f"the refined {motion.species} clip failed the MuJoCo check "
                f"(stance drift {checks['stance_drift_max_mm']:.3g} mm, penetration "
                f"{checks['penetration_max_mm']:.3g} mm > {opts.verify_tol_mm} mm)"
            )
        if not opts.fallback:
            raise RefineConvergenceError(msg, failure.status, failure.window, report)
        if pre is not None:  # the input itself comes back, not its pre-planted form
            out = motion_in.with_contacts(prep.contacts.copy())
            qpos = motion_to_qpos(motion_in, m).qpos
    # no timing here: the motion file of a seeded run is byte-identical from run to run
    # (solve and wall times are in the report)
    report["reg_reference"] = refit
    out.metadata["refine"] = {
        "status": report["status"],
        "success": success,
        "stage": report["stage"],
        "iterations": report["iterations"],
    }
    return RefineResult(
        out,
        qpos,
        motion.fps,
        report["status"],
        success,
        prep.contacts.copy(),
        residual,
        report,
        prep.labels,
    )
