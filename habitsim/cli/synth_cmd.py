"""``habitsim data synth``: build the synthetic gait data set (see :mod:`habitsim.dataset`).

Prints a short summary (clips generated / reused, split counts, wall time) and the
measured statistics table per species × action. Bad arguments (``--clips-per-species
0``, an unknown species, an output path that is a file, a folder holding a data set of
another seed) become ``error: ...`` and exit code 2, with no manifest written.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence

from ..dataset import DatasetBuild, build_dataset, format_stats_table
from .conventions import add_list_option, split_names


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``synth`` to the ``data`` command group."""
    p = sub.add_parser(
        "synth",
        help="build the synthetic gait data set (paired clips of every species)",
        description=(
            "Generate N clips per species with the synthetic gait generator, split them "
            "into train/val/test (held-out species: test only), write DIR/manifest.json, "
            "DIR/stats.csv and DIR/stats.md. An interrupted build resumes where it stopped."
        ),
    )
    p.add_argument("--out", required=True, metavar="DIR", help="data set folder")
    p.add_argument(
        "--clips-per-species",
        type=int,
        default=40,
        metavar="N",
        help="clips per species (default 40)",
    )
    p.add_argument(
        "--chains",
        type=int,
        default=0,
        metavar="N",
        help="chained clips per species (2-4 actions run into one another; default 0)",
    )
    p.add_argument("--seed", type=int, default=0, metavar="S", help="build seed (default 0)")
    add_list_option(p, "--species", help="species (default: the whole catalog)")
    p.add_argument("--workers", type=int, metavar="W", help="worker processes (default: CPU count)")
    p.add_argument(
        "--fps", type=float, default=30.0, metavar="F", help="frame rate [Hz] (default 30)"
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--no-resume", action="store_true", help="regenerate clips already on disk")
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace a data set of another configuration in DIR",
    )
    p.set_defaults(func=_synth)


def parse_species(text: str | Sequence[str] | None) -> list[str] | None:
    """``"cat, dog"`` or ``["cat", "dog"]`` → ``["cat", "dog"]``; None or blank → None
    (every species)."""
    return split_names(text) or None


def format_summary(build: DatasetBuild) -> str:
    """The few lines printed before the statistics table."""
    man = build.manifest
    counts = man.split_counts()
    held = [s["name"] for s in man.species if s["held_out"]]
    lines = [
        f"data set {man.root}: {len(man.clips)} clips of {len(man.species)} species "
        f"({man.clips_per_species} per species"
        + (f" and {man.chains_per_species} chained" if man.chains_per_species else "")
        + f", seed {man.seed}, {man.fps:g} fps)",
        f"  splits: train {counts['train']}, val {counts['val']}, test {counts['test']}"
        + (f" (held out, test only: {', '.join(held)})" if held else ""),
        f"  {build.generated} generated, {build.reused} reused"
        + (f", {build.removed} stale removed" if build.removed else "")
        + f" in {build.wall_time_s:.1f} s with {build.workers} worker(s)",
        f"  files: {man.root / 'manifest.json'}, stats.csv, stats.md",
    ]
    return "\n".join(lines)


def _synth(ns: argparse.Namespace) -> int:
    build = build_dataset(
        ns.out,
        clips_per_species=ns.clips_per_species,
        chains_per_species=ns.chains,
        seed=ns.seed,
        species=parse_species(ns.species),
        workers=ns.workers,
        fps=ns.fps,
        progress=not ns.no_progress,
        resume=not ns.no_resume,
        overwrite=ns.overwrite,
    )
    print(format_summary(build))
    print()
    print(format_stats_table(build.stats))
    return 0
