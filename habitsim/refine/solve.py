"""Solve the refinement of a clip: :func:`refine`.

``refine(motion)`` maps the motion onto its species' model
(:func:`habitsim.qpos.motion_to_qpos`), prepares targets, contact labels and an initial
guess, solves the windows of :func:`~habitsim.refine.windows.plan_windows` in order with
the cached problem of :func:`~habitsim.refine.problem.build_refinement_problem`,
assembles the qpos trajectory, checks the result with MuJoCo's own forward kinematics,
and writes the report (:mod:`habitsim.refine.report`).

Preparation, in this order:

1. **Jitter pre-filter** (``filter_cutoff``): every coordinate of the input qpos (root
   position, root quaternion, hinges) is smoothed by the zero-phase second-difference
   filter ``argmin ‖y − x‖² + λ‖Δ²y‖²`` (a banded solve per coordinate, microseconds),
   with the cutoff scaled to the species' natural frequency √(g/L), so a cat and an
   elephant are smoothed alike in dimensionless time. A leg's hinges are not smoothed
   at the corners of its own touchdowns and lift-offs (the foot's velocity legitimately
   jumps there; smoothing across them makes the foot glide over the ground).
2. **Ground alignment** (``align_ground``): the targets are shifted vertically by a
   smooth per-frame offset, the mean height of the toes the labels put in contact
   (interpolated through flight phases, moving average over 0.25 s, at most 5 % L). A
   clip that hovers or sinks as a whole is then tracked at the right height instead of
   being pulled against its stance constraints.
3. **Initial guess**: the filtered, aligned input with hinges clipped into their ranges
   and, frame by frame, the feet in contact put on the floor; stage B adds the body
   weight shared among the feet in contact and the CoM.
4. **Contact-label cleaning** (``clean_contacts``, :func:`clean_contact_labels`): stance
   runs are trimmed at their ends where the input's toe has moved more than
   :data:`STANCE_SLIP_PER_LEG` × L from where it rests (at most :data:`MAX_TRIM_SHARE`
   of a run at each end, uncapped by default), one-frame swing gaps whose two
   stance runs rest at the same place are filled, and stance runs shorter than
   :data:`MIN_RUN_S` are dropped. Planting a label the input does not follow bends the
   whole leg for its duration and kinks it at the lift-off. Each step is an edit of
   the :class:`~habitsim.stance.labels.StanceLabels` under its reason code; the report
   lists the changes (``contacts.cleaning``, :func:`cleaning_summary`).
5. **Swing clearance** (:func:`swing_clearance`): docs/metrics.md counts a foot as in contact
   whenever its toe is below :data:`CONTACT_HEIGHT_PER_LEG` × L, labelled or not, so a
   swing foot skimming the ground while it moves reads as skating. Each swing phase
   gets a minimum toe height that rises linearly from the ground at the lift-off (and
   falls to it at the touch-down) over :data:`SWING_RAMP_S` to ``swing_clearance`` × L
   (2.5 %: the contact height plus a margin); the swing frames whose minimum is still
   below the contact height are pinned horizontally to the foothold they leave or
   reach. A foot therefore either rests (planted) or rises vertically, or clears the
   contact height while it moves: it never slides where the metric looks.

Each window is solved first with the Gauss-Newton Hessian (at most
:data:`GAUSS_NEWTON_MAX_ITER` iterations), and if IPOPT fails with it, again from the
same start with the exact Hessian; windows whose input leaves the joint ranges by more
than :data:`EXACT_FIRST_EXCESS_RAD` start with the exact Hessian.

Failure is never silent: a window on which IPOPT does not report success, or a result
that fails the MuJoCo check (stance drift or penetration beyond ``verify_tol_mm``),
raises :class:`~habitsim.refine.errors.RefineConvergenceError` — or, with
``fallback=True``, returns the input unchanged with ``success=False`` and the status in
the report.
"""

from __future__ import annotations

import functools
import time
from collections import OrderedDict
from dataclasses import dataclass, field, fields, replace
from typing import Any

import mujoco
import numpy as np

