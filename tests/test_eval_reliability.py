"""``habitsim eval`` when a worker dies or a method misbehaves: a worker killed once
(as the out-of-memory killer would) is retried and the table is the clean run's; a pair
that kills its worker every time, a method that hangs past ``--method-timeout``, raises
or returns garbage each end as a failed row with a note, exit code 1, no traceback. And
the tables do not depend on the number of workers."""

from __future__ import annotations

import csv
import json
import os
import re
import signal
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from helpers import run_cli

from habitsim.cli import main
from habitsim.evaluation.runner import VOLATILE_COLUMNS
from habitsim.transfer_methods import direct_transfer, method_names, register_method

#: What the test methods read from the environment: the marker file of ``flaky``.
_MARKER = "HABITSIM_TEST_FLAKY_MARKER"


def _flaky(source: Any, target: str, **kw: Any) -> Any:
    """SIGKILL its worker the first time (no marker yet), then transfer as ``direct``."""
    marker = os.environ.get(_MARKER, "")
    if marker and not os.path.exists(marker):
        Path(marker).write_text("died")
        os.kill(os.getpid(), signal.SIGKILL)
    return direct_transfer(source, target, **kw)


def _kills_always(source: Any, target: str, **kw: Any) -> Any:
    os.kill(os.getpid(), signal.SIGKILL)


def _hangs(source: Any, target: str, **kw: Any) -> Any:
    while True:
        time.sleep(0.01)


def _raises(source: Any, target: str, **kw: Any) -> Any:
    raise RuntimeError("boom")


def _nan_motion(source: Any, target: str, **kw: Any) -> Any:
    out = direct_transfer(source, target, **kw)
    out.root_positions[:] = np.nan
    return out


def _wrong_type(source: Any, target: str, **kw: Any) -> Any:
    return np.zeros((3, 4))


def _exits(source: Any, target: str, **kw: Any) -> Any:
    raise SystemExit(3)  # a plugin calling sys.exit (found by the fuzzer)


_METHODS = {
    "t_flaky": _flaky,
    "t_kills_always": _kills_always,
    "t_hangs": _hangs,
    "t_raises": _raises,
    "t_nan_motion": _nan_motion,
    "t_wrong_type": _wrong_type,
    "t_exits": _exits,
}


@pytest.fixture(scope="module", autouse=True)
def _methods() -> None:
    for name, fn in _METHODS.items():
        if name not in method_names():
            register_method(name, fn, "test method")


def _args(data: Path, out: Path, methods: str, workers: int, *extra: str) -> list[Any]:
    return [
        "eval",
        "--data",
        data,
        "--out",
        out,
        "--methods",
        methods,
        "--refine",
        "none",
        "--workers",
        str(workers),
        "--report-pairs",
        "0",
        "--no-videos",
        "--no-report",
        "--no-progress",
        "--split",
        "train",
        "--no-track",
        "--no-dynamic",
        "--targets",
        "all",
        *extra,
    ]


def _rows(out: Path) -> list[dict[str, str]]:
    with open(out / "rows.csv", newline="", encoding="utf-8") as fh:
        return [
            {k: v for k, v in r.items() if k not in VOLATILE_COLUMNS} for r in csv.DictReader(fh)
        ]


def _summary(out: Path) -> dict[str, Any]:
    s = json.loads((out / "summary.json").read_text())["methods"]
    for m in s.values():
        for k in VOLATILE_COLUMNS:
            m.pop(k, None)
    return s


def test_tables_do_not_depend_on_the_number_of_workers(
    small_dataset: Path, tmp_path: Path, capsys
) -> None:
    for n in (1, 2):
        code, err = run_cli(_args(small_dataset, tmp_path / f"w{n}", "direct", n), capsys)
        assert code == 0, err
    assert _rows(tmp_path / "w1") == _rows(tmp_path / "w2")
    assert len(_rows(tmp_path / "w1")) == 2
    assert _summary(tmp_path / "w1") == _summary(tmp_path / "w2")


