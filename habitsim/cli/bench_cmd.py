"""``habitsim bench ...``: benchmarks that print figures.

This module owns the ``bench`` sub-commands. It adds ``data`` itself, then each module of
:data:`_EXTRA` adds its own (``register(sub)`` with the ``bench`` sub-parsers). The
benchmarks themselves live in :mod:`habitsim.evaluation.bench`, one module each; these
modules parse, call them and print.

``habitsim bench data`` (:mod:`habitsim.evaluation.bench.data`) builds the default
synthetic data set (every species, 40 clips each, in a temporary folder unless ``--out``)
and prints synthetic clips per second, the build's wall time, and forward-kinematics
throughput in frames per second, numpy and torch. Target of the issue: the default data
set builds in ≤ 120 s on 2 cores.
"""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from ..evaluation.bench.data import DEFAULT_CLIPS, TARGET_BUILD_S
from . import (
    bench_balance,
    bench_export,
    bench_inplace,
    bench_model,
    bench_oneshot,
    bench_real,
    bench_refine,
    bench_render,
    bench_sim,
    bench_t2m,
    bench_train,
    bench_variants,
)
from .conventions import add_check_option, check_exit

if TYPE_CHECKING:  # pragma: no cover
    from ..evaluation.bench.data import DataResult

#: Modules of ``habitsim.cli`` that add more ``bench`` sub-commands, in help order.
_EXTRA = (
    bench_sim,
    bench_refine,
    bench_balance,
    bench_train,
    bench_model,
    bench_real,
    bench_export,
    bench_inplace,
    bench_variants,
    bench_render,
    bench_t2m,
    bench_oneshot,
)


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``data`` (and the sub-commands of the :data:`_EXTRA` modules) to ``bench``."""
    p = sub.add_parser(
        "data",
        help="time the synthetic data set build and forward kinematics",
        description=(
            "Build the default synthetic data set (every species) and print synthetic clips "
            "per second, wall time, and numpy / torch FK frames per second."
        ),
    )
    p.add_argument(
        "--clips-per-species",
        type=int,
        default=DEFAULT_CLIPS,
        metavar="N",
        help=f"clips per species (default {DEFAULT_CLIPS})",
    )
    p.add_argument("--workers", type=int, metavar="W", help="worker processes (default: CPU count)")
    p.add_argument("--seed", type=int, default=0, metavar="S", help="build seed (default 0)")
    p.add_argument(
        "--out",
        metavar="DIR",
        help="build here (an existing data set in DIR is replaced); default: a temporary folder",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_check_option(
        p,
        help="exit with code 1 when the default data set builds slower than "
        f"the target ({TARGET_BUILD_S:.0f} s; default: print the verdict, exit 0)",
    )
    p.set_defaults(func=_bench_data)

    for mod in _EXTRA:
        mod.register(sub)


def _report(res: DataResult) -> str:
    build, fk = res.build, res.fk
    man = build.manifest
    n = len(man.clips)
    frames = sum(c.frames for c in man.clips)
    verdict = "met" if build.wall_time_s <= TARGET_BUILD_S else "MISSED"
    lines = [
        f"bench data: {n} clips ({len(man.species)} species × {man.clips_per_species}), "
        f"{frames} frames at {man.fps:g} fps, {build.workers} worker(s), {res.cpus} CPU(s)",
        f"  build wall time      {build.wall_time_s:8.2f} s"
        + (f"   (target ≤ {TARGET_BUILD_S:.0f} s on 2 cores: {verdict})" if res.default else ""),
        f"  synthetic clips/s    {n / build.wall_time_s:8.1f}   (generate + write + measure)",
        f"  synthetic frames/s   {frames / build.wall_time_s:8.0f}",
        f"  FK numpy frames/s    {fk.numpy_fps:8.0f}   ({fk.frames} frames, batched per species)",
        f"  FK torch f32 frames/s{fk.torch_f32_fps:8.0f}   (max |Δ| vs numpy "
        f"{fk.torch_max_err_mm:.3g} mm)",
        f"  FK torch f64 frames/s{fk.torch_f64_fps:8.0f}",
    ]
    return "\n".join(lines)


def _bench_data(ns: argparse.Namespace) -> int:
    from ..evaluation.bench.data import DataOptions, run_data

    res = run_data(
        DataOptions(
            clips_per_species=ns.clips_per_species,
            workers=ns.workers,
            seed=ns.seed,
            out=ns.out,
            progress=not ns.no_progress,
        )
    )
    print(_report(res))
    print(f"  torch threads        {res.torch_threads:8d}")
    return check_exit(res.missed, ns.check)
