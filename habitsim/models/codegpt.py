"""A causal transformer over the VQ-VAE's code sequences, conditioned on a sentence and a
species' habit (text-to-motion, after T2M-GPT's two-stage VQ-VAE + GPT generation that
"Behave Your Motion" builds on and OmniMotionGPT compares against).

Sequence layout (one token per code step)::

    [text] [habit] [length]  x_0  x_1 … x_{T-2}
       └──── prefix ────┘     └─ code steps ─┘
    output at [length] predicts step 0, output at x_t predicts step t + 1

* **Prefix.** ``text`` = W_t·e (e: the sentence embedding of the caption), replaced by a
  learned null token with probability ``text_dropout`` while training, so the same
  network gives the unconditional prediction used by classifier-free guidance;
  ``habit`` = W_h·g_c (g_c: the species' habit-description embedding stored in the
  VQ-VAE checkpoint, so a held-out species gets one too); ``length`` = an embedding of
  the number of code steps asked for (a sit must fit its rise into the clip).
* **Code step tokens.** The VQ-VAE quantizes with L residual codebooks; step t's token is
  Σ_l E_l[c_{t,l}] + W_p·p_t (p_t: its path features) + a position embedding.
* **Heads.** From the trunk's output h for a step: level 1's logits from h, level l's
  from h + Σ_{j<l} D_j[c_j] (the levels already drawn for that step: a small depth
  factorisation as in RQ-Transformer), and the path from h + Σ_l D_l[c_l].
* **Path as regression.** The decoder follows a continuous path per step (pelvis
  velocity in its heading frame and the heading). Given the step's codes it is nearly
  determined (the codes carry the gait, the speed and the turning), so a regression head
  predicts it; quantising it into tokens would add a second vocabulary and a
  quantisation error for no gain in diversity, which comes from the codes. The heading
  is predicted as its change per step (:func:`path_features`), so a sequence does not
  depend on where it starts facing.

Sampling (:meth:`CodeGPT.sample`): per step and level, guided logits
l_u + s·(l_c − l_u) (s = ``guidance``; 1 = the conditional model alone, 0 = the text
ignored), divided by the temperature, optionally cut to the ``top_k`` best, drawn with a
seeded :class:`torch.Generator`; the path is the conditional and unconditional
predictions blended with min(s, 1) (a regression mean is never extrapolated).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch
from torch import nn

from .errors import ConfigError
from .t2m_config import CodeGPTConfig

__all__ = ["CodeGPTConfig", "CodeGPT", "path_features", "decoder_path", "path_feature_dim"]

#: The prefix tokens before the first code step, in order.
PREFIX_TOKENS = ("text", "habit", "length")
PREFIX = len(PREFIX_TOKENS)


# ---------------------------------------------------------------------------- path features


def path_feature_dim(path_dim: int) -> int:
    """Width of the model's path features for a decoder path of ``path_dim`` channels
    (0 → 0; 2 → 2; 4 → 3: velocity forward / left and the heading change)."""
    if path_dim not in (0, 2, 4):
        raise ConfigError(f"a decoder path has 0, 2 or 4 channels, got {path_dim}")
    return 3 if path_dim == 4 else path_dim


def path_features(path: np.ndarray) -> np.ndarray:
    """Decoder path (T', P) → the model's path features (T', P').

    P = 4 (velocity in the heading frame, cos ψ, sin ψ): (v_f, v_l, Δψ [rad per step]),
    Δψ_0 = ψ_0 (the heading relative to the sequence's start frame), later Δψ wrapped to
    (−π, π]. P = 2 or 0: unchanged.
    """
    p = np.asarray(path, dtype=np.float64)
    if p.shape[1] != 4:
        return p.astype(np.float32)
    psi = np.arctan2(p[:, 3], p[:, 2])
    d = np.diff(psi, prepend=0.0)
    d = np.remainder(d + np.pi, 2 * np.pi) - np.pi
    return np.concatenate([p[:, :2], d[:, None]], axis=1).astype(np.float32)


def decoder_path(feats: torch.Tensor, path_dim: int) -> torch.Tensor:
    """The model's path features (…, T', P') → the decoder's path (…, T', P); inverse of
    :func:`path_features` (the heading integrated from the start)."""
    if path_dim != 4:
        return feats
    psi = torch.cumsum(feats[..., 2], dim=-1)
    return torch.stack([feats[..., 0], feats[..., 1], torch.cos(psi), torch.sin(psi)], dim=-1)


# ---------------------------------------------------------------------------- the network


class CodeGPT(nn.Module):
    """Causal transformer over code steps (see the module docstring).

    Args:
        cfg: shape and regularisation.
        levels: residual codebooks L of the VQ-VAE.
        num_codes: codes K per codebook.
        path_dim: channels of the VQ-VAE decoder's path input (0, 2 or 4).
        text_dim: width of the sentence embeddings.
        habit_dim: width of the habit-description embeddings g_c.
        species: species whose g_c rows :attr:`habit_table` holds (training species).
    """

    habit_table: torch.Tensor
    path_mean: torch.Tensor
    path_std: torch.Tensor

    def __init__(
        self,
        cfg: CodeGPTConfig,
        *,
        levels: int,
        num_codes: int,
        path_dim: int,
        text_dim: int,
        habit_dim: int,
        species: Sequence[str],
    ):
        super().__init__()
        self.cfg = cfg.validate()
        self.levels, self.num_codes = int(levels), int(num_codes)
        self.path_dim = int(path_dim)
        self.pf_dim = path_feature_dim(self.path_dim)
        self.text_dim, self.habit_dim = int(text_dim), int(habit_dim)
        self.species = tuple(species)
        d = cfg.d_model
        self.register_buffer("habit_table", torch.zeros(len(self.species), self.habit_dim))
        self.register_buffer("path_mean", torch.zeros(self.pf_dim))
        self.register_buffer("path_std", torch.ones(self.pf_dim))
        self.text_proj = nn.Linear(self.text_dim, d)
        self.null_text = nn.Parameter(torch.zeros(d))
        self.habit_proj = nn.Linear(self.habit_dim, d)
        self.length_emb = nn.Embedding(cfg.max_steps + 1, d)
        self.code_emb = nn.ModuleList(nn.Embedding(num_codes, d) for _ in range(levels))
        self.path_in = nn.Linear(self.pf_dim, d) if self.pf_dim else None
        self.pos = nn.Embedding(PREFIX + cfg.max_steps, d)
        layer = nn.TransformerEncoderLayer(
            d,
            cfg.heads,
            cfg.ff,
            cfg.dropout,
            activation="gelu",
            batch_first=True,
            norm_first=True,
        )
        self.trunk = nn.TransformerEncoder(
            layer, cfg.layers, norm=nn.LayerNorm(d), enable_nested_tensor=False
        )
        self.depth_emb = nn.ModuleList(nn.Embedding(num_codes, d) for _ in range(levels))
        self.level_heads = nn.ModuleList(self._mlp(d, num_codes) for _ in range(levels))
        self.path_head = self._mlp(d, self.pf_dim) if self.pf_dim else None
        nn.init.normal_(self.null_text, std=0.02)

    @staticmethod
    def _mlp(d: int, out: int) -> nn.Sequential:
        return nn.Sequential(nn.LayerNorm(d), nn.Linear(d, d), nn.GELU(), nn.Linear(d, out))

    # ------------------------------------------------------------------ pieces
    def habit_rows(self, species: Sequence[str]) -> torch.Tensor:
        """g_c rows (B, habit_dim) of training species."""
        from ..errors import UnknownSpeciesError

        idx = []
        for s in species:
            if s not in self.species:
                raise UnknownSpeciesError(s, self.species)
            idx.append(self.species.index(s))
        return self.habit_table[torch.as_tensor(idx, dtype=torch.long)]

    def prefix(
        self, text: torch.Tensor, keep_text: torch.Tensor, habit: torch.Tensor, steps: torch.Tensor
    ) -> torch.Tensor:
        """Prefix tokens (B, 3, d) from sentence embeddings (B, E), a mask (B,) of the rows
        that keep their text (the others get the null token), g_c (B, G) and the number
        of code steps asked for (B,)."""
        t = self.text_proj(text)
        t = torch.where(keep_text[:, None], t, self.null_text.expand_as(t))
        h = self.habit_proj(habit)
        n = self.length_emb(steps.clamp(0, self.cfg.max_steps))
        return torch.stack([t, h, n], dim=1)

    def step_tokens(self, codes: torch.Tensor, pathf: torch.Tensor) -> torch.Tensor:
        """Tokens (B, T, d) of code steps (B, T, L) and normalised path features (B, T, P')."""
        x = sum(emb(codes[..., k]) for k, emb in enumerate(self.code_emb))
        assert isinstance(x, torch.Tensor)
        if self.path_in is not None:
            x = x + self.path_in(pathf)
        return x

    def hidden(self, prefix: torch.Tensor, tokens: torch.Tensor) -> torch.Tensor:
        """Trunk outputs (B, T + 1, d) that predict steps 0 … T of a sequence whose
        first T steps' tokens are ``tokens`` (B, T, d)."""
        x = torch.cat([prefix, tokens], dim=1)
        n = x.shape[1]
        if n > PREFIX + self.cfg.max_steps:
            raise ValueError(f"sequence of {n - PREFIX} steps > max_steps {self.cfg.max_steps}")
        x = x + self.pos(torch.arange(n, device=x.device))[None]
        mask = nn.Transformer.generate_square_subsequent_mask(n, device=x.device)
        y = self.trunk(x, mask=mask, is_causal=True)
        return y[:, PREFIX - 1 :]

    def normalize_path(self, pathf: torch.Tensor) -> torch.Tensor:
        return (pathf - self.path_mean) / self.path_std

    # ------------------------------------------------------------------ training
    def forward(
        self,
        text: torch.Tensor,
        keep_text: torch.Tensor,
        habit: torch.Tensor,
        codes: torch.Tensor,
        pathf: torch.Tensor,
        steps: torch.Tensor,
    ) -> tuple[list[torch.Tensor], torch.Tensor | None]:
        """Teacher-forced predictions of every step of a batch.

        Args:
            text: (B, E) sentence embeddings; keep_text: (B,) bool (False: null token).
            habit: (B, G) habit embeddings g_c.
            codes: (B, T, L) code indices; pathf: (B, T, P') normalised path features.
            steps: (B,) each sequence's own length (the length token).

        Returns:
            (logits of each level, (B, T, K) each; path predictions (B, T, P') or None).
        """
        t = codes.shape[1]
        h = self.hidden(
            self.prefix(text, keep_text, habit, steps),
            self.step_tokens(codes[:, : t - 1], pathf[:, : t - 1]),
        )[:, :t]
        logits = []
        for k in range(self.levels):
            logits.append(self.level_heads[k](h))
            h = h + self.depth_emb[k](codes[..., k])
        path = self.path_head(h) if self.path_head is not None else None
        return logits, path

    # ------------------------------------------------------------------ sampling
    @torch.no_grad()
    def sample(
        self,
        text: torch.Tensor,
        habit: torch.Tensor,
        steps: int,
        *,
        generator: torch.Generator,
        temperature: float = 1.0,
        top_k: int | None = None,
        guidance: float = 1.0,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Draw one sequence of ``steps`` code steps.

        Args:
            text: (E,) sentence embedding of the prompt.
            habit: (G,) the species' habit embedding g_c.
            steps: code steps to make, 1 … ``max_steps``.
            generator: the random source (seeded by the caller).
            temperature: logits are divided by it; 0 takes the most likely code.
            top_k: draw among the k most likely codes only (None: all).
            guidance: classifier-free guidance scale s (module docstring).

        Returns:
            (codes (steps, L) long, path features (steps, P') de-normalised).
        """
        guided = guidance != 1.0
        b = 2 if guided else 1
        keep = torch.tensor([True, False][:b])
        pre = self.prefix(
            text[None].expand(b, -1),
            keep,
            habit[None].expand(b, -1),
            torch.full((b,), steps, dtype=torch.long),
        )
        codes = torch.zeros(b, 0, self.levels, dtype=torch.long)
        pathf = torch.zeros(b, 0, self.pf_dim)
        w_path = min(max(guidance, 0.0), 1.0)
        for _ in range(steps):
            h = self.hidden(pre, self.step_tokens(codes, pathf))[:, -1]
            chosen = []
            for k in range(self.levels):
                lg = self.level_heads[k](h)
                lg = lg[1] + guidance * (lg[0] - lg[1]) if guided else lg[0]
                idx = self._draw(lg, generator, temperature, top_k)
                chosen.append(idx)
                h = h + self.depth_emb[k](idx.expand(b))
            step = torch.stack(chosen).view(1, 1, self.levels).expand(b, -1, -1)
            if self.path_head is not None:
                p = self.path_head(h)
                p = p[1] + w_path * (p[0] - p[1]) if guided else p[0]
                p = p.view(1, 1, -1).expand(b, -1, -1)
            else:
                p = pathf.new_zeros(b, 1, 0)
            codes = torch.cat([codes, step], dim=1)
            pathf = torch.cat([pathf, p], dim=1)
        return codes[0], pathf[0] * self.path_std + self.path_mean

    @staticmethod
    def _draw(
        logits: torch.Tensor, gen: torch.Generator, temperature: float, top_k: int | None
    ) -> torch.Tensor:
        if temperature == 0.0:
            return logits.argmax().view(1)
        lg = logits / temperature
        if top_k is not None and top_k < lg.shape[-1]:
            cut = torch.topk(lg, top_k).values[-1]
            lg = lg.masked_fill(lg < cut, float("-inf"))
        probs = torch.softmax(lg, dim=-1)
        return torch.multinomial(probs, 1, generator=gen)
