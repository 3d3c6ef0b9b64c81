"""The training loss of the habit-preserving VQ-VAE (:func:`compute_losses`): the
reconstruction, commitment, KL, paired, joint-position, contact and stance terms
written out in :mod:`habitsim.models.train`."""

from __future__ import annotations

from typing import cast

import torch
import torch.nn.functional as F

from ..skeleton import FOOT_JOINTS, JOINT_NAMES
from ..species import load_species
from .config import Config
from .data import Batch
from .features import C_DIM, C_INDEX, H_INDEX, Q_DIM, window_positions
from .model import HabitVQVAE

#: Joint indices of the four toes (LF, RF, LH, RH), for the stance term.
_TOES = [JOINT_NAMES.index(n) for n in FOOT_JOINTS]


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
