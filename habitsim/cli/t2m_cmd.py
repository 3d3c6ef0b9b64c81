"""``habitsim t2m``: text to motion (:mod:`habitsim.models.t2m`): build a code set from a
captioned data set, train the transformer on it, generate a motion from a sentence."""

from __future__ import annotations

import argparse
import time
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``codes``, ``train``, ``generate`` and ``train-evaluator`` to ``t2m``."""
    from ..models.t2m_config import T2M_PRESETS

    p = sub.add_parser(
        "codes",
        help="encode every captioned clip of a data set into a code set",
        description=(
            "Encode every captioned clip of DIR (habitsim data captions DIR first) with the "
            "VQ-VAE into code indices and path per code step, with the captions' sentence "
            "embeddings; writes --out clip by clip (a rerun keeps what is there)."
        ),
    )
    p.add_argument("dataset", metavar="DIR", help="captioned data set folder")
    p.add_argument("--out", required=True, type=Path, metavar="CODES", help="code set folder")
    p.add_argument(
        "--checkpoint",
        type=Path,
        metavar="CKPT",
        help="VQ-VAE checkpoint folder (default: the shipped habit model)",
    )
    p.set_defaults(func=_codes)

    p = sub.add_parser(
        "train",
        help="train the text-to-motion transformer on a code set",
        description=(
            "Train the transformer over codes on a code set's train clips (val clips for "
            "the validation records and CKPT/best); default about 25 min on one CPU thread, "
            "tiny in seconds. Checkpoints every 500 steps; --resume continues a run."
        ),
    )
    p.add_argument("--codes", required=True, type=Path, metavar="CODES", help="code set folder")
    p.add_argument("--out", required=True, type=Path, metavar="CKPT", help="checkpoint folder")
    p.add_argument(
        "--config", default="default", choices=sorted(T2M_PRESETS), help="preset (default)"
    )
    p.add_argument("--steps", type=int, metavar="N", help="override the number of steps")
    p.add_argument("--seed", type=int, metavar="S", help="override the seed (default 0)")
    p.add_argument("--stop-at", type=int, metavar="N", help="stop after step N (resume later)")
    p.add_argument("--resume", action="store_true", help="continue the training state in CKPT")
    p.add_argument("--overwrite", action="store_true", help="replace a checkpoint already in CKPT")
    p.set_defaults(func=_train)

    p = sub.add_parser(
        "generate",
        help="make a motion of a species from a sentence",
        description=(
            "Generate a motion of SPECIES doing what TEXT says with a trained transformer "
            "(classifier-free guidance; a held-out or user species borrows a habit by "
            "retrieval and is built on its own skeleton) "
            "and write it as a .npz motion file."
        ),
    )
    p.add_argument("text", metavar="TEXT", help='the prompt, e.g. "a dog trots to the left"')
    p.add_argument("species", metavar="SPECIES", help="species (built-in or user)")
    p.add_argument("--checkpoint", type=Path, metavar="CKPT", help="transformer checkpoint")
    p.add_argument("--out", required=True, type=Path, metavar="FILE", help="output .npz")
    p.add_argument("--seconds", type=float, default=4.0, help="clip length [s] (default 4)")
    p.add_argument("--seed", type=int, default=0, metavar="S", help="seed (default 0)")
    p.add_argument(
        "--temperature", type=float, default=1.0, help="logits divided by it (default 1)"
    )
    p.add_argument(
        "--guidance",
        type=float,
        default=2.0,
        help="classifier-free guidance scale (1: none, 0: prompt ignored; default 2)",
    )
    p.add_argument("--top-k", type=int, metavar="K", help="draw among the K likeliest codes")
    p.set_defaults(func=_generate)

    p = sub.add_parser(
        "train-evaluator",
        help="train the text–motion evaluator (bench t2m measures with it)",
        description=(
            "Train a motion encoder and a text encoder into one embedding (symmetric "
            "InfoNCE) on the (caption, clip) pairs of the train clips of a captioned data "
            "set, apart from the generator; writes OUT/model.safetensors + OUT/config.json."
        ),
    )
    p.add_argument("--data", required=True, type=Path, metavar="DIR", help="captioned data set")
    p.add_argument("--out", required=True, type=Path, metavar="OUT", help="evaluator folder")
    p.add_argument("--steps", type=int, metavar="N", help="optimiser steps (default 600)")
    p.add_argument("--seed", type=int, metavar="S", help="seed (default 0)")
    p.set_defaults(func=_train_evaluator)


def _codes(ns: argparse.Namespace) -> int:
    from ..models.t2m_data import build_code_set

    t0 = time.perf_counter()
    cs = build_code_set(ns.dataset, ns.out, checkpoint=ns.checkpoint)
    steps = sum(c.steps for c in cs.clips)
    print(
        f"{cs.root}: {len(cs.clips)} clips of {len(cs.species)} species, {steps} code steps "
        f"({len(cs.split('train'))} train, {len(cs.split('val'))} val) in "
        f"{time.perf_counter() - t0:.0f} s"
    )
    return 0


def _train(ns: argparse.Namespace) -> int:
    from ..models.t2m_config import t2m_preset
    from ..models.t2m_train import train_codegpt

    cfg = t2m_preset(ns.config)
    changes: dict[str, object] = {}
    if ns.steps is not None:
        changes["train.steps"] = ns.steps
    if ns.seed is not None:
        changes["train.seed"] = ns.seed
    if changes:
        cfg = cfg.replace(**changes)
    res = train_codegpt(
        ns.codes, ns.out, cfg, resume=ns.resume, overwrite=ns.overwrite, stop_at=ns.stop_at
    )
    print(
        f"checkpoint {res.out_dir}: {res.steps}/{cfg.train.steps} steps, "
        f"{res.steps_per_s:.2f} steps/s, {res.wall_time_s:.0f} s"
    )
    for k, v in res.metrics.items():
        print(f"  {k:16s} {v}")
    return 0


def _generate(ns: argparse.Namespace) -> int:
    from ..fileio import output_transaction
    from ..models.t2m import text_to_motion

    with output_transaction({"--out": ns.out}):
        m = text_to_motion(
            ns.text,
            ns.species,
            ns.seconds,
            seed=ns.seed,
            temperature=ns.temperature,
            guidance=ns.guidance,
            top_k=ns.top_k,
            checkpoint=ns.checkpoint,
        )
        m.save(ns.out)
    info = m.metadata["text_to_motion"]
    print(
        f"{ns.out}: {m.species}, {m.num_frames} frames at {m.fps:g} fps "
        f"(habit of {info['habit_species'] or m.species}, guidance {info['guidance']:g})"
    )
    if info["retrieval"]:
        print(f"  {info['retrieval']['explanation']}")
    return 0


def _train_evaluator(ns: argparse.Namespace) -> int:
    from ..evaluation.t2m_evaluator import T2MEvaluatorConfig, train_t2m_evaluator

    changes: dict[str, int] = {}
    if ns.steps is not None:
        changes["steps"] = ns.steps
    if ns.seed is not None:
        changes["seed"] = ns.seed
    cfg = T2MEvaluatorConfig.from_dict({**T2MEvaluatorConfig().to_dict(), **changes})
    res = train_t2m_evaluator(ns.data, ns.out, cfg, log=None)
    print(
        f"evaluator {res.out_dir}: {res.pairs} train clips, {res.steps} steps, "
        f"loss {res.final_loss:.3f}, {res.wall_time_s:.0f} s"
    )
    for split, rp in res.retrieval.items():
        print(f"  {split:5s} R-precision top-1/2/3 " + " ".join(f"{v:.3f}" for v in rp))
    return 0
