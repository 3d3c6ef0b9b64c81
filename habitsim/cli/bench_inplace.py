"""``habitsim bench inplace``: in-place clips, their travel recovered from the feet.

The benchmark is :mod:`habitsim.evaluation.bench.inplace` (what runs, the rows, the
targets); this module parses its options and prints the rows and the targets. With ``--check``
a run that misses a target exits with code 1 (bad input: 2, as every command).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from .conventions import add_check_option, check_exit


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``inplace`` to the ``bench`` command group."""
    p = sub.add_parser(
        "inplace",
        help="in-place clips: root travel recovered from the stance feet, game loops",
        description=(
            "Make every walk or run clip of --dir in place (the root's horizontal travel "
            "removed), import it and compare the recovered root path, heading and stance "
            "labels with the clip's own import; import the Walk and Run loops of each "
            "--gltf file and a synthetic in-place walk loop and print their stance shares "
            "and stance toe heights; print the targets met / MISSED."
        ),
    )
    p.add_argument(
        "--dir",
        type=Path,
        default=None,
        dest="dev_dir",
        metavar="DIR",
        help="folder of .bvh clips to make in place (walk/run in the name; default: none)",
    )
    p.add_argument(
        "--gltf",
        type=Path,
        action="append",
        default=[],
        metavar="FILE",
        help="glTF/GLB file with in-place Walk and Run animations (repeatable)",
    )
    p.add_argument(
        "--species", default="dog", metavar="NAME", help="skeleton to import onto (default dog)"
    )
    add_check_option(
        p, help="exit with code 1 when a target is MISSED (default: print the verdicts, exit 0)"
    )
    p.set_defaults(func=_bench_inplace)


def _bench_inplace(ns: argparse.Namespace) -> int:
    from ..evaluation.bench.inplace import InPlaceBenchOptions, run_inplace

    res = run_inplace(
        InPlaceBenchOptions(dev_dir=ns.dev_dir, gltf=tuple(ns.gltf), species=ns.species)
    )
    print("recovery (clip made in place against the clip as it was):")
    print(
        f"  {'clip':28s} {'in place':>8s} {'dist m':>7s} {'path %':>7s} {'head °':>7s} {'F1':>6s}"
    )
    for r in res.recovery:
        print(
            f"  {r.clip:28s} {('yes' if r.detected else 'NO'):>8s} {r.distance_m:7.2f} "
            f"{100 * r.path_share:7.1f} {r.heading_error_deg:7.1f} {r.stance_f1:6.3f}"
        )
    print("game loops:")
    print(
        f"  {'clip':28s} {'gait':4s} {'in place':>8s} {'loop':>6s} {'travel m':>8s} "
        f"{'stance share LF RF LH RH':>25s} {'stance toe %':>12s}"
    )
    for g in res.loops:
        shares = " ".join(f"{v:.2f}" for v in g.stance_share)
        print(
            f"  {g.clip:28s} {g.gait:4s} {('yes' if g.detected else 'NO'):>8s} {g.loop:>6s} "
            f"{g.recovered_m:8.2f} {shares:>25s} {100 * g.stance_toe_per_leg:12.2f}"
        )
    print("targets:")
    for c in res.checks:
        print(f"  {c.name:52s} {c.shown:>12s}  (target {c.target}: {c.verdict})")
    return check_exit([c.name for c in res.checks if c.verdict == "MISSED"], ns.check)
