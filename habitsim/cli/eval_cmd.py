"""``habitsim eval``: the benchmark runner (see :mod:`habitsim.evaluation.runner`).

Default benchmark (every validation clip to every other training species, kinematic
refinement, unassisted tracking)::

    habitsim data synth --out /tmp/hs_default --clips-per-species 40 --seed 0
    habitsim eval --data /tmp/hs_default --methods direct,ground_truth --out bench

Writes ``bench/rows.csv`` (+ ``rows.parquet``), ``summary.md`` / ``summary.json`` and
``report.html`` / ``report.md``; prints the summary table. An interrupted run continues
with ``--resume``. ``--executor dask --scheduler tcp://HOST:8786`` runs the pairs on a
Dask cluster (see :mod:`habitsim.evaluation.executors` for starting one).
``habitsim eval --report-only --out bench`` rewrites the report of a finished run.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence

from .conventions import add_list_option, split_names


def _csv(text: str | Sequence[str] | None) -> tuple[str, ...] | None:
    return tuple(split_names(text)) or None


def register(sub: argparse._SubParsersAction) -> None:
    """Add the top-level ``eval`` command."""
    from ..controllers import CONTROLLERS

    p = sub.add_parser(
        "eval",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=(
            "Dask cluster (every machine with the same habitsim install and the data/out\n"
            "folders on a shared file system):\n"
            "  dask scheduler --host 0.0.0.0 --port 8786\n"
            "  dask worker tcp://HEAD:8786 --nworkers 2 --nthreads 1     # per machine\n"
            "  habitsim eval --data DIR --out OUT --executor dask --scheduler tcp://HEAD:8786\n"
            "(--executor dask without --scheduler starts a local cluster of --workers.)"
        ),
        help="benchmark transfer methods: transfer → refine → track → every metric",
        description=(
            "For every (validation clip, target species) pair and every method: transfer, "
            "refine, track in MuJoCo and compute every docs/metrics.md metric; one row per pair, "
            "a summary in the paper's Table 1 layout and an HTML/Markdown report."
        ),
    )
    p.add_argument("--data", metavar="DIR", help="synthetic data set folder")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    add_list_option(p, "--methods", default=["direct", "ground_truth"], metavar="METHOD",
                    help="methods (default direct,ground_truth)")
    p.add_argument(
        "--refine",
        default="kinematic",
        choices=("none", "kinematic", "dynamics"),
        help="refinement before tracking (default kinematic)",
    )
    p.add_argument(
        "--controller",
        default="servo",
        choices=CONTROLLERS,
        metavar="NAME",
        help=f"tracking controller: {', '.join(CONTROLLERS)} (default servo)",
    )
    p.add_argument("--assist", action="store_true", help="track with root assistance")
    p.add_argument("--no-track", action="store_true", help="skip the MuJoCo tracking")
    p.add_argument("--no-dynamic", action="store_true", help="skip the inverse-dynamics metrics")
    p.add_argument("--split", default="val", help="split of the source clips (default val)")
    add_list_option(p, "--sources", metavar="SPECIES", help="only these source species")
    add_list_option(p, "--targets", metavar="SPECIES",
                    help="target species (default: the data set's training species)")
    p.add_argument(
        "--reference-split",
        default="train,val",
        metavar="S1,S2",
        help="splits of the real clips the set metrics compare with (default train,val)",
    )
    p.add_argument(
        "--include-self", action="store_true", help="also transfer clips to their own species"
    )
    p.add_argument("--max-clips", type=int, metavar="N", help="only the first N source clips")
    p.add_argument("--evaluator", metavar="DIR", help="evaluator folder (default: the shipped one)")
    p.add_argument("--seed", type=int, default=0, metavar="S", help="seed (default 0)")
    p.add_argument(
        "--executor",
        default="local",
        choices=("local", "dask"),
        help="where pairs run (default local process pool)",
    )
    p.add_argument("--scheduler", metavar="ADDR", help="Dask scheduler address (tcp://host:port)")
    p.add_argument(
        "--workers",
        type=int,
        metavar="N",
        help="local worker processes (default: CPU count; 1 = in-process)",
    )
    p.add_argument("--resume", action="store_true", help="continue a run in OUT")
    p.add_argument("--overwrite", action="store_true", help="delete a run in OUT first")
    p.add_argument(
        "--report-pairs",
        type=int,
        default=3,
        metavar="N",
        help="pairs per method with gait diagrams / tracking curves (default 3)",
    )
    p.add_argument("--no-videos", action="store_true", help="do not render videos")
    p.add_argument("--no-report", action="store_true", help="do not write the HTML/Markdown report")
    p.add_argument(
        "--report-only",
        action="store_true",
        help="only rewrite the report of the finished run in OUT",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_eval)


def _eval(ns: argparse.Namespace) -> int:
    from ..evaluation.runner import EvalConfig, EvalError, run_benchmark

    if ns.report_only:
        from ..evaluation.report import write_report

        for path in write_report(ns.out):
            print(path)
        return 0
    if not ns.data:
        raise EvalError("--data is required (unless --report-only)")
    cfg = EvalConfig(
        data=ns.data,
        out=ns.out,
        methods=_csv(ns.methods) or (),
        refine=ns.refine,
        controller=ns.controller,
        assist=ns.assist,
        track=not ns.no_track,
        dynamic=not ns.no_dynamic,
        split=ns.split,
        sources=_csv(ns.sources),
        targets=_csv(ns.targets),
        include_self=ns.include_self,
        reference_split=ns.reference_split,
        max_clips=ns.max_clips,
        evaluator=ns.evaluator,
        seed=ns.seed,
        report_pairs=ns.report_pairs,
        videos=not ns.no_videos,
    )
    res = run_benchmark(
        cfg,
        executor=ns.executor,
        workers=ns.workers,
        scheduler=ns.scheduler,
        resume=ns.resume,
        overwrite=ns.overwrite,
        progress=not ns.no_progress,
        report=not ns.no_report,
        log=print,
    )
    print(res.table_text)
    errors = sum(s["error"] for s in res.summary.values())
    print(
        f"\n{len(res.rows)} rows ({res.computed} computed, {res.skipped} resumed, "
        f"{errors} errors) in {res.wall_time_s:.1f} s → {res.out}"
    )
    for path in res.report:
        print(f"report: {path}")
    return 0
