"""``--executor dask`` on a real cluster (one ``dask-scheduler`` and two ``dask-worker``
processes on loopback) gives the same rows and summary as the local run."""

from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

distributed = pytest.importorskip(
    "distributed", reason="dask[distributed] is not installed (pip install 'habitsim[cluster]')"
)

from habitsim.dataset import build_dataset  # noqa: E402
from habitsim.evaluation.executors import DaskExecutor, ExecutorError, make_executor  # noqa: E402
from habitsim.evaluation.runner import VOLATILE_COLUMNS, EvalConfig, run_benchmark  # noqa: E402

pytestmark = pytest.mark.slow


def _rows(path: Path) -> list[dict[str, str]]:
    with open(path, newline="", encoding="utf-8") as fh:
        return [
            {k: v for k, v in r.items() if k not in VOLATILE_COLUMNS} for r in csv.DictReader(fh)
        ]


def _summary(path: Path) -> dict:
    s = json.loads(path.read_text())["methods"]
    for m in s.values():
        for k in VOLATILE_COLUMNS:
            m.pop(k, None)
    return s


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    """A scheduler and two single-thread workers on 127.0.0.1; yields the address."""
    tmp = tmp_path_factory.mktemp("dask")
    sched_file = tmp / "scheduler.json"
    env = dict(os.environ, OMP_NUM_THREADS="1", DASK_DISTRIBUTED__WORKER__DAEMON="False")
    address = None
    procs = [
        subprocess.Popen(
            [
                sys.executable,
                "-m",
                "distributed.cli.dask_scheduler",
                "--host",
                "127.0.0.1",
                "--port",
                "0",
                "--no-dashboard",
                "--scheduler-file",
                str(sched_file),
            ],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            env=env,
            cwd=tmp,
        )
    ]
    try:
        deadline = time.monotonic() + 60
        while not sched_file.is_file() and time.monotonic() < deadline:
            time.sleep(0.1)
        assert sched_file.is_file(), "dask scheduler did not start"
        address = json.loads(sched_file.read_text())["address"]
        for i in range(2):
            procs.append(
                subprocess.Popen(
                    [
                        sys.executable,
                        "-m",
                        "distributed.cli.dask_worker",
                        address,
                        "--nthreads",
                        "1",
                        "--nworkers",
                        "1",
                        "--no-dashboard",
                        "--host",
                        "127.0.0.1",
                        "--name",
                        f"w{i}",
                        "--local-directory",
                        str(tmp / f"w{i}"),
                    ],
                    stdout=subprocess.DEVNULL,
                    stderr=subprocess.DEVNULL,
                    env=env,
                    cwd=tmp,
                )
            )
        from distributed import Client

        with Client(address, timeout=30) as c:
            c.wait_for_workers(2, timeout=90)
        yield address
    finally:
        try:  # the scheduler stops itself and its workers
            from distributed import Client

            with Client(address, timeout=5) as c:
                c.shutdown()
        except Exception:  # noqa: BLE001 - fall back to terminating the processes
            pass
        for p in reversed(procs):
            if p.poll() is None:
                try:
                    p.wait(timeout=5)
                except subprocess.TimeoutExpired:
                    p.terminate()
        for p in reversed(procs):
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()


def test_dask_cluster_results_equal_local_run(cluster: str, tmp_path: Path) -> None:
    data = tmp_path / "data"
    build_dataset(
        data,
        clips_per_species=12,
        seed=0,
        species=["cat", "dog", "horse"],
        workers=1,
        progress=False,
    )
    common = dict(
        data=str(data),
        methods=("direct", "ground_truth"),
        refine="none",
        max_clips=1,
        report_pairs=1,
        videos=False,
        track=True,
    )
    local = run_benchmark(
        EvalConfig(out=str(tmp_path / "local"), **common), workers=1, progress=False, report=False
    )
    dask = run_benchmark(
        EvalConfig(out=str(tmp_path / "dask"), **common),
        executor="dask",
        scheduler=cluster,
        progress=False,
        report=False,
    )
    assert dask.computed == local.computed == 4
    assert _rows(dask.out / "rows.csv") == _rows(local.out / "rows.csv")
    assert _summary(dask.out / "summary.json") == _summary(local.out / "summary.json")


def test_executor_errors() -> None:
    with pytest.raises(ExecutorError, match="valid: dask, local"):
        make_executor("spark")
    with pytest.raises(ExecutorError, match="only used with --executor dask"):
        make_executor("local", scheduler="tcp://127.0.0.1:1")
    with pytest.raises(ExecutorError, match="cannot reach"):
        DaskExecutor("tcp://127.0.0.1:9", timeout_s=2.0)
