"""``habitsim bench real --data DIR``: real motion capture through the whole pipeline.

The benchmark is :mod:`habitsim.evaluation.bench.real` (what runs, the rows, the targets;
its printed report in :mod:`habitsim.evaluation.bench.real_report`); this module parses
its options, prints a line per run as it finishes, the legend, the summary and the
targets, and writes ``--json``. A run that misses a target exits with code 1 (bad input:
2, as every command).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from ..evaluation.bench.real import DEFAULT_METHODS, DEFAULT_TARGETS, PERTURB_QVEL, RealOptions
from .conventions import add_frame_options, add_list_option, format_legend, split_names


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``real`` to the ``bench`` command group."""
    p = sub.add_parser(
        "real",
        help="real motion capture (BVH or glTF/GLB clips) through transfer → refine → track",
        description=(
            "Import every BVH or glTF/GLB clip (its first animation) of DIR onto --species, "
            "cut it into windows of --seconds chosen from its locomotion (a lying or "
            "sitting segment is kept out; a clip shorter than a window runs as one shorter "
            "window), and run each window × target × method "
            "through the pipeline (transfer, refinement stage A, unassisted tracking); "
            "print one line per run, a summary and the issue's targets. Exit code 1 when "
            "a target is MISSED, 2 on bad input."
        ),
    )
    p.add_argument(
        "--data", required=True, metavar="DIR", help="folder of .bvh, .glb or .gltf clips"
    )
    add_list_option(
        p,
        "--targets",
        default=list(DEFAULT_TARGETS),
        metavar="SPECIES",
        help=f"target species (default {','.join(DEFAULT_TARGETS)})",
    )
    add_list_option(
        p,
        "--methods",
        default=list(DEFAULT_METHODS),
        metavar="METHOD",
        help=f"transfer methods (default {','.join(DEFAULT_METHODS)})",
    )
    p.add_argument(
        "--species",
        default="dog",
        metavar="NAME",
        help="skeleton the clips are imported onto (default dog)",
    )
    p.add_argument(
        "--map",
        type=Path,
        default=None,
        dest="joint_map",
        metavar="FILE",
        help="joint-map file for every clip, as import-bvh --map takes it",
    )
    add_frame_options(p, "every clip")
    p.add_argument(
        "--seconds", type=float, default=4.0, metavar="S", help="window length [s] (default 4)"
    )
    p.add_argument(
        "--windows-per-clip",
        type=_windows_per_clip,
        default=1,
        metavar="N",
        help=(
            "consecutive windows per clip, from where the animal first moves on its legs "
            "(default 1; all: every whole window)"
        ),
    )
    p.add_argument(
        "--fps",
        type=float,
        default=30.0,
        metavar="HZ",
        help="frame rate the clips are resampled to (default 30; 0 keeps theirs)",
    )
    p.add_argument(
        "--refine", default="A", choices=("none", "A", "B"), help="refinement stage (default A)"
    )
    p.add_argument(
        "--controller",
        default="mpc",
        metavar="NAME",
        help="unassisted tracking controller (default mpc)",
    )
    p.add_argument("--no-track", action="store_true", help="skip the MuJoCo tracking")
    p.add_argument(
        "--no-check",
        action="store_true",
        help="do not track the unrefined transfer to check the refinement",
    )
    p.add_argument("--seed", type=int, default=0, metavar="S", help="seed (default 0)")
    p.add_argument(
        "--repeats",
        type=int,
        default=1,
        metavar="K",
        help=(
            "track every kept reference K times: once as is, K-1 times from initial joint "
            "velocities perturbed by --perturb (seeds S+1..S+K-1); the survival targets "
            "count every run (default 1)"
        ),
    )
    p.add_argument(
        "--perturb",
        type=float,
        default=PERTURB_QVEL,
        metavar="RAD_S",
        help=(
            f"initial joint-velocity noise of the repeated runs [rad/s] (default {PERTURB_QVEL:g})"
        ),
    )
    p.add_argument(
        "--workers",
        type=int,
        default=None,
        metavar="W",
        help="worker processes (default: CPU count; 1 = in this process)",
    )
    add_list_option(
        p,
        "--variants",
        default=[],
        metavar="NAME",
        help=(
            "run transformed copies of every clip instead of the clips (other frame "
            "rates, proportions, toe points, noise...; 'habitsim bench variants --help' "
            "lists them; original = the clip itself)"
        ),
    )
    p.add_argument("--json", metavar="OUT", help="also write the rows and targets here")
    p.set_defaults(func=_bench_real)


