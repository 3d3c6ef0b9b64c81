"""``habitsim bench oneshot``: a species' habits from one to a few of its clips (the
benchmark is :mod:`habitsim.evaluation.bench.oneshot`). Prints, per column (retrieval,
K = 1, 3, 10, oracle), the paired MPJPE, footfall and duty-factor errors, FID, Intra-FID,
1-NNA, habit accuracy and the physics figures, then the real references' rows and the
targets; ``--json`` prints one object."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Any

from .conventions import add_check_option, add_list_option, check_exit, format_legend

_LEGEND = (
    "paired / pose: MPJPE against generate(target, like=source), whole / root-relative, "
    "% of leg length; phase: median footfall phase error [cycle]; duty: mean |duty factor "
    "error|; habit: the evaluator names the target; surv / sim: mean survival and median "
    "sim MPJPE per leg length of the physics runs (refine + tracking)"
)


_GROUPS = {
    "all": "every species",
    "trained": "species the checkpoint trained on (treated as unseen; oracle: its own prior)",
    "held out": "species the checkpoint holds out (no oracle)",
}


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``oneshot`` to the ``bench`` command group."""
    from ..evaluation.bench.oneshot import DEFAULT_SPECIES

    p = sub.add_parser(
        "oneshot",
        help="habits from one to a few clips of a species vs retrieval and the oracle",
        description=(
            "Treat each species as unseen and transfer clips of the other species onto it "
            "with the habit latent of its retrieval neighbour, of K of its own clips "
            "(habit_from), and of its own prior (the oracle, training species only); score "
            "them against the paired ground truth, with the evaluator and (--physics) in "
            "MuJoCo. Real clips (--real-dog, --fox) give the evaluator and physics columns."
        ),
    )
    add_list_option(
        p,
        "--species",
        default=list(DEFAULT_SPECIES),
        metavar="SPECIES",
        help=f"species taken as unseen (default {','.join(DEFAULT_SPECIES)})",
    )
    add_list_option(
        p, "--k", default=[1, 3, 10], metavar="K", convert=int, help="reference clips (1 3 10)"
    )
    p.add_argument(
        "--sources-per-species",
        type=int,
        default=0,
        metavar="N",
        help="sources per species (0: all, one per other species)",
    )
    p.add_argument("--seconds", type=float, default=4.0, metavar="S", help="clip length (4)")
    p.add_argument("--seed", type=int, default=7000, metavar="S", help="first source seed (7000)")
    p.add_argument(
        "--reference-seed", type=int, default=9000, metavar="S", help="first reference seed (9000)"
    )
    p.add_argument(
        "--habit-steps",
        type=int,
        metavar="N",
        help="fit steps (default the fit's; 0: encoder mean)",
    )
    p.add_argument(
        "--prior-weight", type=float, metavar="W", help="fit prior weight (default the fit's)"
    )
    p.add_argument(
        "--habit-objective",
        choices=("frames", "stats"),
        help="what the fit compares (default the fit's)",
    )
    p.add_argument(
        "--fit-text",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="also fit the text embedding as a mix of the species' own and the training "
        "species' (default the fit's)",
    )
    p.add_argument(
        "--physics",
        type=int,
        default=0,
        metavar="N",
        help="sources per species and column also refined and tracked (default 0)",
    )
    p.add_argument("--controller", default="mpc", help="controller of the physics runs (mpc)")
    p.add_argument("--refine", default="A", help="refinement of the physics runs (A)")
    p.add_argument("--real-dog", type=Path, metavar="BVH", help="a real dog clip: 'a new dog'")
    p.add_argument(
        "--real-dog-span",
        type=float,
        nargs=2,
        metavar=("START", "END"),
        help="seconds of --real-dog kept (default 0 4)",
    )
    p.add_argument("--fox", type=Path, metavar="GLB", help="the fox glTF (its Walk)")
    p.add_argument(
        "--real-sources", type=int, default=8, metavar="N", help="sources per real clip (8)"
    )
    p.add_argument("--checkpoint", type=Path, metavar="DIR", help="model (default: shipped)")
    p.add_argument("--json", action="store_true", help="print the figures as one JSON object")
    add_check_option(p)
    p.set_defaults(func=_bench_oneshot)


