"""``habitsim bench t2m``: the text-to-motion protocol (the benchmark is
:mod:`habitsim.evaluation.bench.t2m`). Prints R-precision top-1/2/3, FID, MM-Dist and
diversity with the ground truth as the top row, then the generator per guidance scale,
and the targets; ``--json`` prints one object."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from .conventions import add_check_option, check_exit


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``t2m`` to the ``bench`` command group."""
    p = sub.add_parser(
        "t2m",
        help="text to motion: R-precision, FID, MM-Dist, diversity (ground truth first)",
        description=(
            "Measure the real clips of a captioned data set's split and the text-to-motion "
            "generator at each guidance scale with a text–motion evaluator "
            "(habitsim t2m train-evaluator): R-precision top-1/2/3 in batches of 32, FID "
            "against the real train clips, MM-Dist and diversity."
        ),
    )
    p.add_argument(
        "--evaluator", required=True, type=Path, metavar="DIR", help="text–motion evaluator"
    )
    p.add_argument("--checkpoint", type=Path, metavar="CKPT", help="text-to-motion checkpoint")
    p.add_argument(
        "--data",
        type=Path,
        metavar="DIR",
        help="captioned data set (default: the checkpoint's code set's data set)",
    )
    p.add_argument(
        "--guidance",
        type=float,
        nargs="+",
        default=[1.0, 2.0, 3.0],
        metavar="G",
        help="guidance scales of the generator rows (default 1 2 3)",
    )
    p.add_argument("--split", default="val", help="split whose captions are measured (val)")
    p.add_argument(
        "--batch-size", type=int, default=32, metavar="B", help="R-precision batch (default 32)"
    )
    p.add_argument("--limit", type=int, metavar="N", help="measure at most N clips")
    p.add_argument("--seed", type=int, default=0, metavar="S", help="seed (default 0)")
    p.add_argument("--json", action="store_true", help="print the figures as one JSON object")
    add_check_option(p)
    p.set_defaults(func=_bench_t2m)


def _bench_t2m(ns: argparse.Namespace) -> int:
    from ..evaluation.bench.t2m import T2MBenchOptions, run_t2m, t2m_checks

    opts = T2MBenchOptions(
        guidances=tuple(ns.guidance),
        split=ns.split,
        batch_size=ns.batch_size,
        limit=ns.limit,
        seed=ns.seed,
    )
    res = run_t2m(ns.evaluator, data=ns.data, checkpoint=ns.checkpoint, options=opts)
    checks = t2m_checks(res, opts)
    if ns.json:
        print(json.dumps({**res.to_dict(), "targets": [t.to_dict() for t in checks]}))
    else:
        print(
            f"{res.data} ({res.split}): {res.rows[0].clips} clips, R-precision in "
            f"{res.batches} batch(es) of {opts.batch_size}; evaluator {res.evaluator}"
        )
        print(
            f"  {'':22s} {'top-1':>6s} {'top-2':>6s} {'top-3':>6s} {'FID':>8s} "
            f"{'MM-Dist':>8s} {'diversity':>9s}"
        )
        for r in res.rows:
            name = r.name if r.guidance is None else f"{r.name} (g={r.guidance:g})"
            rp = " ".join(f"{v:6.3f}" for v in r.r_precision[:3])
            print(f"  {name:22s} {rp} {r.fid:8.4f} {r.mm_dist:8.4f} {r.diversity:9.4f}")
        for t in checks:
            print(f"  {t.name}: {t.shown} (target {t.target}) {t.verdict}")
    return check_exit([t.name for t in checks if t.verdict == "MISSED"], ns.check)
