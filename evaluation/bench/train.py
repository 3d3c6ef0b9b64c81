"""``habitsim bench train``: training throughput and transfer latency of the learning core.

Training throughput (:func:`training_throughput`): optimiser steps of a preset's model
(fresh weights) on windows of synthetic clips generated in memory (no data set needed):
steps/s, windows/s, frames/s. Transfer latency (:func:`transfer_latency`):
:func:`habitsim.models.transfer` of one 64-frame clip (horse trot to cat) with a
checkpoint (default: the shipped ``habit`` one), best and median of repeats, end to end
(features, network, blending, contacts) and for the network alone. Target of the issue:
≤ 20 ms per 64-frame clip on CPU.
"""

from __future__ import annotations

import statistics
import time
from dataclasses import dataclass
from pathlib import Path

__all__ = ["TrainOptions", "TrainResult", "run_train", "training_throughput", "transfer_latency"]

#: Transfer latency target per 64-frame clip [ms].
TARGET_LATENCY_MS = 20.0


@dataclass(frozen=True)
class TrainOptions:
    """What a ``bench train`` run does.

    Attributes:
        config: the training preset to time (:func:`habitsim.models.config.preset`).
        steps: timed training steps.
        threads: torch CPU threads (None: the preset's).
        checkpoint: checkpoint of the latency (None: the shipped one).
        repeats: latency repeats.
    """

    config: str = "default"
    steps: int = 10
    threads: int | None = None
    checkpoint: str | Path | None = None
    repeats: int = 20


@dataclass(frozen=True)
class TrainResult:
    """A ``bench train`` run.

    Attributes:
        threads: torch's CPU thread count during the run.
        throughput: :func:`training_throughput`'s figures.
        latency: :func:`transfer_latency`'s figures [ms].
        latency_met: the median end-to-end latency meets :data:`TARGET_LATENCY_MS`.
        missed: the targets missed, one line each.
    """

    threads: int
    throughput: dict[str, float]
    latency: dict[str, float]
    latency_met: bool
    missed: tuple[str, ...]


def training_throughput(config: str = "default", steps: int = 10) -> dict[str, float]:
    """Steps/s of fresh training on in-memory synthetic windows (after 2 warm-up steps);
    for a staged preset (:data:`habitsim.models.recipe.RECIPES`) of its final model, with
    the steps of every stage planned."""
    import numpy as np
    import torch

    from habitsim.gaits import available_actions, generate
    from habitsim.models.config import preset
    from habitsim.models.data import ClipSet, WindowSampler, feature_stats
    from habitsim.models.features import clip_arrays
    from habitsim.models.recipe import RECIPES, single_run_config, stage_configs
    from habitsim.models.train import build_untrained, compute_losses
    from habitsim.species import species_names, training_species

    cfg = preset(config)
    planned = cfg.train.steps
    if config in RECIPES:  # a staged preset: time its final model, plan every stage's steps
        planned = sum(c.train.steps for c in stage_configs(cfg, RECIPES[config]))
        cfg = single_run_config(cfg, RECIPES[config])
    clips, acts = [], []
    keys: list[str | None] = []
    for sp in training_species():
        for k, action in enumerate(available_actions(sp)[:3]):
            m = generate(sp, action, seed=1000 + k, duration_s=4.0)
            clips.append(clip_arrays(m))
            keys.append(f"{action}:{1000 + k}")
            acts.append(action)
    data = ClipSet(clips, keys, acts, clips[0].fps)
    rng = np.random.default_rng(0)
    emb = {
        n: np.random.default_rng(i).standard_normal(384).astype(np.float32)
        for i, n in enumerate(species_names())
    }  # timing only: no text model needed
    model = build_untrained(
        cfg, sorted({c.species for c in clips}), emb, feature_stats(data, cfg.model.window)
    )
    opt = torch.optim.AdamW(model.parameters(), lr=cfg.train.lr)
    sampler = WindowSampler(data, cfg.model.window, rng, paired=cfg.train.paired_weight > 0)
    gen = torch.Generator().manual_seed(0)

    def step() -> None:
        loss, _ = compute_losses(model, sampler.sample(cfg.train.batch_size), cfg, gen, data.fps)
        opt.zero_grad()
        loss.backward()
        opt.step()

    for _ in range(2):
        step()
    t = time.perf_counter()
    for _ in range(steps):
        step()
    dt = (time.perf_counter() - t) / steps
    return {
        "s_per_step": dt,
        "steps_per_s": 1.0 / dt,
        "windows_per_s": cfg.train.batch_size / dt,
        "frames_per_s": cfg.train.batch_size * cfg.model.window / dt,
        "planned_steps": float(planned),
        "planned_minutes": planned * dt / 60.0,
    }


def transfer_latency(checkpoint: str | Path | None = None, repeats: int = 20) -> dict[str, float]:
    """Latency [ms] of transferring one 64-frame clip (best and median of ``repeats``)."""
    import torch

    from habitsim.gaits import generate
    from habitsim.models.features import canonical_window, clip_arrays
    from habitsim.models.transfer import load_model, transfer

    clip = generate("horse", "trot", seed=7, duration_s=70 / 30.0)
    clip = clip.slice(0, 64)
    ck = load_model(checkpoint)
    transfer(clip, to="cat", checkpoint=checkpoint)  # warm-up (loads the model)
    full = []
    for _ in range(repeats):
        t = time.perf_counter()
        transfer(clip, to="cat", checkpoint=checkpoint, seed=1)
        full.append(time.perf_counter() - t)
    m = ck.model
    w = ck.config.model.window
    x = torch.from_numpy(canonical_window(clip_arrays(clip), 0, w)[0][None])
    net = []
    with torch.no_grad():
        for _ in range(repeats):
            t = time.perf_counter()
            codes = m.quantize(m.encode(x), sample=False, update=False).quantized
            z = m.sample_prior("cat", 1, torch.Generator().manual_seed(1)) if m.cfg.use_z else None
            m.decode(codes, m.condition(["cat"], z), m.path(x))
            net.append(time.perf_counter() - t)
    return {
        "frames": float(clip.num_frames),
        "end_to_end_best_ms": 1000 * min(full),
        "end_to_end_median_ms": 1000 * statistics.median(full),
        "network_best_ms": 1000 * min(net),
        "network_median_ms": 1000 * statistics.median(net),
    }


def run_train(options: TrainOptions) -> TrainResult:
    """Time training (after setting torch's threads) and the transfer latency."""
    from habitsim.models.config import preset

    from .machine import torch_threads

    threads = options.threads
    if threads is None:
        threads = preset(options.config).train.threads
    torch_threads(threads)
    tp = training_throughput(options.config, options.steps)
    threads_used = torch_threads()
    lat = transfer_latency(options.checkpoint, options.repeats)
    met = lat["end_to_end_median_ms"] <= TARGET_LATENCY_MS
    missed = (
        ()
        if met
        else (
            f"transfer latency {lat['end_to_end_median_ms']:.1f} ms > {TARGET_LATENCY_MS:.0f} ms",
        )
    )
    return TrainResult(threads_used, tp, lat, met, missed)
