"""Sensible ranges of the numeric command-line arguments, checked before a command runs.

Arguments are matched by their ``dest`` name, so one table covers every command that has
them (``--seed`` of ``transfer``, ``eval``, ``data synth``, …). A value outside its range
(or NaN) is an :class:`~habitsim.errors.ArgumentRangeError` naming the option, the value
and the valid range, printed as ``error: …`` with exit code 2 like every other bad input.
Checks of a single command's options (``data synth --fps``) live in the function it
calls, so the Python API refuses the same values.
"""

from __future__ import annotations

import argparse
import math

from ..errors import ArgumentRangeError, brief

#: Largest seed: every seed must fit numpy's and torch's generators alike.
MAX_SEED = 2**32 - 1

#: dest → (lowest, highest, what the value is); None = no bound on that side.
BOUNDS: dict[str, tuple[float | None, float | None, str]] = {
    "seed": (0, MAX_SEED, "an integer seed"),
    "workers": (1, 1024, "worker processes"),
    "threads": (1, 1024, "threads"),
    "temperature": (1e-3, 10.0, "a sampling temperature (scale of the prior's Gaussian)"),
    "settle": (0.0, 60.0, "seconds of holding the first frame"),
    "control_hz": (1.0, 10_000.0, "a control rate [Hz]"),
    "mpc_hz": (1.0, 1000.0, "an MPC rate [Hz]"),
    "fps": (1.0, 1000.0, "a frame rate [Hz]"),
    "duration": (0.1, 600.0, "seconds"),
    "seconds": (0.1, 600.0, "seconds"),
    "max_iter": (1, 100_000, "IPOPT iterations"),
    "repeats": (1, 100_000, "repeats"),
    "steps": (1, 10_000_000, "training steps"),
    "epochs": (1, 100_000, "training epochs"),
    "habit_steps": (0, 100_000, "Adam steps of fitting the habit latent"),
}


def check_bounds(ns: argparse.Namespace) -> None:
    """Check every bounded argument present (and not None) in a parsed namespace.

    Raises:
        ArgumentRangeError: the first value outside its range, e.g.
            ``--temperature nan; valid: 0.001 to 10 (a sampling temperature …)``.
    """
    for dest, (lo, hi, what) in BOUNDS.items():
        v = getattr(ns, dest, None)
        if v is None or isinstance(v, bool) or not isinstance(v, int | float):
            continue
        ok = not (isinstance(v, float) and math.isnan(v))
        ok = ok and (lo is None or v >= lo) and (hi is None or v <= hi)
        if not ok:
            flag = "--" + dest.replace("_", "-")
            if lo is not None and hi is not None:
                span = f"{_num(lo)} to {_num(hi)}"
            elif lo is not None:
                span = f"at least {_num(lo)}"
            else:
                assert hi is not None  # every entry of BOUNDS has a bound
                span = f"at most {_num(hi)}"
            raise ArgumentRangeError(f"{flag} {brief(v)}; valid: {span} ({what})")


def _num(x: float) -> str:
    return str(x) if isinstance(x, int) else f"{x:g}"
