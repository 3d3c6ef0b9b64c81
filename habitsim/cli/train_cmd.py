"""``habitsim train``: train the habit-preserving VQ-VAE on a synthetic data set.

Writes a checkpoint folder (safetensors + JSON; see :mod:`habitsim.models.checkpoint`),
resumable with ``--resume``; at the end records the reconstruction error of the fixed
reference clips (:data:`habitsim.models.evaluate.REFERENCE_CLIPS`) in its config.json.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from ..errors import JSONFileError
from ..jsonfile import loads_json
from ..models.config import FinetuneConfig


def register(sub: argparse._SubParsersAction) -> None:
    """Add the top-level ``train`` command."""
    from ..models.config import PRESETS, VARIANTS

    p = sub.add_parser(
        "train",
        help="train the habit-preserving motion VQ-VAE (writes a checkpoint folder)",
        description=(
            "Train the motion VQ-VAE with per-species habit flows and text embeddings on a "
            "data set (habitsim data synth, or data import-bvh --dir). Configs: default "
            "≤ 20 min on 2 CPU cores, small ≤ 2 min, large ≤ 2.5 h in three stages that "
            "train the shipped model (path, heading, heading-relative; the earlier stages "
            "go to CKPT/stages/; resume with --resume); --init fine-tunes a trained model."
        ),
    )
    p.add_argument("--data", required=True, type=Path, metavar="DIR", help="data set folder")
    p.add_argument("--out", required=True, type=Path, metavar="CKPT", help="checkpoint folder")
    p.add_argument(
        "--config", default="default", choices=sorted(PRESETS), help="preset (default: default)"
    )
    p.add_argument(
        "--variant",
        default="habit",
        choices=list(VARIANTS),
        help="model variant / ablation (default: habit)",
    )
    p.add_argument(
        "--init",
        default=None,
        metavar="CKPT|VARIANT",
        help="fine-tune: start from this checkpoint (a folder, or 'habit' for the shipped "
        "model) with its model configuration; --config then only sets the schedule, "
        f"by default {FinetuneConfig().steps} steps at lr {FinetuneConfig().lr:g}",
    )
    p.add_argument(
        "--rehearse",
        type=Path,
        metavar="DIR",
        help="mix in the train clips of this data set too (e.g. the synthetic one the model "
        "was trained on), so that a fine-tune on a few clips of one species keeps the others",
    )
    p.add_argument(
        "--rehearse-share",
        type=float,
        default=0.5,
        metavar="F",
        help="share of the training windows drawn from --rehearse, in (0, 1) (default 0.5)",
    )
    p.add_argument("--resume", action="store_true", help="continue the training state in CKPT")
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace a checkpoint already in CKPT (only files habitsim wrote there are removed)",
    )
    p.add_argument("--steps", type=int, metavar="N", help="override the number of steps")
    p.add_argument("--seed", type=int, metavar="S", help="override the seed (default 0)")
    p.add_argument(
        "--threads",
        type=int,
        metavar="N",
        help="torch CPU threads (default: the preset's; default and large 2, small 1)",
    )
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a config value, e.g. --set train.lr=5e-4 (JSON value; repeatable)",
    )
    p.add_argument(
        "--single-run",
        action="store_true",
        help="a staged preset (large): train its final model from scratch in one run, "
        "every stage's model option on from the first step (ablations; "
        "presets without stages train in one run anyway)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_train)


def _parse_set(items: list[str]) -> dict[str, object]:
    from ..models.errors import ConfigError

    out: dict[str, object] = {}
    for it in items:
        if "=" not in it:
            raise ConfigError(f"--set expects KEY=VALUE, got {it!r}")
        k, v = it.split("=", 1)
        try:
            out[k.strip()] = loads_json(v, f"--set {k.strip()}")
        except JSONFileError:  # not JSON (or too big for it): the text itself
            out[k.strip()] = v
    return out


def _finetune_config(init: str, cfg):
    """The fine-tune's configuration: the checkpoint's model, ``cfg``'s schedule with
    the :class:`~habitsim.models.config.FinetuneConfig` schedule (``--steps`` / ``--set``
    apply on top)."""
    from ..models.checkpoint import read_checkpoint_config
    from ..models.config import Config, finetune_schedule
    from ..models.train import resolve_init

    base, _ = read_checkpoint_config(resolve_init(init))
    train = finetune_schedule(cfg.train)
    return Config(name=f"finetune:{base.name}", model=base.model, train=train).validate()


def _train(ns: argparse.Namespace) -> int:
    from ..errors import OutputWriteError, brief_path
    from ..folders import claim_output_folder

    # one training run at a time in CKPT; --resume / --overwrite as for the checkpoint
    with claim_output_folder(
        ns.out, command="train", overwrite=ns.overwrite, resume=ns.resume, log=print
    ):
        try:
            return _train_in(ns)
        except OutputWriteError as e:  # a full disk: the last whole checkpoint stays
            raise OutputWriteError(
                f"{e}. The last complete checkpoint in {brief_path(ns.out)} is kept; once "
                "the output can be written, run again with --resume to continue from it"
            ) from None


def _train_in(ns: argparse.Namespace) -> int:
    """``habitsim train`` in its claimed checkpoint folder."""
    from ..fileio import check_writable
    from ..models.checkpoint import MODEL_FILE
    from ..models.config import preset
    from ..models.errors import ConfigError
    from ..models.recipe import RECIPES, single_run_config
    from ..models.train import train

    cfg = preset(ns.config, ns.variant)
    changes = _parse_set(ns.set)
    stages = RECIPES.get(ns.config)
    if ns.init is not None:
        if ns.single_run:
            raise ConfigError(
                "--single-run trains a staged preset's model from scratch; it cannot be "
                "combined with --init (a fine-tune of a trained model)"
            )
        cfg = _finetune_config(ns.init, cfg)
    elif stages is not None and ns.single_run:
        cfg = single_run_config(cfg, stages)
    elif stages is not None:
        return _train_staged(ns, cfg, stages, changes)
    if ns.steps is not None:
        changes["train.steps"] = ns.steps
    if ns.seed is not None:
        changes["train.seed"] = ns.seed
    if ns.threads is not None:
        changes["train.threads"] = ns.threads
    if changes:
        cfg = cfg.replace(**changes)
    check_writable(Path(ns.out) / MODEL_FILE, "--out")  # before training, not after it
    t0 = time.perf_counter()
    res = train(
        ns.data,
        ns.out,
        cfg,
        resume=ns.resume,
        overwrite=ns.overwrite,
        progress=not ns.no_progress,
        init=ns.init,
        rehearse=ns.rehearse,
        rehearse_share=ns.rehearse_share,
    )
    return _report(ns.out, f"{cfg.name}/{cfg.model.variant}, {res.steps} steps", t0, res.metrics)


def _report(
    out: Path, what: str, t0: float, metrics: dict[str, float], lines: list[str] | None = None
) -> int:
    """Record the reference clips' reconstruction error in ``out`` and print the run's
    summary (``lines``: extra ones after the first)."""
    from ..models.checkpoint import MODEL_FILE
    from ..models.evaluate import record_reference_error

    ref = record_reference_error(out)
    wall = time.perf_counter() - t0
    size = (Path(out) / MODEL_FILE).stat().st_size / 1e6
    print(f"checkpoint {out} ({what}, model.safetensors {size:.1f} MB) in {wall:.0f} s")
    for line in lines or []:
        print(f"  {line}")
    for k, v in metrics.items():
        print(f"  {k:24s} {v}")
    print(
        f"  reference clips: reconstruction MPJPE {ref['mpjpe_mm']:.1f} mm "
        f"({ref['pct_leg']:.2f} % of leg length; root-relative {ref['root_relative_mm']:.1f} mm)"
    )
    return 0


def _train_staged(ns: argparse.Namespace, cfg, stages, changes: dict[str, object]) -> int:
    """``--config large``: the preset's stages (:mod:`habitsim.models.recipe`)."""
    from ..fileio import check_writable
    from ..models.checkpoint import MODEL_FILE
    from ..models.recipe import stage_folders, train_staged

    for key, value in (("train.seed", ns.seed), ("train.threads", ns.threads)):
        if value is not None:
            changes[key] = value
    for folder in stage_folders(ns.out, stages):
        check_writable(Path(folder) / MODEL_FILE, "--out")
    t0 = time.perf_counter()
    res = train_staged(
        ns.data,
        ns.out,
        cfg,
        stages,
        changes=changes,
        first_steps=ns.steps,
        resume=ns.resume,
        overwrite=ns.overwrite,
        progress=not ns.no_progress,
    )
    lines = [
        f"stage {st['name']:18s} {st['steps']:6d} steps at lr {st['lr']:g}  "
        f"{st['wall_time_s']:6d} s  ({st['checkpoint']})"
        for st in res.recipe["stages"]
    ]
    lines.append(f"{'wall time of every stage':24s} {res.recipe['wall_time_s']} s")
    what = f"{cfg.name}/{cfg.model.variant}, {len(stages)} stages, {res.steps} steps"
    return _report(ns.out, what, t0, res.metrics, lines)
