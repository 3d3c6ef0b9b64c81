"""The habit-preserving motion VQ-VAE: encoder, codebook, habit encoders, text projection,
conditioned decoder (paper Fig. 2).

``HabitVQVAE`` holds every tensor of a checkpoint. It works on *raw* feature windows
(B, T, FEAT_DIM) (see :mod:`habitsim.models.features`); inputs are normalised with the
training set's per-dimension mean / std (buffers ``feat_mean`` / ``feat_std``) and the
decoder's output is de-normalised with them.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import cast

import torch
from torch import nn

from ..errors import UnknownSpeciesError
from .config import ModelConfig
from .features import FEAT_DIM, H_INDEX, Q_DIM
from .habit import HabitPosterior, RealNVP, gaussian_log_prob
from .quantizer import EMAQuantizer, QuantizerOutput, residual_quantize
from .vqvae import MotionDecoder, MotionEncoder

__all__ = ["HabitVQVAE", "ROTATION_INPUT_CLIP"]

#: Normalised joint-rotation inputs of the encoders are clipped to ± this many training
#: standard deviations [σ]: part of the trained network's input definition (a checkpoint
#: is trained with it; :attr:`HabitVQVAE.rotation_input_clip` holds a model's own).
#: Velocities, height and contacts are not clipped. Why 3: docs/training.md.
ROTATION_INPUT_CLIP = 3.0

#: Channels of the decoder's path input (pelvis velocity x, y): see ``ModelConfig``.
PATH_DIM = 2
#: Channels the path gains with ``ModelConfig.path_heading`` (cos ψ, sin ψ of the pelvis).
HEADING_DIM = 2


def turn_windows(x: torch.Tensor, turn: torch.Tensor) -> torch.Tensor:
    """Raw windows (B, T, F) turned about the vertical by ``turn`` [rad], one angle per
    window (B,) or per frame (B, T): the pelvis quaternion and every joint velocity (the
    features' only quantities in the window's frame)."""
    if turn.dim() == 1:
        turn = turn[:, None].expand(-1, x.shape[1])
    y = x.clone()
    half = 0.5 * turn
    cw, sz = torch.cos(half), torch.sin(half)
    w, qx, qy, qz = x[..., 0], x[..., 1], x[..., 2], x[..., 3]
    y[..., 0] = cw * w - sz * qz  # (cos ½θ, 0, 0, sin ½θ) ⊗ q
    y[..., 1] = cw * qx - sz * qy
    y[..., 2] = cw * qy + sz * qx
    y[..., 3] = cw * qz + sz * w
    b, t = x.shape[:2]
    v = x[..., Q_DIM:H_INDEX].reshape(b, t, -1, 3)
    c, s = torch.cos(turn)[..., None], torch.sin(turn)[..., None]
    r = torch.stack([c * v[..., 0] - s * v[..., 1], s * v[..., 0] + c * v[..., 1], v[..., 2]], -1)
    y[..., Q_DIM:H_INDEX] = r.reshape(b, t, -1)
    return y


class HabitVQVAE(nn.Module):
    """Motion VQ-VAE whose decoder takes the habit latent z_c and the text embedding g_c.

    Args:
        cfg: model configuration (variant decides whether z_c / g_c are used).
        species: training species: each gets a habit posterior and a flow prior.
        text_names: species whose text embeddings are stored (rows of ``text_table``).
        text_dim: dimension of the raw sentence embeddings.
    """

    # Buffers (registered in ``__init__``), declared for the type checker.
    feat_mean: torch.Tensor
    feat_std: torch.Tensor
    text_table: torch.Tensor

    def __init__(
        self,
        cfg: ModelConfig,
        species: Sequence[str],
        text_names: Sequence[str],
        text_dim: int,
        rotation_input_clip: float = ROTATION_INPUT_CLIP,
    ):
        super().__init__()
        cfg.validate()
        self.cfg = cfg
        #: the encoders' joint-rotation inputs are clipped to ± this many σ
        self.rotation_input_clip = float(rotation_input_clip)
        self.species = tuple(species)
        self.text_names = tuple(text_names)
        self.text_dim = int(text_dim)
        self.register_buffer("feat_mean", torch.zeros(FEAT_DIM))
        self.register_buffer("feat_std", torch.ones(FEAT_DIM))
        self.register_buffer("text_table", torch.zeros(len(self.text_names), self.text_dim))
        qc = cfg.quantizer
        self.encoder = MotionEncoder(FEAT_DIM, qc.code_dim, cfg.net)
        self.quantizer = EMAQuantizer(qc, reset=cfg.code_reset)
        if qc.levels > 1:  # residual levels 2…L (level 1 keeps the single-codebook names)
            self.residual_quantizers = nn.ModuleList(
                [EMAQuantizer(qc, reset=cfg.code_reset) for _ in range(qc.levels - 1)]
            )
        cond = (cfg.habit.z_dim if cfg.use_z else 0) + (cfg.text.proj_dim if cfg.use_g else 0)
        self.cond_dim = cond
        self.path_dim = (
            (PATH_DIM + (HEADING_DIM if cfg.path_heading else 0)) if cfg.path_condition else 0
        )
        self.decoder = MotionDecoder(qc.code_dim, cond, FEAT_DIM, cfg.net, self.path_dim)
        if cfg.use_z:
            h = cfg.habit
            self.posteriors = nn.ModuleDict({s: HabitPosterior(FEAT_DIM, h) for s in self.species})
            self.priors = nn.ModuleDict(
                {s: RealNVP(h.z_dim, h.flow_layers, h.flow_hidden) for s in self.species}
            )
        if cfg.use_g:
            self.text_proj = nn.Linear(self.text_dim, cfg.text.proj_dim)

    # ------------------------------------------------------------------ normalisation
    def normalize(self, x: torch.Tensor) -> torch.Tensor:
        """Encoder input: (x − mean) / std, joint rotations clipped to
        ± :attr:`rotation_input_clip` (default :data:`ROTATION_INPUT_CLIP`)."""
        y = (x - self.feat_mean) / self.feat_std
        c = self.rotation_input_clip
        return torch.cat([y[..., :Q_DIM].clamp(-c, c), y[..., Q_DIM:]], dim=-1)

    def denormalize(self, y: torch.Tensor) -> torch.Tensor:
        return y * self.feat_std + self.feat_mean

    # ------------------------------------------------------------------ VQ-VAE
    def encode(self, x: torch.Tensor) -> torch.Tensor:
        """Raw windows (B, T, F) → latents f (B, code_dim, T / rate)."""
        return self.encoder(self.normalize(x).transpose(1, 2))

    def quantize(self, f: torch.Tensor, **kw) -> QuantizerOutput:
        """Latents (B, code_dim, T') → codes of every level summed (see
        :func:`~habitsim.models.quantizer.residual_quantize`)."""
        levels = [self.quantizer]
        if self.cfg.quantizer.levels > 1:
            levels += [cast(EMAQuantizer, q) for q in self.residual_quantizers]
        return residual_quantize(levels, f, **kw)

    def decode(
        self, codes: torch.Tensor, cond: torch.Tensor | None, path: torch.Tensor | None = None
    ) -> torch.Tensor:
        """Codes (B, code_dim, T'), condition (B, C) and, for a path-conditioned model,
        the source windows' :meth:`path` (B, 2, T') → raw windows (B, T'·rate, F)."""
        if self.path_dim and path is None:
            raise ValueError("this model decodes along a path: pass path=model.path(x)")
        y = self.denormalize(self.decoder(codes, cond, path).transpose(1, 2))
        if self.cfg.heading_relative:
            assert path is not None
            y = turn_windows(y, self.path_heading_frames(path, y.shape[1]))
        return y

    def path_heading_frames(self, path: torch.Tensor, frames: int) -> torch.Tensor:
        """The path's heading (B, path_dim, T') → ψ per frame (B, frames) [rad]: each code's
        mean heading placed at the middle of its frames, unwrapped and linearly
        interpolated between codes (held at the window's ends)."""
        a = torch.atan2(path[:, -1], path[:, -2])
        d = torch.diff(a, dim=1)
        d = torch.remainder(d + torch.pi, 2 * torch.pi) - torch.pi
        a = torch.cat([a[:, :1], a[:, :1] + torch.cumsum(d, dim=1)], dim=1)
        return nn.functional.interpolate(
            a[:, None], size=frames, mode="linear", align_corners=False
        )[:, 0]

    def path(self, x: torch.Tensor) -> torch.Tensor | None:
        """Raw windows (B, T, F) → the pelvis path the decoder follows
        (B, path_dim, T / rate): the horizontal pelvis velocity (Froude units, the window's
        frame), normalised; with ``path_heading`` that velocity in the pelvis' heading frame
        instead, followed by the heading (cos ψ, sin ψ in the window's frame). Each is the
        mean over a code's frames. None for a model without the path input."""
        if not self.path_dim:
            return None
        sl = slice(Q_DIM, Q_DIM + PATH_DIM)
        v = x[..., sl]
        if self.cfg.path_heading:
            w, qx, qy, qz = x[..., :4].unbind(-1)  # the pelvis quaternion comes first
            fx = 1.0 - 2.0 * (qy * qy + qz * qz)
            fy = 2.0 * (qx * qy + w * qz)
            n = torch.sqrt(fx * fx + fy * fy).clamp_min(1e-6)
            c, s = fx / n, fy / n
            # the velocity in the pelvis' own heading frame (forward, left): its direction
            # then no longer tells the heading (backwards stays backwards on a curve)
            v = torch.stack([c * v[..., 0] + s * v[..., 1], c * v[..., 1] - s * v[..., 0]], -1)
            v = (v - self.feat_mean[sl]) / self.feat_std[sl]
            v = torch.cat([v, torch.stack([c, s], dim=-1)], dim=-1)
        else:
            v = (v - self.feat_mean[sl]) / self.feat_std[sl]
        b, t, d = v.shape
        r = self.cfg.rate
        return v.reshape(b, t // r, r, d).mean(dim=2).transpose(1, 2)

    # ------------------------------------------------------------------ habit latent
    def _check_species(self, names: Sequence[str]) -> None:
        bad = sorted({s for s in names if s not in self.species})
        if bad:
            raise UnknownSpeciesError(bad[0], self.species)

    @staticmethod
    def _groups(names: Sequence[str]) -> dict[str, list[int]]:
        g: dict[str, list[int]] = {}
        for i, s in enumerate(names):
            g.setdefault(s, []).append(i)
        return g

    def posterior(
        self, x: torch.Tensor, species: Sequence[str]
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """(μ, log σ) of q(z | m) for raw windows (B, T, F), each with its species' encoder."""
        self._check_species(species)
        xn = self.normalize(x)
        z = self.cfg.habit.z_dim
        mu = x.new_zeros(x.shape[0], z)
        ls = x.new_zeros(x.shape[0], z)
        for s, idx in self._groups(species).items():
            ii = torch.as_tensor(idx, dtype=torch.long, device=x.device)
            m, lg = self.posteriors[s](xn[ii])
            mu = mu.index_copy(0, ii, m)
            ls = ls.index_copy(0, ii, lg)
        return mu, ls

    def _prior(self, species: str) -> RealNVP:
        return cast(RealNVP, self.priors[species])

    def prior_log_prob(self, z: torch.Tensor, species: Sequence[str]) -> torch.Tensor:
        """log p_c(z) (B,), each row under its species' flow prior."""
        self._check_species(species)
        out = z.new_zeros(z.shape[0])
        for s, idx in self._groups(species).items():
            ii = torch.as_tensor(idx, dtype=torch.long, device=z.device)
            out = out.index_copy(0, ii, self._prior(s).log_prob(z[ii]))
        return out

    def sample_posterior(
        self, x: torch.Tensor, species: Sequence[str], generator: torch.Generator | None = None
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """z ~ q(z | m) by reparameterisation and the one-sample KL estimate
        log q(z|m) − log p_c(z) (B,)."""
        mu, ls = self.posterior(x, species)
        eps = torch.randn(mu.shape, generator=generator, dtype=mu.dtype, device=mu.device)
        z = mu + torch.exp(ls) * eps
        kl = gaussian_log_prob(z, mu, ls) - self.prior_log_prob(z, species)
        return z, kl

    def sample_prior(
        self,
        species: str,
        n: int = 1,
        generator: torch.Generator | None = None,
        temperature: float = 1.0,
    ) -> torch.Tensor:
        """n habit latents z_c ~ p_c (n, z_dim) from a training species' flow prior."""
        self._check_species([species])
        return self._prior(species).sample(n, generator, temperature)

    # ------------------------------------------------------------------ text embedding
    def text_embedding(self, species: Sequence[str]) -> torch.Tensor:
        """Raw stored embeddings g_c (B, text_dim) of catalog species."""
        idx = []
        for s in species:
            if s not in self.text_names:
                raise UnknownSpeciesError(s, self.text_names)
            idx.append(self.text_names.index(s))
        return self.text_table[
            torch.as_tensor(idx, dtype=torch.long, device=self.text_table.device)
        ]

    # ------------------------------------------------------------------ condition
    def condition(
        self,
        species: Sequence[str],
        z: torch.Tensor | None = None,
        text: torch.Tensor | None = None,
    ) -> torch.Tensor | None:
        """Decoder condition (B, C) = [z_c, W·g_c] (the parts the variant uses; None if none).

        Args:
            species: species whose text embedding g_c is used (ignored without text).
            z: habit latents (B, z_dim), required when the variant uses z.
            text: raw embeddings (B, text_dim) to use instead of the stored rows.
        """
        parts = []
        if self.cfg.use_z:
            if z is None:
                raise ValueError("this model variant needs a habit latent z")
            parts.append(z)
        if self.cfg.use_g:
            g = self.text_embedding(species) if text is None else text
            parts.append(self.text_proj(g))
        return torch.cat(parts, dim=-1) if parts else None
