"""``habitsim score DIR|FILES``: every per-clip metric of docs/metrics.md on motions from
anywhere (see :mod:`habitsim.evaluation.score`).

::

    habitsim score outputs/ --species dog [--track] [--out scores/ --report]
    habitsim score walk.npz walk.bvh --contacts geometry

Prints one line per file (the physics columns first), a legend and the stance rule
used; ``--out DIR`` writes ``scores.csv`` and ``scores.json`` (every column), with
``--report`` also ``report.html`` / ``report.md``. The tables are written after every
file is scored, each atomically. Exit code 0 when every file was scored, 2 when a file
was bad input (its row says why: another species than ``--species``, a species that
cannot be told, an unreadable file), 1 when scoring a file failed otherwise.
"""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING

from .conventions import add_source_options, format_legend, source_options

if TYPE_CHECKING:
    from ..evaluation.score import ScoreResult

_LEGEND = (
    "residual F / T: the mean force [m·g] and torque [m·g·L] the motion needs beyond what "
    "its stance feet can push on the ground (0: the ground can carry it; 1.0: floating); "
    "torque>motor: share of frames needing a joint torque beyond the motor's limit; "
    "skate, penetr., float: foot skating [mm/frame], ground penetration and floating [mm]; "
    "biomech: departure from the species' gait table (lower is better); survival: share "
    "of the clip tracked unassisted before a fall; sim MPJPE/L: tracking error in leg "
    "lengths (docs/metrics.md)."
)


def register(sub: argparse._SubParsersAction) -> None:
    """Add the top-level ``score`` command."""
    from ..controllers import CONTROLLERS
    from ..evaluation.score import CONTACT_RULES

    p = sub.add_parser(
        "score",
        help="score motions from anywhere (.npz, BVH, glTF) with every per-clip metric",
        description=(
            "Score every motion file given (a folder: every .npz, .bvh, .glb, .gltf under "
            "it) as it is: kinematic plausibility, the dynamic plausibility under its stance "
            "(residual root force and torque, torque beyond the motors), the biomechanical "
            "consistency and, with --track, unassisted tracking in MuJoCo (survival, sim "
            "MPJPE). Stance: a .npz file's own labels, else detected on the geometry "
            "(--contacts). Exit code 2 when a file is bad input, 1 when scoring one failed."
        ),
    )
    p.add_argument("inputs", nargs="+", metavar="DIR|FILE", help="motion files and folders")
    p.add_argument(
        "--species",
        default=None,
        metavar="NAME",
        help="species of the files (required for motion capture that is not a habitsim-"
        "written BVH; a file of another species is an error)",
    )
    p.add_argument(
        "--contacts",
        default="auto",
        choices=CONTACT_RULES,
        help="stance: auto (a .npz file's labels, else detected from the geometry), labels "
        "(the file's, required), geometry (detected for every file) (default auto)",
    )
    p.add_argument(
        "--refine",
        default="none",
        choices=("none", "kinematic", "dynamics"),
        help="refine the motions before scoring them (default none: as they are)",
    )
    p.add_argument("--track", action="store_true", help="track every motion in MuJoCo, unassisted")
    p.add_argument(
        "--controller",
        default="mpc",
        choices=CONTROLLERS,
        metavar="NAME",
        help=f"tracking controller: {', '.join(CONTROLLERS)} (default mpc)",
    )
    p.add_argument("--no-dynamic", action="store_true", help="skip the inverse-dynamics metrics")
    p.add_argument(
        "--no-evaluator",
        action="store_true",
        help="skip the evaluator network's species and action (no torch import)",
    )
    p.add_argument("--seed", type=int, default=0, metavar="S", help="tracking seed (default 0)")
    p.add_argument(
        "--out", default=None, metavar="DIR", help="write scores.csv and scores.json here"
    )
    p.add_argument(
        "--report",
        action="store_true",
        help="also write report.html and report.md into --out",
    )
    p.add_argument(
        "--follow-symlinks",
        action="store_true",
        help="read through links in a given folder that lead out of it (refused by default)",
    )
    add_source_options(p, of="every motion-capture file", span=False, loop=False)
    p.set_defaults(func=_score)


def _score(ns: argparse.Namespace) -> int:
    from ..evaluation.score import ScoreError, ScoreOptions, check_outputs, score_files

    if ns.report and ns.out is None:
        raise ScoreError("--report writes into the --out folder: give --out DIR")
    options = ScoreOptions(
        species=ns.species,
        contacts=ns.contacts,
        refine=ns.refine,
        track=ns.track,
        controller=ns.controller,
        dynamic=not ns.no_dynamic,
        evaluator=not ns.no_evaluator,
        seed=ns.seed,
        source=source_options(ns, plant=False),
        follow_symlinks=ns.follow_symlinks,
    )
    if ns.out is None:
        return _report(ns, score_files(ns.inputs, options))
    from ..folders import claim_output_folder

    check_outputs(ns.out, report=ns.report)
    # one run at a time in --out; a new run replaces only the files habitsim wrote there
    with claim_output_folder(
        ns.out, command="score", overwrite=True, resume_flag=None, overwrite_flag=None
    ):
        return _report(ns, score_files(ns.inputs, options))


def _report(ns: argparse.Namespace, res: ScoreResult) -> int:
    """Print the table (and write ``--out``'s files); the exit code."""
    print(res.table_text())
    print(format_legend(_LEGEND))
    for line in res.stance_lines():
        print(line)
    for r in res.errors:  # each file not scored, on stderr as every command's errors
        print(f"error: {r['file']}: {r['error']}: {r['note']}", file=sys.stderr)
    if ns.out is not None:
        from ..fileio import output_transaction

        with output_transaction():  # the tables and the report: all or none
            written = res.write(ns.out)
            if ns.report:
                from ..evaluation.score_report import write_score_report

                written += write_score_report(res, ns.out)
        for path in written:
            print(f"wrote {path}")
    done = len(res.rows) - len(res.errors)
    print(
        f"{done} of {len(res.rows)} file(s) scored in {res.wall_time_s:.1f} s"
        + (f"; {len(res.errors)} not scored (see above)" if res.errors else "")
    )
    return res.exit_code
