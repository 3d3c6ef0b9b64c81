"""1-D convolutional encoder and conditioned decoder of the motion VQ-VAE (paper 3.2.3).

The layout follows T2M-GPT (Zhang et al. 2023, ``models/encdec.py``), which the paper
builds on: residual blocks of a dilated 3-tap convolution and a 1×1 convolution with
ReLUs, dilations growing by ``dilation`` (3) inside a stack; the encoder halves the time
axis ``down_t`` (2) times with stride-2 4-tap convolutions (rate 4), the decoder doubles
it back with nearest-neighbour upsampling followed by a 3-tap convolution.

Decoder conditioning (paper eq. 1, m̂ = D(f, z_c, g_c)): the condition vector
c = [z_c, W·g_c] is broadcast over time and concatenated to the codes at the decoder's
input, and added (through a linear map) after every upsampling stage, so the habit
information reaches every resolution.
"""

from __future__ import annotations

import torch
from torch import nn

from .config import NetConfig

__all__ = ["ResBlock", "ResStack", "MotionEncoder", "MotionDecoder"]


class ResBlock(nn.Module):
    """x + Conv1×1(ReLU(Conv3(ReLU(x), dilation)))."""

    def __init__(self, width: int, dilation: int):
        super().__init__()
        self.conv1 = nn.Conv1d(width, width, 3, padding=dilation, dilation=dilation)
        self.conv2 = nn.Conv1d(width, width, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x + self.conv2(torch.relu(self.conv1(torch.relu(x))))


class ResStack(nn.Module):
    """``depth`` residual blocks with dilations dilation⁰, dilation¹, … (reversed on request)."""

    def __init__(self, width: int, depth: int, dilation: int, reverse: bool = False):
        super().__init__()
        dil = [dilation**i for i in range(depth)]
        if reverse:
            dil = dil[::-1]
        self.blocks = nn.Sequential(*[ResBlock(width, d) for d in dil])

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.blocks(x)


class MotionEncoder(nn.Module):
    """(B, F, T) normalised features → (B, code_dim, T / 2^down_t) latents f."""

    def __init__(self, in_dim: int, code_dim: int, cfg: NetConfig):
        super().__init__()
        w = cfg.width
        layers: list[nn.Module] = [nn.Conv1d(in_dim, w, 3, padding=1), nn.ReLU()]
        for _ in range(cfg.down_t):
            layers += [
                nn.Conv1d(w, w, 4, stride=2, padding=1),
                ResStack(w, cfg.depth, cfg.dilation),
            ]
        layers.append(nn.Conv1d(w, code_dim, 3, padding=1))
        self.net = nn.Sequential(*layers)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.net(x)


class MotionDecoder(nn.Module):
    """(B, code_dim, T') codes + (B, cond_dim) condition [+ (B, path_dim, T') path at the
    code rate] → (B, out_dim, T'·2^down_t)."""

    def __init__(
        self, code_dim: int, cond_dim: int, out_dim: int, cfg: NetConfig, path_dim: int = 0
    ):
        super().__init__()
        w = cfg.width
        self.cond_dim = cond_dim
        self.path_dim = path_dim
        self.inp = nn.Conv1d(code_dim + cond_dim + path_dim, w, 3, padding=1)
        self.stages = nn.ModuleList()
        self.cond_bias = nn.ModuleList()
        self.path_bias = nn.ModuleList()
        for _ in range(cfg.down_t):
            self.stages.append(
                nn.Sequential(
                    ResStack(w, cfg.depth, cfg.dilation, reverse=True),
                    nn.Upsample(scale_factor=2, mode="nearest"),
                    nn.Conv1d(w, w, 3, padding=1),
                )
            )
            if cond_dim:
                self.cond_bias.append(nn.Linear(cond_dim, w))
            if path_dim:
                self.path_bias.append(nn.Conv1d(path_dim, w, 1))
        self.out = nn.Sequential(
            nn.Conv1d(w, w, 3, padding=1), nn.ReLU(), nn.Conv1d(w, out_dim, 3, padding=1)
        )

    def forward(
        self, codes: torch.Tensor, cond: torch.Tensor | None, path: torch.Tensor | None = None
    ) -> torch.Tensor:
        x = codes
        if self.path_dim:
            if path is None or path.shape != (codes.shape[0], self.path_dim, codes.shape[-1]):
                raise ValueError(
                    f"decoder expects a path of shape ({codes.shape[0]}, {self.path_dim}, "
                    f"{codes.shape[-1]})"
                )
            x = torch.cat([x, path], dim=1)
        if self.cond_dim:
            if cond is None or cond.shape != (codes.shape[0], self.cond_dim):
                raise ValueError(
                    f"decoder expects a condition of shape ({codes.shape[0]}, {self.cond_dim})"
                )
            x = torch.cat([x, cond[:, :, None].expand(-1, -1, codes.shape[-1])], dim=1)
        x = torch.relu(self.inp(x))
        for i, stage in enumerate(self.stages):
            x = stage(x)
            if self.cond_dim:
                x = x + self.cond_bias[i](cond)[:, :, None]
            if self.path_dim:
                assert path is not None
                up = path.repeat_interleave(x.shape[-1] // path.shape[-1], dim=-1)
                x = x + self.path_bias[i](up)
        return self.out(x)
