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
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, cast

import numpy as np
import torch
import torch.nn.functional as F

from ..skeleton import FOOT_JOINTS, JOINT_NAMES
from ..species import load_species, training_species
from .checkpoint import (
    CONFIG_FILE,
    LoadedCheckpoint,
    load_checkpoint,
    load_train_state,
    read_checkpoint_config,
    save_checkpoint,
)
from .config import Config, ModelConfig
from .data import (
    Batch,
    ClipSet,
    WindowSampler,
    feature_stats,
    fixed_windows,
    load_clip_set,
    stack_windows,
)
from .errors import CheckpointError, TrainingDataError
from .features import C_DIM, C_INDEX, H_INDEX, Q_DIM, window_positions
from .model import HabitVQVAE
from .text import species_embeddings

#: Joint indices of the four toes (LF, RF, LH, RH), for the stance term.
_TOES = [JOINT_NAMES.index(n) for n in FOOT_JOINTS]

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


def lr_at(step: int, cfg: Config) -> float:
    """Learning rate of optimiser step ``step`` (0-based)."""
    t = cfg.train
    if t.warmup_steps and step < t.warmup_steps:
        return t.lr * (step + 1) / t.warmup_steps
    if t.lr_schedule == "cosine":
        span = max(1, t.steps - 1 - t.warmup_steps)
        frac = min(1.0, (step - t.warmup_steps) / span)
        return t.lr_final + 0.5 * (t.lr - t.lr_final) * (1.0 + math.cos(math.pi * frac))
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


def _masked_smooth_l1(
    pred: torch.Tensor, target: torch.Tensor, valid: torch.Tensor, beta: float
) -> torch.Tensor:
    """Mean smooth-L1 over valid frames (B, T) and the last axis."""
    e = F.smooth_l1_loss(pred, target, reduction="none", beta=beta).mean(-1)
    w = valid.to(e.dtype)
    return (e * w).sum() / w.sum().clamp_min(1.0)


def _recon_terms(
    pred: torch.Tensor, target: torch.Tensor, valid: torch.Tensor, cfg: Config
) -> tuple[torch.Tensor, torch.Tensor]:
    """(rotation + height term, velocity term) of L_re."""
    b = cfg.train.smooth_l1_beta
    lq = _masked_smooth_l1(pred[..., :Q_DIM], target[..., :Q_DIM], valid, b)
    lh = _masked_smooth_l1(pred[..., H_INDEX:C_INDEX], target[..., H_INDEX:C_INDEX], valid, b)
    lv = _masked_smooth_l1(pred[..., Q_DIM:H_INDEX], target[..., Q_DIM:H_INDEX], valid, b)
    if cfg.train.root_velocity_weight > 0:  # the pelvis' channels, whose error the path integrates
        lv = lv + cfg.train.root_velocity_weight * _masked_smooth_l1(
            pred[..., Q_DIM : Q_DIM + 3], target[..., Q_DIM : Q_DIM + 3], valid, b
        )
    return lq + lh, lv


