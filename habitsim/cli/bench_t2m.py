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
    from .conventions import add_list_option

    add_list_option(
        p,
        "--splits",
        default=["val", "compose", "paraphrase", "human"],
        choices=("val", "train", "compose", "paraphrase", "human"),
        metavar="SPLIT",
        help="splits measured (default val compose paraphrase human; compose needs --checkpoint)",
    )
    p.add_argument(
        "--physics",
        type=int,
        default=0,
        metavar="N",
        help="also refine and track (unassisted, mpc) N generated walks, trots and turns "
        "per split and print their survival (default 0)",
    )
    p.add_argument(
        "--unsupported",
        type=int,
        default=40,
        metavar="N",
        help="human prompts outside the test answered to check the warning / refusal "
        "path (default 40; 0: none)",
    )
    p.add_argument(
        "--batch-size", type=int, default=32, metavar="B", help="R-precision batch (default 32)"
    )
    p.add_argument("--limit", type=int, metavar="N", help="measure at most N clips")
    p.add_argument("--seed", type=int, default=0, metavar="S", help="seed (default 0)")
    p.add_argument("--json", action="store_true", help="print the figures as one JSON object")
    add_check_option(p)
    p.set_defaults(func=_bench_t2m)


def _bench_t2m(ns: argparse.Namespace) -> int:
    import math

    from ..evaluation.bench.t2m import T2MBenchOptions, run_t2m, t2m_checks

    opts = T2MBenchOptions(
        guidances=tuple(ns.guidance),
        splits=tuple(ns.splits),
        batch_size=ns.batch_size,
        limit=ns.limit,
        seed=ns.seed,
        physics=ns.physics,
        unsupported=ns.unsupported,
    )
    res = run_t2m(ns.evaluator, data=ns.data, checkpoint=ns.checkpoint, options=opts)
    checks = t2m_checks(res, opts)
    if ns.json:
        print(json.dumps({**res.to_dict(), "targets": [t.to_dict() for t in checks]}))
        return check_exit([t.name for t in checks if t.verdict == "MISSED"], ns.check)

    def f(v: float, spec: str) -> str:
        return "—".rjust(len(format(0.0, spec))) if math.isnan(v) else format(v, spec)

    print(
        f"{res.data}: R-precision in batches of {opts.batch_size} (— : fewer prompts, or "
        f"no real motion); evaluator {res.evaluator}"
    )
    print(
        f"  {'split':10s} {'':22s} {'n':>4s} {'top-1':>6s} {'top-2':>6s} {'top-3':>6s} "
        f"{'FID':>8s} {'MM-Dist':>8s} {'diversity':>9s} {'agree':>6s}"
    )
    for r in res.rows:
        name = r.name if r.guidance is None else f"{r.name} (g={r.guidance:g})"
        rp = " ".join(f(v, "6.3f") for v in r.r_precision[:3])
        print(
            f"  {r.split:10s} {name:22s} {r.clips:4d} {rp} {f(r.fid, '8.4f')} "
            f"{f(r.mm_dist, '8.4f')} {f(r.diversity, '9.4f')} {f(r.prompt_agreement, '6.3f')}"
        )
    for p in res.physics:
        print(
            f"  physics {p.split}: {p.clips} walks/trots/turns refined and tracked "
            f"{opts.physics_seconds:g} s under mpc: {p.survived:.2f} survived "
            f"(mean survival {p.mean_survival:.2f}; {p.refused} refused)"
        )
    if (u := res.unsupported) is not None:
        print(
            f"  human prompts outside the test: {u.prompts} answered: {u.refused} refused, "
            f"{u.warned} with a warning, {u.silent} without one"
        )
    for t in checks:
        print(f"  {t.name}: {t.shown} (target {t.target}) {t.verdict}")
    return check_exit([t.name for t in checks if t.verdict == "MISSED"], ns.check)
