"""The settings of a refinement: :class:`RefineOptions`."""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
from typing import Final, cast

import numpy as np

from ..physics_constants import CONTACT_HEIGHT_PER_LEG, GRAVITY
from ..stance.planting import PlantingOptions
from .errors import RefineInputError
from .problem import (
    SolverSettings,
)
from .windows import Window, plan_windows

__all__ = [
    "RefineOptions",
    "SWING_CLEARANCE_PER_LEG",
    "SWING_RAMP_S",
    "STANCE_SLIP_PER_LEG",
    "MAX_TRIM_SHARE",
    "MIN_RUN_S",
]


@dataclass(frozen=True)
class RefineOptions:
    """Settings of :func:`~habitsim.refine.refine` (weights are those of
    :mod:`habitsim.refine.problem`). Why each default: docs/refine.md, "Why the defaults".

    Attributes:
        dynamics: stage B (contact forces + centroidal dynamics) instead of stage A.
        window: window length W [frames]; overlap: frames shared by consecutive windows.
        short_window, short_overlap: a clip longer than ``short_window`` but shorter than
            ``window`` is cut into windows of ``short_window`` frames (None: one window of
            its own length). Every window length is a problem of its own to build, so a
            process needs two lengths (see :meth:`plan`).
        filter_cutoff: cutoff of the jitter pre-filter in units of the species' natural
            frequency √(g/L) [rad/s] (10 → 6.4 Hz for a dog, 3.5 Hz for an elephant);
            None switches the filter off.
        jitter_autocorr: the filter runs only on a clip that jitters: when the median
            over its hinges of the lag-1 autocorrelation of what the filter would remove
            (:func:`~habitsim.refine.filtering.jitter_autocorr`) is below this (white
            frame-to-frame noise: about −0.5; smooth motion: 0 to 0.3); None filters
            every clip.
        w_track, w_smooth, w_jerk, w_hinge_jerk, w_reg, w_root, w_residual, w_force: cost weights.
        friction: friction coefficient of the pyramid (None: the model's foot / floor).
        align_ground: shift the targets onto the floor first (:mod:`habitsim.refine.solve`,
            step 2).
        max_align_per_leg: largest ground-alignment shift, share of leg length (beyond it
            a clip has legs of the wrong length, which alignment cannot fix).
        clean_contacts: clean the contact labels before planting them
            (:func:`~habitsim.refine.cleaning.clean_contact_labels`).
        trim_contacts: let the cleaning trim stance runs where the input's toe moves
            (step 1 of the cleaning). Off, labels that are the intent rather than a
            reading of the input (a transfer's footfall schedule taken from its source)
            are planted whole, sliding decoded feet included.
        stance_slip_per_leg: a stance frame at an end of its run whose input toe lies
            horizontally further than this share of leg length from where the run rests
            is relabelled swing (the cleaning's trim).
        max_trim_share: largest share of a stance run the trim removes at each end
            (1: no cap).
        min_run_s: shortest stance run kept and longest swing gap filled by the cleaning
            [s] (at least 2 resp. 1 frames).
        preplant: before the optimisation, plant the input's feet on the labels and lift
            them to the swing clearance by leg IK: the solve starts from, and tracks, feet
            that are already where the constraints want them.
        plant_start: start each solve from the legs planted on the labels and lifted to
            the swing clearance by leg IK (the targets stay the input's): a warm start
            that already satisfies most constraints.
        swing_clearance: lowest toe height of a moving swing foot, share of leg length
            (:func:`~habitsim.refine.clearance.swing_clearance`; at least docs/metrics.md's
            contact height, 2 %); None switches the clearance profile off (swing feet only
            stay above the floor).
        swing_ramp_s: time over which a swing foot's minimum height rises from the ground
            to the clearance after a lift-off (and falls before a touch-down) [s].
        swing_still_per_leg: a swing frame next to a lift-off or touch-down whose input
            toe is still below the contact height and within this share of leg length
            horizontally of the foothold stays on the ground (pinned) instead of being
            lifted to the clearance: a foot is lifted only where it moves low.
        guard: when the result is worse than the input on a metric of the verdict
            (:func:`~habitsim.refine.verdict.compare_metrics`; in practice the jerk), solve
            again with the ``guard_weights`` × ``guard_factor`` (a weight that is 0 is
            switched on at ``guard_start``), at most this many times (0: never), each
            retry starting from the previous solution with the exact Hessian; the
            report's ``guard`` lists the retries and its ``verdict`` says whether the
            result is still worse.
        guard_weights: the cost weights (``w_*`` names) a guard retry raises.
        guard_factor: the factor a guard retry multiplies them by.
        guard_start: the value a guard retry switches a weight that is 0 on at.
        guard_bisect: after a guard retry that is no longer worse than the input, this
            many solves at the weights halfway (geometrically) between the last worse and
            the good ones, keeping the good (the least smoothing that is no jerkier than
            the input); 0: the retry's weights stay.
        fallback: on failure return the input with ``success=False`` instead of raising.
        metrics: compute docs/metrics.md kinematic and dynamic metrics before / after for the
            report (off in benchmarks).
        max_iter, tol, constr_viol_tol: IPOPT settings (constraint tolerance in [m]; the
            optimality tolerance is IPOPT's scaled one).
        gauss_newton_max_iter: iteration limit of the first, Gauss-Newton attempt per
            window (the exact-Hessian retry gets ``max_iter``).
        exact_first_excess_rad: a window whose input leaves the joint ranges by more than
            this [rad] starts with the exact Hessian.
        verify_tol_mm: largest stance drift / penetration [mm] the MuJoCo check accepts.
        reg_fit_above: when the model's reading of the input's angles (what ``w_reg``
            pulls the hinges towards) lies further than this share of leg length from the
            input's joint positions on some frame (max over the frames of the mean joint
            distance), the reading is replaced by the hinges of the model's closest poses
            to the input (:func:`~habitsim.refine.attempt.fit_reference`, one more solve
            per window); None never refits.
        planting: the knobs of the leg IK that plants the feet of the initial guess
            (``plant_start``) and of ``preplant``
            (:class:`~habitsim.stance.planting.PlantingOptions`).
    """

    dynamics: bool = False
    window: int = 100
    overlap: int = 20
    short_window: int | None = 64
    short_overlap: int = 16
    filter_cutoff: float | None = 10.0
    jitter_autocorr: float | None = -0.2
    w_track: float = 1.0
    w_smooth: float = 1e-5
    w_jerk: float = 0.0
    w_hinge_jerk: float = 0.0
    w_reg: float = 3e-2
    w_root: float = 1e-3
    w_residual: float = 2e-2
    w_force: float = 1e-4
    friction: float | None = None
    align_ground: bool = True
    max_align_per_leg: float = 0.05
    clean_contacts: bool = True
    trim_contacts: bool = True
    stance_slip_per_leg: float = 0.15
    max_trim_share: float = 1.0
    min_run_s: float = 0.04
    preplant: bool = False
    plant_start: bool = True
    swing_clearance: float | None = 0.025
    swing_ramp_s: float = 1.0 / 30.0
    swing_still_per_leg: float = 0.002
    guard: int = 5
    guard_weights: tuple[str, ...] = ("w_smooth", "w_jerk", "w_hinge_jerk")
    guard_factor: float = 10.0
    guard_start: float = 1e-7
    guard_bisect: int = 0
    fallback: bool = False
    metrics: bool = True
    max_iter: int = 200
    gauss_newton_max_iter: int = 25
    exact_first_excess_rad: float = 0.4
    tol: float = 1e-5
    constr_viol_tol: float = 1e-5
    verify_tol_mm: float = 0.1
    reg_fit_above: float | None = 0.005
    planting: PlantingOptions = field(default_factory=PlantingOptions)

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name.startswith("w_") and not (np.isfinite(v) and v >= 0):
                raise RefineInputError(f"{f.name} must be a finite number ≥ 0, got {v!r}")
        if self.w_track <= 0:
            raise RefineInputError("w_track must be > 0")
        ja = self.jitter_autocorr
        if ja is not None and not (np.isfinite(ja) and -1.0 <= ja <= 1.0):
            raise RefineInputError(f"jitter_autocorr must be in [-1, 1] or None, got {ja!r}")
        if self.filter_cutoff is not None and not (
            np.isfinite(self.filter_cutoff) and self.filter_cutoff > 0
        ):
            raise RefineInputError(f"filter_cutoff must be > 0 or None, got {self.filter_cutoff!r}")
        sc = self.swing_clearance
        if sc is not None and not (np.isfinite(sc) and CONTACT_HEIGHT_PER_LEG <= sc <= 0.5):
            raise RefineInputError(
                f"swing_clearance must be in [{CONTACT_HEIGHT_PER_LEG}, 0.5] (share of leg "
                f"length) or None, got {sc!r}"
            )
        if self.friction is not None and not (np.isfinite(self.friction) and self.friction > 0):
            raise RefineInputError(f"friction must be > 0, got {self.friction!r}")
        if int(self.guard) < 0:
            raise RefineInputError(f"guard must be ≥ 0, got {self.guard!r}")
        if int(self.guard_bisect) < 0:
            raise RefineInputError(f"guard_bisect must be ≥ 0, got {self.guard_bisect!r}")
        unknown = [w for w in self.guard_weights if w not in self.weights]
        if unknown:
            raise RefineInputError(f"guard_weights must name cost weights (w_*), got {unknown}")
        for name in (
            "max_align_per_leg",
            "stance_slip_per_leg",
            "max_trim_share",
            "min_run_s",
            "swing_ramp_s",
            "swing_still_per_leg",
            "guard_factor",
            "guard_start",
            "exact_first_excess_rad",
        ):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise RefineInputError(f"{name} must be a finite number ≥ 0, got {v!r}")
        if int(self.gauss_newton_max_iter) < 1:
            raise RefineInputError(
                f"gauss_newton_max_iter must be ≥ 1, got {self.gauss_newton_max_iter}"
            )
        if int(self.max_iter) < 1:
            raise RefineInputError(f"max_iter must be ≥ 1, got {self.max_iter}")
        rf = self.reg_fit_above
        if rf is not None and not (np.isfinite(rf) and rf >= 0):
            raise RefineInputError(f"reg_fit_above must be a finite number ≥ 0 or None, got {rf!r}")
        for name in ("tol", "constr_viol_tol", "verify_tol_mm"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise RefineInputError(f"{name} must be > 0, got {v!r}")
        plan_windows(max(self.window + 1, 1), self.window, self.overlap)  # validates sizes
        if self.short_window is not None:
            plan_windows(self.short_window + 1, self.short_window, self.short_overlap)

    def plan(self, n_frames: int) -> list[Window]:
        """The windows of an ``n_frames`` clip: one if it is at most ``window + overlap``
        frames long and not shorter than ``window`` (two windows would solve the
        frames they share twice: a 120-frame clip 200 frames), of ``window`` frames if
        it is longer, else of ``short_window`` frames if it is longer than that, else
        one."""
        sw = self.short_window
        if sw is not None and sw < n_frames < self.window:
            return plan_windows(n_frames, sw, self.short_overlap)
        if n_frames <= self.window + self.overlap:
            return plan_windows(n_frames, max(n_frames, self.window), self.overlap)
        return plan_windows(n_frames, self.window, self.overlap)

    def cutoff_hz(self, leg_length: float, gravity: float = GRAVITY) -> float | None:
        """The pre-filter's cutoff frequency [Hz] for a leg length [m] (None: off)."""
        if self.filter_cutoff is None:
            return None
        return float(self.filter_cutoff) * float(np.sqrt(gravity / leg_length)) / (2 * np.pi)

    @property
    def settings(self) -> SolverSettings:
        """The settings of the first attempt per window: Gauss-Newton, at most
        ``gauss_newton_max_iter`` iterations (the exact-Hessian retry gets max_iter),
        the jerk rows built only when a jerk weight is non-zero."""
        return SolverSettings(
            max_iter=min(int(self.max_iter), int(self.gauss_newton_max_iter)),
            tol=float(self.tol),
            constr_viol_tol=float(self.constr_viol_tol),
            jerk=self.w_jerk > 0 or self.w_hinge_jerk > 0,
        )

    @property
    def weights(self) -> dict[str, float]:
        return {
            f.name: float(getattr(self, f.name)) for f in fields(self) if f.name.startswith("w_")
        }

    def between(self, lower: RefineOptions) -> RefineOptions:
        """These options with each of ``guard_weights`` halfway (the geometric mean)
        between ``lower``'s and these (a weight 0 in ``lower``: these / √guard_factor)."""
        mid = {}
        for k in self.guard_weights:
            hi, lo = float(getattr(self, k)), float(getattr(lower, k))
            mid[k] = float(np.sqrt(lo * hi)) if lo > 0 else hi / float(np.sqrt(self.guard_factor))
        return replace(self, **mid)  # type: ignore[arg-type]

    def escalated(self) -> RefineOptions:
        """The options of a guard retry: each of ``guard_weights`` × ``guard_factor``, or
        ``guard_start`` where it is 0."""
        up = {
            k: (v * self.guard_factor if v > 0 else self.guard_start)
            for k in self.guard_weights
            for v in (float(getattr(self, k)),)
        }
        return replace(self, **up)  # type: ignore[arg-type]


#: Read-only aliases of defaults of :class:`RefineOptions` (names of
#: :mod:`habitsim.refine.solve` from before the options held them); changing one changes
#: nothing: pass ``RefineOptions(...)``.
SWING_CLEARANCE_PER_LEG: Final = cast(float, RefineOptions.swing_clearance)
SWING_RAMP_S: Final = RefineOptions.swing_ramp_s
STANCE_SLIP_PER_LEG: Final = RefineOptions.stance_slip_per_leg
MAX_TRIM_SHARE: Final = RefineOptions.max_trim_share
MIN_RUN_S: Final = RefineOptions.min_run_s
