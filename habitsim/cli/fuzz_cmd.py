"""``habitsim fuzz``: a fuzzing campaign over the readers and the command line.

::

    habitsim fuzz [--n 10000] [--seed 0] [--targets bvh,npz,...] [--show 5] [--check]

Runs :func:`habitsim.fuzz.campaign` (the same campaign as ``python -m habitsim.fuzz`` and
``make fuzz``) and prints the counts by outcome per target (``ok``, ``typed``, ``raw``),
the table's legend, the first raw exceptions with their inputs, and the verdict of the
target "0 raw tracebacks" (``met`` or ``MISSED``). As for the benchmarks, ``--check``
makes a missed target exit with code 1; bad arguments are ``error: …`` and exit code 2.
"""

from __future__ import annotations

import argparse

from .conventions import add_check_option, add_list_option, check_exit


def register(sub: argparse._SubParsersAction) -> None:
    """Add the top-level ``fuzz`` command."""
    from ..fuzz import TARGETS

    p = sub.add_parser(
        "fuzz",
        help="fuzz the readers and the command line; print counts by outcome",
        description=(
            "Feed N mutated inputs (BVH and .npz files, species TOML, data-set manifests, "
            "command lines, absurd but valid-shaped motions for the heavy commands) to "
            "habitsim and count how each ends: ok, typed (a HabitsimError) or raw (any "
            "other exception: a bug). Target: 0 raw."
        ),
    )
    p.add_argument(
        "--n", type=int, default=10_000, metavar="N", help="inputs to try (default 10000)"
    )
    p.add_argument("--seed", type=int, default=0, metavar="S", help="campaign seed (default 0)")
    add_list_option(
        p,
        "--targets",
        choices=list(TARGETS),
        help=f"what to fuzz (default all: {', '.join(TARGETS)})",
    )
    p.add_argument(
        "--show", type=int, default=5, metavar="K", help="raw exceptions to show (default 5)"
    )
    p.add_argument("--no-progress", action="store_true", help="no progress notes on stderr")
    add_check_option(p)
    p.set_defaults(func=_fuzz)


#: Most inputs of one campaign (10,000 take about 5 minutes on one core).
MAX_INPUTS = 1_000_000


def _fuzz(ns: argparse.Namespace) -> int:
    from ..errors import ArgumentRangeError, brief
    from ..fuzz import campaign, print_campaign

    if not 1 <= ns.n <= MAX_INPUTS:
        raise ArgumentRangeError(f"--n {brief(ns.n)}; valid: 1 to {MAX_INPUTS} (fuzzed inputs)")
    if not 0 <= ns.show <= 1000:
        raise ArgumentRangeError(f"--show {brief(ns.show)}; valid: 0 to 1000 (raw exceptions)")
    res = campaign(ns.n, ns.seed, ns.targets, keep=ns.show, progress=not ns.no_progress)
    print_campaign(res, ns.n, ns.seed)
    raw = res.total["raw"]
    print(f"target: 0 raw tracebacks — {raw} raw: {'met' if raw == 0 else 'MISSED'}")
    return check_exit([f"{raw} raw traceback(s)"] if raw else [], ns.check)
