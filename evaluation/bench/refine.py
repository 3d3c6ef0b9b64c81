"""``habitsim bench refine``: refinement speed, scaling, success rate and tracking survival.

* :func:`species_timing` — per species and stage (``stages``, default A and B): the time
  to build the window problem (once per process), and the median over ``clips``
  100-frame, 30 fps synthetic clips with injected artefacts (slide, sink, jitter,
  limits; :func:`habitsim.refine.inject_artefacts`) of the IPOPT solve time summed over
  the windows (``solve``), of the wall time of the whole :func:`habitsim.refine.refine`
  call without metrics (``call``) and of the process CPU time over that same call
  (``cpu``: every thread's, so up to the core count × ``call`` when IPOPT's linear
  algebra runs threaded; on a shared machine the fairest of the three). The window
  problems are built before the clocks start, so no column counts building (``build``
  times it once). IPOPT's linear algebra runs on the OpenBLAS thread pool, whose threads
  spin on a busy machine (with ``OMP_NUM_THREADS=1``, ``cpu`` ≈ ``call``). Targets of the
  issue: stage A ≤ 0.5 s, stage B ≤ 2 s per clip. With ``survival``, the survival of
  unassisted tracking (:func:`habitsim.sim.track`, ``survival_controller``, default
  ``mpc``) of the same clips before and after stage-A refinement (target: after ≥
  before).
* :func:`scaling` — on ``scaling_species``: solve time of 100, 300 and 1000 frames
  (``lengths``) per stage (linear growth = constant time per frame).
* :func:`success_rates` — IPOPT success rate over ``success_clips`` clips per stage of
  random species, action and artefact mix, or of random windows of a data set's test
  split (target ≥ 98 %).
* :func:`clean_synthetic` / :func:`clean_real` — the change of clean input: a 4 s,
  30 fps clip refined as it is (stage A), per frame the mean joint position change in
  leg lengths (:func:`habitsim.refine.verdict.input_change`), its largest and median
  value over the frames, the skate and penetration before and after, and the time of
  the call. Clean clips: the project's own synthetic walks (clean by construction), or
  the first 4 s window of every clip of a folder of real clips, imported as
  ``bench real`` imports and windows them (target: at most 1 % of leg length on every
  frame).
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = [
    "CleanChange",
    "RefineBenchOptions",
    "clean_real",
    "clean_synthetic",
    "model_floor",
    "SpeciesTiming",
    "SuccessRate",
    "Timing",
    "scaling",
    "species_missed",
    "species_timing",
    "success_rates",
    "test_split",
    "timed",
]

#: Median solve-time targets per 100-frame clip [s].
TARGET_S = {"A": 0.5, "B": 2.0}
#: Controllers the survival runs may use (unassisted).
SURVIVAL_CONTROLLERS = ("servo", "servo+stance", "balance", "mpc")
#: Target IPOPT success rate on artefact clips.
TARGET_SUCCESS = 0.98
#: Artefacts injected into the timed clips.
ARTEFACTS = ("slide", "sink", "jitter", "limits")
#: Clean input: the largest per-frame change of a refined clean clip [leg lengths].
TARGET_CLEAN_CHANGE = 0.01
#: Length of a clean-input clip [s] and its frame rate [Hz] (``bench real``'s windows).
CLEAN_SECONDS = 4.0
CLEAN_FPS = 30.0
#: A reported build time below this [s] is a cache lookup, not a build.
_BUILD_NOISE_S = 0.01


@dataclass(frozen=True)
class RefineBenchOptions:
    """What a ``bench refine`` run does.

    Attributes:
        species: species (empty: every species of the catalog).
        stages: refinement stages to time (``A``, ``B``).
        clips: 100-frame clips per species and stage.
        survival: track the clips before and after stage-A refinement.
        survival_controller: unassisted controller of the survival runs
            (:data:`SURVIVAL_CONTROLLERS`).
        data: draw the success-rate clips from this data set's test split (None:
            freshly generated clips of random species and actions).
        scaling_species: species of the scaling run.
        lengths: clip lengths of the scaling run [frames].
        success_clips: random artefact clips per stage for the success rate.
        seed: seed.
    """

    species: tuple[str, ...] = ()
    stages: tuple[str, ...] = ("A", "B")
    clips: int = 3
    survival: bool = True
    survival_controller: str = "mpc"
    data: str | None = None
    scaling_species: str = "dog"
    lengths: tuple[int, ...] = (100, 300, 1000)
    success_clips: int = 50
    seed: int = 0


def species_of(options: RefineBenchOptions) -> list[str]:
    """The species a run covers."""
    from habitsim.species import species_names

    return list(options.species) or species_names()


def clip(
    species: str,
    frames: int,
    seed: int,
    action: str | None = None,
    kinds: tuple[str, ...] = ARTEFACTS,
) -> Any:
    """A ``frames``-long 30 fps synthetic clip of ``species`` (walk, or the first action
    it has; ``action`` when given) with the artefacts ``kinds`` injected."""
    from habitsim.gaits import available_actions, generate
    from habitsim.refine import inject_artefacts

    rng = np.random.default_rng(seed)
    acts = [a for a in available_actions(species) if a not in ("sit",)]
    act = action or ("walk" if "walk" in acts else acts[0])
    clean = generate(
        species, act, seed=int(rng.integers(1 << 30)), fps=30.0, duration_s=frames / 30.0
    )
    return inject_artefacts(clean, kinds, seed=seed)


def test_split(data: str) -> list[tuple[str, str, Any]]:
    """(species, action, motion) of every test-split clip of a data set."""
    from habitsim.dataset import iter_clips

    return [(e.species, e.action, m) for e, m in iter_clips(data, split="test")]


def _test_window(
    clips: list[tuple[str, str, Any]], rng: np.random.Generator, frames: int, kinds: tuple[str, ...]
) -> tuple[str, str, Any]:
    """A random ``frames``-long window of a random test clip with artefacts injected."""
    from habitsim.refine import inject_artefacts

    sp, act, m = clips[int(rng.integers(len(clips)))]
    start = int(rng.integers(max(m.num_frames - frames, 0) + 1))
    win = m.slice(start, start + frames)
    return sp, act, inject_artefacts(win, kinds, seed=int(rng.integers(1 << 30)))


def _prebuild(motion: Any, opts: Any) -> float:
    """Build (or fetch from the cache) the window problems of a clip; wall time [s]."""
    from habitsim.refine.solve import get_problem

    t0 = time.perf_counter()
    for n in sorted({w.length for w in opts.plan(motion.num_frames)}):
        get_problem(motion.species, n, opts.dynamics, opts.settings)
    return time.perf_counter() - t0


@dataclass(frozen=True)
class Timing:
    """Solve, wall and CPU time of one refinement, its window problems built beforehand.

    Attributes:
        ok: IPOPT converged.
        solve: IPOPT time summed over the windows [s] (NaN when it failed).
        call: wall time of the :func:`habitsim.refine.refine` call [s], less any build it
            still did.
        cpu: process CPU time over the call, every thread [s].
        cpu_includes_build: the call built a problem (a retry with other solver settings),
            counted in ``cpu``.
        build: time building the window problems [s].
        iterations: IPOPT iterations.
        result: the refinement's result (None when it failed).
    """

    ok: bool
    solve: float
    call: float
    cpu: float
    cpu_includes_build: bool
    build: float
    iterations: int
    result: Any = field(default=None, repr=False)

    def scaling_dict(self) -> dict[str, Any]:
        """``ok``, ``solve``, ``call``, ``cpu``, ``build`` (the JSON of a scaling run)."""
        return {
            "ok": self.ok,
            "solve": self.solve,
            "call": self.call,
            "cpu": self.cpu,
            "build": self.build,
        }


def timed(motion: Any, stage: str) -> Timing:
    """Refine one clip at ``stage`` (``A``, ``B``) and time it (:class:`Timing`)."""
    from habitsim.refine import RefineConvergenceError, RefineOptions, refine

    opts = RefineOptions(dynamics=stage == "B", metrics=False)
    prebuilt = _prebuild(motion, opts)
    w0, c0 = time.perf_counter(), time.process_time()
    try:
        res = refine(motion, opts)
        ok, solve, build = True, res.report["solve_time_s"], res.report["build_time_s"]
        iters = res.report["iterations"]
    except RefineConvergenceError as e:
        ok, solve, build = False, float("nan"), e.report.get("build_time_s", 0.0)
        iters = e.report.get("iterations", 0)
        res = None
    cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    return Timing(
        ok, solve, wall - build, cpu, build > _BUILD_NOISE_S, prebuilt + build, iters, res
    )


def _survival(motion: Any, controller: str) -> float:
    from habitsim.sim import track

    return float(track(motion, controller=controller).survival)


@dataclass(frozen=True)
class SpeciesTiming:
    """One species' figures.

    Attributes:
        species: the species.
        record: the JSON object of the species: per stage ``build_s``, ``median_solve``,
            ``median_call``, ``median_cpu`` [s], ``median_iterations``, ``failed``; with
            the survival runs ``survival_before`` and ``survival_after``.
        over_target: per stage, the median solve is over its target (False when no clip
            converged).
    """

    species: str
    record: dict[str, Any]
    over_target: dict[str, bool]


def species_timing(species: str, options: RefineBenchOptions) -> SpeciesTiming:
    """Time every stage on ``options.clips`` artefact clips of a species (and track them
    before and after stage-A refinement with ``options.survival``)."""
    from habitsim.refine import RefineOptions
    from habitsim.refine.solve import get_problem

    rec: dict[str, Any] = {}
    over: dict[str, bool] = {}
    clips = [clip(species, 100, options.seed + k) for k in range(options.clips)]
    refined: list[Any] = []
    for st in options.stages:
        t0 = time.perf_counter()
        opts = RefineOptions(dynamics=st == "B")
        get_problem(species, opts.plan(100)[0].length, opts.dynamics, opts.settings)
        build = time.perf_counter() - t0
        runs = [timed(c, st) for c in clips]
        good = [r for r in runs if r.ok]
        med = {
            k: statistics.median([getattr(r, k) for r in good]) if good else float("nan")
            for k in ("solve", "call", "cpu", "iterations")
        }
        rec[st] = {
            "build_s": build,
            **{f"median_{k}": v for k, v in med.items()},
            "failed": len(runs) - len(good),
        }
        over[st] = bool(good) and not med["solve"] <= TARGET_S[st]
        if st == "A":
            refined = [r.result for r in runs]
    if options.survival:
        ctl = options.survival_controller
        before = [_survival(c, ctl) for c in clips]
        after = [_survival(r.motion, ctl) for r in refined if r is not None]
        rec["survival_before"] = float(np.mean(before))
        rec["survival_after"] = float(np.mean(after)) if after else float("nan")
    return SpeciesTiming(species, rec, over)


def species_missed(timings: list[SpeciesTiming], stages: tuple[str, ...]) -> list[str]:
    """The per-species targets missed: a stage's median solve time (every clip failing
    misses too), survival after refinement below survival before."""
    missed = []
    for t in timings:
        sp, rec = t.species, t.record
        for st in stages:
            med = rec[st]["median_solve"]
            if not med <= TARGET_S[st]:  # NaN (every clip failed) misses too
                missed.append(f"{sp} stage {st} median solve {med:.3f} s > {TARGET_S[st]} s")
        s_before, s_after = rec.get("survival_before"), rec.get("survival_after")
        if s_before is not None and not s_after >= s_before:
            missed.append(f"{sp} survival after refinement {s_after:.2f} < before {s_before:.2f}")
    return missed


def scaling(options: RefineBenchOptions, stage: str) -> list[tuple[int, Timing]]:
    """One clip of every length of ``options.lengths`` on the scaling species, timed."""
    return [
        (n, timed(clip(options.scaling_species, n, options.seed + 100), stage))
        for n in options.lengths
    ]


@dataclass(frozen=True)
class SuccessRate:
    """IPOPT's success on the random artefact clips of one stage.

    Attributes:
        stage: the stage.
        ok: clips solved; tried: clips refined.
        rate: ``ok / tried`` (0 when none was tried).
        failed: ``species/action/artefacts`` of every failure (``species/action: why`` for
            a clip that could not be generated).
        missed: the target missed (one line), or None.
    """

    stage: str
    ok: int
    tried: int
    rate: float
    failed: list[str]
    missed: str | None


def success_rates(
    options: RefineBenchOptions,
    species: list[str],
    test_clips: list[tuple[str, str, Any]] | None = None,
) -> Iterator[SuccessRate]:
    """IPOPT's success rate per stage, as each stage finishes.

    Args:
        options: the run's options (``success_clips``, ``stages``, ``seed``).
        species: species the generated clips are drawn from.
        test_clips: :func:`test_split`'s clips to draw windows from instead.
    """
    from habitsim.errors import HabitsimError
    from habitsim.gaits import available_actions

    rng = np.random.default_rng(options.seed + 7)
    for st in options.stages:
        ok = tried = 0
        fails = []
        drawn = []
        for _ in range(options.success_clips):
            kinds = tuple(a for a in ARTEFACTS + ("float",) if rng.random() < 0.5) or ("slide",)
            sp = act = "?"
            try:
                if test_clips:
                    sp, act, m = _test_window(test_clips, rng, 100, kinds)
                else:
                    sp = str(rng.choice(species))
                    act = str(rng.choice(available_actions(sp)))
                    m = clip(sp, 100, int(rng.integers(1 << 30)), act, kinds)
            except HabitsimError as e:  # an action that cannot be generated at this length
                fails.append(f"{sp}/{act}: {e}")
                continue
            drawn.append((sp, act, kinds, m))
        # solved grouped by species: the process keeps only a few built problems
        for sp, act, kinds, m in sorted(drawn, key=lambda d: d[0]):
            r = timed(m, st)
            tried += 1
            ok += bool(r.ok)
            if not r.ok:
                fails.append(f"{sp}/{act}/{'+'.join(kinds)}")
        rate = ok / max(tried, 1)
        missed = None
        if rate < TARGET_SUCCESS:
            missed = f"stage {st} IPOPT success {100 * rate:.1f} % < {100 * TARGET_SUCCESS:.0f} %"
        yield SuccessRate(st, ok, tried, rate, fails, missed)


# --------------------------------------------------------------------------- clean input
@dataclass(frozen=True)
class CleanChange:
    """How far refinement moves one clean clip (stage A, default options).

    Attributes:
        name: ``species/action`` (synthetic) or ``file@start s`` (real).
        ok: the refinement succeeded.
        max, median: largest and median over the frames of the mean joint position
            change [leg lengths] (:func:`habitsim.refine.verdict.input_change`).
        joint_max: the largest change of one joint in one frame [leg lengths].
        floor_max, floor_median: the same change of the model's closest pose to the input
            (:func:`model_floor`): what no refinement can bring closer [leg lengths].
        skate_before, skate_after: ``skate_mm`` of the input and of the result [mm/frame].
        penetration_before, penetration_after: ``penetration_mm`` [mm].
        call: wall time of the refine() call less any problem build [s].
        cpu: process CPU time over the call, every thread [s] (on a shared machine the
            fairer of the two).
        retries: guard solves (retries, and solves at the weights halfway).
    """

    name: str
    ok: bool
    max: float
    median: float
    joint_max: float
    floor_max: float
    floor_median: float
    skate_before: float
    skate_after: float
    penetration_before: float
    penetration_after: float
    call: float
    cpu: float
    retries: int

    @property
    def met(self) -> bool:
        """The clean-input target held on every frame."""
        return self.ok and self.max <= TARGET_CLEAN_CHANGE


def clean_change(name: str, motion: Any) -> CleanChange:
    """Refine a clean clip at stage A (:func:`timed`) and measure how far it moved."""
    from habitsim.metrics.kinematic import penetration_mm, skate_mm
    from habitsim.refine.verdict import input_change

    r = timed(motion, "A")
    out = motion if r.result is None else r.result.motion
    ch = input_change(motion, out)
    floor = model_floor(motion)
    guard = [] if r.result is None else r.result.report.get("guard", [])
    return CleanChange(
        name,
        r.ok,
        ch["max"],
        ch["median"],
        ch["joint_max"],
        floor["max"],
        floor["median"],
        skate_mm(motion),
        skate_mm(out),
        penetration_mm(motion),
        penetration_mm(out),
        r.call,
        r.cpu,
        len(guard),
    )


def model_floor(motion: Any) -> dict[str, float]:
    """How far the species model's closest poses lie from a clip
    (:func:`habitsim.refine.verdict.input_change` of them): the refinement's tracking
    term alone (no contact labels, swing clearance, ground alignment, regularisation,
    smoothing or guard), every hinge within its joint range and every joint above the
    floor. A pose the model's hinges cannot take (a twist of the trunk, an axial turn of
    a leg) keeps this distance whatever the refinement does; NaN when the solve fails."""
    import numpy as np

    from habitsim.refine import RefineOptions, refine
    from habitsim.refine.verdict import input_change

    opts = RefineOptions(
        metrics=False,
        w_smooth=0.0,
        w_reg=0.0,
        w_root=0.0,
        swing_clearance=None,
        clean_contacts=False,
        align_ground=False,
        plant_start=False,
        filter_cutoff=None,
        guard=0,
        fallback=True,
    )
    res = refine(motion, opts, contacts=np.zeros((motion.num_frames, 4), bool))
    if not res.success:
        return {"max": float("nan"), "median": float("nan"), "joint_max": float("nan")}
    return input_change(motion, res.motion)


def clean_synthetic(species: list[str], seed: int = 0) -> Iterator[CleanChange]:
    """The clean-input change of a 4 s, 30 fps synthetic walk (or the species' first
    action) of every species, as each finishes."""
    from habitsim.gaits import available_actions, generate

    for sp in species:
        acts = [a for a in available_actions(sp) if a not in ("sit",)]
        act = "walk" if "walk" in acts else acts[0]
        clean = generate(sp, act, seed=seed, fps=CLEAN_FPS, duration_s=CLEAN_SECONDS)
        yield clean_change(f"{sp}/{act}", clean)


def clean_real(
    folder: str, species: str = "dog", windows_per_clip: int = 1
) -> Iterator[CleanChange]:
    """The clean-input change of the first ``windows_per_clip`` 4 s windows of every clip
    of ``folder``, imported onto ``species`` and resampled to 30 fps, the windows chosen
    from its locomotion as ``bench real`` chooses them
    (:func:`~habitsim.evaluation.bench.real.clip_windows`); clips without a whole window
    are left out.

    Raises:
        BenchRealError: not a folder, no readable clip in it, or ``windows_per_clip`` < 1.
    """
    from habitsim.motion import resample_motion

    from .real import BenchRealError, clip_windows, read_clip, source_files

    if int(windows_per_clip) < 1:
        raise BenchRealError(f"windows per clip must be ≥ 1, got {windows_per_clip}")
    for f in source_files(folder):
        m = resample_motion(read_clip(f, species), CLEAN_FPS)
        frames = int(round(CLEAN_SECONDS * m.fps))
        windows, _ = clip_windows(m, frames, windows_per_clip, frames)
        for w in windows:
            if not w.short:
                yield clean_change(f"{f.name}@{w.start / m.fps:.1f}s", m.slice(w.start, w.stop))
