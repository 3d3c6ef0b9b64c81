"""Shared test fixtures."""

from __future__ import annotations

from pathlib import Path

import pytest
from helpers import EVAL_ARGS

from habitsim.cli import main

pytest_plugins = ["pytester"]


@pytest.fixture
def torch_one_thread():
    """Run a test with one torch thread (bit-reproducible CPU results), then restore."""
    import torch

    n = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(n)


@pytest.fixture(scope="module")
def motion_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from habitsim.gaits import generate

    p = tmp_path_factory.mktemp("motion") / "walk.npz"
    generate("dog", "walk", seed=0, duration_s=0.5).save(p)
    return p


@pytest.fixture(scope="module")
def small_dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from habitsim.dataset import build_dataset

    out = tmp_path_factory.mktemp("data")
    build_dataset(
        out, clips_per_species=1, seed=0, species=["cat", "dog"], workers=1, progress=False
    )
    return out


@pytest.fixture(scope="module")
def eval_run(small_dataset: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("eval") / "run"
    assert main(["eval", "--data", str(small_dataset), "--out", str(out), *EVAL_ARGS]) == 0
    return out


@pytest.fixture
def unwritable(tmp_path: Path, request):
    """A folder path nothing can be written under (``request.param``: "file" or
    "read_only"); the read-only folder is made writable again at the end."""
    kind = request.param
    if kind == "file":
        blocker = tmp_path / "blocker"
        blocker.write_text("a file where a folder should be")
        yield blocker / "sub"
        return
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        yield ro / "sub"
    finally:
        ro.chmod(0o755)
