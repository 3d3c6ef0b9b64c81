"""Pool workers die with their parent (issue 17): SIGKILL or SIGTERM of a running
``habitsim data synth`` / ``habitsim eval`` leaves no worker process behind."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow

psutil = pytest.importorskip("psutil")


def _start(args: list[str], tmp_path: Path) -> tuple[subprocess.Popen, list]:
    """Start ``habitsim ARGS`` and wait until its pool workers are running."""
    env = dict(os.environ, OMP_NUM_THREADS="1")
    proc = subprocess.Popen(
        [sys.executable, "-m", "habitsim", *args],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        env=env,
        cwd=tmp_path,
    )
    parent = psutil.Process(proc.pid)
    deadline = time.monotonic() + 30
    workers: list = []
    while time.monotonic() < deadline and proc.poll() is None:
        workers = parent.children(recursive=True)
        if len(workers) >= 2:
            break
        time.sleep(0.05)
    assert len(workers) >= 2, f"no pool started: {proc.stderr.read().decode()[-500:]}"
    return proc, workers


def _assert_all_gone(workers: list, within_s: float = 5.0) -> None:
    gone, alive = psutil.wait_procs(workers, timeout=within_s)
    for p in alive:  # do not leave them behind even when the test fails
        p.kill()
    assert not alive, f"{len(alive)} worker(s) outlived their parent"


def _synth(tmp_path: Path) -> list[str]:
    return [
        "data",
        "synth",
        "--out",
        str(tmp_path / "d"),
        "--clips-per-species",
        "40",
        "--workers",
        "2",
        "--no-progress",
    ]


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM], ids=["SIGKILL", "SIGTERM"])
def test_synth_workers_die_with_the_parent(tmp_path: Path, sig: int) -> None:
    proc, workers = _start(_synth(tmp_path), tmp_path)
    time.sleep(0.3)  # let the workers start on clips
    proc.send_signal(sig)
    proc.wait(timeout=15)
    if sig == signal.SIGTERM:
        assert proc.returncode == 130  # stopped like Ctrl-C, not killed by the signal
    _assert_all_gone(workers)
    # nothing writes into the folder after the run is gone
    files = sorted((tmp_path / "d").rglob("*"))
    time.sleep(0.5)
    assert sorted((tmp_path / "d").rglob("*")) == files


_EXECUTOR_SCRIPT = """
import time
from habitsim.evaluation.executors import LocalExecutor

def slow(x):
    time.sleep(60)
    return x

if __name__ == "__main__":
    for _ in LocalExecutor(2).map_unordered(slow, list(range(8))):
        pass
"""


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM], ids=["SIGKILL", "SIGTERM"])
def test_eval_executor_workers_die_with_the_parent(tmp_path: Path, sig: int) -> None:
    """The local executor of ``habitsim eval`` (a parent stuck waiting on 60 s tasks)."""
    script = tmp_path / "run.py"
    script.write_text(_EXECUTOR_SCRIPT)
    proc = subprocess.Popen([sys.executable, str(script)], stderr=subprocess.PIPE)
    parent = psutil.Process(proc.pid)
    deadline = time.monotonic() + 20
    workers: list = []
    while time.monotonic() < deadline and len(workers) < 2:
        workers = parent.children(recursive=True)
        time.sleep(0.05)
    assert len(workers) >= 2
    time.sleep(0.3)
    proc.send_signal(sig)
    if sig == signal.SIGTERM:
        # a plain Python parent dies of SIGTERM at once, as it would of SIGKILL
        proc.wait(timeout=10)
    _assert_all_gone(workers)
    proc.wait(timeout=10)


@pytest.fixture(scope="module")
def eval_data(tmp_path_factory) -> Path:
    from habitsim.dataset import build_dataset

    out = tmp_path_factory.mktemp("data")
    build_dataset(
        out, clips_per_species=1, seed=0, species=["cat", "dog"], workers=1, progress=False
    )
    return out


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM], ids=["SIGKILL", "SIGTERM"])
def test_dask_eval_workers_die_with_the_parent(tmp_path: Path, eval_data: Path, sig: int) -> None:
    """``habitsim eval --executor dask`` (a local cluster of 2 worker processes) killed
    while its workers refine: no worker process is left, nothing is written after."""
    pytest.importorskip("distributed")
    out = tmp_path / "run"
    args = ["eval", "--data", str(eval_data), "--out", str(out), "--executor", "dask"]
    args += ["--workers", "2", "--methods", "direct", "--refine", "kinematic"]
    args += ["--split", "train", "--targets", "all", "--report-pairs", "1", "--no-videos"]
    args += ["--no-report", "--no-progress"]
    proc, _ = _start(args, tmp_path)
    parent = psutil.Process(proc.pid)
    time.sleep(3.0)  # the cluster's workers up and on their first pairs
    workers = parent.children(recursive=True)
    assert proc.poll() is None, "the run ended before it could be killed"
    proc.send_signal(sig)
    proc.wait(timeout=60)
    if sig == signal.SIGTERM:
        assert proc.returncode == 130  # stopped like Ctrl-C
    _assert_all_gone(workers, within_s=10.0)
    files = sorted(out.rglob("*"))
    time.sleep(1.0)
    assert sorted(out.rglob("*")) == files


_HELD_LOCK_SCRIPT = """
import time
from concurrent.futures import ProcessPoolExecutor

import habitsim.cli
from habitsim.workers import stop_pool

if __name__ == "__main__":
    pool = ProcessPoolExecutor(1)
    future = pool.submit(time.sleep, 60)
    while not future.running():
        time.sleep(0.01)
    # what an interrupt inside ``as_completed`` leaves behind: a future's lock held by
    # the main thread, so the pool's manager thread blocks when it cancels that future
    future._condition.acquire()
    stop_pool(pool, timeout_s=1.0)
    print("stopped", flush=True)
    habitsim.cli.main = lambda: 130  # a command that was interrupted
    habitsim.cli.run()
"""


def test_an_interrupt_that_left_a_future_lock_held_still_exits(tmp_path: Path) -> None:
    """With a future's lock left held, the pool's manager thread never ends; ``stop_pool``
    returns anyway, and ``habitsim.cli.run`` leaves with 130 instead of hanging in the exit
    hook of ``concurrent.futures`` that joins that thread."""
    script = tmp_path / "run.py"
    script.write_text(_HELD_LOCK_SCRIPT)
    proc = subprocess.run(
        [sys.executable, str(script)], capture_output=True, text=True, timeout=60, cwd=tmp_path
    )
    assert proc.stdout.strip() == "stopped", proc.stderr[-500:]
    assert proc.returncode == 130
