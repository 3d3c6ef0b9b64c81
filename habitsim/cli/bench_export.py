"""``habitsim bench export``: a motion onto a user's rig and back (the benchmark is
:mod:`habitsim.evaluation.bench.export`). Prints, per rig and motion, the round trip's
max / median error on the joints the rig maps, the same with the import's root-height
offset removed (the pose), the offset, the import's root scale, and the median slide of the
rig's stance feet with the default travel and with ``--travel feet``; ``--json`` prints one
object per case."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from .conventions import add_check_option, check_exit


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``export`` to the ``bench`` command group."""
    p = sub.add_parser(
        "export",
        help="a motion onto your rig and imported back: round-trip error per rig",
        description=(
            "Write the species' synthetic walk and trot and each rig's own clip onto each "
            "rig (data export-bvh --rig), import it back, and print the error of every joint "
            "the rig maps in mm."
        ),
    )
    p.add_argument(
        "rigs", type=Path, nargs="+", metavar="RIG", help="rig files (.bvh, .glb, .gltf)"
    )
    p.add_argument("--species", default="dog", help="species of the motions (default dog)")
    p.add_argument(
        "--duration", type=float, default=4.0, metavar="S", help="synthetic clip length [s]"
    )
    p.add_argument(
        "--own-seconds",
        type=float,
        default=20.0,
        metavar="S",
        help="seconds of each rig's own clip to export back (default 20)",
    )
    p.add_argument("--json", action="store_true", help="one JSON object per case")
    add_check_option(
        p,
        help="exit with code 1 when a rig's own clip or a synthetic motion does not come "
        "back within 1 mm "
        "(default: print the verdict, exit 0)",
    )
    p.set_defaults(func=_bench_export)


def _bench_export(ns: argparse.Namespace) -> int:
    from ..evaluation.bench.export import export_checks, run_export

    res = run_export(ns.rigs, ns.species, ns.duration, own_seconds=ns.own_seconds)
    if ns.json:
        for c in res.cases:
            print(json.dumps(c.to_dict()))
    else:
        print(
            f"{'rig':<28} {'motion':<9} {'joints':>6} {'max':>8} {'median':>8} "
            f"{'pose max':>9} {'pose med':>9} {'height':>8} {'scale':>7} {'slide':>6} "
            f"{'feet':>6}  (mm)"
        )
        for c in res.cases:
            f = c.figures
            print(
                f"{c.rig[:28]:<28} {c.motion:<9} {c.joints:>6} {f['max_mm']:8.3f} "
                f"{f['median_mm']:8.3f} {f['pose_max_mm']:9.3f} {f['pose_median_mm']:9.3f} "
                f"{f['height_offset_mm']:8.2f} {c.root_scale:7.4f} {c.slide_mm:6.1f} "
                f"{c.slide_feet_mm:6.1f}"
            )
    checks = export_checks(res)
    for t in checks:
        print(f"target: {t.name}: {t.shown} ({t.target}: {t.verdict})")
    return check_exit([t.name for t in checks if t.verdict == "MISSED"], ns.check)
