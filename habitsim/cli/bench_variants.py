"""``habitsim bench variants --data DIR``: stance labels of transformed copies of the clips.

The benchmark is :mod:`habitsim.evaluation.bench.variants` (the variants, the figures,
the targets); this module parses its options, prints a line per clip × variant as it is
imported, the legend and the targets, and writes ``--json``.
"""

from __future__ import annotations

import argparse
import json
import time

from ..evaluation.bench.variants import MAX_DUTY_CHANGE, MIN_STANCE_F1, VARIANTS, VariantsOptions
from .conventions import add_check_option, add_list_option, check_exit, format_legend, split_names

_HEAD = (
    f"{'clip':<24} {'variant':<16} {'fps':>5} {'duty LF RF LH RH':>19} {'fore':>5} "
    f"{'hind':>5} {'<2':>5} {'F1 min':>6} {'Δduty':>6} {'s':>5}"
)
_LEGEND = (
    "fps: the variant's frame rate [Hz] (imported at it); duty: share of frames each foot "
    "is labelled in stance, LF RF LH RH; fore, hind: mean duty factor of the fore / hind "
    "feet; <2: share of frames with fewer than two feet in stance; F1 min: lowest per-foot "
    "stance F1 against the original clip's labels over the same instants; Δduty: largest "
    "per-foot change of the duty factor over those instants; s: time to make and import "
    "the variant [s]."
)


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``variants`` to the ``bench`` command group."""
    listing = "; ".join(f"{v.name}: {v.description}" for v in VARIANTS.values())
    p = sub.add_parser(
        "variants",
        help="stance labels of transformed copies of BVH clips (frame rates, proportions...)",
        description=(
            "Make transformed copies of every BVH clip of DIR (other frame rates, speeds, "
            "body proportions, toe points, noise, trimmed and padded starts, rig exports), "
            "import each onto --species and compare its stance labels with the original "
            f"clip's (per-foot F1 ≥ {MIN_STANCE_F1}, duty factors within "
            f"{MAX_DUTY_CHANGE}). Variants: {listing}."
        ),
    )
    p.add_argument("--data", required=True, metavar="DIR", help="folder of .bvh clips")
    add_list_option(
        p, "--clips", default=[], metavar="NAME", help="only these clips (file names or stems)"
    )
    add_list_option(p, "--variants", default=[], metavar="NAME", help="the variants (default: all)")
    p.add_argument(
        "--species", default="dog", metavar="NAME", help="skeleton imported onto (default dog)"
    )
    p.add_argument("--seed", type=int, default=0, metavar="S", help="seed of the noise (default 0)")
    p.add_argument("--json", metavar="OUT", help="also write the rows and targets here")
    add_check_option(p)
    p.set_defaults(func=_bench_variants)


def _line(r: dict) -> str:
    if r.get("status") != "ok":
        return f"{r['clip']:<24} {r['variant']:<16} error: {r.get('note', '')}"
    duty = " ".join(f"{d:.2f}" for d in r["duty"])
    return (
        f"{r['clip']:<24} {r['variant']:<16} {r['fps']:>5.0f} {duty:>19} "
        f"{r['duty_fore']:>5.2f} {r['duty_hind']:>5.2f} {r['under_two']:>5.2f} "
        f"{min(r['f1']):>6.3f} {r['duty_change']:>6.3f} {r['time_import_s']:>5.1f}"
    )


def _bench_variants(ns: argparse.Namespace) -> int:
    from ..evaluation.bench.variants import evaluate_targets, run
    from ..fileio import atomic_write_text, json_safe

    t0 = time.perf_counter()
    opts = VariantsOptions(
        data=ns.data,
        clips=tuple(split_names(ns.clips)),
        variants=tuple(split_names(ns.variants)),
        species=ns.species,
        seed=ns.seed,
    )
    print(_HEAD, flush=True)
    rows = run(opts, on_row=lambda r: print(_line(r), flush=True))
    checks = evaluate_targets(rows)
    print(format_legend(_LEGEND))
    for c in checks:
        print(f"  {c.name}: {c.shown} (target {c.target}) {c.verdict}")
    wall = time.perf_counter() - t0
    print(f"bench variants finished in {wall:.1f} s ({len(rows)} imports)")
    if ns.json:
        doc = {
            "kind": "habitsim.bench.variants",
            "config": {k: v for k, v in vars(ns).items() if k != "func"},
            "rows": rows,
            "targets": [c.to_dict() for c in checks],
            "wall_time_s": wall,
        }
        atomic_write_text(ns.json, json.dumps(json_safe(doc), indent=2) + "\n")
        print(f"rows written to {ns.json}")
    return check_exit([c.name for c in checks if c.verdict == "MISSED"], ns.check)
