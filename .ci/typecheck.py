"""Type-check the habitsim package with mypy, under its installed module names.

The installed ``habitsim`` package is assembled from four source folders (see ``ROOTS`` in
setup.py): ``controllers/`` is ``habitsim.controllers``, ``evaluation/`` is
``habitsim.evaluation`` and ``mjcf_models/`` is ``habitsim.mjcf_models``. mypy names a
module after its file path and does not follow the editable install's import hook, so
this script gives it every source file with its installed module name (the same mapping
setup.py installs) and runs one build. Configuration: ``[tool.mypy]`` in pyproject.toml.

Usage (from anywhere; ``make typecheck`` runs it): ``python .ci/typecheck.py``.
Exit status 0 when there is no error, 1 otherwise, 2 when mypy cannot run.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

from mypy import build
from mypy.errors import CompileError
from mypy.main import process_options
from mypy.modulefinder import BuildSource

REPO = Path(__file__).resolve().parent.parent

#: Source folder -> installed package name (as ``ROOTS`` in setup.py).
ROOTS = {
    "habitsim": "habitsim",
    "mjcf_models": "habitsim.mjcf_models",
    "controllers": "habitsim.controllers",
    "evaluation": "habitsim.evaluation",
}
#: Developer tools kept with the tests (not installed), checked under the name they are
#: imported by from ``tests/``.
TOOLS = {"tests/fuzzing": "fuzzing"}


def sources() -> list[BuildSource]:
    """Every ``.py`` file under :data:`ROOTS` and :data:`TOOLS`, with its module name."""
    out = []
    for folder, package in {**ROOTS, **TOOLS}.items():
        root = REPO / folder
        for path in sorted(root.rglob("*.py")):
            rel = path.relative_to(root).with_suffix("")
            parts = [p for p in rel.parts if p != "__init__"]
            if "__pycache__" in rel.parts:
                continue
            module = ".".join([package, *parts])
            out.append(BuildSource(str(path.relative_to(REPO)), module))
    return out


def main() -> int:
    os.chdir(REPO)
    # Read the options (pyproject.toml's [tool.mypy]) as the command line would; the
    # target given here only satisfies the parser, the sources are replaced below.
    _, options = process_options(
        ["--config-file", "pyproject.toml", "habitsim"] + sys.argv[1:],
        require_targets=False,
    )
    srcs = sources()
    messages: list[str] = []

    def flush(filename: str | None, new: list[str], serious: bool) -> None:
        messages.extend(new)
        for line in new:
            print(line)

    try:
        build.build(srcs, options, flush_errors=flush)
    except CompileError as exc:
        for line in exc.messages:
            if line not in messages:
                print(line)
        return 2
    errors = sum(1 for line in messages if ": error:" in line)
    files = len({line.split(":", 1)[0] for line in messages if ": error:" in line})
    if errors:
        print(
            f"Found {errors} error{'s' * (errors != 1)} in {files} file{'s' * (files != 1)}"
            f" (checked {len(srcs)} source files)"
        )
        return 1
    print(f"Success: no issues found in {len(srcs)} source files")
    return 0


if __name__ == "__main__":
    sys.exit(main())
