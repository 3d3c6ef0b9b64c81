"""Category-specific habit encoders (paper 3.3.1).

For every training species c:

* a **posterior** q_φ(z | m_c) = N(μ_φ(m_c), σ_φ(m_c)) computed by a small transformer
  over the motion window (frames pooled ``token_stride`` at a time, sinusoidal positions,
  mean over tokens) — eq. 8;
* a **prior** p_c(z) = p_w(F⁻¹(z))·|det ∂F⁻¹/∂z|: a RealNVP bijector F of affine coupling
  layers (Dinh et al. 2017) on top of an isotropic Gaussian w — eq. 9, trained by the
  negative log-likelihood of the posterior's samples (eq. 10).

At transfer time z_c is *sampled from the target species' prior* (w ~ N(0, I), z = F(w)).
"""

from __future__ import annotations

import math
from typing import cast

import torch
from torch import nn

from .config import HabitConfig

__all__ = ["AffineCoupling", "RealNVP", "HabitPosterior", "gaussian_log_prob"]

_LOG_2PI = math.log(2.0 * math.pi)


def gaussian_log_prob(
    x: torch.Tensor, mu: torch.Tensor | None = None, log_std: torch.Tensor | None = None
) -> torch.Tensor:
    """log N(x; μ, σ²I) summed over the last axis (standard normal by default)."""
    if mu is None:
        return -0.5 * (x.pow(2) + _LOG_2PI).sum(-1)
    assert log_std is not None
    return (-0.5 * ((x - mu) * torch.exp(-log_std)).pow(2) - log_std - 0.5 * _LOG_2PI).sum(-1)


class AffineCoupling(nn.Module):
    """z = m⊙w + (1−m)⊙(w·exp(s(m⊙w)) + t(m⊙w)); log|det| = Σ(1−m)⊙s.

    s is bounded by ``scale · tanh`` for stable training; the last layer starts at zero,
    so a fresh layer is the identity.
    """

    mask: torch.Tensor  # buffer (registered in ``__init__``)

    def __init__(self, dim: int, hidden: int, mask: torch.Tensor):
        super().__init__()
        self.register_buffer("mask", mask.to(torch.float32))
        self.net = nn.Sequential(
            nn.Linear(dim, hidden),
            nn.GELU(),
            nn.Linear(hidden, hidden),
            nn.GELU(),
            nn.Linear(hidden, 2 * dim),
        )
        last = cast(nn.Linear, self.net[-1])
        nn.init.zeros_(last.weight)
        nn.init.zeros_(last.bias)
        self.scale = nn.Parameter(torch.ones(dim))

    def _st(self, x_masked: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        s, t = self.net(x_masked).chunk(2, dim=-1)
        inv = 1.0 - self.mask
        return self.scale * torch.tanh(s) * inv, t * inv

    def forward(self, w: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(z, log|det ∂z/∂w|)."""
        wm = w * self.mask
        s, t = self._st(wm)
        z = wm + (1.0 - self.mask) * (w * torch.exp(s) + t)
        return z, s.sum(-1)

    def inverse(self, z: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(w, log|det ∂w/∂z|)."""
        zm = z * self.mask
        s, t = self._st(zm)
        w = zm + (1.0 - self.mask) * ((z - t) * torch.exp(-s))
        return w, -s.sum(-1)


class RealNVP(nn.Module):
    """A stack of affine coupling layers with alternating masks: the bijector F of eq. 9."""

    def __init__(self, dim: int, layers: int, hidden: int):
        super().__init__()
        self.dim = dim
        base = torch.arange(dim) % 2 == 0
        self.layers = nn.ModuleList(
            [AffineCoupling(dim, hidden, base if i % 2 == 0 else ~base) for i in range(layers)]
        )

    def forward(self, w: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """z = F(w) and log|det ∂F/∂w|."""
        logdet = w.new_zeros(w.shape[:-1])
        for layer in self.layers:
            w, ld = layer(w)
            logdet = logdet + ld
        return w, logdet

    def inverse(self, z: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """w = F⁻¹(z) and log|det ∂F⁻¹/∂z|."""
        logdet = z.new_zeros(z.shape[:-1])
        for layer in reversed(self.layers):
            z, ld = cast(AffineCoupling, layer).inverse(z)
            logdet = logdet + ld
        return z, logdet

    def log_prob(self, z: torch.Tensor) -> torch.Tensor:
        """log p(z) = log N(F⁻¹(z); 0, I) + log|det ∂F⁻¹/∂z| (eq. 9)."""
        w, logdet = self.inverse(z)
        return gaussian_log_prob(w) + logdet

    def sample(
        self, n: int, generator: torch.Generator | None = None, temperature: float = 1.0
    ) -> torch.Tensor:
        """n samples z = F(w), w ~ N(0, temperature²·I), shape (n, dim)."""
        p = next(self.parameters())
        w = torch.randn(n, self.dim, generator=generator, dtype=p.dtype, device=p.device)
        return self(w * temperature)[0]


def _sinusoid(n: int, d: int, device: torch.device, dtype: torch.dtype) -> torch.Tensor:
    pos = torch.arange(n, device=device, dtype=dtype)[:, None]
    i = torch.arange(0, d, 2, device=device, dtype=dtype)
    ang = pos / torch.pow(torch.tensor(10000.0, device=device, dtype=dtype), i / d)
    pe = torch.zeros(n, d, device=device, dtype=dtype)
    pe[:, 0::2] = torch.sin(ang)
    pe[:, 1::2] = torch.cos(ang[:, : pe[:, 1::2].shape[1]])
    return pe


class HabitPosterior(nn.Module):
    """q_φ(z | m): (B, T, F) normalised features → (μ, log σ), each (B, z_dim)."""

    def __init__(self, in_dim: int, cfg: HabitConfig):
        super().__init__()
        self.stride = cfg.token_stride
        self.proj = nn.Linear(in_dim * cfg.token_stride, cfg.d_model)
        layer = nn.TransformerEncoderLayer(
            cfg.d_model, cfg.heads, cfg.ff, dropout=0.0, batch_first=True, norm_first=True
        )
        self.encoder = nn.TransformerEncoder(layer, cfg.layers, enable_nested_tensor=False)
        self.norm = nn.LayerNorm(cfg.d_model)
        self.head = nn.Linear(cfg.d_model, 2 * cfg.z_dim)
        with torch.no_grad():  # start with a narrow posterior so z informs the decoder at once
            self.head.bias[cfg.z_dim :].fill_(-3.0)

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        b, t, f = x.shape
        pad = (-t) % self.stride
        if pad:
            x = torch.cat([x, x[:, -1:].expand(b, pad, f)], dim=1)
        tokens = x.reshape(b, -1, self.stride * f)
        h = self.proj(tokens)
        h = h + _sinusoid(h.shape[1], h.shape[2], h.device, h.dtype)[None]
        h = self.norm(self.encoder(h)).mean(dim=1)
        mu, log_std = self.head(h).chunk(2, dim=-1)
        return mu, log_std.clamp(-6.0, 2.0)
