"""``habitsim bench real``: real motion capture through the whole pipeline.

Every clip of a folder (:data:`habitsim.bvh_mapping.SOURCE_SUFFIXES`: BVH, glTF/GLB) is
imported onto ``species`` (default dog) with :func:`habitsim.bvh_mapping.import_bvh`
(which reads it with :func:`habitsim.bvh_mapping.read_source`), resampled to ``fps``
(default 30 Hz, the rate the shipped model and the refinement are built for) and cut into
windows of ``seconds`` (default 4 s) chosen from its activity timeline
(:func:`habitsim.activity.timeline`, :func:`habitsim.activity.choose_windows`):
consecutive windows from the first locomotion frame of each stretch where the animal
stands or moves on its legs, at most ``windows_per_clip`` (default 1; ``all``: every
whole window) per clip. A segment whose trunk rests on the ground (lying, sitting) is
kept out of the windows and named in a note. A clip (or upright stretch) shorter than one
window runs as one shorter window (``short_window`` in its rows, marked in the table), of
at least ``min_seconds``; only a clip without such a stretch (lying throughout) is left
out, with a note. Each window × target
(default cat, horse, camel, tiger, elephant) × method (default habit, direct) runs through
:func:`habitsim.pipeline.run_clip` (transfer → refine stage A → unassisted ``mpc``
tracking, with the refinement check), in an executor of the evaluation
(:mod:`habitsim.evaluation.executors`, ``workers`` processes).

Per row: the import's contact F1 against the source's own feet (the importer's
``metadata["import"]["contact_f1"]``, read by :class:`habitsim.bvh_mapping.ImportReport`,
one value per foot; None when the importer gives none), the stance toe height (median
height of the labelled-stance toes / leg length: the import's own labels, and the
transfer's), how the transfer's stance labels were
found, skate / jerk / penetration before and after refinement, the refinement check,
survival, sim MPJPE / leg length, the wall time per stage, and the dynamic plausibility
of the tracked reference (docs/metrics.md's ``root_residual_mg`` and
``torque_saturation`` under its stance labels: a window whose reference needs a large
"hand of god" force, or more torque than the motors have, cannot be tracked by any
controller without falling or deviating); the columns it takes from the pipeline's run
come from the one row builder, :func:`habitsim.evaluation.rows.run_row`. Skating is
docs/metrics.md's ``skate_mm`` (toes within 2 % of leg length of the ground count as in
contact, labelled or not); the rows and the summary also give it over the labelled stance
frames only (``skate_labelled_mm_*``), the frames the refinement plants.
:func:`evaluate_targets` checks the issue's targets (``met`` / ``MISSED``; ``n/a`` when a
target does not apply to the run):

* refinement: skate ≤ 1 mm/frame, jerk ≤ the input's and penetration ≤ 1 mm on ≥ 95 % of
  the refined transfers;
* ≥ 90 % of the habit transfers survive the whole window unassisted under ``mpc``,
  over the windows whose source moves below a gallop (peak Froude number at most
  :data:`~habitsim.gait_stats.GALLOP_FROUDE`); gallops, whose flight phases are beyond
  model-based tracking on a CPU (docs/controllers.md, "Limits"), are counted
  beside the target, never in it;
* median sim MPJPE of the habit windows ≤ 0.10 leg length (the median over every
  tracked window is shown beside it);
* habit ≥ direct on mean survival;
* transfer + refine + track of one 4 s window ≤ 10 s (median; scaled with ``seconds``).

``repeats`` K tracks every kept reference K times: once from the reference's own state
(the row's figures) and K − 1 times with Gaussian noise of ``perturb`` rad/s (default
10⁻³) on the initial joint velocities, one seed each (:func:`habitsim.sim.track`'s
``init_noise``). A window near its balance limit survives or falls on float-level
differences (thread counts, a library version), so one run is one sample; with repeats
the two survival targets count every run (share of whole runs, mean survival over all
runs) and each row says in how many of its runs it was tracked whole. The sim MPJPE and
the wall times stay those of the unperturbed run.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from habitsim.errors import HabitsimError

from ..rows import finite_or_none, run_row
from .targets import TargetCheck, exit_code, verdict

if TYPE_CHECKING:  # pragma: no cover
    from habitsim.activity import Timeline, Window
    from habitsim.motion import Motion

__all__ = [
    "BenchRealError",
    "RealOptions",
    "RealPlan",
    "WindowTask",
    "evaluate_targets",
    "galloping",
    "exit_code",
    "plan",
    "read_clip",
    "run_tasks",
    "run_window",
    "source_files",
    "survival_runs",
    "clip_windows",
]

#: Default target species.
DEFAULT_TARGETS = ("cat", "horse", "camel", "tiger", "elephant")
#: Default transfer methods.
DEFAULT_METHODS = ("habit", "direct")
#: Refinement targets: skating [mm/frame] and mean penetration [mm] after refinement …
REFINE_SKATE_MM = 1.0
REFINE_PENETRATION_MM = 1.0
#: … on at least this share of the refined transfers.
REFINE_SHARE = 0.95
#: Share of habit transfers that survive the whole window unassisted under mpc.
SURVIVAL_SHARE = 0.90
#: Median sim MPJPE of the habit windows [leg lengths].
MPJPE_PER_LEG = 0.10
#: Transfer + refine + track of one 4 s window [s].
SECONDS_PER_4S_CLIP = 10.0
#: Initial joint-velocity noise [rad/s] of the repeated runs.
PERTURB_QVEL = 1e-3

#: A row of ``bench real`` (one window × target × method), a JSON object: the window
#: (``clip``, ``start_s`` [s], ``frames``, ``fps`` [Hz], ``window_s`` [s],
#: ``short_window`` (a clip shorter than a window, run as one shorter window),
#: ``activity`` (its segments, e.g. ``locomotion (walk, trot)``), ``species``, ``target``,
#: the import's figures), ``method``, ``status`` (``ok``, ``unavailable``, ``error``) and
#: ``note``, then on ``ok`` the columns of :meth:`habitsim.evaluation.rows.RunRow.real_columns`,
#: the tracking runs (``survival_runs``, ``whole_runs``, ``time_repeats_s`` [s]) and
#: :meth:`~habitsim.evaluation.rows.RunRow.real_tail_columns`, and ``time_total_s`` [s].
RealRow = dict[str, Any]


class BenchRealError(HabitsimError, ValueError):
    """Bad input to ``bench real``: no readable clip in the folder, no clip long enough for
    a window, bad window settings."""


@dataclass(frozen=True)
class RealOptions:
    """What a ``bench real`` run does.

    Attributes:
        data: folder of source clips.
        targets: target species.
        methods: transfer methods (:func:`habitsim.transfer_methods.method_names`).
        species: skeleton the clips are imported onto.
        joint_map, units, up: the importer's options for every clip
            (:func:`habitsim.bvh_mapping.import_bvh`; None: its defaults).
        seconds: window length [s].
        min_seconds: a clip shorter than one window runs as one shorter window of at
            least this length [s].
        windows_per_clip: consecutive windows per clip, or ``"all"``.
        fps: frame rate the clips are resampled to [Hz] (0 keeps theirs).
        refine: refinement stage (``none``, ``A``, ``B``).
        controller: unassisted tracking controller (:data:`habitsim.controllers.CONTROLLERS`).
        track: run the MuJoCo tracking.
        check: track the unrefined transfer too, to check the refinement.
        seed: seed of the transfer and the first tracking run.
        repeats: tracking runs per kept reference (the first unperturbed).
        perturb: initial joint-velocity noise of the repeated runs [rad/s].
        workers: worker processes (None: the CPU count; 1: in this process).
        variants: run these transformed copies of every clip instead of the clips
            (:mod:`habitsim.evaluation.bench.variants`; ``original`` is the clip itself).
    """

    data: str | Path
    targets: tuple[str, ...] = DEFAULT_TARGETS
    methods: tuple[str, ...] = DEFAULT_METHODS
    species: str = "dog"
    joint_map: Path | None = None
    units: str | None = None
    up: str | None = None
    seconds: float = 4.0
    min_seconds: float = 1.0
    windows_per_clip: int | Literal["all"] = 1
    fps: float = 30.0
    refine: str = "A"
    controller: str = "mpc"
    track: bool = True
    check: bool = True
    seed: int = 0
    repeats: int = 1
    perturb: float = PERTURB_QVEL
    workers: int | None = None
    variants: tuple[str, ...] = ()


# ---------------------------------------------------------------------------- sources


def read_clip(
    path: str | Path | Any,
    species: str,
    joint_map: Path | None = None,
    units: str | None = None,
    up: str | None = None,
) -> Motion:
    """One source clip on ``species``' skeleton (:func:`habitsim.bvh_mapping.import_bvh`,
    the options as ``import-bvh`` takes them, None for its defaults), with stance labels
    and ``metadata["import"]`` when the importer finds them. A glTF/GLB file gives its
    first animation; ``path`` may also be a parsed :class:`habitsim.bvh.BVHData`.

    Raises:
        SkeletonMappingError: a file type :func:`~habitsim.bvh_mapping.read_source` does
            not read (lists the readable ones), an unmappable skeleton.
        BVHParseError / GLTFError: an unreadable file.
    """
    from habitsim.bvh_mapping import import_bvh

    motion, _ = import_bvh(path, species, joint_map=joint_map, units=units, up=up)
    return motion


def source_files(folder: str | Path) -> list[Path]:
    """The readable source clips of a folder (sorted).

    Raises:
        BenchRealError: not a folder, or no readable clip in it.
    """
    from habitsim.bvh_mapping import SOURCE_SUFFIXES

    d = Path(folder)
    if not d.is_dir():
        raise BenchRealError(f"--data {d}: not a folder")
    files = sorted(p for p in d.iterdir() if p.is_file() and p.suffix.lower() in SOURCE_SUFFIXES)
    if not files:
        raise BenchRealError(
            f"--data {d}: no source clips ({', '.join(sorted(SOURCE_SUFFIXES))} files) in it"
        )
    return files


def clip_windows(
    motion: Motion, frames: int, max_windows: int, min_frames: int
) -> tuple[list[Window], Timeline]:
    """The windows of one clip (:func:`habitsim.activity.choose_windows` on its
    :func:`~habitsim.activity.timeline`) and the timeline."""
    from habitsim.activity import choose_windows, timeline

    tl = timeline(motion)
    return choose_windows(tl, frames, max_windows, min_frames), tl


def _window_activity(tl: Timeline, start: int, stop: int) -> str:
    """The activities of the segments a window overlaps, e.g. ``locomotion (walk, trot),
    standing``."""
    parts: dict[str, list[str]] = {}
    for s in tl.segments:
        if s.stop > start and s.start < stop:
            gaits = parts.setdefault(s.activity.value, [])
            if s.gait and s.gait not in gaits:
                gaits.append(s.gait)
    return ", ".join(f"{a} ({', '.join(g)})" if g else a for a, g in parts.items())


# ---------------------------------------------------------------------------- tasks


@dataclass(frozen=True)
class WindowTask:
    """One window of a clip to one target with every method; plain data, picklable."""

    clip: str
    start_s: float
    motion: Any  # the window (a Motion)
    target: str
    methods: tuple[str, ...]
    refine: str
    controller: str
    track: bool
    guard: bool
    seed: int
    repeats: int = 1
    perturb: float = PERTURB_QVEL
    short: bool = False
    activity: str = ""


def _import_f1(motion: Motion) -> list[float] | None:
    """The import's per-foot contact F1 (:attr:`habitsim.bvh_mapping.ImportReport.
    contact_f1`, its finite values), None when the motion has no import report.

    Raises:
        MetadataError: an import report with a missing or malformed field.
    """
    from habitsim.bvh_mapping import ImportReport

    report = ImportReport.from_metadata(motion.metadata)
    if report is None:
        return None
    vals = [finite_or_none(x) for x in report.contact_f1]
    return [v for v in vals if v is not None] or None


def run_window(task: WindowTask) -> list[RealRow]:
    """Every method of one (window, target) through the pipeline: one row per method.

    A failure inside a row (a typed error or a bug) becomes ``status = "error"`` with the
    message in ``note``; the benchmark goes on.
    """
    from habitsim.gait_stats import peak_froude
    from habitsim.pipeline import run_clip, stance_toe_height, track_reference
    from habitsim.transfer_methods import MethodUnavailable

    src = task.motion
    f1 = _import_f1(src)
    base = {
        "clip": task.clip,
        "start_s": task.start_s,
        "frames": src.num_frames,
        "fps": src.fps,
        "window_s": src.num_frames / src.fps,
        "short_window": task.short,
        "activity": task.activity,
        "species": src.species,
        "target": task.target,
        "import_contact_f1": f1,
        "import_contact_f1_mean": None if f1 is None else float(np.mean(f1)),
        "source_labels": src.contacts is not None,
        "stance_toe_height_import": finite_or_none(stance_toe_height(src, src.contacts)),
        "source_froude_peak": peak_froude(src),
        "source_flight_share": None
        if src.contacts is None
        else float((~np.asarray(src.contacts, bool).any(axis=1)).mean()),
    }
    rows = []
    for method in task.methods:
        row: RealRow = {**base, "method": method, "status": "ok", "note": ""}
        t0 = time.perf_counter()
        try:
            run = run_clip(
                src,
                task.target,
                method=method,
                refine=task.refine,
                controller=task.controller,
                seed=task.seed,
                track=task.track,
                guard=task.guard,
            )
        except MethodUnavailable as e:
            row.update(status="unavailable", note=str(e))
            rows.append(row)
            continue
        except Exception as e:  # noqa: BLE001 - recorded in the row, the run goes on
            msg = str(e) if isinstance(e, HabitsimError) else f"{type(e).__name__}: {e}"
            row.update(status="error", note=msg, time_total_s=time.perf_counter() - t0)
            rows.append(row)
            continue
        runs: list[float] = []
        t_rep = time.perf_counter()
        if run.track_result is not None:
            runs.append(float(run.track_result.survival))
            for i in range(1, task.repeats):
                try:
                    again = track_reference(
                        run,
                        controller=task.controller,
                        seed=task.seed + i,
                        init_noise=task.perturb,
                    )
                except HabitsimError as e:
                    row["note"] = f"repeat {i} failed: {e}"
                    continue
                runs.append(float(again.survival))
        t_rep = time.perf_counter() - t_rep
        figures = run_row(run, dynamics=task.track)
        row.update(
            {
                **figures.real_columns(),
                "survival_runs": runs or None,
                "whole_runs": sum(x >= 1.0 for x in runs) if runs else None,
                "time_repeats_s": t_rep,
                **figures.real_tail_columns(),
                "time_total_s": time.perf_counter() - t0 - t_rep,
            }
        )
        rows.append(row)
    return rows


@dataclass(frozen=True)
class RealPlan:
    """The tasks of a run (grouped by target) and the notes on its clips (resting
    segments kept out, short windows, skipped clips)."""

    tasks: tuple[WindowTask, ...]
    notes: tuple[str, ...]


def plan(options: RealOptions) -> RealPlan:
    """The tasks of a run and the notes on its clips: resting segments kept out, short
    windows, skipped clips (every input checked first).

    Raises:
        BenchRealError / UnknownSpeciesError / UnknownMethodError / SimulationError: bad
            options, a folder in which no clip stands or moves on its legs.
    """
    from habitsim.controllers import CONTROLLERS
    from habitsim.motion import resample_motion
    from habitsim.pipeline import refine_mode
    from habitsim.sim import SimulationError
    from habitsim.species import load_species
    from habitsim.transfer_methods import get_method

    o = options
    if not (math.isfinite(o.seconds) and o.seconds > 0):
        raise BenchRealError(f"--seconds must be > 0, got {o.seconds}")
    if not (math.isfinite(o.min_seconds) and o.min_seconds > 0):
        raise BenchRealError(f"min_seconds must be > 0, got {o.min_seconds}")
    every = o.windows_per_clip == "all"
    if not every and not (isinstance(o.windows_per_clip, int) and o.windows_per_clip >= 1):
        raise BenchRealError(
            f"--windows-per-clip must be >= 1 or 'all', got {o.windows_per_clip!r}"
        )
    if not (math.isfinite(o.fps) and o.fps >= 0):
        raise BenchRealError(f"--fps must be >= 0, got {o.fps}")
    repeats, perturb = int(o.repeats), float(o.perturb)
    if repeats < 1:
        raise BenchRealError(f"--repeats must be >= 1, got {repeats}")
    if not (math.isfinite(perturb) and perturb > 0):
        raise BenchRealError(f"--perturb must be a finite rate > 0 [rad/s], got {perturb}")
    if o.controller not in CONTROLLERS:
        from habitsim.errors import unknown_choice

        raise SimulationError(unknown_choice("controller", o.controller, CONTROLLERS))
    species = load_species(o.species).name
    targets = [load_species(t).name for t in o.targets]
    methods = list(o.methods)
    if not targets:
        raise BenchRealError("--targets names no species")
    if not methods:
        raise BenchRealError("--methods names no method")
    for method in methods:
        get_method(method)  # UnknownMethodError listing the registered ones
    mode = refine_mode(o.refine)
    files = source_files(o.data)
    if o.joint_map is not None:
        from habitsim.bvh_mapping import load_joint_map

        load_joint_map(o.joint_map)  # a bad map file fails here, not once per clip
    notes: list[str] = []
    windows: list[tuple[str, float, Any, bool, str]] = []
    sources: list[tuple[str, Any]] = [(f.name, f) for f in files]
    if o.variants:
        from .variants import variant_sources

        sources = variant_sources(files, o.variants, o.seed, notes)
    for name, f in sources:
        try:
            m = read_clip(f, species, joint_map=o.joint_map, units=o.units, up=o.up)
        except HabitsimError as e:
            notes.append(f"{name}: skipped, import failed: {e}")
            continue
        if o.fps > 0:
            m = resample_motion(m, o.fps)
        frames = int(round(o.seconds * m.fps))
        max_windows = m.num_frames if o.windows_per_clip == "all" else o.windows_per_clip
        # a short window is never asked to be longer than a whole one
        min_frames = max(2, int(round(min(o.min_seconds, o.seconds) * m.fps)))
        chosen, tl = clip_windows(m, frames, max_windows, min_frames)
        for seg in tl.segments:
            if seg.trunk_on_ground:
                notes.append(
                    f"{name}: {seg.activity.value} {seg.start_s:.2f}–{seg.end_s:.2f} s "
                    "(trunk on the ground): kept out of the windows"
                )
        if not chosen:
            notes.append(
                f"{name}: skipped, no stretch of {o.min_seconds:g} s or more in which the "
                "animal stands or moves on its legs ("
                + ", ".join(
                    f"{s.activity.value} {s.start_s:.2f}–{s.end_s:.2f} s" for s in tl.segments
                )
                + ")"
            )
            continue
        for w in chosen:
            if w.short:
                sec = w.frames / m.fps
                what = (
                    "the clip"
                    if w.frames == m.num_frames
                    else f"its longest stretch on its legs ({sec:.2f} s of {m.duration:.2f} s)"
                )
                notes.append(
                    f"{name}: {what} is shorter than one {o.seconds:g} s window: runs as "
                    f"one {sec:.2f} s window"
                )
            windows.append(
                (
                    name,
                    round(w.start / m.fps, 3),
                    m.slice(w.start, w.stop),
                    w.short,
                    _window_activity(tl, w.start, w.stop),
                )
            )
    if not windows:
        raise BenchRealError(
            f"--data {o.data}: no clip gives a window (every clip lies or sits throughout, "
            "or failed to import); " + "; ".join(notes)
        )
    tasks = [
        WindowTask(
            clip,
            start,
            w,
            t,
            tuple(methods),
            mode,
            o.controller,
            o.track,
            o.check,
            o.seed,
            repeats,
            perturb,
            short,
            activity,
        )
        for t in targets  # grouped by target: a process keeps few built refinement problems
        for clip, start, w, short, activity in windows
    ]
    return RealPlan(tuple(tasks), tuple(notes))


def run_tasks(
    tasks: Sequence[WindowTask],
    workers: int | None = None,
    on_row: Callable[[RealRow], None] | None = None,
) -> list[RealRow]:
    """Run every task in a local executor (``workers`` processes; 1: in this process).

    Args:
        tasks: :func:`plan`'s tasks.
        workers: worker processes (None: the CPU count).
        on_row: called with every row as its task finishes (completion order).

    Returns:
        The rows in task order, each task's methods in its order.
    """
    from ..executors import ExecutorError, TaskLost, make_executor

    rows: list[RealRow] = []
    ex = make_executor("local", workers=workers)
    try:
        for task, result in ex.map_unordered(run_window, list(tasks)):
            if isinstance(result, TaskLost):
                raise ExecutorError(f"{task.clip} at {task.start_s:g} s: {result.note}")
            for r in result:
                rows.append(r)
                if on_row is not None:
                    on_row(r)
    finally:
        ex.close()
    methods = list(tasks[0].methods) if tasks else []
    order = {(t.clip, t.start_s, t.target): i for i, t in enumerate(tasks)}
    rows.sort(
        key=lambda r: (order[(r["clip"], r["start_s"], r["target"])], methods.index(r["method"]))
    )
    return rows


# ---------------------------------------------------------------------------- targets


def survival_runs(row: RealRow) -> list[float]:
    """Survival of every tracking run of a row (the unperturbed run first; one run
    without repeats)."""
    runs = row.get("survival_runs")
    if runs:
        return [float(x) for x in runs]
    return [] if row.get("survival") is None else [float(row["survival"])]


def galloping(row: RealRow) -> bool:
    """The row's source window gallops: its peak Froude number is above
    :data:`~habitsim.gait_stats.GALLOP_FROUDE` (unknown counts as not)."""
    from habitsim.gait_stats import GALLOP_FROUDE

    fr = finite_or_none(row.get("source_froude_peak"))
    return fr is not None and fr > GALLOP_FROUDE


def evaluate_targets(
    rows: Sequence[RealRow],
    *,
    seconds: float,
    refine: str = "A",
    controller: str = "mpc",
    tracked: bool = True,
) -> list[TargetCheck]:
    """The issue's targets over the rows: name, measured value, target, verdict.

    Verdicts are ``met``, ``MISSED`` or ``n/a`` (the run does not measure it: no
    refinement, no tracking, another controller, a method missing).
    """
    from habitsim.gait_stats import GALLOP_FROUDE

    ok = [r for r in rows if r.get("status") == "ok"]
    out: list[TargetCheck] = []

    # refinement
    ref = [r for r in ok if refine != "none"]
    good = [
        r
        for r in ref
        if (r.get("skate_mm_after") is not None and r["skate_mm_after"] <= REFINE_SKATE_MM)
        and (
            r.get("penetration_mm_after") is not None
            and r["penetration_mm_after"] <= REFINE_PENETRATION_MM
        )
        and (
            r.get("jerk_after") is not None
            and r.get("jerk_before") is not None
            and r["jerk_after"] <= r["jerk_before"] * (1 + 1e-9)
        )
    ]
    share = len(good) / len(ref) if ref else None
    out.append(
        TargetCheck(
            "refinement: skate ≤ 1 mm/frame, jerk ≤ input, penetration ≤ 1 mm",
            share,
            "-" if share is None else f"{100 * share:.0f} % of {len(ref)}",
            f"≥ {100 * REFINE_SHARE:.0f} % of transfers",
            verdict(None if share is None else share >= REFINE_SHARE),
        )
    )

    # survival of habit transfers under mpc, unassisted (every run of every window below
    # a gallop; the gallop windows beside it)
    trk = [r for r in ok if tracked and r.get("survival") is not None]
    habit = [r for r in trk if r["method"] == "habit"]
    below = [r for r in habit if not galloping(r)]
    gallops = [r for r in habit if galloping(r)]
    applies = tracked and controller == "mpc" and below
    hruns = [x for r in below for x in survival_runs(r)]
    share = (sum(x >= 1.0 for x in hruns) / len(hruns)) if applies else None
    shown = "-"
    if share is not None:
        shown = f"{100 * share:.0f} % of {len(below)}"
        if len(hruns) > len(below):
            shown = f"{100 * share:.0f} % of {len(hruns)} runs"
    if gallops:
        gruns = [x for r in gallops for x in survival_runs(r)]
        shown += (
            f"; gallops (Fr > {GALLOP_FROUDE:g}, not counted): "
            f"{sum(x >= 1.0 for x in gruns)}/{len(gruns)} whole"
        )
    out.append(
        TargetCheck(
            f"habit transfers surviving unassisted (mpc), source Fr ≤ {GALLOP_FROUDE:g}",
            share,
            shown,
            f"≥ {100 * SURVIVAL_SHARE:.0f} %",
            verdict(None if share is None else share >= SURVIVAL_SHARE),
        )
    )

    # median sim MPJPE of the habit windows; over every tracked window beside it
    e = [r["sim_mpjpe_per_leg"] for r in trk if r.get("sim_mpjpe_per_leg") is not None]
    eh = [r["sim_mpjpe_per_leg"] for r in habit if r.get("sim_mpjpe_per_leg") is not None]
    med = float(np.median(eh)) if eh else None
    shown = "-" if med is None else f"{med:.3f} of {len(eh)}"
    if med is not None and e:
        shown += f" (all tracked windows {float(np.median(e)):.3f})"
    out.append(
        TargetCheck(
            "median sim MPJPE / leg length, habit windows",
            med,
            shown,
            f"≤ {MPJPE_PER_LEG}",
            verdict(None if med is None else med <= MPJPE_PER_LEG),
        )
    )

    # habit ≥ direct on survival
    direct = [r for r in trk if r["method"] == "direct"]
    value: float | None = None
    if habit and direct:
        sh = float(np.mean([x for r in habit for x in survival_runs(r)]))
        sd = float(np.mean([x for r in direct for x in survival_runs(r)]))
        shown, value = f"{sh:.2f} vs {sd:.2f}", sh - sd
        met = verdict(sh >= sd - 1e-9)
    else:
        shown, met = "-", verdict(None)
    out.append(TargetCheck("habit ≥ direct on mean survival", value, shown, "habit ≥ direct", met))

    # time per clip
    limit = SECONDS_PER_4S_CLIP * seconds / 4.0
    tt = [sum(r.get(f"time_{k}_s") or 0.0 for k in ("transfer", "refine", "track")) for r in ok]
    med = float(np.median(tt)) if tt else None
    out.append(
        TargetCheck(
            f"transfer + refine + track of one {seconds:g} s window (median)",
            med,
            "-" if med is None else f"{med:.1f} s",
            f"≤ {limit:.1f} s" + ("" if seconds == 4 else " (10 s per 4 s)"),
            verdict(None if med is None else med <= limit),
        )
    )
    return out