from ..errors import InvalidMotionError
from ..motion import Motion
from ..physics_constants import CONTACT_HEIGHT_PER_LEG, GRAVITY
from ..qpos import (
    QposTrajectory,
    motion_to_qpos,
    qpos_joint_positions,
    qpos_to_motion,
    species_model,
)
from ..rotations import quat_mul, quat_normalize
from ..stance.labels import EditReason, StanceLabels, StanceSource, runs
from ..stance.planting import plant_motion
from .errors import RefineConvergenceError, RefineError, RefineInputError
from .problem import (
    FEET,
    LEG_PREFIXES,
    ModelInfo,
    RefinementProblem,
    SolverSettings,
    build_refinement_problem,
)
from .verdict import VERDICT_METRICS, WORSE_TOLERANCE, compare_metrics
from .windows import Window, plan_windows

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

#: Default lowest toe height of a moving swing foot, share of leg length: the contact
#: height plus a margin of 0.5 % L.
SWING_CLEARANCE_PER_LEG = 0.025
#: Time over which a swing foot's minimum height rises from the ground to the clearance
#: [s] (one frame at 30 fps; four at 120 fps, three of them pinned and rising vertically).
SWING_RAMP_S = 1.0 / 30.0
#: A stance frame whose input toe lies further than this share of leg length
#: (horizontally) from where the stance run rests is relabelled swing if it is at an end
#: of the run.
STANCE_SLIP_PER_LEG = 0.15
#: Largest share of a stance run the cleaning trims at each of its ends (1: no cap, the
#: default). Measured on 50 transfers of real 4 s clips (``habitsim bench real``): a cap
#: of a sixth kept the stance of the sliding decoded feet of habit transfers (refinement
#: reverted by the tracking check on 3 transfers instead of 7, sim MPJPE 0.136 instead of
#: 0.149 leg lengths) but planting the slides raised the jerk of four cat transfers, so
#: the three refinement targets held on 90 % instead of 96 %, and as many habit
#: transfers survived the window (17 against 18 of 25). The trade-off is an option.
MAX_TRIM_SHARE = 1.0
#: Shortest stance run kept and longest swing gap filled [s] (at least 2 resp. 1 frames).
MIN_RUN_S = 0.04
#: The weights a guard retry multiplies by :data:`GUARD_FACTOR`; one that is 0 (the jerk
#: terms by default) is switched on at its :data:`GUARD_START` value instead. The jerk
#: terms are off in the first solve: they cost 3–5× its time (the Gauss-Newton attempt
#: needs more iterations than its cap), and most clips come out no jerkier without them.
#: Three retries (weights 1e-5, 1e-4, 1e-3): on 50 transfers of real 4 s clips
#: (``habitsim bench real``) two transfers were still jerkier than their input after two
#: retries (dog_back_001 to the camel, habit: 317 → 393 m/s³; to the cat, direct: 165 →
#: 189) and came out smoother after the third (262 and 142). A retry starts from the
#: previous attempt's solution (it already meets every constraint; only the weights
#: changed) with the exact Hessian: with the jerk terms on, the Gauss-Newton attempt
#: runs into its iteration cap before the exact one starts. On the direct transfers of
#: five real 4 s windows to the tiger the retries took 24–36 IPOPT iterations instead of
#: 40–80 (refinement 2.1–7.3 s instead of 5.0–11.3 s) and reached the same solutions
#: (equal jerk); to the cat, whose retries start exact anyway, the iterations fell from
#: 33–42 to 22–37.
GUARD_WEIGHTS = ("w_smooth", "w_jerk", "w_hinge_jerk")
GUARD_FACTOR = 10.0
GUARD_START = {"w_smooth": 1e-5, "w_jerk": 1e-5, "w_hinge_jerk": 1e-5}
#: Iteration limit of the Gauss-Newton attempt per window (it converges in 7–30 when it
#: does; beyond, the exact-Hessian retry is faster).
GAUSS_NEWTON_MAX_ITER = 25
#: A window whose input leaves the joint ranges by more than this [rad] starts with the
#: exact Hessian: clipping such angles puts the initial guess centimetres off its
#: contact constraints, a start Gauss-Newton does not recover from.
EXACT_FIRST_EXCESS_RAD = 0.4
#: IPOPT return statuses counted as success.
SUCCESS_STATUSES = ("Solve_Succeeded", "Solved_To_Acceptable_Level")


