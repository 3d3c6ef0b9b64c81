"""The benchmark runner: every (validation clip, target species) pair through
transfer → refine → track → every metric, for every method, one row per pair.

Usage (CLI: ``habitsim eval``)::

    from habitsim.evaluation.runner import EvalConfig, run_benchmark
    result = run_benchmark(EvalConfig(data="/tmp/hs_default", out="bench",
                                      methods=("direct", "ground_truth")))
    print(result.table_markdown)

Pairs: every clip of the ``split`` (default ``val``) × every target species (default:
the data set's training species), the source's own species left out. For each pair and
method, :func:`evaluate_pair` (run by an executor, in any process or machine) runs the
clip through :func:`habitsim.pipeline.run_clip` (transfer → refine → track, the stance
labels passed from stage to stage; its refinement check is off here, so the rows measure
the refinement as it is) and measures:

1. **transfer** with the method (:mod:`habitsim.evaluation.methods`); a method that
   cannot serve the pair gives a row with ``status = "unavailable"``;
2. the paper's metrics on the transferred motion: evaluator features (kept for the set
   metrics) and predictions (``habit_correct``: predicted species = target, NaN for a
   target the evaluator has no class for; ``action_correct``: predicted action = the
   source's action), ``mpjpe_mm`` against the source scaled to the target's size and
   ``paired_mpjpe_mm`` against ``generate(target, like=source)``, and the
   biomechanical consistency (:mod:`habitsim.evaluation.biomech`) against the target's
   gait table, from foot contacts detected on the geometry (every method alike);
3. **refine** with :func:`habitsim.refine.refine` (``--refine kinematic|dynamics``,
   with ``fallback``: a failed solve keeps the input and says so in ``refine_status``).
   Stance phases are the transfer's labels (``direct``: the source's; ``ground_truth``:
   the planned stance; the learned methods:
   :func:`habitsim.models.transfer.transfer_contacts`), found by the transfer stage
   when a method sets none;
4. kinematic (:mod:`~habitsim.evaluation.kinematic`) and dynamic
   (:mod:`~habitsim.evaluation.dynamic`) plausibility of the reference that is tracked
   (the refined motion, or the transferred one);
5. **track** it with :func:`habitsim.sim.track` (unassisted by default; the reference
   contact labels are the refined ones): the simulated
   metrics of docs/metrics.md, and the biomechanical score of the simulated motion from its
   simulated foot contacts (``sim_biomech_score``; NaN when the transferred motion is
   no gait, e.g. a sit).

A failure inside a pair (a typed habitsim error or a bug) becomes ``status = "error"``
with the message in ``note``; the benchmark goes on and ``--resume`` retries it.

Output folder::

    run.json                   configuration (checked by --resume)
    rows/<key>.json            one finished pair (written atomically; --resume skips it)
    traces/<key>/…             contacts, tracking error and motions of the report's pairs
    rows.csv, rows.parquet     every row (Parquet when pyarrow is installed)
    features.npz               evaluator features of every transferred motion (by key)
    reference_features.npz     evaluator features of the real reference clips
    summary.json, summary.csv  one line per method (set metrics + row means)
    summary.md                 the paper's Table 1 layout plus physical columns
    report.html, report.md     see :mod:`habitsim.evaluation.report`

Set metrics per method (:mod:`habitsim.evaluation.distribution`) compare the features of
its transferred motions with the *real* clips of the targets ("the original data of the
target category", paper Sec. 4.1.2): each target's clips in the ``reference_split``
splits, default ``train,val`` (the test split stays reserved). With only the ``val``
clips the action mix would match the sources exactly, but the default data set has 3–5
per species, too few for a 32-dimensional Gaussian fit and below the 5 samples
``downstream_fid`` requires; with ``test`` the action mix differs (FID(real val, real
test) = 129 on the default data set). Per-target metrics only ever see real clips of the
target species, so a clip is never compared with itself there. The pooled metrics
(``fid``, ``one_nna``) are unconditional, as in the paper: they compare motion
distributions whatever the species, and the validation sources are real clips of that
same pool, so a method that returns its input nearly unchanged (``direct``) scores well on
them; ``intra_fid``, ``downstream_fid`` and ``habit_accuracy`` are the species-conditional
measures. FID over
all pairs; Intra-FID per target species; downstream FID per (source, target) species
pair; diversity of the transferred features beside ``diversity_real`` of the reference;
1-NNA on class-balanced sets (the larger set subsampled with a fixed seed). Every other
summary column is the mean of the method's ``ok`` rows that have a finite value
(``habit_accuracy`` = mean of ``habit_correct``, ``action_accuracy`` = mean of
``action_correct``).
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import math
import shutil
import time
import traceback
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from habitsim.controllers import CONTROLLERS
from habitsim.errors import HabitsimError, OutputPathError, brief, brief_path, unknown_choice
from habitsim.fileio import atomic_write, atomic_write_text, check_writable, json_safe, make_dirs
from habitsim.motion import Motion

__all__ = [
    "EvalError",
    "EvalConfig",
    "PairTask",
    "BenchmarkResult",
    "REFINE_MODES",
    "ROW_ID_COLUMNS",
    "TABLE1_COLUMNS",
    "PHYSICAL_COLUMNS",
    "VOLATILE_COLUMNS",
    "DEFAULT_METHODS",
    "DEFAULT_CONTROLLER",
    "DEFAULT_TARGETS",
    "DEFAULT_CLIPS_PER_SOURCE",
    "DEFAULT_DATA_CLIPS_PER_SPECIES",
    "default_data",
    "plan_tasks",
    "evaluate_pair",
    "run_benchmark",
    "summarize",
    "load_rows",
    "format_table",
    "write_tables",
]

REFINE_MODES = ("none", "kinematic", "dynamics")

#: What ``habitsim eval`` measures with no options: the product's own method beside the
#: baseline and the paired ground truth, refinement stage A (``kinematic``) and the
#: controller the README recommends, unassisted.
DEFAULT_METHODS = ("habit", "direct", "ground_truth")
DEFAULT_CONTROLLER = "mpc"
#: The default run's size, chosen to finish within 20 min on 2 cores: the first
#: validation clip of every training species (12 sources) to three targets of different
#: build (small digitigrade, large unguligrade, pacer): 33 pairs per method, 99 in all.
DEFAULT_TARGETS = ("cat", "horse", "camel")
DEFAULT_CLIPS_PER_SOURCE = 1
#: Clips per species of the data set ``habitsim eval`` builds when given no ``--data``
#: (every species; 1–3 validation clips per training species, the first a trot for 8 of
#: the 12, and 16–18 train clips as the set metrics' real references).
DEFAULT_DATA_CLIPS_PER_SPECIES = 20
RUN_FORMAT_VERSION = 1

#: Identity / status columns of a row (strings), in order.
ROW_ID_COLUMNS = (
    "key",
    "method",
    "clip",
    "source",
    "target",
    "action",
    "gait",
    "pair_key",
    "target_held_out",
    "status",
    "note",
    "refine_status",
    "track_status",
    "pred_species",
    "pred_action",
    "biomech_gait",
    "sim_biomech_gait",
)
#: Columns whose values change from run to run (timings): left out of comparisons.
VOLATILE_COLUMNS = (
    "time_transfer_s",
    "time_refine_s",
    "time_track_s",
    "time_total_s",
    "cpu_total_s",
    "realtime_factor",
)
#: Summary columns of the paper's Table 1 (set metrics + content), in display order.
TABLE1_COLUMNS = (
    ("fid", "FID ↓"),
    ("intra_fid", "Intra-FID ↓"),
    ("downstream_fid", "Downstream ↓"),
    ("diversity", "Diversity →"),
    ("diversity_real", "(real)"),
    ("one_nna", "1-NNA →0.5"),
    ("mpjpe_mm", "MPJPE mm"),
    ("paired_mpjpe_mm", "paired MPJPE mm ↓"),
    ("habit_accuracy", "habit acc ↑"),
    ("action_accuracy", "action acc ↑"),
)
#: Physical summary columns added to Table 1.
PHYSICAL_COLUMNS = (
    ("skate_mm", "skate mm ↓"),
    ("penetration_mm", "penetr. mm ↓"),
    ("float_mm", "float mm ↓"),
    ("root_residual_mg", "root resid. mg ↓"),
    ("survival", "survival ↑"),
    ("sim_mpjpe_mm", "sim MPJPE mm ↓"),
    ("cost_of_transport", "CoT"),
    ("biomech_score", "biomech ↓"),
)
_SET_METRICS = ("fid", "intra_fid", "downstream_fid", "diversity", "diversity_real", "one_nna")


class EvalError(HabitsimError, ValueError):
    """Bad benchmark input: unknown method / refine mode / species, a data set without
    clips in the split, an output folder holding another run (without ``--resume``)."""


@dataclass(frozen=True)
class EvalConfig:
    """What a benchmark run does.

    Attributes:
        data: synthetic data set folder.
        out: output folder.
        methods: method names (:func:`habitsim.evaluation.methods.method_names`).
        refine: ``none``, ``kinematic`` or ``dynamics``.
        controller: tracking controller (:data:`habitsim.controllers.CONTROLLERS`).
        assist: root assistance while tracking.
        track: run the MuJoCo tracking at all.
        dynamic: compute the dynamic plausibility (inverse dynamics) of the reference.
        split: split of the source clips.
        sources: only these source species (None: all of the split).
        targets: target species (None: the data set's training species).
        include_self: also transfer a clip to its own species.
        max_clips: only the first N source clips (manifest order) — for quick runs.
        clips_per_source: only the first N clips of each source species (manifest
            order; None: all), applied before ``max_clips``.
        reference_split: comma-separated splits of the real clips for the set metrics
            (only the summary depends on it; it may change on ``--resume``).
        evaluator: evaluator folder (None: the shipped one).
        seed: seed passed to the methods and used by the set metrics.
        report_pairs: pairs per method whose traces (gait diagrams, tracking error,
            videos) are kept for the report.
        videos: render videos of the report pairs when :mod:`habitsim.render` works.
    """

    data: str
    out: str
    methods: tuple[str, ...] = DEFAULT_METHODS
    refine: str = "kinematic"
    controller: str = DEFAULT_CONTROLLER
    assist: bool = False
    track: bool = True
    dynamic: bool = True
    split: str = "val"
    sources: tuple[str, ...] | None = None
    targets: tuple[str, ...] | None = None
    include_self: bool = False
    max_clips: int | None = None
    clips_per_source: int | None = None
    reference_split: str = "train,val"
    evaluator: str | None = None
    seed: int = 0
    report_pairs: int = 3
    videos: bool = True

    def __post_init__(self) -> None:
        object.__setattr__(self, "data", str(Path(self.data).resolve()))
        object.__setattr__(self, "out", str(Path(self.out).resolve()))
        object.__setattr__(self, "methods", tuple(self.methods))
        if self.sources is not None:
            object.__setattr__(self, "sources", tuple(self.sources))
        if self.targets is not None:
            object.__setattr__(self, "targets", tuple(self.targets))
        if self.evaluator is not None:
            object.__setattr__(self, "evaluator", str(Path(self.evaluator).resolve()))
        if not self.methods:
            raise EvalError("no methods given")
        if len(set(self.methods)) != len(self.methods):
            raise EvalError(f"methods listed twice: {', '.join(self.methods)}")
        from habitsim.dataset import SPLITS

        bad = [x for x in self.reference_split.split(",") if x.strip() not in SPLITS]
        if bad or not self.reference_split.strip():
            raise EvalError(
                f"reference_split {self.reference_split!r}: comma-separated splits of "
                f"{', '.join(SPLITS)}"
            )
        if self.refine not in REFINE_MODES:
            raise EvalError(unknown_choice("refine mode", self.refine, REFINE_MODES))
        if self.controller not in CONTROLLERS:
            raise EvalError(unknown_choice("controller", self.controller, CONTROLLERS))
        if self.max_clips is not None and self.max_clips < 1:
            raise EvalError(f"max_clips must be >= 1, got {self.max_clips}")
        if self.clips_per_source is not None and self.clips_per_source < 1:
            raise EvalError(f"clips_per_source must be >= 1, got {self.clips_per_source}")

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        for k in ("methods", "sources", "targets"):
            if d[k] is not None:
                d[k] = list(d[k])
        return d

    #: fields that must match for --resume (the others only select which pairs run)
    RESUME_KEYS = (
        "data",
        "refine",
        "controller",
        "assist",
        "track",
        "dynamic",
        "evaluator",
        "seed",
    )


@dataclass(frozen=True)
class PairTask:
    """One (method, source clip, target) unit of work; plain data, picklable."""

    key: str
    method: str
    clip: str
    clip_path: str
    source: str
    target: str
    target_held_out: bool
    action: str
    gait: str
    pair_key: str
    refine: str
    controller: str
    assist: bool
    track: bool
    dynamic: bool
    seed: int
    evaluator: str | None
    out: str
    trace: bool = False
    videos: bool = False


# ---------------------------------------------------------------------------- planning


def default_data(
    out: str | Path,
    *,
    workers: int | None = None,
    progress: bool = True,
    log: Callable[[str], None] | None = None,
) -> Path:
    """The synthetic data set of a run given no data: ``OUT/data``, every species,
    :data:`DEFAULT_DATA_CLIPS_PER_SPECIES` clips each, seed 0; built on the first run and
    reused after (a folder holding another configuration is rebuilt).

    Raises:
        DatasetError: ``OUT/data`` cannot be written.
    """
    from habitsim.dataset import build_dataset, check_resumable
    from habitsim.errors import DatasetError

    folder = Path(out) / "data"
    try:
        check_resumable(folder, seed=0)
        overwrite = False
    except DatasetError:
        overwrite = True  # another configuration (or not a data set): rebuild it
    if log:
        log(
            f"eval: no --data given: the default synthetic data set in {folder} "
            f"({DEFAULT_DATA_CLIPS_PER_SPECIES} clips per species, seed 0)"
        )
    build_dataset(
        folder,
        clips_per_species=DEFAULT_DATA_CLIPS_PER_SPECIES,
        seed=0,
        workers=workers,
        progress=progress,
        overwrite=overwrite,
    )
    return folder


def _manifest(cfg: EvalConfig):
    from habitsim.dataset import load_manifest

    return load_manifest(cfg.data, check_files=False)


def _targets(cfg: EvalConfig, man) -> list[str]:
    from habitsim.species import load_species

    if cfg.targets is None:
        return [s["name"] for s in man.species if not s["held_out"]]
    return [load_species(t).name for t in cfg.targets]


def plan_tasks(cfg: EvalConfig) -> list[PairTask]:
    """Every (source clip, target, method) task of a run, in a fixed order.

    Raises:
        EvalError: unknown methods, no clips in the split, no targets.
    """
    from .methods import get_method

    for m in cfg.methods:
        get_method(m)  # raises UnknownMethodError listing the registered ones
    man = _manifest(cfg)
    clips = man.select(split=cfg.split, species=cfg.sources)
    if cfg.clips_per_source is not None:
        seen: dict[str, int] = {}
        kept = []
        for c in clips:
            seen[c.species] = seen.get(c.species, 0) + 1
            if seen[c.species] <= cfg.clips_per_source:
                kept.append(c)
        clips = kept
    if cfg.max_clips is not None:
        clips = clips[: cfg.max_clips]
    if not clips:
        raise EvalError(
            f"the data set at {cfg.data} has no {cfg.split!r} clips"
            + (f" of {', '.join(cfg.sources)}" if cfg.sources else "")
        )
    targets = _targets(cfg, man)
    if not targets:
        raise EvalError("no target species")
    held = {s["name"]: bool(s["held_out"]) for s in man.species}
    from habitsim.species import load_species

    trace_pairs = _report_pairs(clips, targets, cfg.report_pairs, cfg.include_self)
    tasks = []
    for c in clips:
        for t in targets:
            if t == c.species and not cfg.include_self:
                continue
            for m in cfg.methods:
                stem = Path(c.path).stem
                tasks.append(
                    PairTask(
                        key=f"{m}__{stem}__{t}",
                        method=m,
                        clip=c.path,
                        clip_path=str(Path(cfg.data) / c.path),
                        source=c.species,
                        target=t,
                        target_held_out=held.get(t, load_species(t).held_out),
                        action=c.action,
                        gait=c.gait,
                        pair_key=c.pair_key,
                        refine=cfg.refine,
                        controller=cfg.controller,
                        assist=cfg.assist,
                        track=cfg.track,
                        dynamic=cfg.dynamic,
                        seed=cfg.seed,
                        evaluator=cfg.evaluator,
                        out=cfg.out,
                        trace=(c.path, t) in trace_pairs,
                        videos=cfg.videos,
                    )
                )
    return tasks


def _report_pairs(clips, targets: list[str], n: int, include_self: bool) -> set[tuple[str, str]]:
    """Up to n (clip, target) pairs for the report: locomotion clips of distinct actions,
    each to a different target."""
    from habitsim.gaits import LOCOMOTION_ACTIONS

    out: set[tuple[str, str]] = set()
    seen: set[str] = set()
    ti = 0
    pool = [c for c in clips if c.action in LOCOMOTION_ACTIONS] or list(clips)
    for c in pool:
        if len(out) >= n:
            break
        if c.action in seen and len({x.action for x in pool}) > len(seen):
            continue
        for _ in range(len(targets)):
            t = targets[ti % len(targets)]
            ti += 1
            if t != c.species or include_self:
                out.add((c.path, t))
                seen.add(c.action)
                break
    return out


# ---------------------------------------------------------------------------- one pair


def _finite(x: Any) -> float:
    try:
        v = float(x)
    except (TypeError, ValueError):
        return math.nan
    return v if math.isfinite(v) else math.nan


def _row_base(task: PairTask) -> dict[str, Any]:
    return {
        "key": task.key,
        "method": task.method,
        "clip": task.clip,
        "source": task.source,
        "target": task.target,
        "action": task.action,
        "gait": task.gait,
        "pair_key": task.pair_key,
        "target_held_out": str(task.target_held_out).lower(),
        "status": "ok",
        "note": "",
        "refine_status": "",
        "track_status": "",
    }


class _NotAGait(Exception):
    pass


def evaluate_pair(task: PairTask) -> dict[str, Any]:
    """Run one (method, clip, target) task and return its row (plus ``features``).

    Never raises for a failure inside the pair: the row's ``status`` says what happened.
    """
    from habitsim.motion import load_motion
    from habitsim.pipeline import run_clip

    from .methods import MethodUnavailable, ground_truth_transfer

    t0 = time.perf_counter()
    c0 = time.process_time()
    row = _row_base(task)
    try:
        src = load_motion(task.clip_path)
        try:
            # transfer → refine → track: the one pipeline (habitsim.pipeline); the
            # refinement check is off so the rows measure the refinement as it is
            run = run_clip(
                src,
                task.target,
                method=task.method,
                refine=task.refine,
                controller=task.controller,
                assist=task.assist,
                seed=task.seed,
                track=task.track,
                guard=False,
            )
        except MethodUnavailable as e:
            row.update(status="unavailable", note=str(e))
            return row
        out = run.transferred.motion
        ref = run.refined.motion
        row["time_transfer_s"] = run.times["transfer"]
        row.update(_paper_metrics(task, src, out))
        try:
            gt = out if task.method == "ground_truth" else ground_truth_transfer(src, task.target)
            from .distribution import mpjpe_mm

            row["paired_mpjpe_mm"] = mpjpe_mm(out, gt)
            row["paired_mpjpe_per_leg"] = (
                row["paired_mpjpe_mm"] / 1000.0 / out.species_info.leg_length
            )
        except MethodUnavailable:
            row["paired_mpjpe_mm"] = row["paired_mpjpe_per_leg"] = math.nan
        from .biomech import biomech_metrics

        row.update(biomech_metrics(out, use_labels=False).to_dict())

        row["refine_status"] = run.refined.status
        row["time_refine_s"] = run.times["refine"]
        from .kinematic import KINEMATIC_KEYS

        row.update({k: run.refined.metrics[k] for k in KINEMATIC_KEYS})
        if task.dynamic:
            from .dynamic import dynamic_metrics

            row.update(dynamic_metrics(ref, run.model, run.refined.contacts))
        sim_res = run.track_result
        if task.track:
            row["track_status"] = run.tracked.status
            row["time_track_s"] = run.times["track"]
            if sim_res is not None:
                row.update(
                    {
                        k: (float(v) if isinstance(v, bool | int | float) else v)
                        for k, v in dict(getattr(sim_res, "metrics", {}) or {}).items()
                    }
                )
                try:
                    if not math.isfinite(_finite(row.get("biomech_score"))):
                        raise _NotAGait  # the reference is no gait (standing, sitting)
                    sim_m = sim_res.motion()
                    sb = biomech_metrics(sim_m, species=task.target, contacts=sim_m.contacts)
                    row["sim_biomech_score"] = sb.score
                    row["sim_biomech_gait"] = sb.gait
                except _NotAGait:
                    row["sim_biomech_score"] = math.nan
                    row["sim_biomech_gait"] = ""
                except Exception as e:  # noqa: BLE001
                    row["sim_biomech_score"] = math.nan
                    row["note"] = f"simulated biomech failed: {e}"
        else:
            row["track_status"] = "off"
        if task.trace:
            _write_trace(task, src, out, ref, sim_res)
    except HabitsimError as e:
        row.update(status="error", note=f"{type(e).__name__}: {e}")
    except Exception as e:  # noqa: BLE001 - recorded in the row, the run goes on
        tb = traceback.extract_tb(e.__traceback__)[-1]
        row.update(
            status="error", note=f"{type(e).__name__}: {e} ({Path(tb.filename).name}:{tb.lineno})"
        )
    row["time_total_s"] = time.perf_counter() - t0
    row["cpu_total_s"] = time.process_time() - c0
    return row


def _paper_metrics(task: PairTask, src: Motion, out: Motion) -> dict[str, Any]:
    from .distribution import transfer_mpjpe_mm
    from .evaluator import load_evaluator

    ev = load_evaluator(task.evaluator)
    p = ev.predict([out])
    known = task.target in ev.config.species
    r: dict[str, Any] = {
        "pred_species": p.species[0],
        "pred_action": p.actions[0],
        "habit_correct": float(p.species[0] == task.target) if known else math.nan,
        "action_correct": float(p.actions[0] == task.action),
        "features": [float(x) for x in p.features[0]],
        "frames": out.num_frames,
    }
    r["mpjpe_mm"] = transfer_mpjpe_mm(out, src)
    r["mpjpe_per_leg"] = r["mpjpe_mm"] / 1000.0 / out.species_info.leg_length
    return r


def _per_frame_error_mm(sim_res: Any) -> np.ndarray:
    from habitsim.qpos import qpos_joint_positions

    q = np.asarray(sim_res.qpos)
    ref = np.asarray(sim_res.reference_qpos)[: len(q)]
    a = qpos_joint_positions(sim_res.model, q)
    b = qpos_joint_positions(sim_res.model, ref)
    return np.linalg.norm(a - b, axis=-1).mean(1) * 1000.0


def _write_trace(task: PairTask, src: Motion, out: Motion, ref: Motion, sim_res: Any) -> None:
    """Contacts, tracking error and motions of a report pair (traces/<key>/)."""
    folder = Path(task.out) / "traces" / task.key
    make_dirs(folder)
    arrays: dict[str, np.ndarray] = {
        "fps": np.array(out.fps),
        "source_contacts": src.contacts if src.contacts is not None else src.detect_contacts(),
        "transferred_contacts": out.detect_contacts(),
        "reference_contacts": ref.detect_contacts(),
    }
    out.save(folder / "transferred.npz")
    if sim_res is not None:
        arrays["simulated_contacts"] = np.asarray(sim_res.contacts, bool)
        arrays["tracking_error_mm"] = _per_frame_error_mm(sim_res)
        with contextlib.suppress(Exception):
            sim_res.motion().save(folder / "simulated.npz")
        if task.videos:
            _render(sim_res, folder / "simulated.gif")
    with atomic_write(folder / "trace.npz") as fh:
        np.savez_compressed(fh, **arrays)


def _render(sim_res: Any, path: Path) -> None:
    """A small GIF of the simulated run, if rendering works here (else nothing): the
    reference as a ghost beside the body, stance feet marked."""
    from habitsim import render

    with contextlib.suppress(Exception):
        if not render.render_available():
            return
        q = np.asarray(sim_res.qpos)
        step = max(1, int(round(sim_res.fps / 15.0)))
        render.render_video(
            sim_res.model,
            q[::step],
            sim_res.fps / step,
            path,
            width=320,
            height=240,
            reference=np.asarray(sim_res.reference_qpos)[: len(q)][::step],
            contacts=np.asarray(sim_res.contacts)[::step],
            reference_contacts=np.asarray(sim_res.reference_contacts)[: len(q)][::step],
            species=sim_res.species,
        )


# ---------------------------------------------------------------------------- tables


def _row_path(out: Path, key: str) -> Path:
    return out / "rows" / f"{key}.json"


def load_rows(out: str | Path) -> list[dict[str, Any]]:
    """Every finished row of a run folder (with ``features``), sorted by key."""
    folder = Path(out) / "rows"
    rows = []
    for p in sorted(folder.glob("*.json")):
        try:
            row = json.loads(p.read_text(encoding="utf-8"))
        except (json.JSONDecodeError, UnicodeDecodeError, RecursionError, OSError) as e:
            reason = "nested too deep" if isinstance(e, RecursionError) else brief(str(e), 200)
            raise EvalError(
                f"{p}: unreadable row file ({reason}); delete it to recompute the pair"
            ) from None
        if (
            not isinstance(row, dict)
            or not isinstance(row.get("key"), str)
            or not isinstance(row.get("status"), str)
            or row["key"] != p.stem
        ):
            raise EvalError(
                f"{p}: not a row of this run (a JSON object with the string 'key' {p.stem!r} "
                "and a 'status'); delete it to recompute the pair"
            )
        rows.append(row)
    return rows


def _columns(rows: Sequence[dict[str, Any]]) -> list[str]:
    cols = [c for c in ROW_ID_COLUMNS]
    extra = sorted({k for r in rows for k in r} - set(cols) - {"features"})
    return cols + extra


def _cell(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, float):
        return "" if math.isnan(v) else repr(v)
    return str(v)


def _num(v: Any) -> float:
    return math.nan if v is None or v == "" else _finite(v)


def write_tables(out: str | Path, rows: Sequence[dict[str, Any]]) -> list[Path]:
    """Write rows.csv (and rows.parquet with pyarrow) and features.npz atomically."""
    out = Path(out)
    rows = sorted(rows, key=lambda r: r["key"])
    cols = _columns(rows)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(cols)
    for r in rows:
        w.writerow([_cell(r.get(c)) for c in cols])
    atomic_write_text(out / "rows.csv", buf.getvalue())
    written = [out / "rows.csv"]
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        pass
    else:
        data = {}
        for c in cols:
            vals = [r.get(c) for r in rows]
            if c in ROW_ID_COLUMNS or any(isinstance(v, str) for v in vals if v is not None):
                data[c] = pa.array([None if v is None else str(v) for v in vals], pa.string())
            else:
                data[c] = pa.array([_num(v) for v in vals], pa.float64())
        with atomic_write(out / "rows.parquet") as fh:
            pq.write_table(pa.table(data), fh)
        written.append(out / "rows.parquet")
    feats = [(r["key"], r["features"]) for r in rows if r.get("features")]
    # (0, 0) when no pair has features (every pair failed): a table of no rows
    features = (
        np.array([f for _, f in feats], dtype=np.float64).reshape(len(feats), -1)
        if feats
        else np.zeros((0, 0))
    )
    with atomic_write(out / "features.npz") as fh:
        np.savez_compressed(fh, keys=np.array([k for k, _ in feats], dtype=str), features=features)
    written.append(out / "features.npz")
    return written


# ---------------------------------------------------------------------------- summary


def _nanmean(vals: Sequence[float]) -> float:
    v = [x for x in vals if math.isfinite(x)]
    return float(np.mean(v)) if v else math.nan


def _reference_features(
    cfg: EvalConfig, targets: Sequence[str]
) -> tuple[np.ndarray, list[str], list[str]]:
    """Evaluator features, species and clip paths of the real clips of the targets
    (cached in the run folder)."""
    from habitsim.dataset import iter_clips

    from .evaluator import load_evaluator

    path = Path(cfg.out) / "reference_features.npz"
    ev = load_evaluator(cfg.evaluator)
    man = _manifest(cfg)
    tag = json.dumps(
        {
            "data": cfg.data,
            "seed": man.seed,
            "n": len(man.clips),
            "split": cfg.reference_split,
            "evaluator": str(ev.path),
            "targets": sorted(targets),
        },
        sort_keys=True,
    )
    if path.is_file():
        with np.load(path, allow_pickle=False) as z:
            if str(z["tag"]) == tag:
                return (z["features"], [str(s) for s in z["species"]], [str(c) for c in z["clips"]])
    motions, species, clips = [], [], []
    splits = [x.strip() for x in cfg.reference_split.split(",") if x.strip()]
    for t in sorted(targets):
        have = [sp for sp in splits if man.select(split=sp, species=t)]
        for sp in have or [None]:
            for e, m in iter_clips(man, split=sp, species=t):
                motions.append(m)
                species.append(t)
                clips.append(e.path)
    feats = ev.features(motions) if motions else np.zeros((0, ev.feature_dim))
    with atomic_write(path) as fh:
        np.savez_compressed(
            fh,
            tag=np.array(tag),
            features=feats,
            species=np.array(species, dtype=str),
            clips=np.array(clips, dtype=str),
        )
    return feats, species, clips


def summarize(
    rows: Sequence[dict[str, Any]],
    real_features: np.ndarray | None = None,
    real_species: Sequence[str] | None = None,
    real_clips: Sequence[str] | None = None,
    *,
    seed: int = 0,
    methods: Sequence[str] | None = None,
) -> dict[str, dict[str, Any]]:
    """One summary per method: set metrics (with real features) and means of its rows.

    Args:
        rows: benchmark rows (with ``features`` for the set metrics).
        real_features: (M, D) evaluator features of the real reference clips.
        real_species: (M,) their species.
        real_clips: (M,) their clip paths (unused by the metrics; kept with the features).
        seed: seed of the diversity pairs and the 1-NNA balancing.
        methods: order of the methods (default: as they appear in the rows).

    Returns:
        method → {"pairs", "ok", "unavailable", "error", set metrics…, row means…}.
    """
    from .distribution import FIDError, diversity, downstream_fid, fid, intra_fid, one_nna

    if methods is None:
        methods = list(dict.fromkeys(r["method"] for r in rows))
    numeric = sorted(
        {
            k
            for r in rows
            for k, v in r.items()
            if k not in ROW_ID_COLUMNS
            and k not in VOLATILE_COLUMNS
            and k != "features"
            and (isinstance(v, int | float) and not isinstance(v, bool) or v is None)
        }
    )
    out: dict[str, dict[str, Any]] = {}
    for m in methods:
        mr = [r for r in rows if r["method"] == m]
        ok = [r for r in mr if r["status"] == "ok"]
        s: dict[str, Any] = {
            "pairs": len(mr),
            "ok": len(ok),
            "unavailable": sum(r["status"] == "unavailable" for r in mr),
            "error": sum(r["status"] == "error" for r in mr),
        }
        for k in numeric:
            s[k] = _nanmean([_num(r.get(k)) for r in ok])
        s["habit_accuracy"] = s.pop("habit_correct", math.nan)
        s["action_accuracy"] = s.pop("action_correct", math.nan)
        for k in _SET_METRICS:
            s[k] = math.nan
        fr = [r for r in ok if r.get("features")]
        if fr and real_features is not None and len(real_features) >= 2:
            g = np.array([r["features"] for r in fr], dtype=np.float64)
            rs = list(real_species or [])
            with contextlib.suppress(FIDError):
                if len(g) >= 2:
                    s["fid"] = fid(g, real_features)
            with contextlib.suppress(FIDError):
                s["intra_fid"] = intra_fid(g, [r["target"] for r in fr], real_features, rs)
            with contextlib.suppress(FIDError):
                s["downstream_fid"] = downstream_fid(
                    g, [r["source"] for r in fr], [r["target"] for r in fr], real_features, rs
                )
            if len(g) >= 2:
                s["diversity"] = diversity(g, seed=seed)
            s["diversity_real"] = diversity(real_features, seed=seed)
            s["one_nna"] = one_nna(real_features, g, balance=True, seed=seed)
            s["real_clips"] = int(len(real_features))
        out[m] = s
    return out


def _fmt(v: Any) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "—"
    if isinstance(v, int):
        return str(v)
    a = abs(v)
    if a == 0:
        return "0"
    if a >= 100:
        return f"{v:.1f}"
    if a >= 1:
        return f"{v:.2f}"
    return f"{v:.3f}"


def format_table(
    summary: dict[str, dict[str, Any]], markdown: bool = True, controller: str | None = None
) -> str:
    """The summary in the paper's Table 1 layout plus the physical columns (and, given the
    run's tracking ``controller``, a column naming it, so tables of runs with different
    controllers can be stacked)."""
    cols = [("pairs", "pairs")] + list(TABLE1_COLUMNS) + list(PHYSICAL_COLUMNS)
    lead = ["method"] + (["controller"] if controller is not None else [])
    head = lead + [h for _, h in cols]
    tag = [controller] if controller is not None else []
    body = [[m] + tag + [_fmt(s.get(k)) for k, _ in cols] for m, s in summary.items()]
    if markdown:
        lines = [
            "| " + " | ".join(head) + " |",
            "|" + "|".join(["---"] * len(lead) + ["---:"] * len(cols)) + "|",
        ]
        lines += ["| " + " | ".join(r) + " |" for r in body]
        return "\n".join(lines)
    widths = [max(len(x[i]) for x in [head] + body) for i in range(len(head))]

    def fmt(r: list[str]) -> str:
        cells = zip(r, widths, strict=True)
        return "  ".join(c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(cells))

    return "\n".join([fmt(head)] + [fmt(r) for r in body])


def tracking_label(controller: str, assist: bool, track: bool) -> str:
    """The tracking column of a run: the controller (``+assist`` with root assistance)."""
    if not track:
        return "—"
    return controller + ("+assist" if assist else "")


def _controller_label(cfg: EvalConfig) -> str:
    return tracking_label(cfg.controller, cfg.assist, cfg.track)


def _write_summary(
    out: Path,
    summary: dict[str, dict[str, Any]],
    cfg: EvalConfig,
    wall_time_s: float,
    cpu_time_s: float = math.nan,
) -> None:
    doc = {
        "config": cfg.to_dict(),
        "wall_time_s": wall_time_s,
        # CPU seconds of every pair (all runs of a resumed benchmark); / cores ≈ wall time
        # on an otherwise idle machine
        "cpu_time_s": cpu_time_s,
        "methods": json_safe(summary),
    }
    atomic_write_text(
        out / "summary.json",
        json.dumps(
            json_safe(doc),
            indent=2,
            sort_keys=True,
        )
        + "\n",
    )
    keys = sorted({k for s in summary.values() for k in s})
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["method"] + keys)
    for m, s in summary.items():
        w.writerow([m] + [_cell(s.get(k)) for k in keys])
    atomic_write_text(out / "summary.csv", buf.getvalue())
    text = (
        f"# habitsim benchmark\n\nData `{cfg.data}`, split `{cfg.split}`, refine "
        f"`{cfg.refine}`, controller `{cfg.controller}`"
        f"{' with root assistance' if cfg.assist else ', unassisted'}.\n\n"
        + format_table(summary, controller=_controller_label(cfg))
        + "\n"
    )
    atomic_write_text(out / "summary.md", text)


# ---------------------------------------------------------------------------- run


@dataclass
class BenchmarkResult:
    """A finished (or resumed) benchmark run.

    Attributes:
        config: the run's configuration.
        rows: every row (sorted by key).
        summary: method → summary dict.
        computed: pairs evaluated by this call; skipped: pairs found done (resume).
        wall_time_s: wall time of this call [s].
        out: the output folder.
        report: paths of the written report files.
    """

    config: EvalConfig
    rows: list[dict[str, Any]]
    summary: dict[str, dict[str, Any]]
    computed: int
    skipped: int
    wall_time_s: float
    out: Path
    report: list[Path] = field(default_factory=list)

    @property
    def table_markdown(self) -> str:
        return format_table(self.summary, markdown=True, controller=_controller_label(self.config))

    @property
    def table_text(self) -> str:
        return format_table(self.summary, markdown=False, controller=_controller_label(self.config))


#: Files of a run folder written at the end of a run (checked before it starts).
_TABLE_FILES = (
    "run.json",
    "rows.csv",
    "rows.parquet",
    "features.npz",
    "reference_features.npz",
    "summary.json",
    "summary.csv",
    "summary.md",
)


def _check_outputs(out: Path, report: bool) -> None:
    """Check, before any pair runs, that the tables (and the report) of a run can be
    written: a folder named ``summary.csv`` or a read-only ``report_files/`` is an
    :class:`~habitsim.errors.OutputPathError` now, not after hours of work."""
    for name in _TABLE_FILES:
        check_writable(out / name, "--out")
    check_writable(out / "traces" / "pair" / "transferred.npz", "--out")
    if report:
        from .report import check_report_outputs

        check_report_outputs(out)


def _check_out(cfg: EvalConfig, resume: bool, overwrite: bool) -> None:
    out = Path(cfg.out)
    if out.exists() and not out.is_dir():
        raise EvalError(f"{out} exists and is not a folder")
    run = out / "run.json"
    if not run.is_file():
        if (out / "rows").is_dir() and any((out / "rows").glob("*.json")) and not overwrite:
            raise EvalError(f"{out} holds rows without run.json; pass --overwrite to start over")
        return
    if overwrite:
        for sub in ("rows", "traces", "report_files"):
            shutil.rmtree(out / sub, ignore_errors=True)
        for f in (
            "run.json",
            "rows.csv",
            "rows.parquet",
            "features.npz",
            "summary.json",
            "summary.csv",
            "summary.md",
            "report.html",
            "report.md",
            "reference_features.npz",
        ):
            try:
                (out / f).unlink()
            except FileNotFoundError:
                pass
            except OSError as e:  # a folder of that name, a read-only folder
                raise OutputPathError(
                    f"--out {brief_path(out / f)}: cannot be replaced "
                    f"({e.strerror or type(e).__name__})"
                ) from None
        return
    if not resume:
        raise EvalError(
            f"{out} already holds a benchmark run; pass --resume to continue it "
            "or --overwrite to start over"
        )
    try:
        old = json.loads(run.read_text(encoding="utf-8"))["config"]
        if not isinstance(old, dict):
            raise TypeError("'config' is not a JSON object")
    except (json.JSONDecodeError, KeyError, TypeError, UnicodeDecodeError, RecursionError) as e:
        reason = "nested too deep" if isinstance(e, RecursionError) else brief(str(e), 200)
        raise EvalError(f"{run}: unreadable ({reason}); pass --overwrite to start over") from None
    new = cfg.to_dict()
    diff = [k for k in EvalConfig.RESUME_KEYS if old.get(k) != new.get(k)]
    if diff:
        raise EvalError(
            f"cannot resume {out}: it was run with other settings ("
            + ", ".join(f"{k}: {brief(old.get(k))} → {brief(new.get(k))}" for k in diff)
            + "); use another --out or --overwrite"
        )


def run_benchmark(
    cfg: EvalConfig,
    *,
    executor: str = "local",
    workers: int | None = None,
    scheduler: str | None = None,
    resume: bool = False,
    overwrite: bool = False,
    progress: bool = True,
    report: bool = True,
    log: Callable[[str], None] | None = None,
) -> BenchmarkResult:
    """Run (or resume) a benchmark and write its tables and report.

    Args:
        cfg: the :class:`EvalConfig`.
        executor: ``local`` (process pool) or ``dask``.
        workers: local processes (default: CPU count); for ``dask`` without a scheduler,
            the size of the local cluster.
        scheduler: Dask scheduler address (``tcp://host:port``).
        resume: continue a run in ``cfg.out`` (finished pairs are skipped).
        overwrite: delete a previous run in ``cfg.out`` first.
        progress: show a tqdm progress bar with ETA.
        report: write report.html / report.md at the end.
        log: where to print progress notes (None: silent).

    Raises:
        EvalError: see the class. ExecutorError: the executor cannot start.
    """
    from .executors import make_executor

    t0 = time.perf_counter()
    _check_out(cfg, resume, overwrite)
    tasks = plan_tasks(cfg)
    out = Path(cfg.out)
    make_dirs(out / "rows", "--out")
    _check_outputs(out, report)
    atomic_write_text(
        out / "run.json",
        json.dumps(
            {
                "kind": "habitsim.benchmark",
                "format_version": RUN_FORMAT_VERSION,
                "config": cfg.to_dict(),
            },
            indent=2,
            sort_keys=True,
        )
        + "\n",
    )
    done = {}
    for r in load_rows(out):
        if r.get("status") in ("ok", "unavailable"):
            done[r["key"]] = r
    # grouped by target species (stable): a worker keeps only a few built refinement
    # problems (habitsim.refine.solve.MAX_CACHED_PROBLEMS), one per target and stage
    pending = sorted((t for t in tasks if t.key not in done), key=lambda t: t.target)
    if log:
        log(
            f"eval: {len(tasks)} pairs ({len(cfg.methods)} methods), {len(tasks) - len(pending)} "
            f"already done, {len(pending)} to run on {executor}"
        )
    ex = make_executor(executor, workers=workers, scheduler=scheduler)
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(
            total=len(tasks),
            initial=len(tasks) - len(pending),
            unit="pair",
            desc="eval",
            dynamic_ncols=True,
            smoothing=0.1,
        )
    computed = 0
    last_table = time.monotonic()
    try:
        for task, row in ex.map_unordered(evaluate_pair, pending):
            with atomic_write(_row_path(out, task.key), "w") as fh:
                json.dump(json_safe(row), fh, sort_keys=True)
            computed += 1
            if bar is not None:
                bar.update(1)
                if row["status"] == "error":
                    bar.write(f"error in {task.key}: {row['note']}")
            if time.monotonic() - last_table > 60.0:
                write_tables(out, load_rows(out))
                last_table = time.monotonic()
    finally:
        if bar is not None:
            bar.close()
        ex.close()
    keys = {t.key for t in tasks}
    rows = [r for r in load_rows(out) if r["key"] in keys]
    write_tables(out, rows)
    targets = sorted({t.target for t in tasks})
    real, real_sp, real_clips = _reference_features(cfg, targets)
    summary = summarize(rows, real, real_sp, real_clips, seed=cfg.seed, methods=cfg.methods)
    wall = time.perf_counter() - t0
    cpu = float(sum(_num(r.get("cpu_total_s")) for r in rows if r.get("cpu_total_s") is not None))
    _write_summary(out, summary, cfg, wall, cpu)
    res = BenchmarkResult(cfg, rows, summary, computed, len(tasks) - len(pending), wall, out)
    if report:
        from .report import write_report

        res.report = write_report(out)
    return res
