"""``habitsim bench data``: the synthetic data set build and forward-kinematics throughput.

:func:`run_data` builds a synthetic data set (every species, 40 clips each by default,
in a temporary folder unless ``out``) and measures the build's wall time and synthetic
clips per second, then forward-kinematics throughput in frames per second over every
frame of the built clips (:func:`fk_throughput`): numpy (:func:`habitsim.skeleton.fk`)
and torch (:func:`habitsim.models.kinematics.fk_torch`, float32 and float64, no
autograd), each batched per species. Target of the issue: the default data set builds in
≤ 120 s on 2 cores.
"""

from __future__ import annotations

import functools
import os
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from habitsim.dataset import DatasetBuild

__all__ = ["DataOptions", "DataResult", "FKThroughput", "fk_throughput", "run_data"]

#: Build-time target of the default data set [s] (on 2 cores).
TARGET_BUILD_S = 120.0
#: Clips per species of the default data set.
DEFAULT_CLIPS = 40


@dataclass(frozen=True)
class DataOptions:
    """What a ``bench data`` run does.

    Attributes:
        clips_per_species: clips per species.
        workers: worker processes (None: the CPU count).
        seed: build seed.
        out: build here (an existing data set there is replaced); None: a temporary folder.
        progress: show a progress bar.
    """

    clips_per_species: int = DEFAULT_CLIPS
    workers: int | None = None
    seed: int = 0
    out: str | None = None
    progress: bool = True


@dataclass(frozen=True)
class FKThroughput:
    """Forward-kinematics frames per second over every frame of a built data set.

    Attributes:
        frames: frames measured.
        numpy_fps, torch_f32_fps, torch_f64_fps: frames per second [1/s].
        torch_max_err_mm: largest float32 torch vs numpy position difference [mm].
    """

    frames: int
    numpy_fps: float
    torch_f32_fps: float
    torch_f64_fps: float
    torch_max_err_mm: float


@dataclass(frozen=True)
class DataResult:
    """A ``bench data`` run.

    Attributes:
        build: the data set build (manifest, wall time [s], workers).
        fk: the forward-kinematics throughput.
        cpus: CPUs of the machine.
        torch_threads: torch's CPU thread count.
        default: the build is the default data set (the target applies to it only).
        missed: the targets missed, one line each.
    """

    build: DatasetBuild
    fk: FKThroughput
    cpus: int | None
    torch_threads: int
    default: bool
    missed: tuple[str, ...]


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


def fk_throughput(out_dir: str | Path) -> FKThroughput:
    """Forward-kinematics frames per second over every frame of a built data set.

    Frames are concatenated per species (one skeleton each) and FK runs once per
    species per pass; the best of three passes counts.
    """
    import torch

    from habitsim.dataset import iter_clips
    from habitsim.models.kinematics import fk_torch
    from habitsim.skeleton import fk, get_skeleton

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
    fps: dict[str, float] = {}
    err = float("nan")
    for dtype, key in ((torch.float32, "f32"), (torch.float64, "f64")):
        tb = [
            (s, torch.as_tensor(r, dtype=dtype), torch.as_tensor(q, dtype=dtype))
            for s, r, q in batches
        ]
        with torch.no_grad():
            t = _best_time(functools.partial(_fk_all, fk_torch, tb))
        fps[key] = frames / t
        if dtype == torch.float32:
            with torch.no_grad():
                err = max(
                    float(np.abs(fk_torch(s, r, q).double().numpy() - fk(s, r0, q0)).max())
                    for (s, r, q), (_, r0, q0) in zip(tb, batches, strict=True)
                )
    return FKThroughput(frames, frames / t_np, fps["f32"], fps["f64"], err * 1000.0)


def _is_default(build: DatasetBuild) -> bool:
    """The build is the default data set (the target applies to it only)."""
    man = build.manifest
    return man.clips_per_species >= DEFAULT_CLIPS and len(man.species) >= 17


def run_data(options: DataOptions) -> DataResult:
    """Build the data set (never reusing clips: generation is timed) and measure FK."""
    from habitsim.dataset import build_dataset

    from .machine import torch_threads

    def run(out: str, overwrite: bool) -> DataResult:
        build = build_dataset(
            out,
            clips_per_species=options.clips_per_species,
            seed=options.seed,
            workers=options.workers,
            progress=options.progress,
            resume=False,  # time generation, never reuse clips
            overwrite=overwrite,
        )
        fk = fk_throughput(out)
        default = _is_default(build)
        missed: tuple[str, ...] = ()
        if default and build.wall_time_s > TARGET_BUILD_S:
            missed = (f"build {build.wall_time_s:.1f} s > {TARGET_BUILD_S:.0f} s",)
        return DataResult(build, fk, os.cpu_count(), torch_threads(), default, missed)

    if options.out is not None:
        return run(options.out, overwrite=True)
    with tempfile.TemporaryDirectory(prefix="habitsim-bench-") as tmp:
        return run(str(Path(tmp) / "data"), overwrite=False)