def _escalate(name: str, value: float) -> float:
    """A guard retry's weight: × GUARD_FACTOR, or the GUARD_START value if it was 0."""
    return value * GUARD_FACTOR if value > 0 else GUARD_START[name]


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
        align_ground: shift the targets onto the floor first (module docstring).
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


# --------------------------------------------------------------------------- caches
#: Most built problems kept per process (least recently used dropped first). A built
#: 100-frame window holds 0.3 (stage A) to 0.8 GB (stage B, exact Hessian) of CasADi
#: graphs; unbounded, a run over 17 species with both stages grew past 24 GB.
MAX_CACHED_PROBLEMS = 6

_PROBLEMS: OrderedDict[tuple, RefinementProblem] = OrderedDict()
_BUILDS = 0  # problems built so far in this process


@functools.lru_cache(maxsize=32)
def _species_model(species: str) -> mujoco.MjModel:
    try:
        return species_model(species)
    except InvalidMotionError as e:
        raise RefineError(str(e)) from e


def get_problem(
    species: str,
    n_frames: int,
    dynamics: bool = False,
    settings: SolverSettings | None = None,
    model: mujoco.MjModel | None = None,
) -> RefinementProblem:
    """The built problem of a species (or model) and window length, cached per process.

    The first call per (species, W, stage, settings) builds it (seconds); later calls
    return the same object while it is among the :data:`MAX_CACHED_PROBLEMS` most
    recently used (so process clips grouped by species). Default settings: those
    :func:`refine` uses first (``RefineOptions().settings``).
    """
    global _BUILDS
    settings = settings or RefineOptions().settings
    key = (
        species if model is None else ("model", id(model)),
        int(n_frames),
        bool(dynamics),
        settings,
    )
    pr = _PROBLEMS.get(key)
    if pr is None:
        m = _species_model(species) if model is None else model
        pr = build_refinement_problem(m, int(n_frames), bool(dynamics), settings)
        pr._model_ref = m  # keep id(model) alive
        _PROBLEMS[key] = pr
        _BUILDS += 1
        while len(_PROBLEMS) > MAX_CACHED_PROBLEMS:
            _PROBLEMS.popitem(last=False)
    else:
        _PROBLEMS.move_to_end(key)
    return pr


def clear_cache() -> None:
    """Forget every built problem."""
    _PROBLEMS.clear()


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


def _resolve_contacts(motion: Motion, contacts: np.ndarray | None) -> StanceLabels:
    """The labels a refinement plants: ``contacts`` when given, else the motion's own,
    else those detected on it.

    Raises:
        RefineInputError: labels of the wrong shape, or not booleans (or 0/1).
    """
    t = motion.num_frames
    if contacts is None:
        if motion.contacts is not None:
            contacts, source = motion.contacts, StanceSource.INPUT
        else:
            return StanceLabels(motion.detect_contacts(), StanceSource.DETECTED)
    else:
        source = StanceSource.GIVEN
    c = np.asarray(contacts)
    if c.shape != (t, 4):
        raise RefineInputError(
            f"contacts must have shape ({t}, 4) (feet LF, RF, LH, RH), got {c.shape}"
        )
    if c.dtype != bool:
        if not np.issubdtype(c.dtype, np.number) or not np.all(np.isin(c, (0, 1))):
            raise RefineInputError("contacts must be booleans (or 0/1)")
    return StanceLabels(c, source)


