"""Staged training recipes: a preset whose model options come on one stage at a time.

The shipped ``habit`` model is trained in stages: the ``large`` network with the source's
path at the decoder's input, then a short fine-tune that adds the path's heading, then one
that reads the decoder's pelvis in that heading's frame. Each later stage starts from the
previous stage's weights (:func:`habitsim.models.train.train` with ``init``; the new
heading channels start at zero, so the fine-tune starts where the previous stage ended).
Trained from scratch with every option on at once, the same network generalised less well
to held-out species (the shipped checkpoint's README).

``habitsim train --config large`` runs :data:`RECIPES` ``["large"]`` with
:func:`train_staged`: the earlier stages go to ``OUT/stages/<k>-<name>``, the last one to
``OUT`` itself, and ``OUT/config.json`` records the recipe (every stage's options,
schedule, steps and wall time). Every stage is a resumable checkpoint of its own: with
``resume`` a finished stage is kept and an unfinished one continues.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..fileio import atomic_write_text
from ..jsonfile import load_json
from .checkpoint import CONFIG_FILE, _readable
from .config import Config, finetune_schedule
from .errors import CheckpointError, ConfigError
from .train import TrainResult, train


@dataclass(frozen=True)
class Stage:
    """One stage of a staged recipe.

    Attributes:
        name: short name (the stage's folder is ``<k>-<name>``).
        model: model options this stage switches on, as ``--set`` keys
            (``{"model.path_heading": True}``); they stay on in the later stages.
        steps: optimiser steps; ``None`` (the first stage only) keeps the preset's.
        lr: peak learning rate of a fine-tune stage (its other schedule values are
            :func:`habitsim.models.config.finetune_schedule`'s); ``None`` for the first
            stage, which trains from scratch on the preset's schedule.
    """

    name: str
    model: dict[str, Any] = field(default_factory=dict)
    steps: int | None = None
    lr: float | None = None


#: Staged presets of ``habitsim train --config``: the ``large`` preset trains the shipped
#: ``habit`` model (12000 + 3000 + 3000 steps).
RECIPES: dict[str, tuple[Stage, ...]] = {
    "large": (
        Stage("path", {"model.path_condition": True}),
        Stage("heading", {"model.path_heading": True}, steps=3000, lr=3e-4),
        Stage("heading-relative", {"model.heading_relative": True}, steps=3000, lr=3e-4),
    ),
}


def _check_stages(stages: Sequence[Stage]) -> None:
    if not stages:
        raise ConfigError("a staged recipe needs at least one stage")
    for k, st in enumerate(stages):
        bad = [key for key in st.model if not key.startswith("model.")]
        if bad:
            raise ConfigError(
                f"stage {k + 1} ({st.name}): {bad} are not model options "
                "(a stage switches on model.* keys; its schedule is steps / lr)"
            )
        if k > 0 and (st.steps is None or st.lr is None):
            raise ConfigError(
                f"stage {k + 1} ({st.name}): a fine-tune stage needs its steps and lr"
            )


def stage_configs(
    base: Config,
    stages: Sequence[Stage],
    changes: dict[str, Any] | None = None,
    first_steps: int | None = None,
) -> list[Config]:
    """The configuration of every stage.

    Args:
        base: the preset (its schedule is the first stage's; the fine-tune stages use
            :func:`~habitsim.models.config.finetune_schedule` of it).
        stages: the recipe.
        changes: ``--set`` overrides applied to every stage (a stage's own steps and
            learning rate are applied after them).
        first_steps: the first stage's number of steps (``--steps``), if not the preset's.

    Raises:
        ConfigError: a malformed recipe or an unknown / invalid override.
    """
    _check_stages(stages)
    changes = dict(changes or {})
    clash = sorted({key for st in stages for key in st.model} & set(changes))
    if clash:
        raise ConfigError(
            f"{', '.join(clash)}: the staged {base.name!r} recipe sets these itself; train "
            "its final model in one run (--single-run) or start from another preset to set "
            "them by hand"
        )
    model_on: dict[str, Any] = {}
    out: list[Config] = []
    for k, st in enumerate(stages):
        model_on.update(st.model)
        if k == 0:
            cfg = base.replace(**model_on, **changes)
            steps = first_steps if first_steps is not None else st.steps
            if steps is not None:
                cfg = cfg.replace(**{"train.steps": steps})
        else:
            ft = dataclasses.replace(base, train=finetune_schedule(base.train))
            cfg = ft.replace(**model_on, **changes)
            cfg = cfg.replace(**{"train.steps": st.steps, "train.lr": st.lr})
        out.append(dataclasses.replace(cfg, name=f"{base.name}:{st.name}").validate())
    return out


def single_run_config(base: Config, stages: Sequence[Stage]) -> Config:
    """The recipe's final model trained from scratch in one run: every stage's model
    options on from the first step, on the preset's (first stage's) schedule."""
    _check_stages(stages)
    model_on: dict[str, Any] = {}
    for st in stages:
        model_on.update(st.model)
    return base.replace(**model_on)


def stage_folders(out_dir: str | Path, stages: Sequence[Stage]) -> list[Path]:
    """Where each stage's checkpoint goes: ``OUT/stages/<k>-<name>``, the last ``OUT``."""
    out = Path(out_dir)
    return [out / "stages" / f"{k + 1}-{st.name}" for k, st in enumerate(stages[:-1])] + [out]


@dataclass(frozen=True)
class StagedResult:
    """What :func:`train_staged` did: one :class:`TrainResult` per stage."""

    out_dir: Path
    stages: list[TrainResult]
    recipe: dict[str, Any]

    @property
    def steps(self) -> int:
        return sum(r.steps for r in self.stages)

    @property
    def metrics(self) -> dict[str, float]:
        return self.stages[-1].metrics


def train_staged(
    data_dir: str | Path,
    out_dir: str | Path,
    base: Config,
    stages: Sequence[Stage],
    *,
    changes: dict[str, Any] | None = None,
    first_steps: int | None = None,
    resume: bool = False,
    overwrite: bool = False,
    progress: bool = True,
    log: Callable[[str], None] = print,
    text_embeddings: dict[str, np.ndarray] | None = None,
) -> StagedResult:
    """Train a staged recipe into ``out_dir`` (see the module docstring).

    Args:
        data_dir: data set folder (every stage trains on it).
        out_dir: the final checkpoint folder; the earlier stages go to
            :func:`stage_folders`.
        base, stages, changes, first_steps: see :func:`stage_configs`.
        resume: continue every stage's checkpoint that exists (a finished stage is kept).
        overwrite: replace existing checkpoints instead of refusing.
        progress, log: as :func:`~habitsim.models.train.train`.
        text_embeddings: the first stage's text embeddings (the later stages keep the
            previous stage's).

    Raises:
        ConfigError: a malformed recipe or override (before anything is trained).
        CheckpointError, TrainingDataError: as :func:`~habitsim.models.train.train`.
    """
    configs = stage_configs(base, stages, changes, first_steps)
    folders = stage_folders(out_dir, stages)
    held = [f for f in folders if (f / CONFIG_FILE).is_file()]
    if held and not resume and not overwrite:  # refused now, not after hours of stage 1
        raise CheckpointError(
            f"{held[0]} already holds a checkpoint; pass --resume to continue the staged run "
            "or --overwrite"
        )
    results: list[TrainResult] = []
    for k, (st, cfg, folder) in enumerate(zip(stages, configs, folders, strict=True)):
        log(f"stage {k + 1}/{len(stages)} ({st.name}): {folder}")
        results.append(
            train(
                data_dir,
                folder,
                cfg,
                resume=resume,
                overwrite=overwrite,
                progress=progress,
                log=log,
                text_embeddings=text_embeddings if k == 0 else None,
                init=None if k == 0 else folders[k - 1],
            )
        )
    recipe = _record_recipe(Path(out_dir), base, stages, configs, folders)
    return StagedResult(Path(out_dir), results, recipe)


def _record_recipe(
    out: Path,
    base: Config,
    stages: Sequence[Stage],
    configs: Sequence[Config],
    folders: Sequence[Path],
) -> dict[str, Any]:
    """Merge the recipe (every stage's options, schedule, steps and wall time, the latter
    read from the stage's checkpoint so resumed stages count every session) into
    ``OUT/config.json``."""
    rows: list[dict[str, Any]] = []
    walls: list[int] = []
    for st, cfg, folder in zip(stages, configs, folders, strict=True):
        doc = load_json(folder / CONFIG_FILE, "checkpoint config", error=CheckpointError)
        walls.append(round(float(doc["training"]["wall_time_s"])))
        rows.append(
            {
                "name": st.name,
                "checkpoint": "." if folder == out else str(folder.relative_to(out)),
                "model": dict(st.model),
                "steps": cfg.train.steps,
                "lr": cfg.train.lr,
                "wall_time_s": walls[-1],
            }
        )
    recipe = {
        "preset": base.name,
        "stages": rows,
        "wall_time_s": sum(walls),
        "threads": configs[-1].train.threads,
    }
    p = out / CONFIG_FILE
    doc = load_json(p, "checkpoint config", error=CheckpointError)
    doc["recipe"] = recipe
    atomic_write_text(p, json.dumps(doc, indent=2) + "\n")
    _readable(out, [CONFIG_FILE])
    return recipe
