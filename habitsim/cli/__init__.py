"""The ``habitsim`` command line.

Each command group lives in its own module exposing ``register(subparsers)``; the module
adds its commands, each with ``set_defaults(func=...)`` taking the parsed namespace and
returning an exit code. Every :class:`~habitsim.errors.HabitsimError` becomes a one-line
``error: ...`` message on stderr and its ``exit_code``: 2 for bad input, 1 for an output
that failed while being written (:class:`~habitsim.errors.OutputWriteError`: a full
disk). Output into a pipe closed early (``habitsim species list | head -1``) ends the
command quietly with exit code 141 (128 + SIGPIPE, as a shell reports it), without a
traceback. Shared option conventions (lists of names, ``--check``) are in
:mod:`habitsim.cli.conventions`.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import sys
import threading
from collections.abc import Iterator, Sequence

from ..errors import HabitsimError, bounded

# (group name, help, module names registering into it). Group None = top-level commands.
_GROUPS: list[tuple[str | None, str, tuple[str, ...]]] = [
    ("species", "the species catalog", ("species_cmd",)),
    (
        "data",
        "data sets: synthetic gaits, BVH import, captions",
        ("synth_cmd", "bvh_cmd", "captions_cmd"),
    ),
    ("motion", "inspect motion files", ("motion_cmd",)),
    ("t2m", "text to motion: code set, training, generation, evaluator", ("t2m_cmd",)),
    ("models", "per-species MuJoCo (MJCF) models", ("models_cmd",)),
    ("bench", "benchmarks that print figures", ("bench_cmd",)),
    (
        None,
        "",
        (
            "demo_cmd",
            "track_cmd",
            "eval_cmd",
            "score_cmd",
            "train_evaluator_cmd",
            "train_cmd",
            "transfer_cmd",
            "refine_cmd",
            "retarget_cmd",
        ),
    ),
]


def build_parser() -> argparse.ArgumentParser:
    """The full argument parser (also used by the docs and tests)."""
    import importlib

    from .. import __version__

    parser = argparse.ArgumentParser(
        prog="habitsim",
        description="Cross-species animal motion transfer with habits, checked in physics.",
    )
    parser.add_argument("--version", action="version", version=f"habitsim {__version__}")
    top = parser.add_subparsers(dest="command", metavar="COMMAND")
    for group, help_text, modules in _GROUPS:
        if group is None:
            target = top
        else:
            gp = top.add_parser(group, help=help_text, description=help_text)
            target = gp.add_subparsers(dest=f"{group}_command", metavar="SUBCOMMAND")
            gp.set_defaults(func=lambda ns, gp=gp: (gp.print_help(), 2)[1])
        for mod in modules:
            importlib.import_module(f"habitsim.cli.{mod}").register(target)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``habitsim`` console script."""
    parser = build_parser()
    ns = parser.parse_args(argv)
    if not hasattr(ns, "func"):
        parser.print_help()
        return 2
    try:
        from .bounds import check_bounds

        check_bounds(ns)
        with _sigterm_as_interrupt():
            code = int(ns.func(ns) or 0)
        sys.stdout.flush()  # a closed pipe shows here, not at interpreter exit
        return code
    except BrokenPipeError:
        return _closed_pipe()
    except HabitsimError as e:
        print(f"error: {bounded(str(e))}", file=sys.stderr)
        return e.exit_code
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


def run() -> None:
    """Entry point of the ``habitsim`` console script and of ``python -m habitsim``.

    Runs :func:`main` and exits with its code. After an interrupt (Ctrl-C or SIGTERM) the
    command's own cleanup has already run (pools stopped, partial outputs removed), and
    the process leaves with :func:`os._exit`: an interrupt that lands while
    ``concurrent.futures`` holds a future's lock leaves that lock held, and the module's
    exit hook would then wait forever for its pool's manager thread.
    """
    code = main()
    if code == 130:
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(Exception):
                stream.flush()
        os._exit(code)
    sys.exit(code)


#: Exit code when stdout is a pipe its reader closed (128 + SIGPIPE).
EXIT_CLOSED_PIPE = 141


def _closed_pipe() -> int:
    """The reader of stdout went away: point stdout at /dev/null so the interpreter's
    final flush cannot fail again, and exit quietly (the Python docs' SIGPIPE recipe)."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError):  # stdout without a file descriptor (captured, closed)
        pass
    return EXIT_CLOSED_PIPE


@contextlib.contextmanager
def _sigterm_as_interrupt() -> Iterator[None]:
    """While a command runs, SIGTERM stops it like Ctrl-C (KeyboardInterrupt), so pools
    are shut down and temporary files removed; the previous handler is restored after."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def interrupt(signum, frame):  # noqa: ARG001 - signal handler signature
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, interrupt)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


if __name__ == "__main__":  # pragma: no cover
    run()