def _ground_offset(
    targets: np.ndarray, contacts: np.ndarray, fps: float, toe_idx: list[int]
) -> np.ndarray:
    """(T,) smooth vertical offset: mean toe height of the feet in contact."""
    t = targets.shape[0]
    toe_z = targets[:, toe_idx, 2]
    n = contacts.sum(axis=1)
    have = n > 0
    if not np.any(have):
        return np.zeros(t)
    raw = np.where(have, (toe_z * contacts).sum(axis=1) / np.maximum(n, 1), np.nan)
    frames = np.arange(t)
    filled = np.interp(frames, frames[have], raw[have])
    k = max(1, int(round(0.25 * fps)))
    if k > 1 and t > 1:
        pad = np.pad(filled, (k // 2, k - 1 - k // 2), mode="edge")
        filled = np.convolve(pad, np.ones(k) / k, mode="valid")
    return filled


#: Who :func:`clean_contact_labels` is in the labels' edit records.
CLEANED_BY = "refine.clean_contact_labels"
#: Foot names of the cleaning summary (a fifth foot and beyond go by their index).
_FOOT_NAMES = ("LF", "RF", "LH", "RH")


def clean_contact_labels(
    labels: StanceLabels,
    toes: np.ndarray,
    fps: float,
    leg_length: float,
    slip_per_leg: float = STANCE_SLIP_PER_LEG,
    min_run_s: float = MIN_RUN_S,
    trim: bool = True,
    max_trim_share: float = MAX_TRIM_SHARE,
) -> StanceLabels:
    """Contact labels made consistent with the motion before they are planted.

    For every foot, in this order (one recorded edit per step, by :data:`CLEANED_BY`):

    1. *trim* (:attr:`~habitsim.stance.labels.EditReason.SLIP_TRIM`): the frames at either
       end of a stance run whose toe lies horizontally further than ``slip_per_leg`` × L
       from where the run rests (the median of its toe positions) become swing — the
       input moves that foot, so planting it there would drag the leg — at most
       ``max_trim_share`` of the run at each end (below 1, every labelled footfall keeps
       a stance even where the foot slides through all of it);
    2. *fill* (:attr:`~habitsim.stance.labels.EditReason.GAP_FILL`): a swing gap of at
       most ``min_run_s`` (at least one frame) between two stance runs that rest within
       ``slip_per_leg`` × L of each other becomes stance (the foot did not step);
    3. *drop* (:attr:`~habitsim.stance.labels.EditReason.BLIP_DROP`): a stance run
       shorter than ``min_run_s`` (at least two frames) that does not touch the clip's
       first or last frame becomes swing (a blip, not a step).

    Args:
        labels: (T, 4) stance labels (LF, RF, LH, RH).
        toes: (T, 4, ≥2) toe positions of the motion [m] (x, y used).
        fps: frame rate [Hz].
        leg_length: the species' hind-leg length L [m].
        slip_per_leg: the distance a stance toe may lie from its run's rest, share of L.
        min_run_s: shortest stance run kept and longest swing gap filled [s].
        trim: run step 1 (off: only fill and drop).
        max_trim_share: step 1 trims at most this share of a run at each end
            (:data:`MAX_TRIM_SHARE`; 1 for no cap).

    Returns:
        The cleaned labels, ``labels`` with the edits of the steps that changed a frame
        (:func:`cleaning_summary` tells what changed).
    """
    c0 = labels.array
    xy = np.asarray(toes, float)[..., :2]
    t, nf = c0.shape
    tol = float(slip_per_leg) * float(leg_length)
    max_gap = max(1, int(round(min_run_s * fps)))
    min_stance = max(2, int(round(min_run_s * fps)))
    trimmed = c0.copy()
    for f in range(nf):
        for a, b in runs(c0[:, f]) if trim else ():
            anchor = np.median(xy[a:b, f], axis=0)
            far = np.linalg.norm(xy[a:b, f] - anchor, axis=1) > tol
            lo, hi = a, b
            cap = int(np.floor(float(max_trim_share) * (b - a)))
            while lo < hi and far[lo - a] and lo - a < cap:
                lo += 1
            while hi > lo and far[hi - 1 - a] and b - hi < cap:
                hi -= 1
            trimmed[a:lo, f] = False
            trimmed[hi:b, f] = False
    filled = trimmed.copy()
    for f in range(nf):
        rs = runs(trimmed[:, f])
        for (a0, b0), (a1, b1) in zip(rs, rs[1:], strict=False):
            if b0 < a1 and a1 - b0 <= max_gap:
                p0 = np.median(xy[a0:b0, f], axis=0)
                p1 = np.median(xy[a1:b1, f], axis=0)
                if np.linalg.norm(p1 - p0) <= tol:
                    filled[b0:a1, f] = True
    dropped = filled.copy()
    for f in range(nf):
        for a, b in runs(filled[:, f]):
            if b - a < min_stance and a > 0 and b < t:
                dropped[a:b, f] = False
    return (
        labels.edited(trimmed, by=CLEANED_BY, reason=EditReason.SLIP_TRIM)
        .edited(filled, by=CLEANED_BY, reason=EditReason.GAP_FILL)
        .edited(dropped, by=CLEANED_BY, reason=EditReason.BLIP_DROP)
    )


def cleaning_summary(cleaned: StanceLabels, since: int = 0) -> dict[str, Any]:
    """What :func:`clean_contact_labels` changed, as the report lists it
    (``contacts.cleaning``).

    Args:
        cleaned: labels returned by :func:`clean_contact_labels`.
        since: the number of edits the labels had before they were cleaned.

    Returns:
        ``frames_changed``: labels that differ from those before the cleaning (a frame
        trimmed and filled again is unchanged); per foot (``LF`` …): the frames
        ``trimmed``, the gaps ``filled`` and the stance runs ``dropped``.
    """
    counts = np.zeros((3, cleaned.n_feet), dtype=int)
    steps = (EditReason.SLIP_TRIM, EditReason.GAP_FILL, EditReason.BLIP_DROP)
    for e in cleaned.edits[since:]:
        if e.by != CLEANED_BY or e.reason not in steps:
            continue
        k = steps.index(e.reason)
        for f, frames in enumerate(e.frames):
            # trimmed: frames; filled gaps and dropped runs: blocks of consecutive frames
            # (the gaps and runs of one foot never touch each other)
            counts[k, f] += len(frames) if k == 0 else len(runs(e.mask(cleaned.n_frames)[:, f]))
    out: dict[str, Any] = {"frames_changed": int(cleaned.changed_since(since).sum())}
    for f in range(cleaned.n_feet):
        out[_FOOT_NAMES[f] if f < len(_FOOT_NAMES) else str(f)] = {
            "trimmed": int(counts[0, f]),
            "filled": int(counts[1, f]),
            "dropped": int(counts[2, f]),
        }
    return out


def swing_clearance(
    contacts: np.ndarray,
    fps: float,
    leg_length: float,
    clearance_per_leg: float = SWING_CLEARANCE_PER_LEG,
    ramp_s: float = SWING_RAMP_S,
) -> tuple[np.ndarray, np.ndarray]:
    """The swing clearance profile of contact labels (module docstring, step 5).

    A swing frame k frames from the nearest stance frame must hold its toe at least
    ``clearance_per_leg`` × L × min(1, k / r) high, r = max(1, round(ramp_s · fps));
    the swing frames whose minimum is below docs/metrics.md's contact height are pinned
    horizontally to the neighbouring foothold (a swing run whose every frame would be
    pinned gets the full clearance in its middle frame(s), so the foot can move there).

    Args:
        contacts: (T, 4) bool labels.
        fps: frame rate [Hz].
        leg_length: L [m].
        clearance_per_leg: the full clearance, share of L (≥ the contact height).
        ramp_s: rise time from the ground to the full clearance [s].

    Returns:
        ``floor`` (T, 4): lowest toe height [m] in swing, NaN in stance; ``pins``
        (T-1, 4) bool: frame pairs (t, t+1) whose horizontal toe displacement must be 0
        (every pair of stance or pinned swing frames).
    """
    c = np.asarray(contacts, bool)
    t, nf = c.shape
    full = float(clearance_per_leg) * float(leg_length)
    h_c = CONTACT_HEIGHT_PER_LEG * float(leg_length)
    r = max(1, int(round(ramp_s * fps)))
    frames = np.arange(t)
    floor = np.full((t, nf), np.nan)
    rest = c.copy()
    for f in range(nf):
        stance = np.flatnonzero(c[:, f])
        for a, b in runs(~c[:, f]):
            k = frames[a:b]
            if len(stance):
                d = np.abs(k[:, None] - stance[None, :]).min(axis=1).astype(float)
            else:
                d = np.full(len(k), np.inf)
            h = full * np.minimum(1.0, d / r)
            low = h < h_c
            if low.all():
                top = d == d.max()
                h[top], low[top] = full, False
            floor[a:b, f] = h
            rest[a:b, f] = low
    pins = rest[1:] & rest[:-1]
    return floor, pins


#: Largest ground-alignment shift, a share of leg length: beyond it a clip is not
#: hovering or sinking but has legs of the wrong length, which alignment cannot fix.
MAX_ALIGN_PER_LEG = 0.05


def _lowpass(x: np.ndarray, lam: float, weights: np.ndarray | None = None) -> np.ndarray:
    """Zero-phase smoothing along axis 0: argmin |y − x|² + λ Σ_k w_k (Δ²y)_k².

    Args:
        x: (T, n) signals.
        lam: the penalty λ (cutoff: λ = 1 / (2 − 2 cos ω_c)²).
        weights: optional (T-2,) per-second-difference weights in [0, 1] (0 lets the
            signal bend there).
    """
    from scipy.linalg import solveh_banded

    t = x.shape[0]
    if t < 3 or lam <= 0:
        return x.copy()
    wk = lam * (np.ones(t - 2) if weights is None else np.asarray(weights, float))
    c = (1.0, -2.0, 1.0)  # row k of D² has c at columns k, k+1, k+2
    ab = np.zeros((3, t))  # I + λ D²ᵀ W D² in upper banded form: row 2 − j = diagonal j
    ab[2] = 1.0
    for i in range(3):
        ab[2, i : i + t - 2] += wk * c[i] * c[i]
        if i < 2:
            ab[1, i + 1 : i + t - 1] += wk * c[i] * c[i + 1]
    ab[0, 2:] += wk * c[0] * c[2]
    return solveh_banded(ab, x)


def _lowpass_qpos(
    q: np.ndarray, info: Any, fps: float, f_c: float, contacts: np.ndarray
) -> np.ndarray:
    """Contact-aware jitter filter of a qpos trajectory (see :class:`RefineOptions`).

    Root position, root quaternion (then renormalised) and every hinge are smoothed
    with the second-difference filter of cutoff ``f_c`` [Hz]; a leg's hinges are not
    smoothed at the corners of its touchdowns and lift-offs (the two second differences
    around a label change), where a foot's velocity legitimately jumps.
    """
    lam = 1.0 / (2.0 - 2.0 * np.cos(2 * np.pi * min(f_c / fps, 0.5))) ** 2
    out = q.copy()
    fa = info.free_qposadr
    out[:, fa : fa + 3] = _lowpass(q[:, fa : fa + 3], lam)
    out[:, fa + 3 : fa + 7] = quat_normalize(_lowpass(q[:, fa + 3 : fa + 7], lam))
    names = info.hinge_names
    axial = [
        a for a, n in zip(info.hinge_qposadr, names, strict=True) if not n.startswith(LEG_PREFIXES)
    ]
    out[:, axial] = _lowpass(q[:, axial], lam)
    t = len(q)
    for f, leg in enumerate(FEET):
        cols = [
            a for a, n in zip(info.hinge_qposadr, names, strict=True) if n.startswith(f"{leg}_")
        ]
        if not cols or t < 3:
            continue
        change = np.flatnonzero(contacts[1:, f] != contacts[:-1, f])  # between t and t+1
        wk = np.ones(t - 2)
        for c in change:  # second differences centred on c and c+1 (index k ↔ frame k+1)
            wk[max(c - 1, 0) : min(c + 1, t - 2)] = 0.0
        out[:, cols] = _lowpass(q[:, cols], lam, wk)
    return out


def _gibbs_quat(g: np.ndarray) -> np.ndarray:
    return quat_normalize(np.concatenate([np.ones(g.shape[:-1] + (1,)), g], axis=-1))


# --------------------------------------------------------------------------- solve
@dataclass
class _Prepared:
    model: mujoco.MjModel
    qpos_in: np.ndarray
    targets: np.ndarray
    qref: np.ndarray
    href: np.ndarray
    x0: np.ndarray
    labels: StanceLabels  # the labels planted (cleaned)
    glob: dict[str, float]
    offset: np.ndarray
    swing_floor: np.ndarray | None
    clearance: np.ndarray | None
    pins: np.ndarray
    labels_input: StanceLabels  # the labels as they came (given, the input's, detected)
    cleaning: dict[str, Any] | None  # :func:`cleaning_summary` (None: not cleaned)

    @property
    def contacts(self) -> np.ndarray:
        """(T, 4) bool labels planted (read-only)."""
        return self.labels.array


def _inside_ranges(info: ModelInfo, hinges: np.ndarray) -> np.ndarray:
    """Hinge angles clipped just inside their joint ranges (an initial guess on a bound
    would start IPOPT's barrier at infinity)."""
    span = np.where(np.isfinite(info.upper - info.lower), info.upper - info.lower, 1.0)
    margin = np.minimum(1e-6, 1e-3 * span)
    return np.clip(hinges, info.lower + margin, info.upper - margin)


def _prepare(
    motion: Motion,
    labels_in: StanceLabels,
    opts: RefineOptions,
    model: mujoco.MjModel,
    pr: RefinementProblem,
) -> _Prepared:
    info, nx, nv = pr.info, pr.nx, pr.nv
    labels = labels_in
    c = labels.array
    q_raw = motion_to_qpos(motion, model).qpos
    f_c = opts.cutoff_hz(motion.species_info.leg_length, info.gravity)
    if f_c is None:
        q, targets = q_raw, motion.global_positions()
    else:
        q = _lowpass_qpos(q_raw, info, motion.fps, f_c, c)
        targets = qpos_joint_positions(model, q)
    toe_idx = [motion.skeleton.foot_indices[i] for i in range(4)]
    sp = motion.species_info
    cleaning = None
    if opts.clean_contacts:
        labels = clean_contact_labels(
            labels_in, targets[:, toe_idx], motion.fps, sp.leg_length, trim=opts.trim_contacts
        )
        cleaning = cleaning_summary(labels, since=len(labels_in.edits))
        c = labels.array
        if cleaning["frames_changed"] and f_c is not None:  # corners moved: filter again
            q = _lowpass_qpos(q_raw, info, motion.fps, f_c, c)
            targets = qpos_joint_positions(model, q)
    offset = np.zeros(len(q))
    if opts.align_ground:
        lim = MAX_ALIGN_PER_LEG * motion.species_info.leg_length
        offset = np.clip(_ground_offset(targets, c, motion.fps, toe_idx), -lim, lim)
    targets = targets.copy()
    targets[..., 2] -= offset[:, None]
    fa = info.free_qposadr
    qref = q[:, fa + 3 : fa + 7]
    href = q[:, info.hinge_qposadr]
    x0 = np.zeros((len(q), nx))
    x0[:, :3] = q[:, fa : fa + 3]
    x0[:, 2] -= offset
    x0[:, 6:nv] = _inside_ranges(info, href)
    # initial guess only: put the feet in contact on the floor frame by frame (clipping
    # out-of-range angles and the smooth alignment leave them off it by centimetres)
    sole0 = np.asarray(pr.frame.map(len(q))(x0[:, :nv].T, qref.T)[1])[2].reshape(len(q), 4)
    x0[:, 2] -= _stance_height(sole0, c)
    if nx > nv:  # stage B: weight shared by the feet in contact, spread over the edges
        share = c / np.maximum(c.sum(axis=1, keepdims=True), 1)
        x0[:, nv : nv + 16] = np.repeat(share / 4.0, 4, axis=1)
        x0[:, nv + 16 :] = np.asarray(pr.frame.map(len(q))(x0[:, :nv].T, qref.T)[2]).T
    glob = {
        "leg_length": sp.leg_length,
        "fps": motion.fps,
        "gravity": info.gravity,
        "mu": info.friction if opts.friction is None else float(opts.friction),
        **opts.weights,
    }
    # swing feet clear docs/metrics.md's contact height wherever they move (module docstring)
    if opts.swing_clearance is None:
        clearance, pins = None, c[1:] & c[:-1]
    else:
        clearance, pins = swing_clearance(c, motion.fps, sp.leg_length, opts.swing_clearance)
    if opts.plant_start:
        x0[:, :nv] = _planted_start(motion, model, info, q, offset, c, clearance, x0[:, :nv])
    return _Prepared(
        model,
        q_raw,
        targets,
        qref,
        href,
        x0,
        labels,
        glob,
        offset,
        None,
        clearance,
        pins,
        labels_in,
        cleaning,
    )


def _planted_start(
    motion: Motion,
    model: mujoco.MjModel,
    info: ModelInfo,
    q: np.ndarray,
    offset: np.ndarray,
    contacts: np.ndarray,
    clearance: np.ndarray | None,
    x0: np.ndarray,
) -> np.ndarray:
    """The initial guess of :attr:`RefineOptions.plant_start`: the (filtered, aligned)
    input with its legs planted on the labels and lifted to the clearance by leg IK.
    The root orientation stays the reference's; a frame IK could not plant keeps
    ``x0``'s pose (the solver starts there either way)."""
    qa = q.copy()
    fa = info.free_qposadr
    qa[:, fa + 2] -= offset
    aligned = qpos_to_motion(model, qa, motion.species, motion.fps)
    floor = None if clearance is None else np.where(contacts, np.nan, clearance)
    try:
        planted, _ = plant_motion(aligned, contacts, floor)
    except (InvalidMotionError, np.linalg.LinAlgError, ValueError):
        return x0
    qp = motion_to_qpos(planted, model).qpos
    out = x0.copy()
    out[:, :3] = qp[:, fa : fa + 3]
    out[:, 6:] = _inside_ranges(info, qp[:, info.hinge_qposadr])
    bad = ~np.all(np.isfinite(out), axis=1)
    out[bad] = x0[bad]
    return out


def _preplant(
    motion: Motion, labels_in: StanceLabels, opts: RefineOptions
) -> tuple[Motion, StanceLabels, dict[str, Any]]:
    """The input with its feet planted on its (cleaned) labels and lifted to the swing
    clearance by leg IK (:func:`habitsim.stance.planting.plant_motion`), the labels, and the
    label fields of :class:`_Prepared` (input labels, cleaning). The optimisation then
    starts from, and tracks, a motion whose feet already rest where they are labelled to
    and clear the ground where they move."""
    sp = motion.species_info
    labels, cleaning = labels_in, None
    if opts.clean_contacts:
        labels = clean_contact_labels(
            labels_in, motion.foot_positions(), motion.fps, sp.leg_length, trim=opts.trim_contacts
        )
        cleaning = cleaning_summary(labels, since=len(labels_in.edits))
    c = labels.array
    floor = None
    if opts.swing_clearance is not None:
        floor = swing_clearance(c, motion.fps, sp.leg_length, opts.swing_clearance)[0]
    planted, _ = plant_motion(motion, c, floor)
    fields_ = {"labels_input": labels_in, "cleaning": cleaning}
    return planted, labels, fields_


def _stance_height(sole: np.ndarray, contacts: np.ndarray) -> np.ndarray:
    """(T,) mean height of the soles in contact, interpolated through flight frames."""
    n = contacts.sum(axis=1)
    have = n > 0
    if not np.any(have):
        return np.zeros(len(sole))
    raw = (sole * contacts).sum(axis=1) / np.maximum(n, 1)
    frames = np.arange(len(sole))
    return np.interp(frames, frames[have], raw[have])


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
            excess = np.maximum(info.lower - prep.href[sl], prep.href[sl] - info.upper).max()
            start_exact = excess > EXACT_FIRST_EXCESS_RAD or x_init is not None
            settings = [exact] if start_exact else [opts.settings, exact]
        for k, st_k in enumerate(settings):
            built = _BUILDS
            pr = get_problem(motion.species, win.length, opts.dynamics, st_k, model=model_arg)
            if _BUILDS > built:
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
        escalated: dict[str, Any] = {k: _escalate(k, getattr(opts, k)) for k in GUARD_WEIGHTS}
        opts = replace(opts, **escalated)
        prep.glob.update(opts.weights)
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
