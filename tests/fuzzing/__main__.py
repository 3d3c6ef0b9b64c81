"""``python -m fuzzing`` (from ``tests/``; ``make fuzz``): run a fuzzing campaign and print
its counts by outcome.

::

    python -m fuzzing [--n 10000] [--seed 0] [--targets bvh,npz,...] [--show 5]
                      [--time-limit 120] [--memory-mb 300] [--check]

Prints the counts by outcome per target (``ok``, ``typed``, ``raw``, ``hang``,
``memory``) with each target's peak memory, the table's legend, the first failures with
their inputs, and the verdict of the target "0 raw tracebacks, hangs or memory
blow-ups" (``met`` or ``MISSED``). ``--check`` makes a missed target exit with code 1;
bad arguments are ``error: …`` and exit code 2.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from habitsim.cli.bounds import check_bounds
from habitsim.cli.conventions import add_check_option, add_list_option, check_exit
from habitsim.errors import ArgumentRangeError, HabitsimError, brief

from .campaign import TARGETS, FuzzLimits, campaign, print_campaign

#: Most inputs of one campaign (10,000 take about 5 minutes on one core).
MAX_INPUTS = 1_000_000


def build_parser() -> argparse.ArgumentParser:
    """The campaign's command line."""
    p = argparse.ArgumentParser(
        prog="python -m fuzzing",
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
    p.add_argument(
        "--time-limit",
        type=float,
        default=120.0,
        metavar="S",
        help="seconds an input may run before it counts as a hang (default 120)",
    )
    p.add_argument(
        "--memory-mb",
        type=float,
        default=300.0,
        metavar="M",
        help="memory an input may take beyond 4 x its size, in MB (default 300)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress notes on stderr")
    add_check_option(p)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Run a campaign; the exit code is 0, 1 (``--check`` and a raw exception) or 2 (bad
    arguments: ``error: …`` on stderr)."""
    ns = build_parser().parse_args(argv)
    try:
        check_bounds(ns)  # --seed: as every habitsim command's
        if not 1 <= ns.n <= MAX_INPUTS:
            raise ArgumentRangeError(f"--n {brief(ns.n)}; valid: 1 to {MAX_INPUTS} (fuzzed inputs)")
        if not 0 <= ns.show <= 1000:
            raise ArgumentRangeError(f"--show {brief(ns.show)}; valid: 0 to 1000 (raw exceptions)")
        if not 0.1 <= ns.time_limit <= 3600:
            raise ArgumentRangeError(f"--time-limit {brief(ns.time_limit)}; valid: 0.1 to 3600 s")
        if not 50 <= ns.memory_mb <= 16384:
            raise ArgumentRangeError(f"--memory-mb {brief(ns.memory_mb)}; valid: 50 to 16384 MB")
        limits = FuzzLimits(time_s=ns.time_limit, memory_mb=ns.memory_mb)
        res = campaign(
            ns.n, ns.seed, ns.targets, keep=ns.show, progress=not ns.no_progress, limits=limits
        )
    except HabitsimError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print_campaign(res, ns.n, ns.seed)
    t = res.total
    bad = t["raw"] + t["hang"] + t["memory"]
    print(
        f"target: 0 raw tracebacks, hangs or memory blow-ups — {t['raw']} raw, {t['hang']} "
        f"hang, {t['memory']} memory: {'met' if bad == 0 else 'MISSED'}"
    )
    return check_exit(
        [f"{bad} raw traceback(s), hang(s) or memory blow-up(s)"] if bad else [], ns.check
    )


if __name__ == "__main__":
    sys.exit(main())
