"""Training of the habit-preserving VQ-VAE (``habitsim train``).

One optimiser (AdamW) trains everything jointly on random heading-canonical windows:

    L = L_re(m, m̂)                               smooth-L1 on q (+ height) + α·smooth-L1 on v
      + β·‖f − sg(e)‖²                            commitment (the codebook learns by EMA)
      + w_kl·E_q[log q(z|m) − log p_c(z)]          habit posterior vs. its species' flow prior
      + w_pair·L_re(m_B, D(f_A, z_B, g_B))        paired cross-species term (habitsim data),
                                                  z_B ~ p_B drawn from B's prior as at transfer
      + w_pos·[smooth-L1 of FK pose rel. pelvis      joint-position term (pose and root path
               + smooth-L1 of the pelvis path] / h   as separate terms)
      + w_c·BCE(contact logits, stance labels)      decoded foot contacts (4 channels)
      + w_st·smooth-L1(toe velocity / leg, 0)        feet rest on the labels' stance frames
                                                  (toe velocity by FK of the decoded window)

The paired term carries the contact and stance terms of B's clip too. Augmentations
(``TrainConfig``): Gaussian noise on the encoder's input, speed variants of every clip,
and, with residual codebooks, quantizer dropout.

The −log p_c(z) part of the KL term is the prior's NLL of paper eq. 10; the log q part
keeps the Gaussian posterior from collapsing onto a point. The learning rate warms up
linearly, stays at ``lr`` and drops to ``lr_final`` after the fraction ``lr_drop`` of the
steps (the paper's two-level schedule). Validation reports, on fixed windows of the val
split, the reconstruction MPJPE (mm and % of leg length) and, for val pairs, the paired
transfer MPJPE of the model (z from the target's prior) beside the ``direct`` baseline.

Everything random is seeded from ``TrainConfig.seed``: the weights (inside
:func:`torch.random.fork_rng`, so the caller's global RNG is untouched), the window
sampler (:class:`numpy.random.Generator`) and the stochastic layers (a
:class:`torch.Generator`). A resumable checkpoint stores all three states.

Parts: the loss terms in :mod:`habitsim.models.losses`, validation in
:mod:`habitsim.models.validation`, the optimiser state of a resumable checkpoint in
:mod:`habitsim.models.resume`, and the start of a fine-tune in
:mod:`habitsim.models.finetune`; the training windows come from
:mod:`habitsim.models.data`.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from ..jsonfile import load_json
from ..species import training_species
from .checkpoint import (
    CONFIG_FILE,
    LoadedCheckpoint,
    load_checkpoint,
    load_train_state,
    read_checkpoint_config,
    save_checkpoint,
)
from .config import Config
from .data import ClipSet, WindowSampler, feature_stats, load_clip_set
from .errors import CheckpointError, TrainingDataError
from .finetune import _init_state, _load_init
from .finetune import resolve_init as resolve_init
from .losses import _contact_loss as _contact_loss
from .losses import _position_loss as _position_loss
from .losses import _recon_terms as _recon_terms
from .losses import _stance_loss as _stance_loss
from .losses import compute_losses
from .model import HabitVQVAE
from .resume import _optimizer_state, _restore_optimizer, _same_except_steps
from .text import species_embeddings
from .validation import _Validator, evaluate_windows
from .validation import direct_windows as direct_windows

__all__ = ["TrainResult", "build_untrained", "compute_losses", "evaluate_windows", "train", "lr_at"]


@dataclass
class TrainResult:
    """Outcome of :func:`train`.

    Attributes:
        out_dir: checkpoint folder.
        steps: optimiser steps done in total.
        wall_time_s: wall time of this run [s].
        metrics: last validation figures.
        history: every validation record.
    """

    out_dir: Path
    steps: int
    wall_time_s: float
    metrics: dict[str, float]
    history: list[dict[str, Any]] = field(default_factory=list)


def warmup_cosine(step: int, steps: int, warmup: int, lr: float, lr_final: float) -> float:
    """Learning rate of optimiser step ``step`` (0-based) of ``steps``: linear warm-up over
    ``warmup`` steps to ``lr``, then a cosine down to ``lr_final`` at the last step."""
    if warmup and step < warmup:
        return lr * (step + 1) / warmup
    span = max(1, steps - 1 - warmup)
    frac = min(1.0, (step - warmup) / span)
    return lr_final + 0.5 * (lr - lr_final) * (1.0 + math.cos(math.pi * frac))


def lr_at(step: int, cfg: Config) -> float:
    """Learning rate of optimiser step ``step`` (0-based)."""
    t = cfg.train
    if t.lr_schedule == "cosine" or (t.warmup_steps and step < t.warmup_steps):
        return warmup_cosine(step, t.steps, t.warmup_steps, t.lr, t.lr_final)
    return t.lr if step < t.lr_drop * t.steps else t.lr_final


def build_untrained(
    cfg: Config,
    species: list[str],
    text: dict[str, np.ndarray],
    stats: tuple[np.ndarray, np.ndarray],
) -> HabitVQVAE:
    """A freshly initialised model (weights seeded by ``cfg.train.seed``)."""
    names = sorted(text)
    dim = int(next(iter(text.values())).shape[0])
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(cfg.train.seed)
        model = HabitVQVAE(cfg.model, species, names, dim)
    with torch.no_grad():
        model.text_table.copy_(torch.from_numpy(np.stack([text[n] for n in names])))
        model.feat_mean.copy_(torch.from_numpy(stats[0]))
        model.feat_std.copy_(torch.from_numpy(stats[1]))
    return model


def train(
    data_dir: str | Path,
    out_dir: str | Path,
    config: Config,
    *,
    resume: bool = False,
    overwrite: bool = False,
    progress: bool = True,
    log: Callable[[str], None] = print,
    text_embeddings: dict[str, np.ndarray] | None = None,
    init: str | Path | None = None,
    rehearse: str | Path | None = None,
    rehearse_share: float = 0.5,
) -> TrainResult:
    """Train a model on a synthetic data set and write a checkpoint folder.

    Args:
        data_dir: data set folder (``habitsim data synth``); its ``train`` split of
            training species is used for training, ``val`` for validation.
        out_dir: checkpoint folder (see :mod:`habitsim.models.checkpoint`).
        config: configuration (:func:`habitsim.models.config.preset`).
        resume: continue from the training state in ``out_dir`` (the config may only
            differ in the number of steps and the validation / checkpoint periods).
        overwrite: replace a checkpoint already in ``out_dir`` instead of refusing.
        progress: show a tqdm progress bar.
        log: where one-line messages go.
        text_embeddings: ``{species: g}`` to use instead of embedding the catalog's
            descriptions with ``config.model.text.model`` (tests, custom texts).
        init: fine-tune: start from this checkpoint's weights (a folder, or a shipped
            variant name such as ``habit``) instead of a fresh model. ``config.model``
            must equal the checkpoint's, except that ``model.path_heading`` may be
            switched on for a path-conditioned checkpoint (the new channels start at
            zero); its species, text embeddings and feature normalisation are kept, and
            the data's clips of its species are trained on.
        rehearse: a second data set folder whose ``train`` clips (of the model's species)
            are mixed in, so that a fine-tune on a few clips of one species does not
            forget the others (rehearsal; fine-tuned on six real dog clips alone, the
            shipped model's habit accuracy fell from 0.98 to 0.32).
        rehearse_share: with ``rehearse``, the share of training windows drawn from it
            (the rest from ``data_dir``), in (0, 1).

    Raises:
        TrainingDataError: no training clips.
        CheckpointError: ``out_dir`` holds a checkpoint (without ``resume`` / ``overwrite``)
            or one that cannot be resumed with this config.
    """
    cfg = config.validate()
    t = cfg.train
    out = Path(out_dir)
    existing = (out / CONFIG_FILE).is_file()
    if existing and not resume and not overwrite:
        raise CheckpointError(
            f"{out} already holds a checkpoint; pass --resume to continue it or --overwrite"
        )
    old_threads = torch.get_num_threads()
    if t.threads is not None:
        torch.set_num_threads(t.threads)
    t0 = time.perf_counter()
    try:
        base: LoadedCheckpoint | None = None
        if init is not None:
            base = _load_init(init, cfg)
        known = set(base.model.species) if base else {s.name for s in training_species()}
        speeds = (1.0 - t.speed_jitter, 1.0 + t.speed_jitter) if t.speed_jitter > 0 else ()
        tr = load_clip_set(data_dir, "train", progress=progress, mirror=t.mirror, speeds=speeds)
        species = sorted(s for s in tr.species if s in known)
        if not species:
            raise TrainingDataError(
                f"{data_dir}: the train split has no clip of "
                + (
                    f"the species of {init} ({', '.join(sorted(known))})"
                    if base
                    else "a training species"
                )
            )
        if len(species) != len(tr.species):
            tr = tr.of_species(known)
        weights = None
        data_species = species  # validation stays on the data's own clips
        if rehearse is not None:
            if not 0.0 < rehearse_share < 1.0:
                raise TrainingDataError(
                    f"rehearse_share must be in (0, 1) (a share of the training windows), "
                    f"got {rehearse_share}"
                )
            extra = load_clip_set(rehearse, "train", mirror=t.mirror, speeds=speeds)
            extra = extra.of_species(known)
            if not extra.clips:
                raise TrainingDataError(
                    f"{rehearse}: the train split has no clip of the model's species "
                    f"({', '.join(sorted(known))}) to rehearse"
                )
            n_new, n_old = len(tr.clips), len(extra.clips)
            tr = tr + extra
            weights = np.concatenate(
                [
                    np.full(n_new, (1.0 - rehearse_share) / n_new),
                    np.full(n_old, rehearse_share / n_old),
                ]
            )
            species = sorted(s for s in tr.species if s in known)
        try:
            val: ClipSet | None = load_clip_set(data_dir, "val", species=data_species)
        except TrainingDataError:
            val = None
        fps = tr.fps
        from ..species import species_names

        if base is not None:
            species = list(base.model.species)  # every habit encoder stays; the data's train
            table = base.model.text_table.detach().numpy()
            text = {n: table[i] for i, n in enumerate(base.model.text_names)}
        elif text_embeddings is not None:
            text = dict(text_embeddings)
        else:
            text = species_embeddings(species_names(), cfg.model.text.model)
        from .text import description_sha256

        text_meta = {
            "model": cfg.model.text.model if text_embeddings is None or base else "custom",
            "description_sha256": {n: description_sha256(n) for n in sorted(text)}
            if text_embeddings is None
            else {},
        }
        if base is not None:
            stats = (base.model.feat_mean.numpy(), base.model.feat_std.numpy())
        else:
            stats = feature_stats(tr, cfg.model.window)
        model = build_untrained(cfg, species, text, stats)
        if base is not None:
            model.load_state_dict(_init_state(base.model, model))
        opt = torch.optim.AdamW(
            model.parameters(),
            lr=t.lr,
            betas=(0.9, 0.99),
            weight_decay=t.weight_decay,
            foreach=True,
        )
        rng = np.random.default_rng(t.seed)
        gen = torch.Generator().manual_seed(t.seed + 1)
        start = 0
        history: list[dict[str, Any]] = []
        prev_wall = 0.0
        if resume and existing:
            old_cfg, doc = read_checkpoint_config(out)
            if not _same_except_steps(old_cfg, cfg):
                raise CheckpointError(
                    f"{out}: cannot resume: its config differs from this one in more than the "
                    "number of steps (train it to a new --out instead)"
                )
            ck = load_checkpoint(out)
            if list(ck.model.species) != species:
                raise CheckpointError(
                    f"{out}: cannot resume: trained on species {ck.model.species}, "
                    f"data has {species}"
                )
            tensors, js = load_train_state(out, doc)
            model.load_state_dict(ck.model.state_dict())
            _restore_optimizer(opt, tensors, js["optimizer"])
            rng.bit_generator.state = js["numpy_rng"]
            gen.set_state(tensors["rng.torch"])
            start = int(js["step"])
            history = list(doc.get("training", {}).get("history", []))
            prev_wall = float(doc.get("training", {}).get("wall_time_s", 0.0))
            log(f"resuming {out} at step {start}/{t.steps}")
        elif resume:
            log(f"{out}: nothing to resume, starting from step 0")

        sampler = WindowSampler(
            tr, cfg.model.window, rng, paired=t.paired_weight > 0, weights=weights
        )
        validator = _Validator(val, cfg.model.window) if val is not None else None
        n_pairs = sum(1 for p in sampler.partners if p)
        log(
            f"training {cfg.name}/{cfg.model.variant}: {len(tr.clips)} clips of "
            f"{len(species)} species ({n_pairs} with a paired clip), "
            f"{sum(p.numel() for p in model.parameters()) / 1e6:.2f} M parameters, "
            f"{t.steps} steps × {t.batch_size} windows of {cfg.model.window} frames, "
            f"{torch.get_num_threads()} thread(s)"
        )

        def meta(step: int, metrics: dict[str, float]) -> dict[str, Any]:
            return {
                "fps": fps,
                "text": text_meta,
                "data": {
                    "dir": str(Path(data_dir).resolve()),
                    "rehearse": None
                    if rehearse is None
                    else {"dir": str(Path(rehearse).resolve()), "share": rehearse_share},
                    "train_clips": len(tr.clips),
                    "val_clips": 0 if val is None else len(val.clips),
                },
                "metrics": {"val": metrics},
                "training": {
                    "step": step,
                    "wall_time_s": prev_wall + time.perf_counter() - t0,
                    "history": history,
                },
                "versions": {"torch": torch.__version__},
                **({"init": {"checkpoint": str(base.path)}} if base else {}),
            }

        def checkpoint(step: int, metrics: dict[str, float]) -> None:
            tensors, opt_js = _optimizer_state(opt)
            tensors["rng.torch"] = gen.get_state()
            js = {"step": step, "numpy_rng": rng.bit_generator.state, "optimizer": opt_js}
            save_checkpoint(out, model, cfg, meta(step, metrics), (tensors, js))

        model.train()
        metrics: dict[str, float] = dict(history[-1]) if history else {}
        bar = None
        if progress:
            from tqdm import tqdm

            bar = tqdm(
                total=t.steps,
                initial=start,
                desc=f"train {cfg.model.variant}",
                unit="step",
                dynamic_ncols=True,
            )
        run: dict[str, float] = {}
        n_run = 0
        for step in range(start, t.steps):
            for g in opt.param_groups:
                g["lr"] = lr_at(step, cfg)
            batch = sampler.sample(t.batch_size)
            loss, logs = compute_losses(model, batch, cfg, gen, fps)
            if not torch.isfinite(loss):
                raise TrainingDataError(f"non-finite loss at step {step}: {logs}")
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            for k, v in logs.items():
                run[k] = run.get(k, 0.0) + v
            n_run += 1
            done = step + 1
            if bar is not None:
                bar.update(1)
                post = {"loss": f"{logs['loss']:.4f}", "ppl": f"{logs['perplexity']:.0f}"}
                if "val_mpjpe_mm" in metrics:
                    post["val_mm"] = f"{metrics['val_mpjpe_mm']:.1f}"
                bar.set_postfix(post)
            if done % t.val_every == 0 or done == t.steps:
                rec: dict[str, Any] = {
                    "step": done,
                    "elapsed_s": round(prev_wall + time.perf_counter() - t0, 1),
                }
                rec.update({f"train_{k}": round(v / max(n_run, 1), 5) for k, v in run.items()})
                run, n_run = {}, 0
                if validator is not None:
                    rec.update({k: round(v, 3) for k, v in validator(model, fps, t.seed).items()})
                history.append(rec)
                metrics = {k: v for k, v in rec.items() if k.startswith("val_")}
                msg = " ".join(
                    f"{k}={v}"
                    for k, v in rec.items()
                    if k
                    in (
                        "step",
                        "train_loss",
                        "train_perplexity",
                        "val_mpjpe_mm",
                        "val_mpjpe_pct_leg",
                        "val_paired_mpjpe_mm",
                        "val_paired_direct_mm",
                    )
                )
                (bar.write if bar is not None else log)(msg)
            if done % t.checkpoint_every == 0 or done == t.steps:
                checkpoint(done, metrics)
        if bar is not None:
            bar.close()
        if start >= t.steps:
            log(f"{out}: already trained for {start} ≥ {t.steps} steps")
        return TrainResult(out, max(start, t.steps), time.perf_counter() - t0, metrics, history)
    finally:
        torch.set_num_threads(old_threads)


def record_metrics(out_dir: str | Path, metrics: dict[str, Any]) -> None:
    """Merge ``metrics`` into the ``metrics`` of a checkpoint's ``config.json``."""
    p = Path(out_dir) / CONFIG_FILE
    doc = load_json(p, "checkpoint config", error=CheckpointError)
    doc.setdefault("metrics", {}).update(metrics)
    from ..fileio import atomic_write_text
    from .checkpoint import _readable

    atomic_write_text(p, json.dumps(doc, indent=2) + "\n")
    _readable(p.parent, [CONFIG_FILE])


def loaded_summary(ck: LoadedCheckpoint) -> str:
    """One line describing a loaded checkpoint."""
    c = ck.config
    n = sum(p.numel() for p in ck.model.parameters())
    qc = c.model.quantizer
    levels = f" × {qc.levels} residual levels" if qc.levels > 1 else ""
    return (
        f"{ck.path}: variant {c.model.variant}, {n / 1e6:.2f} M parameters, "
        f"{len(ck.model.species)} training species, "
        f"codebook {qc.num_codes}×{qc.code_dim}{levels}"
    )
