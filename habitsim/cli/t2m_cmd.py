"""``habitsim t2m``: text to motion (:mod:`habitsim.models.t2m`): build a code set from a
captioned data set, train the transformer on it, generate a motion from a sentence."""

from __future__ import annotations

import argparse
import sys
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
        help="make a motion from a sentence, then refine and track it",
        description=(
            "Generate a motion doing what TEXT says with a trained transformer "
            "(classifier-free guidance; a held-out species borrows a habit by retrieval), "
            "on the species the text names (or --species), and write it as a .npz motion "
            "file; --refine and --track take it through the pipeline as habitsim eval "
            "does. A clip that does not show the action the text asks for (or a text "
            "naming no action habitsim makes) is written with a warning saying what it shows."
        ),
    )
    p.add_argument("text", metavar="TEXT", help='the prompt, e.g. "a horse trots to the left"')
    p.add_argument(
        "--species",
        metavar="SPECIES",
        help="species (built-in or user) when TEXT names none (it must agree when TEXT names one)",
    )
    p.add_argument("--checkpoint", type=Path, metavar="CKPT", help="transformer checkpoint")
    p.add_argument("--out", required=True, type=Path, metavar="OUT.npz", help="output motion")
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
    p.add_argument(
        "--refine",
        default="none",
        choices=("none", "kinematic", "dynamic"),
        help="refine the generated clip (CasADi/IPOPT; default none); --out is the refined "
        "clip unless it tracks worse than the unrefined one",
    )
    p.add_argument("--track", action="store_true", help="track the clip in MuJoCo, unassisted")
    from ..controllers import CONTROLLERS

    p.add_argument(
        "--controller",
        default="mpc",
        choices=CONTROLLERS,
        help="tracking controller (default mpc)",
    )
    p.add_argument(
        "--video", type=Path, metavar="V.mp4", help="render the tracked run (implies --track)"
    )
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
    from ..errors import MotionFileError
    from ..fileio import output_transaction

    if ns.out.suffix != ".npz":
        raise MotionFileError(f"--out must end in .npz, got {ns.out.name!r}")
    if ns.video is not None:
        from ..render import check_video_writer

        check_video_writer(ns.video)  # fail before generating
    # the destinations checked first; the files appear together or not at all
    with output_transaction({"--out": ns.out, "--video": ns.video}):
        return _generate_outputs(ns)


def _generate_outputs(ns: argparse.Namespace) -> int:
    import warnings

    from ..captions.prompts import PromptWarning, describe_facts
    from ..pipeline import run_text

    with warnings.catch_warnings():  # printed below, once, as the command's warnings
        warnings.simplefilter("ignore", PromptWarning)
        tr = run_text(
            ns.text,
            ns.species,
            seconds=ns.seconds,
            seed=ns.seed,
            temperature=ns.temperature,
            guidance=ns.guidance,
            top_k=ns.top_k,
            checkpoint=ns.checkpoint,
            refine=ns.refine,
            controller=ns.controller,
            track=ns.track or ns.video is not None,
        )
    run = tr.run
    run.reference.save(ns.out)
    m = tr.generated
    info = m.metadata["text_to_motion"]
    print(
        f"{ns.out}: {m.species}, {m.num_frames} frames at {m.fps:g} fps "
        f"(habit of {info['habit_species'] or m.species}, guidance {info['guidance']:g}); "
        f"it shows {describe_facts(tr.facts)}"
    )
    if info["retrieval"]:
        print(f"  {info['retrieval']['explanation']}")
    if run.refine != "none":
        print(f"  refinement {run.refined.status}: {run.refine_note}")
    res = run.track_result
    if run.tracked.status != "off":
        surv = "n/a" if res is None else f"{res.survival:.2f}"
        print(f"  tracked with {run.controller}: {run.tracked.status}, survival {surv}")
    if ns.video is not None:
        from ..render import RenderError, render_tracking

        if res is None:
            raise RenderError(f"no video: the tracking failed ({run.tracked.status})")

        render_tracking(res, ns.video)
        print(f"  video {ns.video}")
    for note in tr.warnings:
        print(f"warning: {note}", file=sys.stderr)
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
