"""``habitsim demo --out DIR``: the furthest pipeline stage that exists, end to end.

Until transfer, refinement and simulation exist, the demo builds a small synthetic gait
data set (4 clips per species, every catalog species) in ``DIR`` and prints its measured
gait statistics per species × action: planned and measured Froude number and duty
factor, relative stride length, footfall phase error and foot skating. Re-running on the
same folder reuses the clips already there; a folder holding a data set of another
configuration (an older generator, say) is rebuilt.
"""

from __future__ import annotations

import argparse
import time

from ..dataset import build_dataset, check_resumable, format_stats_table
from ..errors import DatasetError
from .synth_cmd import format_summary

#: Clips per species of the demo data set.
DEMO_CLIPS_PER_SPECIES = 4


def register(sub: argparse._SubParsersAction) -> None:
    """Add the top-level ``demo`` command."""
    p = sub.add_parser(
        "demo",
        help="run the demo (currently: a small synthetic data set and its gait statistics)",
        description=(
            "Build a small synthetic gait data set of every species in DIR and print its "
            "measured gait statistics."
        ),
    )
    p.add_argument(
        "--out", default="demo_out", metavar="DIR", help="output folder (default demo_out)"
    )
    p.add_argument(
        "--clips-per-species", type=int, default=DEMO_CLIPS_PER_SPECIES, metavar="N",
        help=f"clips per species (default {DEMO_CLIPS_PER_SPECIES})",
    )
    p.add_argument("--seed", type=int, default=0, metavar="S", help="seed (default 0)")
    p.add_argument("--workers", type=int, metavar="W", help="worker processes (default: CPU count)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_demo)


def _demo(ns: argparse.Namespace) -> int:
    t0 = time.perf_counter()
    try:
        check_resumable(ns.out, seed=ns.seed)
        overwrite = False
    except DatasetError:
        overwrite = True  # an earlier demo with another configuration: rebuild it
    print("habitsim demo: synthetic gait data set of every species (the pipeline's first stage)")
    build = build_dataset(
        ns.out,
        clips_per_species=ns.clips_per_species,
        seed=ns.seed,
        workers=ns.workers,
        progress=not ns.no_progress,
        overwrite=overwrite,
    )
    print(format_summary(build))
    print()
    print(format_stats_table(build.stats))
    print()
    print(
        "Fr = v²/(g·h) measured from the root path, duty = stance share, stride/h = stride "
        "length / hip height,\nphase err = |measured − planned footfall phase| [stride], "
        "skate/pen = foot skating / ground penetration [mm],\nstable = share of frames with "
        "≥ 3 feet down whose centre of mass is inside the support polygon; for jump, "
        "Fr plan is the take-off Froude number."
    )
    print(f"clips: {ns.out}/{{train,val,test}}/<species>/*.npz, listed in {ns.out}/manifest.json;")
    print(f"this table is also in {ns.out}/stats.md and {ns.out}/stats.csv")
    print(f"demo finished in {time.perf_counter() - t0:.1f} s")
    return 0