def test_a_worker_killed_once_is_retried_and_the_table_is_the_clean_runs(
    small_dataset: Path, tmp_path: Path, capsys, monkeypatch
) -> None:
    marker = tmp_path / "marker"
    marker.write_text("no kill")  # the clean run: the marker is there
    monkeypatch.setenv(_MARKER, str(marker))
    code, err = run_cli(_args(small_dataset, tmp_path / "clean", "t_flaky", 2), capsys)
    assert code == 0, err
    marker.unlink()  # now the first pair kills its worker once
    code = main([str(a) for a in _args(small_dataset, tmp_path / "killed", "t_flaky", 2)])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert marker.read_text() == "died"
    assert "worker process died" in out
    assert _rows(tmp_path / "killed") == _rows(tmp_path / "clean")
    assert _summary(tmp_path / "killed") == _summary(tmp_path / "clean")


def test_a_pair_that_always_kills_its_worker_is_a_failed_row(
    small_dataset: Path, tmp_path: Path, capsys
) -> None:
    code, err = run_cli(
        _args(small_dataset, tmp_path / "o", "t_kills_always,direct", 2, "--retries", "1"), capsys
    )
    assert code == 1
    assert "Traceback" not in err
    rows = _rows(tmp_path / "o")
    bad = [r for r in rows if r["method"] == "t_kills_always"]
    assert len(bad) == 2 and all(r["status"] == "error" for r in bad)
    assert all("worker process died" in r["note"] and "2 times" in r["note"] for r in bad)
    assert all(r["status"] == "ok" for r in rows if r["method"] == "direct")
    assert "worker process died" in err  # the failed rows are listed on stderr
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())["methods"]
    assert summary["t_kills_always"]["error"] == 2


@pytest.mark.parametrize("workers", [1, 2])
def test_a_method_that_hangs_is_stopped_by_the_time_limit(
    small_dataset: Path, tmp_path: Path, capsys, workers: int
) -> None:
    t0 = time.monotonic()
    code, err = run_cli(
        _args(small_dataset, tmp_path / "o", "t_hangs", workers, "--method-timeout", "0.5"),
        capsys,
    )
    assert time.monotonic() - t0 < 60
    assert code == 1 and "Traceback" not in err
    rows = _rows(tmp_path / "o")
    assert len(rows) == 2
    assert all(
        r["status"] == "error" and "method 't_hangs' exceeded 0.5 s" in r["note"] for r in rows
    )


@pytest.mark.parametrize("method", ["t_raises", "t_nan_motion", "t_wrong_type", "t_exits"])
def test_a_method_that_raises_or_returns_garbage_is_a_failed_row(
    small_dataset: Path, tmp_path: Path, capsys, method: str
) -> None:
    code, err = run_cli(_args(small_dataset, tmp_path / "o", method, 1), capsys)
    assert code == 1 and "Traceback" not in err
    rows = _rows(tmp_path / "o")
    assert rows and all(r["status"] == "error" and r["note"] for r in rows)
    # garbage is refused by habitsim's checks, not a raw error
    if method not in ("t_raises", "t_exits"):
        assert not any(re.search(r"\(\w+\.py:\d+\)$", r["note"]) for r in rows), rows


def test_method_timeout_and_retries_are_checked(small_dataset: Path, tmp_path: Path, capsys):
    for extra in (["--method-timeout", "0"], ["--method-timeout", "nan"], ["--retries", "-1"]):
        code, err = run_cli(_args(small_dataset, tmp_path / "o", "direct", 1, *extra), capsys)
        assert code == 2 and err.startswith("error: "), (extra, err)


@pytest.mark.slow
def test_dask_tables_equal_the_local_ones(small_dataset: Path, tmp_path: Path, capsys) -> None:
    """``--executor dask`` (a local cluster of two worker processes) gives the rows and
    summary of ``--workers 1``."""
    pytest.importorskip("distributed")
    code, err = run_cli(_args(small_dataset, tmp_path / "local", "direct", 1), capsys)
    assert code == 0, err
    argv = _args(small_dataset, tmp_path / "dask", "direct", 2, "--executor", "dask")
    code, err = run_cli(argv, capsys)
    assert code == 0, err
    assert _rows(tmp_path / "dask") == _rows(tmp_path / "local")
    assert _summary(tmp_path / "dask") == _summary(tmp_path / "local")
