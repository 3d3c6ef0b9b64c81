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

1. **transfer** with the method (:mod:`habitsim.transfer_methods`); a method that
   cannot serve the pair gives a row with ``status = "unavailable"``;
2. the paper's metrics on the transferred motion: evaluator features (kept for the set
   metrics) and predictions (``habit_correct``: predicted species = target, NaN for a
   target the evaluator has no class for; ``action_correct``: predicted action = the
   source's action), ``mpjpe_mm`` against the source scaled to the target's size and
   ``paired_mpjpe_mm`` against ``generate(target, like=source)``, and the
   biomechanical consistency (:mod:`habitsim.metrics.biomech`) against the target's
   gait table, from foot contacts detected on the geometry (every method alike);
3. **refine** with :func:`habitsim.refine.refine` (``--refine kinematic|dynamics``,
   with ``fallback``: a failed solve keeps the input and says so in ``refine_status``).
   Stance phases are the transfer's labels (``direct``: the source's; ``ground_truth``:
   the planned stance; the learned methods:
   :func:`habitsim.stance.schedule.transfer_contacts`), found by the transfer stage
   when a method sets none;
4. kinematic (:mod:`~habitsim.metrics.kinematic`) and dynamic
   (:mod:`~habitsim.metrics.dynamic`) plausibility of the reference that is tracked
   (the refined motion, or the transferred one);
5. **track** it with :func:`habitsim.sim.track` (unassisted by default; the reference
   contact labels are the refined ones): the simulated
   metrics of docs/metrics.md, and the biomechanical score of the simulated motion from its
   simulated foot contacts (``sim_biomech_score``; NaN when the transferred motion is
   no gait, e.g. a sit).

A failure inside a pair (a typed habitsim error or a bug) becomes ``status = "error"``
with the message in ``note``; the benchmark goes on and ``--resume`` retries it.

Output folder (claimed with :func:`habitsim.folders.claim_output_folder`: one run at a
time, ``--overwrite`` removes only the files habitsim wrote there)::

    .habitsim-written          the record of every file habitsim wrote in the folder
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
splits, default ``train,val`` (the test split stays reserved). With only the ``val`` clips
the action mix would match the sources exactly, but the default data set has only a few
per species, too few for a 32-dimensional Gaussian fit and below the 5 samples
``downstream_fid`` requires; with ``test`` the action mix differs. Per-target metrics only
ever see real clips of the target species, so a clip is never compared with itself there.
The pooled metrics (``fid``, ``one_nna``) are unconditional, as in the paper: they compare
motion distributions whatever the species, and the validation sources are real clips of
that same pool, so a method that returns its input nearly unchanged (``direct``) scores
well on them; ``intra_fid``, ``downstream_fid`` and ``habit_accuracy`` are the
species-conditional measures. FID over all pairs; Intra-FID per target species; downstream
FID per (source, target) species pair; diversity of the transferred features beside
``diversity_real`` of the reference; 1-NNA on class-balanced sets (the larger set
subsampled with a fixed seed). Every other summary column is the mean of the method's
``ok`` rows that have a finite value (``habit_accuracy`` = mean of ``habit_correct``,
``action_accuracy`` = mean of ``action_correct``).

The runner's pieces, one concept per module (every public name is re-exported here):
:mod:`~habitsim.evaluation.config` (:class:`EvalConfig`, :class:`PairTask`, the
defaults), :mod:`~habitsim.evaluation.planning` (:func:`default_data`,
:func:`plan_tasks`), :mod:`~habitsim.evaluation.pairs` (:func:`evaluate_pair`),
:mod:`~habitsim.evaluation.tables` (rows and the Table 1 layout),
:mod:`~habitsim.evaluation.summary` (:func:`summarize`); this module runs them
(:func:`run_benchmark`).
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from habitsim.errors import OutputWriteError, brief, brief_path
from habitsim.fileio import atomic_write, atomic_write_text, check_writable, json_safe, make_dirs
from habitsim.folders import claim_output_folder
from habitsim.jsonfile import load_json

