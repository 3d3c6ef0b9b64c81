"""``habitsim eval``: the benchmark runner (see :mod:`habitsim.evaluation.runner`).

With no options, ``habitsim eval`` measures the product: the methods ``habit`` (the
shipped model), ``direct`` and ``ground_truth``, refinement stage A (``kinematic``) and
unassisted tracking with the ``mpc`` controller, on a synthetic data set it builds in
``eval_out/data`` (20 clips per species, seed 0; reused by later runs): the first
validation clip of each training species to cat, horse and camel, 99 pairs, sized to
finish within 20 min on 2 cores. The whole benchmark (every validation clip to every
other training species) of a data set of your own::

    habitsim data synth --out /tmp/hs_default --clips-per-species 40 --seed 0
    habitsim eval --data /tmp/hs_default --targets all --clips-per-source all --out bench

Writes ``bench/rows.csv`` (+ ``rows.parquet``), ``summary.md`` / ``summary.json`` and
``report.html`` / ``report.md``; prints the summary table. An interrupted run continues
with ``--resume``. ``--executor dask --scheduler tcp://HOST:8786`` runs the pairs on a
Dask cluster (see :mod:`habitsim.evaluation.executors` for starting one).
``habitsim eval --report-only --out bench`` rewrites the report of a finished run.

Another method joins the table by ``--method NAME=DIR`` (a folder of its outputs,
``DIR/<target>/<clip_id>.npz`` or ``.bvh``: :mod:`habitsim.evaluation.outputs`) or as a
plugin (an installed package's entry point in the ``habitsim.methods`` group, listed in
``--methods``' help). A run with any pair in error exits with code 1.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from ..evaluation.runner import (
    DEFAULT_CLIPS_PER_SOURCE,
    DEFAULT_CONTROLLER,
    DEFAULT_DATA_CLIPS_PER_SPECIES,
    DEFAULT_METHODS,
    DEFAULT_TARGETS,
)
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
            "  dask scheduler --host HEAD --port 8786   # HEAD: a private address (no auth)\n"
            "  dask worker tcp://HEAD:8786 --nworkers 2 --nthreads 1     # per machine\n"
            "  habitsim eval --data DIR --out OUT --executor dask --scheduler tcp://HEAD:8786\n"
            "(--executor dask without --scheduler starts a local cluster of --workers.)"
        ),
        help="benchmark transfer methods: transfer → refine → track → every metric",
        description=(
            "For every (validation clip, target species) pair and every method: transfer, "
            "refine, track in MuJoCo and compute every docs/metrics.md metric; one row per pair, "
            "a summary in the paper's Table 1 layout and an HTML/Markdown report. With no "
            "options it measures the product: habit, direct and ground_truth, refinement "
            "stage A and the mpc controller unassisted, on a synthetic data set built in "
            "OUT/data, the first validation clip of every training species to cat, horse and "
            "camel (99 pairs)."
        ),
    )
    p.add_argument(
        "--data",
        metavar="DIR",
        help="synthetic data set folder (default: build OUT/data, "
        f"{DEFAULT_DATA_CLIPS_PER_SPECIES} clips per species, seed 0)",
    )
    p.add_argument(
        "--out", default="eval_out", metavar="DIR", help="output folder (default eval_out)"
    )
    from ..transfer_methods import method_names

    add_list_option(
        p,
        "--methods",
        default=list(DEFAULT_METHODS),
        metavar="METHOD",
        help=f"methods (default {','.join(DEFAULT_METHODS)}; registered: "
        f"{', '.join(method_names())})",
    )
    p.add_argument(
        "--method",
        action="append",
        default=[],
        dest="method_outputs",
        metavar="NAME=DIR",
        help="another method's outputs, DIR/<target>/<clip_id>.npz (or .bvh), put in the "
        "table as NAME (repeatable)",
    )
    p.add_argument(
        "--refine",
        default="kinematic",
        choices=("none", "kinematic", "dynamics"),
        help="refinement before tracking (default kinematic: stage A)",
    )
    p.add_argument(
        "--controller",
        default=DEFAULT_CONTROLLER,
        choices=CONTROLLERS,
        metavar="NAME",
        help=f"tracking controller: {', '.join(CONTROLLERS)} (default {DEFAULT_CONTROLLER}; "
        "servo has no balance and falls within about a second)",
    )
    p.add_argument("--assist", action="store_true", help="track with root assistance")
    p.add_argument("--no-track", action="store_true", help="skip the MuJoCo tracking")
    p.add_argument("--no-dynamic", action="store_true", help="skip the inverse-dynamics metrics")
    p.add_argument("--split", default="val", help="split of the source clips (default val)")
    add_list_option(p, "--sources", metavar="SPECIES", help="only these source species")
    add_list_option(
        p,
        "--targets",
        default=list(DEFAULT_TARGETS),
        metavar="SPECIES",
        help=f"target species (default {','.join(DEFAULT_TARGETS)}; "
        "'all': the data set's training species)",
    )
    p.add_argument(
        "--clips-per-source",
        default=str(DEFAULT_CLIPS_PER_SOURCE),
        metavar="N",
        help=f"first N validation clips of each source species (default "
        f"{DEFAULT_CLIPS_PER_SOURCE}; 'all': every clip)",
    )
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
    p.add_argument(
        "--method-timeout",
        type=float,
        metavar="S",
        help="stop a transfer method's call after S seconds: its row fails (default: no limit)",
    )
    p.add_argument(
        "--retries",
        type=int,
        default=2,
        metavar="N",
        help="run a pair whose worker process died (e.g. out of memory) again up to N times "
        "before its row fails (default 2)",
    )
    p.add_argument(
        "--follow-symlinks",
        action="store_true",
        help="read clips through links in --data that lead out of it (refused by default)",
    )
    p.add_argument("--resume", action="store_true", help="continue a run in OUT")
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="delete a run in OUT first (only the files habitsim wrote there)",
    )
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
    targets = _csv(ns.targets)
    if targets is not None and [t.lower() for t in targets] == ["all"]:
        targets = None  # the data set's training species
    cps = str(ns.clips_per_source).strip().lower()
    if cps == "all":
        clips_per_source = None
    else:
        try:
            clips_per_source = int(cps)
        except ValueError:
            raise EvalError(
                f"--clips-per-source must be a whole number >= 1 or 'all', got "
                f"{ns.clips_per_source!r}"
            ) from None
    from ..evaluation.outputs import parse_method_outputs

    outputs = [parse_method_outputs(text) for text in ns.method_outputs]
    data = ns.data
    if not data:
        from ..evaluation.runner import default_data

        data = str(default_data(ns.out, workers=ns.workers, progress=not ns.no_progress, log=print))
    cfg = EvalConfig(
        data=data,
        out=ns.out,
        methods=_csv(ns.methods) or (),
        refine=ns.refine,
        controller=ns.controller,
        assist=ns.assist,
        track=not ns.no_track,
        dynamic=not ns.no_dynamic,
        split=ns.split,
        sources=_csv(ns.sources),
        targets=targets,
        include_self=ns.include_self,
        reference_split=ns.reference_split,
        max_clips=ns.max_clips,
        clips_per_source=clips_per_source,
        evaluator=ns.evaluator,
        seed=ns.seed,
        report_pairs=ns.report_pairs,
        videos=not ns.no_videos,
        outputs=tuple((o.name, o.folder) for o in outputs),
        follow_symlinks=ns.follow_symlinks,
        method_timeout_s=ns.method_timeout,
        worker_retries=ns.retries,
    )
    if outputs:
        from ..evaluation.outputs import dataset_clip_ids, stray_outputs

        clip_ids = dataset_clip_ids(cfg.data)
        for o in outputs:
            stray = stray_outputs(o, clip_ids)
            if stray:
                print(
                    f"warning: {o.name}: {len(stray)} file(s) under {o.folder} follow no pair "
                    f"of this run (DIR/<target>/<clip_id>.npz|.bvh), not read: "
                    + ", ".join(stray[:10])
                    + (" …" if len(stray) > 10 else ""),
                    file=sys.stderr,
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
    if errors:
        for r in res.rows:
            if r.get("status") == "error":
                print(f"error in {r['key']}: {r.get('note', '')}", file=sys.stderr)
    return 1 if errors else 0
