"""Helpers shared by test files: running the command line in this process, listing a folder, the
unwritable destinations, the small evaluation's arguments and another process holding an
output folder."""

from __future__ import annotations

import contextlib
import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from habitsim.cli import main
from habitsim.errors import OutputPathError


def run_cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    """Exit code and stderr of ``habitsim ARGV`` run in this process."""
    code = main([str(a) for a in argv])
    err = capsys.readouterr().err
    return code, err


def files_under(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


EXAMPLE_BVH = Path(__file__).parents[1] / "habitsim" / "examples" / "dog_walk.bvh"


EVAL_ARGS = [
    "--methods",
    "direct",
    "--refine",
    "none",
    "--workers",
    "1",
    "--report-pairs",
    "0",
    "--no-videos",
    "--no-report",
    "--no-progress",
    "--max-clips",
    "1",
    "--split",
    "train",
    "--no-track",
    "--no-dynamic",
    "--targets",
    "all",
]


#: The two unwritable destinations of each writer's regression test: a file where a folder
#: should be, and a read-only folder (skipped for the super-user, who writes there anyway).
UNWRITABLE = [
    "file",
    pytest.param(
        "read_only",
        marks=pytest.mark.skipif(os.geteuid() == 0, reason="the super-user writes anywhere"),
    ),
]


def _typed_output_error(exc: BaseException) -> None:
    assert isinstance(exc, OutputPathError), repr(exc)
    assert len(str(exc)) < 600


DATA = Path(__file__).parent / "data"


DOG = DATA / "dog_mocap_cm_yup.bvh"


def _dog_text() -> str:
    return DOG.read_text()


def install_plugin(
    folder: Path, dist: str, module: str, code: str, entries: dict[str, str]
) -> Path:
    """A pip-installed package as ``folder`` holds it for sys.path: the module
    ``module.py`` with ``code`` and ``dist-0.1.dist-info`` declaring ``entries`` (method
    name → ``module:function``) in the ``habitsim.methods`` entry-point group. Put
    ``folder`` on sys.path (``monkeypatch.syspath_prepend``) to install it."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / f"{module}.py").write_text(code)
    info = folder / f"{dist}-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {dist}\nVersion: 0.1\n")
    lines = ["[habitsim.methods]", *(f"{k} = {v}" for k, v in entries.items())]
    (info / "entry_points.txt").write_text("\n".join(lines) + "\n")
    return folder


_HOLDER = (
    "import sys, time; from habitsim.folders import claim_output_folder\n"
    "with claim_output_folder(sys.argv[1], command='eval'):\n"
    "    print('held', flush=True); time.sleep(60)\n"
)


@contextlib.contextmanager
def hold(out: Path) -> Iterator[subprocess.Popen]:
    """Another process holding ``out`` until the block ends; then it is SIGKILLed (its
    lock file stays behind)."""
    proc = subprocess.Popen(
        [sys.executable, "-c", _HOLDER, str(out)], stdout=subprocess.PIPE, text=True
    )
    try:
        assert proc.stdout is not None and proc.stdout.readline().strip() == "held"
        yield proc
    finally:
        proc.kill()
        proc.wait()
