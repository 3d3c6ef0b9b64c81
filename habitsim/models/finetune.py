"""Fine-tuning from a checkpoint (``--init``): which checkpoint, whether its model fits
this run's, and its weights carried into the new model."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import torch

from .checkpoint import LoadedCheckpoint, load_checkpoint
from .config import Config, ModelConfig
from .errors import CheckpointError
from .model import HabitVQVAE


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
