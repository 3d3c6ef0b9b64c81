"""``habitsim train-evaluator``: train the frozen motion evaluator of the evaluation suite.

Reproduces the evaluator shipped in ``habitsim/evaluation/evaluator/`` (see
:mod:`habitsim.evaluation.evaluator`)::

    habitsim data synth --out /tmp/hs_default --clips-per-species 40 --seed 0
    habitsim train-evaluator --data /tmp/hs_default --out OUT

``OUT`` receives ``model.safetensors``, ``config.json`` and ``README.md`` (with the
accuracies per split); point ``habitsim eval --evaluator OUT`` at it to use it.
"""

from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    """Add the top-level ``train-evaluator`` command."""
    p = sub.add_parser(
        "train-evaluator",
        help="train the motion evaluator (features for FID etc., species/action heads)",
        description=(
            "Train the evaluator network on the training split of a synthetic data set and "
            "write OUT/model.safetensors, OUT/config.json and OUT/README.md (accuracies on "
            "train, val, test and the held-out species)."
        ),
    )
    p.add_argument("--data", required=True, metavar="DIR", help="synthetic data set folder")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.add_argument("--epochs", type=int, metavar="N", help="training epochs (default 12)")
    p.add_argument("--seed", type=int, metavar="S", help="training seed (default 0)")
    p.add_argument(
        "--threads",
        type=int,
        default=1,
        metavar="N",
        help="torch CPU threads (default 1, deterministic)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_train)


def _train(ns: argparse.Namespace) -> int:
    import torch

    from ..evaluation.evaluator import EvaluatorConfig, EvaluatorError, train_evaluator

    if ns.threads < 1:
        raise EvaluatorError(f"--threads must be >= 1, got {ns.threads}")
    torch.set_num_threads(ns.threads)
    over = {}
    if ns.epochs is not None:
        over["epochs"] = ns.epochs
    if ns.seed is not None:
        over["seed"] = ns.seed
    cfg = EvaluatorConfig(**over)
    train_evaluator(ns.data, ns.out, cfg, progress=not ns.no_progress)
    return 0