def _position_loss(
    pred: torch.Tensor,
    target: torch.Tensor,
    valid: torch.Tensor,
    species: list[str],
    fps: float,
    beta: float,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Smooth-L1 on forward-kinematics positions [hip heights], as two terms: the pose
    (every joint relative to the pelvis) plus the pelvis' path (integrated from the
    decoded velocities). In one term on global positions the integrated drift of the
    root enters every joint's error, drowns the limbs' gradient, and the limbs were learnt
    several times slower.

    Returns:
        (the loss, the decoded joint positions (B, T, J, 3) [m]).
    """
    pos = window_positions(pred, species, fps)
    with torch.no_grad():
        pt = window_positions(target, species, fps)
    h = torch.tensor([load_species(s).hip_height for s in species], dtype=pred.dtype)[
        :, None, None, None
    ]
    pp, pt = pos / h, pt / h
    pose = F.smooth_l1_loss(
        pp[..., 1:, :] - pp[..., :1, :],
        pt[..., 1:, :] - pt[..., :1, :],
        reduction="none",
        beta=beta,
    ).mean((-1, -2))
    path = F.smooth_l1_loss(pp[..., 0, :], pt[..., 0, :], reduction="none", beta=beta).mean(-1)
    w = valid.to(pose.dtype)
    return ((pose + path) * w).sum() / w.sum().clamp_min(1.0), pos


def _contact_loss(pred: torch.Tensor, target: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
    """Binary cross-entropy of the decoded contact logits against the stance labels."""
    e = F.binary_cross_entropy_with_logits(
        pred[..., C_INDEX : C_INDEX + C_DIM],
        target[..., C_INDEX : C_INDEX + C_DIM],
        reduction="none",
    ).mean(-1)
    w = valid.to(e.dtype)
    return (e * w).sum() / w.sum().clamp_min(1.0)


def _stance_loss(
    pos: torch.Tensor,
    target: torch.Tensor,
    valid: torch.Tensor,
    species: list[str],
    fps: float,
    beta: float,
) -> torch.Tensor:
    """Smooth-L1 of the decoded toe velocity [leg lengths / s] towards zero on frames
    whose label and the previous frame's are both stance (mean over those frames)."""
    toes = _TOES
    leg = torch.tensor([load_species(s).leg_length for s in species], dtype=pos.dtype)
    v = (pos[:, 1:, toes] - pos[:, :-1, toes]) * (fps / leg[:, None, None, None])
    c = target[..., C_INDEX : C_INDEX + C_DIM] > 0.5
    on = c[:, 1:] & c[:, :-1] & (valid[:, 1:] & valid[:, :-1])[..., None]
    e = F.smooth_l1_loss(v, torch.zeros_like(v), reduction="none", beta=beta).sum(-1)
    w = on.to(e.dtype)
    return (e * w).sum() / w.sum().clamp_min(1.0)


def _kinematic_terms(
    pred: torch.Tensor,
    target: torch.Tensor,
    valid: torch.Tensor,
    species: list[str],
    fps: float,
    cfg: Config,
    logs: dict[str, float],
    tag: str = "",
) -> torch.Tensor:
    """Position, contact and stance terms of one set of decoded windows (weighted)."""
    t = cfg.train
    total = pred.new_zeros(())
    if t.position_weight > 0 or t.stance_weight > 0:
        lp, pos = _position_loss(pred, target, valid, species, fps, t.smooth_l1_beta)
        if t.position_weight > 0:
            total = total + t.position_weight * lp
            logs[f"{tag}pos"] = float(lp.detach())
        if t.stance_weight > 0:
            ls = _stance_loss(pos, target, valid, species, fps, t.smooth_l1_beta)
            total = total + t.stance_weight * ls
            logs[f"{tag}stance"] = float(ls.detach())
    if t.contact_weight > 0:
        lc = _contact_loss(pred, target, valid)
        total = total + t.contact_weight * lc
        logs[f"{tag}contact"] = float(lc.detach())
    return total


def _prior_draws(
    model: HabitVQVAE, species: list[str], generator: torch.Generator | None
) -> torch.Tensor:
    """One z_c ~ p_c per item (B, z_dim), drawn per species group."""
    z = torch.zeros(len(species), model.cfg.habit.z_dim)
    groups: dict[str, list[int]] = {}
    for i, s in enumerate(species):
        groups.setdefault(s, []).append(i)
    for s, idx in groups.items():
        z[idx] = model.sample_prior(s, len(idx), generator)
    return z


