"""Validation during training: deterministic reconstruction and transfer of fixed
windows, their MPJPE, and the ``direct`` baseline beside it."""

from __future__ import annotations

import math

import numpy as np
import torch

from ..species import load_species
from .data import ClipSet, fixed_windows, stack_windows
from .features import H_INDEX, Q_DIM, window_positions
from .model import HabitVQVAE


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
