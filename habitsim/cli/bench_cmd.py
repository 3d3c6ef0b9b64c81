"""``habitsim bench ...``: benchmarks that print figures.

This module owns the ``bench`` sub-commands. It adds ``data`` itself, then each module of
:data:`_EXTRA` adds its own (``register(sub)`` with the ``bench`` sub-parsers).

``habitsim bench data`` builds the default synthetic data set (every species, 40 clips
each, in a temporary folder unless ``--out``) and prints synthetic clips per second, the
build's wall time, and forward-kinematics throughput in frames per second over every
frame of the built clips: numpy (:func:`habitsim.skeleton.fk`) and torch
(:func:`habitsim.models.kinematics.fk_torch`, float32 and float64, no autograd), each batched per
species. Target of the issue: the default data set builds in ≤ 120 s on 2 cores.
"""

from __future__ import annotations

import argparse
import functools
import os
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from ..dataset import DatasetBuild, build_dataset, iter_clips
from . import bench_balance, bench_model, bench_real, bench_refine, bench_sim, bench_train
from .conventions import add_check_option, check_exit

#: Modules of ``habitsim.cli`` that add more ``bench`` sub-commands, in help order.
_EXTRA = (bench_sim, bench_refine, bench_balance, bench_train, bench_model, bench_real)
#: Build-time target of the default data set [s] (on 2 cores).
TARGET_BUILD_S = 120.0
_DEFAULT_CLIPS = 40


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
        default=_DEFAULT_CLIPS,
        metavar="N",
        help=f"clips per species (default {_DEFAULT_CLIPS})",
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


def _fk_all(fk_fn: Callable[..., object], batches: list[tuple[Any, Any, Any]]) -> list[object]:
    """``fk_fn`` on every (skeleton, root, rotations) batch."""
    return [fk_fn(s, r, q) for s, r, q in batches]


def _best_time(fn: Callable[[], object], repeats: int = 3) -> float:
    """Fastest of ``repeats`` runs of ``fn`` [s] (after one warm-up run)."""
    fn()
    best = float("inf")
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return best


def fk_throughput(out_dir: str | Path) -> dict[str, float]:
    """Forward-kinematics frames per second over every frame of a built data set.

    Frames are concatenated per species (one skeleton each) and FK runs once per
    species per pass; the best of three passes counts.

    Returns:
        ``frames``, ``numpy_fps``, ``torch_f32_fps``, ``torch_f64_fps`` and
        ``torch_max_err_mm`` (largest float32 torch vs numpy position difference [mm]).
    """
    import torch

    from ..models.kinematics import fk_torch
    from ..skeleton import fk, get_skeleton

    roots: dict[str, list[np.ndarray]] = {}
    quats: dict[str, list[np.ndarray]] = {}
    for entry, m in iter_clips(out_dir):
        roots.setdefault(entry.species, []).append(m.root_positions)
        quats.setdefault(entry.species, []).append(m.rotations)
    batches = [
        (get_skeleton(sp), np.concatenate(roots[sp]), np.concatenate(quats[sp])) for sp in roots
    ]
    frames = sum(r.shape[0] for _, r, _ in batches)
    t_np = _best_time(lambda: [fk(s, r, q) for s, r, q in batches])
    out = {"frames": float(frames), "numpy_fps": frames / t_np}
    for dtype, key in ((torch.float32, "torch_f32_fps"), (torch.float64, "torch_f64_fps")):
        tb = [
            (s, torch.as_tensor(r, dtype=dtype), torch.as_tensor(q, dtype=dtype))
            for s, r, q in batches
        ]
        with torch.no_grad():
            t = _best_time(functools.partial(_fk_all, fk_torch, tb))
        out[key] = frames / t
        if dtype == torch.float32:
            with torch.no_grad():
                err = max(
                    float(np.abs(fk_torch(s, r, q).double().numpy() - fk(s, r0, q0)).max())
                    for (s, r, q), (_, r0, q0) in zip(tb, batches, strict=True)
                )
            out["torch_max_err_mm"] = err * 1000.0
    return out


def _is_default(build: DatasetBuild) -> bool:
    """The build is the default data set (the target applies to it only)."""
    man = build.manifest
    return man.clips_per_species >= _DEFAULT_CLIPS and len(man.species) >= 17


def _report(build: DatasetBuild, fk_stats: dict[str, float], cpus: int | None) -> str:
    man = build.manifest
    n = len(man.clips)
    frames = sum(c.frames for c in man.clips)
    default = _is_default(build)
    verdict = "met" if build.wall_time_s <= TARGET_BUILD_S else "MISSED"
    lines = [
        f"bench data: {n} clips ({len(man.species)} species × {man.clips_per_species}), "
        f"{frames} frames at {man.fps:g} fps, {build.workers} worker(s), {cpus} CPU(s)",
        f"  build wall time      {build.wall_time_s:8.2f} s"
        + (f"   (target ≤ {TARGET_BUILD_S:.0f} s on 2 cores: {verdict})" if default else ""),
        f"  synthetic clips/s    {n / build.wall_time_s:8.1f}   (generate + write + measure)",
        f"  synthetic frames/s   {frames / build.wall_time_s:8.0f}",
        f"  FK numpy frames/s    {fk_stats['numpy_fps']:8.0f}   "
        f"({int(fk_stats['frames'])} frames, batched per species)",
        f"  FK torch f32 frames/s{fk_stats['torch_f32_fps']:8.0f}   (max |Δ| vs numpy "
        f"{fk_stats['torch_max_err_mm']:.3g} mm)",
        f"  FK torch f64 frames/s{fk_stats['torch_f64_fps']:8.0f}",
    ]
    return "\n".join(lines)


def _bench_data(ns: argparse.Namespace) -> int:
    import torch

    missed: list[str] = []

    def run(out: str, overwrite: bool) -> None:
        build = build_dataset(
            out,
            clips_per_species=ns.clips_per_species,
            seed=ns.seed,
            workers=ns.workers,
            progress=not ns.no_progress,
            resume=False,  # time generation, never reuse clips
            overwrite=overwrite,
        )
        fk_stats = fk_throughput(out)
        print(_report(build, fk_stats, os.cpu_count()))
        print(f"  torch threads        {torch.get_num_threads():8d}")
        if _is_default(build) and build.wall_time_s > TARGET_BUILD_S:
            missed.append(f"build {build.wall_time_s:.1f} s > {TARGET_BUILD_S:.0f} s")

    if ns.out is not None:
        run(ns.out, overwrite=True)
    else:
        with tempfile.TemporaryDirectory(prefix="habitsim-bench-") as tmp:
            run(str(Path(tmp) / "data"), overwrite=False)
    return check_exit(missed, ns.check)