def compute_losses(
    model: HabitVQVAE, batch: Batch, cfg: Config, generator: torch.Generator | None, fps: float
) -> tuple[torch.Tensor, dict[str, float]]:
    """Total training loss of one batch and its logged parts (training mode: sampled
    codes, EMA update, reparameterised z)."""
    t = cfg.train
    x_in = batch.x
    if t.input_noise > 0:  # noise in normalised units, on every channel but the contacts
        noise = torch.randn(batch.x.shape, generator=generator, dtype=batch.x.dtype)
        noise[..., C_INDEX:] = 0.0
        x_in = batch.x + t.input_noise * noise * model.feat_std
    f = model.encode(x_in)
    n_levels = None
    levels = model.cfg.quantizer.levels
    if levels > 1 and t.quantizer_dropout > 0:
        b0 = batch.x.shape[0]
        drop = torch.rand(b0, generator=generator) < t.quantizer_dropout
        fewer = torch.randint(1, levels, (b0,), generator=generator)
        n_levels = torch.where(drop, fewer, torch.full_like(fewer, levels))
    qo = model.quantize(f, generator=generator, n_levels=n_levels)
    logs: dict[str, float] = {}
    codes = [qo.quantized]
    species = list(batch.species)
    kl = batch.x.new_zeros(())
    n_pair = int(batch.pair_src.numel()) if t.paired_weight > 0 else 0
    z_a = z_b = None
    if model.cfg.use_z:
        z_a, kl_a = model.sample_posterior(batch.x, species, generator)
        kl = kl_a.mean()
        if n_pair:  # as at transfer time: the target's z_c is a draw from its prior
            with torch.no_grad():
                z_b = _prior_draws(model, batch.pair_species, generator)
    cond_a = model.condition(species, z_a)
    if n_pair:
        codes.append(qo.quantized[batch.pair_src])
        cond_b = model.condition(batch.pair_species, z_b)
    dec_in = torch.cat(codes, dim=0)
    cond = None
    if cond_a is not None:
        # cond_b is set whenever cond_a is (same model, same condition kinds)
        cond = torch.cat([cond_a, cast(torch.Tensor, cond_b)], dim=0) if n_pair else cond_a
    path = model.path(x_in)
    if path is not None and n_pair:  # a paired window follows its source's path
        path = torch.cat([path, path[batch.pair_src]], dim=0)
    y = model.decode(dec_in, cond, path)
    b = batch.x.shape[0]
    lq, lv = _recon_terms(y[:b], batch.x, batch.valid, cfg)
    recon = lq + t.alpha * lv
    total = recon + t.beta * qo.commit_loss + t.kl_weight * kl
    total = total + _kinematic_terms(y[:b], batch.x, batch.valid, species, fps, cfg, logs)
    if n_pair:
        pq, pv = _recon_terms(y[b:], batch.pair_x, batch.pair_valid, cfg)
        pair_logs: dict[str, float] = {}
        paired = (
            pq
            + t.alpha * pv
            + _kinematic_terms(
                y[b:],
                batch.pair_x,
                batch.pair_valid,
                batch.pair_species,
                fps,
                cfg,
                pair_logs,
                "paired_",
            )
        )
        total = total + t.paired_weight * paired
        logs["paired"] = float(paired.detach())
    logs.update(
        loss=float(total.detach()),
        rec_q=float(lq.detach()),
        rec_v=float(lv.detach()),
        commit=float(qo.commit_loss.detach()),
        kl=float(kl.detach()),
        perplexity=float(qo.perplexity),
    )
    return total, logs


def _mpjpe(
    pred: torch.Tensor, target: torch.Tensor, valid: torch.Tensor, species: list[str], fps: float
) -> tuple[np.ndarray, np.ndarray]:
    """Per-window MPJPE [m] and as a fraction of leg length, (N,) each."""
    pp = window_positions(pred, species, fps)
    pt = window_positions(target, species, fps)
    e = torch.linalg.norm(pp - pt, dim=-1).mean(-1)  # (N, T)
    w = valid.to(e.dtype)
    m = ((e * w).sum(1) / w.sum(1).clamp_min(1.0)).numpy()
    leg = np.array([load_species(s).leg_length for s in species])
    return m, m / leg


@torch.no_grad()
def evaluate_windows(
    model: HabitVQVAE,
    x: torch.Tensor,
    valid: torch.Tensor,
    species: list[str],
    fps: float,
    target_species: list[str] | None = None,
    target_x: torch.Tensor | None = None,
    target_valid: torch.Tensor | None = None,
    seed: int = 0,
    batch: int = 64,
) -> dict[str, np.ndarray]:
    """Deterministic reconstruction (or transfer) of fixed windows.

    Without ``target_*``: reconstruct each window (nearest codes, posterior-mean z) and
    return per-window ``mpjpe_m`` / ``mpjpe_frac``. With them: decode with the target
    species' condition (z from its prior, seeded) and compare with the target windows.
    """
    was = model.training
    model.eval()
    gen = torch.Generator().manual_seed(seed)
    out_m, out_f = [], []
    for s in range(0, x.shape[0], batch):
        xb, sp = x[s : s + batch], species[s : s + batch]
        qo = model.quantize(model.encode(xb), sample=False, update=False)
        if target_species is None:
            z = model.posterior(xb, sp)[0] if model.cfg.use_z else None
            y = model.decode(qo.quantized, model.condition(sp, z), model.path(xb))
            m, fr = _mpjpe(y, xb, valid[s : s + batch], sp, fps)
        else:
            assert target_x is not None and target_valid is not None
            tsp = target_species[s : s + batch]
            z = None
            if model.cfg.use_z:
                z = torch.cat([model.sample_prior(t, 1, gen) for t in tsp], dim=0)
            y = model.decode(qo.quantized, model.condition(tsp, z), model.path(xb))
            m, fr = _mpjpe(y, target_x[s : s + batch], target_valid[s : s + batch], tsp, fps)
        out_m.append(m)
        out_f.append(fr)
    model.train(was)
    return {"mpjpe_m": np.concatenate(out_m), "mpjpe_frac": np.concatenate(out_f)}