def _windows_per_clip(text: str) -> int | str:
    """``--windows-per-clip``: a count, or ``all``."""
    if text.strip().lower() == "all":
        return "all"
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"invalid --windows-per-clip {text!r}; valid: a count >= 1 or 'all'"
        ) from None


def options(ns: argparse.Namespace) -> RealOptions:
    """The benchmark's options from the parsed command line."""
    return RealOptions(
        data=ns.data,
        targets=tuple(split_names(ns.targets)),
        methods=tuple(split_names(ns.methods)),
        species=ns.species,
        joint_map=ns.joint_map,
        units=ns.units,
        up=ns.up,
        seconds=ns.seconds,
        windows_per_clip=ns.windows_per_clip,
        fps=ns.fps,
        refine=ns.refine,
        controller=ns.controller,
        track=not ns.no_track,
        check=not ns.no_check,
        seed=ns.seed,
        repeats=ns.repeats,
        perturb=ns.perturb,
        workers=ns.workers,
        variants=tuple(split_names(ns.variants)),
    )


def _bench_real(ns: argparse.Namespace) -> int:
    from ..evaluation.bench.real import evaluate_targets, exit_code, plan, run_tasks
    from ..evaluation.bench.real_report import HEAD, LEGEND, format_row, format_summary
    from ..fileio import atomic_write_text, json_safe

    t0 = time.perf_counter()
    opts = options(ns)
    planned = plan(opts)
    tasks, notes = planned.tasks, planned.notes
    clips = len({t.clip for t in tasks})
    wins = len({(t.clip, t.start_s) for t in tasks})
    shorts = len({(t.clip, t.start_s) for t in tasks if t.short})
    targets = list(dict.fromkeys(t.target for t in tasks))
    methods = list(tasks[0].methods)
    print(
        f"bench real: {wins} window(s) of {ns.seconds:g} s"
        + (f" ({shorts} shorter: clips shorter than a window)" if shorts else "")
        + f" from {clips} clip(s) of {ns.data} "
        f"(imported onto {ns.species}, {ns.fps:g} fps) × {', '.join(targets)} × "
        f"{', '.join(methods)}; refine {tasks[0].refine}; "
        + (f"tracking unassisted ({ns.controller})" if not ns.no_track else "no tracking")
        + (
            f"; {tasks[0].repeats} runs per window (the first as is, the others with "
            f"{tasks[0].perturb:g} rad/s initial joint-velocity noise)"
            if tasks[0].repeats > 1 and not ns.no_track
            else ""
        )
    )
    for n in notes:
        print(f"  note: {n}")
    print(HEAD, flush=True)
    rows = run_tasks(tasks, ns.workers, on_row=lambda r: print(format_row(r), flush=True))
    checks = evaluate_targets(
        rows,
        seconds=ns.seconds,
        refine=tasks[0].refine,
        controller=ns.controller,
        tracked=not ns.no_track,
    )
    print(format_legend(LEGEND))
    print(format_summary(rows, checks))
    wall = time.perf_counter() - t0
    print(f"bench real finished in {wall:.1f} s ({len(rows)} runs)")
    if ns.json:
        doc = {
            "kind": "habitsim.bench.real",
            "config": {k: v for k, v in vars(ns).items() if k != "func"},
            "notes": list(notes),
            "rows": rows,
            "targets": [t.to_dict() for t in checks],
            "wall_time_s": wall,
        }
        atomic_write_text(ns.json, json.dumps(json_safe(doc), indent=2) + "\n")
        print(f"rows written to {ns.json}")
    return exit_code(checks)
