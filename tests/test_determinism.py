"""Same seed, same bytes: the command line's outputs (data sets, transfers, refinements,
tracking, evaluation tables) are byte-identical across runs, timing keys aside."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from helpers import EVAL_ARGS, files_under, run_cli

#: Keys of wall-clock measurements in JSON reports and tables (never in array files).
_TIMING_KEY = re.compile(
    r"(wall|cpu|solve|build|mean|max)_time|^time_|realtime_factor|median_ms$|^cpu_total_s$"
)


def _without_timing(v, drop: tuple[str, ...] = ()):
    if isinstance(v, dict):
        return {
            k: _without_timing(x, drop)
            for k, x in v.items()
            if not _TIMING_KEY.search(str(k)) and k not in drop
        }
    if isinstance(v, list):
        return [_without_timing(x, drop) for x in v]
    return v


def _same_bytes(a: Path, b: Path) -> None:
    assert a.read_bytes() == b.read_bytes(), f"{a.name}: same seed, different bytes"


def _same_report(a: Path, b: Path, drop: tuple[str, ...] = ()) -> None:
    """Same JSON but for timing keys (and the keys ``drop``, e.g. the output folder)."""
    ra, rb = (_without_timing(json.loads(p.read_text()), drop) for p in (a, b))
    assert ra == rb, f"{a.name}: same seed, different report (timing keys removed)"


def _twice(tmp_path: Path, capsys, argv: list) -> tuple[Path, Path]:
    """Run ``habitsim ARGV`` in folders run1/ and run2/ ({d} = the folder)."""
    outs = []
    for k in (1, 2):
        d = tmp_path / f"run{k}"
        d.mkdir()
        code, err = run_cli([str(a).format(d=d) for a in argv], capsys)
        assert code == 0, err
        outs.append(d)
    return outs[0], outs[1]


def test_same_seed_synth_is_byte_identical(tmp_path: Path, capsys) -> None:
    a, b = _twice(
        tmp_path,
        capsys,
        [
            "data",
            "synth",
            "--out",
            "{d}/data",
            "--species",
            "cat,dog",
            "--clips-per-species",
            "1",
            "--workers",
            "1",
            "--no-progress",
        ],
    )
    files = files_under(a / "data")
    assert files == files_under(b / "data") and any(f.endswith(".npz") for f in files)
    for f in files:
        if (a / "data" / f).is_file():
            _same_bytes(a / "data" / f, b / "data" / f)


@pytest.mark.parametrize("method", ["direct", "habit"])
def test_same_seed_transfer_is_byte_identical(
    tmp_path: Path, motion_file: Path, capsys, method: str
) -> None:
    argv = ["transfer", motion_file, "--to", "cat", "--method", method, "--seed", "3"]
    a, b = _twice(tmp_path, capsys, [*argv, "--out", "{d}/o.npz", "--bvh", "{d}/o.bvh"])
    _same_bytes(a / "o.npz", b / "o.npz")
    _same_bytes(a / "o.bvh", b / "o.bvh")


@pytest.mark.slow
def test_same_seed_refine_is_byte_identical(tmp_path: Path, motion_file: Path, capsys) -> None:
    a, b = _twice(
        tmp_path,
        capsys,
        [
            "refine",
            motion_file,
            "--max-iter",
            "20",
            "--out",
            "{d}/r.npz",
            "--qpos",
            "{d}/q.npz",
            "--report",
            "{d}/r.json",
        ],
    )
    _same_bytes(a / "r.npz", b / "r.npz")  # no solve time in the motion's metadata
    _same_bytes(a / "q.npz", b / "q.npz")
    _same_report(a / "r.json", b / "r.json")


@pytest.mark.slow
def test_same_seed_track_is_byte_identical(tmp_path: Path, motion_file: Path, capsys) -> None:
    a, b = _twice(
        tmp_path, capsys, ["track", motion_file, "--out", "{d}/s.npz", "--report", "{d}/s.json"]
    )
    _same_bytes(a / "s.npz", b / "s.npz")
    _same_report(a / "s.json", b / "s.json")


def test_same_seed_eval_tables_are_identical(
    tmp_path: Path, small_dataset: Path, eval_run: Path, capsys
) -> None:
    import csv

    from habitsim.evaluation.runner import VOLATILE_COLUMNS

    again = tmp_path / "run"
    code, err = run_cli(["eval", "--data", small_dataset, "--out", again, *EVAL_ARGS], capsys)
    assert code == 0, err
    assert files_under(eval_run) == files_under(again)
    arrays = [f for f in files_under(again) if f.endswith(".npz")]
    assert arrays
    for f in [*arrays, "summary.csv"]:
        _same_bytes(eval_run / f, again / f)

    def rows(p: Path) -> list[dict]:
        with p.open(newline="", encoding="utf-8") as fh:
            return [
                {k: v for k, v in r.items() if k not in VOLATILE_COLUMNS}
                for r in csv.DictReader(fh)
            ]

    assert rows(eval_run / "rows.csv") == rows(again / "rows.csv")
    for f in ["summary.json", *(f for f in files_under(again) if f.startswith("rows/"))]:
        _same_report(eval_run / f, again / f, drop=("out",))


def _pools() -> list[tuple[str, int]]:
    from threadpoolctl import threadpool_info

    return sorted((d["filepath"], d["num_threads"]) for d in threadpool_info())


def test_one_thread_limits_every_pool_and_restores_them() -> None:
    import torch

    from habitsim.threads import one_thread

    before, torch_before = _pools(), torch.get_num_threads()
    with one_thread():
        assert torch.get_num_threads() == 1
        assert {n for _, n in _pools()} == {1}
    assert _pools() == before and torch.get_num_threads() == torch_before


def _under_threads(n: int, fn):
    """``fn()`` with torch, BLAS and OpenMP set to ``n`` threads by the caller."""
    import torch
    from threadpoolctl import threadpool_limits

    import habitsim.threads  # noqa: F401  (CasADi's OpenBLAS known to threadpoolctl)

    old = torch.get_num_threads()
    torch.set_num_threads(n)
    try:
        with threadpool_limits(limits=n):
            return fn()
    finally:
        torch.set_num_threads(old)


def test_transfer_does_not_depend_on_the_callers_threads() -> None:
    import numpy as np

    import habitsim
    from habitsim.gaits import generate

    m = generate("dog", "trot", seed=1, duration_s=4.0)
    one, two = (
        _under_threads(n, lambda: habitsim.transfer(m, "cat", seed=3, plant=False)) for n in (1, 2)
    )
    assert np.array_equal(one.rotations, two.rotations)
    assert np.array_equal(one.root_positions, two.root_positions)


@pytest.fixture(scope="module")
def trot_to_cat(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 3 s trot transferred to the cat (long enough for threads to change sums)."""
    import habitsim
    from habitsim.gaits import generate

    p = tmp_path_factory.mktemp("trot") / "cat.npz"
    habitsim.transfer(generate("dog", "trot", seed=1, duration_s=3.0), "cat", seed=3).save(p)
    return p


@pytest.mark.slow
def test_refine_does_not_depend_on_the_machines_threads(tmp_path: Path, trot_to_cat: Path) -> None:
    """``habitsim refine`` in processes whose BLAS libraries start with 1 and 2 threads
    (as on machines of 1 and 2 cores): the same bytes."""
    import os
    import subprocess
    import sys

    outs = []
    for n in ("1", "2"):
        env = {**os.environ, "OPENBLAS_NUM_THREADS": n, "OMP_NUM_THREADS": n}
        out = tmp_path / f"r{n}.npz"
        argv = ["refine", str(trot_to_cat), "--max-iter", "20", "--out", str(out)]
        done = subprocess.run(
            [sys.executable, "-m", "habitsim", *argv], env=env, capture_output=True, text=True
        )
        assert done.returncode == 0, done.stderr
        outs.append(out)
    _same_bytes(*outs)