def direct_windows(x: torch.Tensor, species: list[str], target_species: list[str]) -> torch.Tensor:
    """The ``direct`` baseline on canonical windows: same quaternions and height ratio,
    root speed scaled by the hip-height ratio (velocities in the target's Froude units)."""
    y = x.clone()
    ratio = torch.tensor(
        [
            math.sqrt(load_species(t).hip_height / load_species(s).hip_height)
            for s, t in zip(species, target_species, strict=True)
        ],
        dtype=x.dtype,
    )
    y[..., Q_DIM:H_INDEX] = x[..., Q_DIM:H_INDEX] * ratio[:, None, None]
    return y


class _Validator:
    """Fixed validation windows and their pairs, built once."""

    def __init__(self, val: ClipSet, window: int, max_windows: int = 256):
        wins = fixed_windows(val, window, per_clip=2)[:max_windows]
        self.x, self.valid, self.species, clip_idx = stack_windows(val, wins, window)
        partners = val.partners()
        px, pv, psp, src = [], [], [], []
        from .features import canonical_window

        for k, ((_ci, st), i) in enumerate(zip(wins, clip_idx, strict=True)):
            for j in partners[i][:2]:
                f, v, _ = canonical_window(val.clips[j], st, window)
                px.append(torch.from_numpy(f))
                pv.append(torch.from_numpy(v))
                psp.append(val.clips[j].species)
                src.append(k)
        self.has_pairs = bool(src)
        if src:
            self.pair_x = torch.stack(px)
            self.pair_valid = torch.stack(pv)
            self.pair_species = psp
            self.pair_src = torch.as_tensor(src)
            self.pair_valid = self.pair_valid & self.valid[self.pair_src]

    def __call__(self, model: HabitVQVAE, fps: float, seed: int) -> dict[str, float]:
        r = evaluate_windows(model, self.x, self.valid, self.species, fps)
        out = {
            "val_mpjpe_mm": float(r["mpjpe_m"].mean() * 1000.0),
            "val_mpjpe_pct_leg": float(r["mpjpe_frac"].mean() * 100.0),
        }
        if self.has_pairs:
            src_sp = [self.species[i] for i in self.pair_src.tolist()]
            xs = self.x[self.pair_src]
            p = evaluate_windows(
                model,
                xs,
                self.valid[self.pair_src],
                src_sp,
                fps,
                self.pair_species,
                self.pair_x,
                self.pair_valid,
                seed=seed,
            )
            d = _mpjpe(
                direct_windows(xs, src_sp, self.pair_species),
                self.pair_x,
                self.pair_valid,
                self.pair_species,
                fps,
            )
            out["val_paired_mpjpe_mm"] = float(p["mpjpe_m"].mean() * 1000.0)
            out["val_paired_direct_mm"] = float(d[0].mean() * 1000.0)
        return out


def _optimizer_state(opt: torch.optim.Optimizer) -> tuple[dict[str, torch.Tensor], dict[str, Any]]:
    sd = opt.state_dict()
    tensors: dict[str, torch.Tensor] = {}
    scalars: dict[str, dict[str, float]] = {}
    for idx, st in sd["state"].items():
        for k, v in st.items():
            if torch.is_tensor(v) and v.dim() > 0:
                tensors[f"opt.{idx}.{k}"] = v
            else:
                scalars.setdefault(str(idx), {})[k] = float(v)
    groups = [
        {k: v for k, v in g.items() if k != "params"} | {"params": list(g["params"])}
        for g in sd["param_groups"]
    ]
    return tensors, {"scalars": scalars, "param_groups": groups}


