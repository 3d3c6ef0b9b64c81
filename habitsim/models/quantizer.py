"""Codebook with soft quantization, EMA updates and dead-code reset (paper 3.2.1, 3.2.3).

* **Soft quantization** (eqs. 2–3): while training, the code index of each latent f_i is
  *sampled* from p(e_k | f_i) ∝ exp(−‖f_i − e_k‖² / τ) (Gumbel-max trick, seeded by a
  :class:`torch.Generator`); in evaluation the most probable code (τ → 0) is taken.
  The decoder receives e_k with a straight-through gradient f + sg(e_k − f).
* **EMA** (eq. 7, after van den Oord et al. / T2M-GPT's ``QuantizeEMAReset``): with the
  one-hot assignments A (N × K) of a batch,
  ``count ← λ·count + (1 − λ)·Aᵀ1``, ``sum ← λ·sum + (1 − λ)·Aᵀf`` and
  ``e_k ← sum_k / count_k`` for every code with ``count_k ≥ threshold``.
* **Code reset**: a code with ``count_k < threshold`` (dead) is set to a random latent of
  the batch (and its sum / count restarted from it), instead of keeping its old value.
* **Commitment loss**: ‖f − sg(e)‖² (mean over elements); the codebook itself learns by
  EMA only, so the paper's embedding term has no gradient to carry here.
* **Residual levels** (:func:`residual_quantize`, ``QuantizerConfig.levels`` > 1): level
  l quantizes r_l = f − Σ_{m<l} e_m with its own codebook of the same kind; the decoder
  gets f + sg(Σ e_l − f) and the commitment loss is Σ_l ‖r_l − sg(e_l)‖² (as in MoMask's
  residual VQ, Guo et al. 2024).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import nn

from .config import QuantizerConfig

__all__ = ["QuantizerOutput", "EMAQuantizer", "code_probabilities", "residual_quantize"]


def _sq_distances(f: torch.Tensor, codebook: torch.Tensor) -> torch.Tensor:
    """‖f_i − e_k‖², (N, K)."""
    return (
        f.pow(2).sum(-1, keepdim=True) - 2.0 * f @ codebook.t() + codebook.pow(2).sum(-1)[None, :]
    ).clamp_min(0.0)


def code_probabilities(f: torch.Tensor, codebook: torch.Tensor, tau: float) -> torch.Tensor:
    """p(e_k | f_i) = softmax_k(−‖f_i − e_k‖² / τ), (N, K) (paper eq. 3)."""
    return torch.softmax(-_sq_distances(f, codebook) / tau, dim=-1)


@dataclass
class QuantizerOutput:
    """Result of :meth:`EMAQuantizer.forward`.

    Attributes:
        quantized: (B, D, T') codes with the straight-through gradient.
        indices: (B, T') chosen code indices (of the first level).
        commit_loss: scalar ‖f − sg(e)‖² (summed over the levels).
        perplexity: exp(entropy) of the batch's code usage (of the first level).
        level_indices: (B, T', L) the indices of every level.
    """

    quantized: torch.Tensor
    indices: torch.Tensor
    commit_loss: torch.Tensor
    perplexity: torch.Tensor
    level_indices: torch.Tensor


class EMAQuantizer(nn.Module):
    """K × D codebook updated by EMA, with optional dead-code reset.

    Args:
        cfg: codebook size, temperature, EMA decay, reset threshold.
        reset: reset dead codes (False = the ``habit_ema`` variant).
    """

    # Buffers (registered in ``__init__``), declared for the type checker.
    codebook: torch.Tensor
    code_sum: torch.Tensor
    code_count: torch.Tensor
    initialized: torch.Tensor

    def __init__(self, cfg: QuantizerConfig, reset: bool = True):
        super().__init__()
        self.num_codes = cfg.num_codes
        self.code_dim = cfg.code_dim
        self.tau = float(cfg.tau)
        self.decay = float(cfg.ema_decay)
        self.threshold = float(cfg.reset_threshold)
        self.reset = bool(reset)
        self.register_buffer("codebook", torch.zeros(cfg.num_codes, cfg.code_dim))
        self.register_buffer("code_sum", torch.zeros(cfg.num_codes, cfg.code_dim))
        self.register_buffer("code_count", torch.zeros(cfg.num_codes))
        self.register_buffer("initialized", torch.zeros((), dtype=torch.bool))

    # ------------------------------------------------------------------ codebook maintenance
    @staticmethod
    def _random_rows(f: torch.Tensor, n: int, generator: torch.Generator | None) -> torch.Tensor:
        """``n`` rows drawn from ``f`` (N, D) without replacement (tiled when N < n)."""
        if f.shape[0] < n:
            reps = (n + f.shape[0] - 1) // f.shape[0]
            f = f.repeat(reps, 1)
        perm = torch.randperm(f.shape[0], generator=generator, device=f.device)[:n]
        return f[perm]

    @torch.no_grad()
    def init_codebook(self, f: torch.Tensor, generator: torch.Generator | None = None) -> None:
        """Initialise every code with a random latent of ``f`` (N, D) (T2M-GPT's init)."""
        rows = self._random_rows(f.detach(), self.num_codes, generator)
        self.codebook.copy_(rows)
        self.code_sum.copy_(rows)
        self.code_count.fill_(1.0)
        self.initialized.fill_(True)

    @torch.no_grad()
    def ema_update(
        self, f: torch.Tensor, indices: torch.Tensor, generator: torch.Generator | None = None
    ) -> int:
        """One EMA step with latents ``f`` (N, D) assigned to ``indices`` (N,).

        Returns:
            the number of codes reset (0 without reset).
        """
        f = f.detach().to(self.codebook.dtype)
        idx = indices.view(-1)
        count = torch.bincount(idx, minlength=self.num_codes).to(f.dtype)  # (K,) = Aᵀ1
        total = torch.zeros_like(self.code_sum).index_add_(0, idx, f)  # (K, D) = Aᵀf
        lam = self.decay
        self.code_sum.mul_(lam).add_(total, alpha=1.0 - lam)
        self.code_count.mul_(lam).add_(count, alpha=1.0 - lam)
        alive = self.code_count >= self.threshold
        updated = self.code_sum / self.code_count.clamp_min(1e-12)[:, None]
        if self.reset:
            dead = ~alive
            n_dead = int(dead.sum())
            new = self.codebook.clone()
            new[alive] = updated[alive]
            if n_dead:
                rand = self._random_rows(f, self.num_codes, generator)
                new[dead] = rand[dead]
                self.code_sum[dead] = rand[dead]
                self.code_count[dead] = 1.0
            self.codebook.copy_(new)
            return n_dead
        self.codebook.copy_(torch.where(alive[:, None], updated, self.codebook))
        return 0

    # ------------------------------------------------------------------ quantization
    def select(
        self,
        f: torch.Tensor,
        sample: bool,
        tau: float | None = None,
        generator: torch.Generator | None = None,
    ) -> torch.Tensor:
        """Code indices (N,) of latents ``f`` (N, D): sampled (eq. 3) or nearest."""
        d = _sq_distances(f.detach(), self.codebook)
        if not sample:
            return d.argmin(dim=-1)
        t = self.tau if tau is None else float(tau)
        u = torch.rand(d.shape, generator=generator, device=d.device, dtype=d.dtype)
        e = (-torch.log(u.clamp(1e-20, 1.0))).clamp_min(1e-20)  # Exp(1) draws
        gumbel = -torch.log(e)
        return (-d / t + gumbel).argmax(dim=-1)

    def dequantize(self, indices: torch.Tensor) -> torch.Tensor:
        """Codes (B, D, T') of indices (B, T')."""
        return self.codebook[indices].permute(0, 2, 1).contiguous()

    def forward(
        self,
        f: torch.Tensor,
        sample: bool | None = None,
        update: bool | None = None,
        generator: torch.Generator | None = None,
    ) -> QuantizerOutput:
        """Quantize encoder latents ``f`` (B, D, T').

        Args:
            f: latents.
            sample: sample the index (default: ``self.training``).
            update: EMA / reset step on this batch (default: ``self.training``).
            generator: random source of the sampling and the resets.
        """
        sample = self.training if sample is None else sample
        update = self.training if update is None else update
        b, d, t = f.shape
        flat = f.permute(0, 2, 1).reshape(-1, d)
        if update and not bool(self.initialized):
            self.init_codebook(flat, generator)
        idx = self.select(flat, sample=sample, generator=generator)
        e = self.codebook[idx].clone()  # codes before this batch's update (T2M-GPT order)
        if update:
            self.ema_update(flat, idx, generator)
        commit = torch.mean((flat - e.detach()) ** 2)
        q = flat + (e - flat).detach()
        with torch.no_grad():
            usage = torch.bincount(idx, minlength=self.num_codes).to(f.dtype)
            p = usage / usage.sum()
            perplexity = torch.exp(-(p * torch.log(p.clamp_min(1e-10))).sum())
        return QuantizerOutput(
            quantized=q.view(b, t, d).permute(0, 2, 1).contiguous(),
            indices=idx.view(b, t),
            commit_loss=commit,
            perplexity=perplexity,
            level_indices=idx.view(b, t, 1),
        )


def residual_quantize(
    levels: list[EMAQuantizer],
    f: torch.Tensor,
    n_levels: torch.Tensor | None = None,
    **kw,
) -> QuantizerOutput:
    """Quantize latents ``f`` (B, D, T') by the codebooks ``levels`` in turn, each on the
    residual the previous ones left (keyword arguments go to every level's forward).

    ``n_levels`` (B,) keeps only the first n codebooks' codes of each item (quantizer
    dropout while training; every level still sees, and learns from, its residual).
    With one level this is that level's own output.
    """
    if len(levels) == 1:
        return levels[0](f, **kw)
    r = f
    total = torch.zeros_like(f)
    commit = f.new_zeros(())
    outs = []
    for k, q in enumerate(levels):
        o = q(r, **kw)
        e = o.quantized.detach()  # the codes' values (the straight-through part is f's)
        r = r - e
        if n_levels is not None:
            e = e * (n_levels > k).to(e.dtype)[:, None, None]
        total = total + e
        commit = commit + o.commit_loss
        outs.append(o)
    return QuantizerOutput(
        quantized=f + (total - f).detach(),
        indices=outs[0].indices,
        commit_loss=commit,
        perplexity=outs[0].perplexity,
        level_indices=torch.stack([o.indices for o in outs], dim=-1),
    )