def _f(x: Any, fmt: str) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "-".rjust(int(fmt.split(".")[0]))
    return format(x, fmt)


def _table(summaries: dict[str, dict[str, float]], title: str) -> None:
    print(title)
    print(
        f"  {'column':10s} {'pairs':>5s} {'paired':>7s} {'pose':>6s} {'phase':>6s} {'duty':>6s} "
        f"{'FID':>7s} {'iFID':>7s} {'1-NNA':>6s} {'habit':>6s} {'surv':>5s} {'sim':>6s}"
    )
    for col, s in summaries.items():
        if not s["pairs"]:
            continue
        print(
            f"  {col:10s} {int(s['pairs']):5d} {_f(s['paired_pct'], '7.2f')} "
            f"{_f(s['pose_pct'], '6.2f')} {_f(s['phase_error'], '6.3f')} "
            f"{_f(s['duty_error'], '6.3f')} {_f(s.get('fid'), '7.2f')} "
            f"{_f(s.get('intra_fid'), '7.2f')} {_f(s.get('one_nna'), '6.3f')} "
            f"{_f(s['habit_accuracy'], '6.3f')} {_f(s['survival'], '5.2f')} "
            f"{_f(s['sim_mpjpe_per_leg'], '6.3f')}"
        )


def _bench_oneshot(ns: argparse.Namespace) -> int:
    from dataclasses import replace

    from ..evaluation.bench.oneshot import (
        OneshotOptions,
        RealReference,
        oneshot_checks,
        run_oneshot,
    )
    from ..models.habit_fit import HabitFitOptions

    fit = HabitFitOptions()
    if ns.habit_steps is not None:
        fit = replace(fit, steps=ns.habit_steps, method="fit" if ns.habit_steps else "encoder")
    if ns.prior_weight is not None:
        fit = replace(fit, prior_weight=ns.prior_weight)
    if ns.habit_objective is not None:
        fit = replace(fit, objective=ns.habit_objective)
    if ns.fit_text is not None:
        fit = replace(fit, fit_text=ns.fit_text)
    real = []
    if ns.real_dog is not None:
        a, b = ns.real_dog_span or (0.0, 4.0)
        real.append(RealReference("labrador", ns.real_dog, "dog", start_s=a, end_s=b))
    if ns.fox is not None:
        real.append(RealReference("fox glTF", ns.fox, "fox", animation="Walk", loop_s=ns.seconds))
    opts = OneshotOptions(
        species=tuple(ns.species),
        ks=tuple(ns.k),
        sources=ns.sources_per_species,
        duration_s=ns.seconds,
        seed=ns.seed,
        reference_seed=ns.reference_seed,
        fit=fit,
        physics=ns.physics,
        controller=ns.controller,
        refine=ns.refine,
        real=tuple(real),
        real_sources=ns.real_sources,
        checkpoint=ns.checkpoint,
    )
    res = run_oneshot(opts)
    checks = oneshot_checks(res, opts)
    if ns.json:
        print(json.dumps({**res.to_dict(), "targets": [t.to_dict() for t in checks]}))
    else:
        near = ", ".join(f"{s}→{n}" for s, n in res.neighbours.items())
        print(f"species taken as unseen → their retrieval neighbour: {near}")
        for group, summ in res.summaries.items():
            _table(summ, f"synthetic, {_GROUPS[group]}")
        print("pose MPJPE per species [% leg]: " + ", ".join(res.columns))
        for sp, per in res.per_species.items():
            print(f"  {sp:10s} " + " ".join(_f(per.get(c), "6.2f") for c in res.columns))
        for name, summ in res.real_summaries.items():
            _table(summ, f"real reference: {name}")
        print(format_legend(_LEGEND, "  "))
        for t in checks:
            print(f"  {t.name}: {t.shown} (target {t.target}) {t.verdict}")
    return check_exit([t.name for t in checks if t.verdict == "MISSED"], ns.check)
