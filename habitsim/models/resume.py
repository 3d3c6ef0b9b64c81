"""Resuming a training run: the optimiser's state as checkpoint tensors and back, and
which config changes a resume allows."""

from __future__ import annotations

from typing import Any

import torch

from .config import Config
from .errors import CheckpointError


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