from .config import (
    DEFAULT_CLIPS_PER_SOURCE,
    DEFAULT_CONTROLLER,
    DEFAULT_METHODS,
    DEFAULT_TARGETS,
    REFINE_MODES,
    RUN_FORMAT_VERSION,
    EvalConfig,
    EvalError,
    PairTask,
)
from .pairs import evaluate_pair, lost_row
from .planning import DEFAULT_DATA_CLIPS_PER_SPECIES, default_data, plan_tasks
from .summary import _controller_label, _reference_features, _write_summary, summarize
from .tables import (
    PHYSICAL_COLUMNS,
    ROW_ID_COLUMNS,
    TABLE1_COLUMNS,
    VOLATILE_COLUMNS,
    _num,
    _row_path,
    format_table,
    load_rows,
    write_tables,
)

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


def _check_resume(cfg: EvalConfig) -> None:
    """On ``--resume``, refuse a run folder whose ``run.json`` is unreadable or records
    other settings (see :attr:`EvalConfig.RESUME_KEYS`)."""
    out = Path(cfg.out)
    run = out / "run.json"
    if not run.is_file():
        return
    try:
        doc = load_json(run, "run file", error=EvalError)
    except EvalError as e:
        raise EvalError(f"{e}; pass --overwrite to start over") from None
    old = doc.get("config") if isinstance(doc, dict) else None
    if not isinstance(old, dict):
        raise EvalError(f"{run}: no 'config' object; pass --overwrite to start over")
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
        overwrite: delete a previous run in ``cfg.out`` first: only the files habitsim
            wrote there (:func:`habitsim.folders.claim_output_folder`).
        progress: show a tqdm progress bar with ETA.
        report: write report.html / report.md at the end.
        log: where to print progress notes (None: silent).

    Raises:
        EvalError: see the class. ExecutorError: the executor cannot start.
        OutputFolderError: ``cfg.out`` holds files habitsim did not write, or an earlier
            run without ``resume`` / ``overwrite``.
        OutputBusyError: another run is writing into ``cfg.out``.
        OutputWriteError: an output failed while being written (a full disk); the rows
            already written stay, ``resume`` continues.
    """

    t0 = time.perf_counter()
    out = Path(cfg.out)
    if out.exists() and not out.is_dir():
        raise EvalError(f"{out} exists and is not a folder")
    tasks = plan_tasks(cfg)
    with claim_output_folder(
        out, command="eval", overwrite=overwrite, resume=resume, log=log
    ) as claim:
        if claim.earlier is not None:
            _check_resume(cfg)
        try:
            return _run(cfg, tasks, t0, executor, workers, scheduler, progress, report, log)
        except OutputWriteError as e:  # a full disk: the finished rows stay
            raise OutputWriteError(
                f"{e}. The pairs already evaluated are kept in {brief_path(out / 'rows')}; "
                "once the output can be written, run again with --resume to continue"
            ) from None


def _run(
    cfg: EvalConfig,
    tasks: list[PairTask],
    t0: float,
    executor: str,
    workers: int | None,
    scheduler: str | None,
    progress: bool,
    report: bool,
    log: Callable[[str], None] | None,
) -> BenchmarkResult:
    """:func:`run_benchmark` in its claimed output folder."""
    from .executors import ExecutorOptions, TaskLost, make_executor

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
    # problems (habitsim.refine.cache.MAX_CACHED_PROBLEMS), one per target and stage
    pending = sorted((t for t in tasks if t.key not in done), key=lambda t: t.target)
    if log:
        log(
            f"eval: {len(tasks)} pairs ({len(cfg.methods)} methods), {len(tasks) - len(pending)} "
            f"already done, {len(pending)} to run on {executor}"
        )
    options = ExecutorOptions(retries=cfg.worker_retries, log=log)
    ex = make_executor(executor, workers=workers, scheduler=scheduler, options=options)
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
            if isinstance(row, TaskLost):  # its worker died every time: a failed row
                row = lost_row(task, row.note)
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
