"""The settings of a refinement: :class:`RefineOptions`."""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from ..physics_constants import CONTACT_HEIGHT_PER_LEG, GRAVITY
from .errors import RefineInputError
from .problem import (
    SolverSettings,
)
from .windows import Window, plan_windows

__all__ = ["RefineOptions", "SWING_CLEARANCE_PER_LEG", "GAUSS_NEWTON_MAX_ITER"]

#: Default lowest toe height of a moving swing foot, share of leg length: the contact
#: height plus a margin of 0.5 % L.
SWING_CLEARANCE_PER_LEG = 0.025
#: Iteration limit of the Gauss-Newton attempt per window (it converges in 7–30 when it
#: does; beyond, the exact-Hessian retry is faster).
GAUSS_NEWTON_MAX_ITER = 25


@dataclass(frozen=True)
class RefineOptions:
    """Settings of :func:`refine` (weights are those of :mod:`habitsim.refine.problem`).

    Attributes:
        dynamics: stage B (contact forces + centroidal dynamics) instead of stage A.
        window: window length W [frames]; overlap: frames shared by consecutive windows.
            100 / 20 (3.3 s at 30 fps): every window starts IPOPT afresh, and with 64 / 16
            a 100-frame clip took two windows and 1.4× the time of one.
        short_window, short_overlap: a clip longer than ``short_window`` but shorter than
            ``window`` is cut into windows of ``short_window`` frames (None: one window of
            its own length). Every window length is a problem of its own to build (3–9 s,
            0.3–0.8 GB), so clips of many lengths would each build one; this way a
            process needs two lengths (see :meth:`plan`).
        filter_cutoff: cutoff of the jitter pre-filter in units of the species' natural
            frequency √(g/L) [rad/s] (10 → 6.4 Hz for a dog, 3.5 Hz for an elephant);
            None switches the filter off.
        w_track, w_smooth, w_jerk, w_hinge_jerk, w_reg, w_root, w_residual, w_force: cost weights.
        friction: friction coefficient of the pyramid (None: the model's foot / floor).
        align_ground: shift the targets onto the floor first (:mod:`habitsim.refine.solve`, step 2).
        clean_contacts: clean the contact labels before planting them
            (:func:`clean_contact_labels`).
        trim_contacts: let the cleaning trim stance runs where the input's toe moves
            (step 1 of :func:`clean_contact_labels`). Off, labels that are the intent
            rather than a reading of the input (a transfer's footfall schedule taken
            from its source) are planted whole, sliding decoded feet included. Measured
            on habit transfers of real clips to the cat: trimming halves the stance
            (duty 0.45 → 0.24, flight phases appear) and the refined clip tracks worse
            than its input; without it the duty stays, but the solve needs 3–8× the
            iterations and the planted slides raise the jerk, so trimming stays the
            default and the pipeline's tracking check keeps the better clip.
        preplant: before the optimisation, plant the input's feet on the labels and lift
            them to the swing clearance by leg IK (:func:`_preplant`): the solve starts
            from, and tracks, feet that are already where the constraints want them. Off
            by default: on 50 transfers of real 4 s clips it met the three targets on 50
            instead of 49 in a similar time, but it moves clean clips' legs (a synthetic
            trot 6.4 mm from itself instead of under 6.1).
        plant_start: start each solve from the legs planted on the labels and lifted to
            the swing clearance by leg IK (the targets stay the input's): a warm start
            that already satisfies most constraints. Gauss-Newton then converges in
            7–14 iterations instead of 8–22 on artefact clips whose feet sink.
        swing_clearance: lowest toe height of a moving swing foot, share of leg length
            (:func:`swing_clearance`; at least docs/metrics.md's contact height, 2 %); None
            switches the clearance profile off (swing feet only stay above the floor).
        guard: when the result is worse than the input on a metric of the verdict
            (:func:`compare_metrics`; in practice the jerk), solve again with
            ``w_smooth``, ``w_jerk`` and ``w_hinge_jerk`` × :data:`GUARD_FACTOR` (the
            jerk weights, 0 by default, switched on at :data:`GUARD_START`), at most
            this many times (0: never), each retry starting from the previous solution
            with the exact Hessian; the report's ``guard`` lists the retries and its
            ``verdict`` says whether the result is still worse.
        fallback: on failure return the input with ``success=False`` instead of raising.
        metrics: compute docs/metrics.md kinematic and dynamic metrics before / after for the
            report (off in benchmarks).
        max_iter, tol, constr_viol_tol: IPOPT settings (constraint tolerance in [m]; 10 µm,
            ten times below ``verify_tol_mm``: at 1 µm the Gauss-Newton iterations crawl
            through the last digits linearly and stage B ran into their cap). The
            optimality tolerance is IPOPT's scaled one: 1e-5 instead of 1e-6 saved 16 %
            of the stage-A iterations on artefact clips with the same verdicts.
        verify_tol_mm: largest stance drift / penetration [mm] the MuJoCo check accepts.
    """

    dynamics: bool = False
    window: int = 100
    overlap: int = 20
    short_window: int | None = 64
    short_overlap: int = 16
    filter_cutoff: float | None = 10.0
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
    clean_contacts: bool = True
    trim_contacts: bool = True
    preplant: bool = False
    plant_start: bool = True
    swing_clearance: float | None = SWING_CLEARANCE_PER_LEG
    guard: int = 3
    fallback: bool = False
    metrics: bool = True
    max_iter: int = 200
    tol: float = 1e-5
    constr_viol_tol: float = 1e-5
    verify_tol_mm: float = 0.1

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name.startswith("w_") and not (np.isfinite(v) and v >= 0):
                raise RefineInputError(f"{f.name} must be a finite number ≥ 0, got {v!r}")
        if self.w_track <= 0:
            raise RefineInputError("w_track must be > 0")
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
        if int(self.max_iter) < 1:
            raise RefineInputError(f"max_iter must be ≥ 1, got {self.max_iter}")
        for name in ("tol", "constr_viol_tol", "verify_tol_mm"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise RefineInputError(f"{name} must be > 0, got {v!r}")
        plan_windows(max(self.window + 1, 1), self.window, self.overlap)  # validates sizes
        if self.short_window is not None:
            plan_windows(self.short_window + 1, self.short_window, self.short_overlap)

    def plan(self, n_frames: int) -> list[Window]:
        """The windows of an ``n_frames`` clip: of ``window`` frames if it is at least that
        long, else of ``short_window`` frames if it is longer than that, else one."""
        sw = self.short_window
        if sw is not None and sw < n_frames < self.window:
            return plan_windows(n_frames, sw, self.short_overlap)
        return plan_windows(n_frames, self.window, self.overlap)

    def cutoff_hz(self, leg_length: float, gravity: float = GRAVITY) -> float | None:
        """The pre-filter's cutoff frequency [Hz] for a leg length [m] (None: off)."""
        if self.filter_cutoff is None:
            return None
        return float(self.filter_cutoff) * float(np.sqrt(gravity / leg_length)) / (2 * np.pi)

    @property
    def settings(self) -> SolverSettings:
        """The settings of the first attempt per window: Gauss-Newton, at most
        :data:`GAUSS_NEWTON_MAX_ITER` iterations (the exact-Hessian retry gets max_iter),
        the jerk rows built only when a jerk weight is non-zero."""
        return SolverSettings(
            max_iter=min(int(self.max_iter), GAUSS_NEWTON_MAX_ITER),
            tol=float(self.tol),
            constr_viol_tol=float(self.constr_viol_tol),
            jerk=self.w_jerk > 0 or self.w_hinge_jerk > 0,
        )

    @property
    def weights(self) -> dict[str, float]:
        return {
            f.name: float(getattr(self, f.name)) for f in fields(self) if f.name.startswith("w_")
        }