def _restore_optimizer(
    opt: torch.optim.Optimizer, tensors: dict[str, torch.Tensor], js: dict[str, Any]
) -> None:
    state: dict[int, dict[str, Any]] = {}
    for key, v in tensors.items():
        if key.startswith("opt."):
            _, idx, k = key.split(".", 2)
            state.setdefault(int(idx), {})[k] = v
    for idx, sc in js["scalars"].items():
        for k, v in sc.items():
            state.setdefault(int(idx), {})[k] = torch.tensor(v, dtype=torch.float32)
    groups = js["param_groups"]
    for g in groups:
        if isinstance(g.get("betas"), list):
            g["betas"] = tuple(g["betas"])
    try:
        opt.load_state_dict({"state": state, "param_groups": groups})
    except (ValueError, KeyError) as e:
        raise CheckpointError(f"optimiser state does not fit the model ({e})") from e


def _same_except_steps(a: Config, b: Config) -> bool:
    da, db = a.to_dict(), b.to_dict()
    for d in (da, db):
        d["train"].pop("steps")
        d["train"].pop("threads")
        d["train"].pop("val_every")
        d["train"].pop("checkpoint_every")
        d.pop("name")
    return da == db


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


def resolve_init(init: str | Path) -> Path:
    """The folder of the checkpoint a fine-tune starts from: ``init`` itself, or the
    shipped checkpoint of a variant name (``habit``) unless a folder of that name exists."""
    from .config import VARIANTS
    from .transfer import resolve_checkpoint

    named = str(init) in VARIANTS and not Path(init).is_dir()
    return resolve_checkpoint(str(init)) if named else Path(init)


def _load_init(init: str | Path, cfg: Config) -> LoadedCheckpoint:
    """The checkpoint a fine-tune starts from (folder or shipped variant name)."""
    base = load_checkpoint(resolve_init(init))
    if base.config.model != cfg.model and not _adds_heading(base.config.model, cfg.model):
        raise CheckpointError(
            f"--init {init}: its model configuration differs from this run's; fine-tuning "
            "keeps the checkpoint's model (only training settings may change, or "
            "model.path_heading be switched on for a path-conditioned checkpoint)"
        )
    return base


def _adds_heading(old: ModelConfig, new: ModelConfig) -> bool:
    """``new`` is the path-conditioned ``old`` with the path's heading channels and / or
    the heading-relative output switched on."""
    return (
        old.path_condition
        and new.path_heading >= old.path_heading
        and new.heading_relative >= old.heading_relative
        and dataclasses.replace(
            new, path_heading=old.path_heading, heading_relative=old.heading_relative
        )
        == old
    )


def _init_state(base: HabitVQVAE, model: HabitVQVAE) -> dict[str, torch.Tensor]:
    """``base``'s tensors for ``model``. When ``model``'s path also carries the heading
    (:func:`_adds_heading`), the decoder's weights on the new heading channels start at
    zero, so the fine-tune starts from the base's decoder (exactly so on windows whose
    heading stays the first frame's; a turning window's velocity is now read in the
    turning heading's frame)."""
    state = dict(base.state_dict())
    if model.path_dim == base.path_dim:
        return state
    old, code_dim = base.path_dim, base.cfg.quantizer.code_dim
    for key, new in model.state_dict().items():
        v = state[key]
        if v.shape == new.shape:
            continue
        w = torch.zeros_like(new)
        if key == "decoder.inp.weight":  # input channels: codes, path, condition
            w[:, : code_dim + old] = v[:, : code_dim + old]
            w[:, code_dim + model.path_dim :] = v[:, code_dim + old :]
        elif key.startswith("decoder.path_bias."):
            w[:, :old] = v
        else:
            raise CheckpointError(f"cannot carry tensor {key} {tuple(v.shape)} into the model")
        state[key] = w
    return state


def record_metrics(out_dir: str | Path, metrics: dict[str, Any]) -> None:
    """Merge ``metrics`` into the ``metrics`` of a checkpoint's ``config.json``."""
    p = Path(out_dir) / CONFIG_FILE
    doc = json.loads(p.read_text(encoding="utf-8"))
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
