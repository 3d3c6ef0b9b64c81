"""``habitsim bench train``: training throughput and transfer latency of the learning core.

The benchmark is :mod:`habitsim.evaluation.bench.train`; this module parses its options
and prints training steps/s, windows/s and frames/s of a preset, the steps its run
plans, and the transfer latency per 64-frame clip against the target (≤ 20 ms on CPU).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ..evaluation.bench.train import TARGET_LATENCY_MS
from .conventions import add_check_option, check_exit


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``train`` to the ``bench`` command group."""
    p = sub.add_parser(
        "train",
        help="time training steps and transfer latency of the learning core",
        description=(
            "Print training throughput (steps/s, frames/s) of a config preset and the "
            "transfer latency per 64-frame clip (target ≤ 20 ms on CPU)."
        ),
    )
    p.add_argument("--config", default="default", help="preset to time (default: default)")
    p.add_argument(
        "--steps", type=int, default=10, metavar="N", help="timed training steps (default 10)"
    )
    p.add_argument(
        "--threads", type=int, metavar="N", help="torch CPU threads (default: the preset's)"
    )
    p.add_argument(
        "--checkpoint",
        type=Path,
        metavar="DIR",
        help="checkpoint for the latency (default: shipped)",
    )
    p.add_argument(
        "--repeats", type=int, default=20, metavar="R", help="latency repeats (default 20)"
    )
    add_check_option(p)
    p.set_defaults(func=_bench_train)


def _bench_train(ns: argparse.Namespace) -> int:
    from ..evaluation.bench.train import TrainOptions, run_train

    res = run_train(
        TrainOptions(
            config=ns.config,
            steps=ns.steps,
            threads=ns.threads,
            checkpoint=ns.checkpoint,
            repeats=ns.repeats,
        )
    )
    tp, lat = res.throughput, res.latency
    print(f"bench train ({ns.config} config, {res.threads} torch thread(s))")
    print(
        f"  training      {tp['steps_per_s']:8.2f} steps/s  {tp['windows_per_s']:8.1f} windows/s  "
        f"{tp['frames_per_s']:9.0f} frames/s"
    )
    print(
        f"  planned run   {tp['planned_steps']:8.0f} steps ≈ {tp['planned_minutes']:.1f} min "
        "(training steps only)"
    )
    verdict = "met" if res.latency_met else "MISSED"
    print(
        f"  transfer 64 frames  end-to-end {lat['end_to_end_best_ms']:6.1f} ms best, "
        f"{lat['end_to_end_median_ms']:6.1f} ms median "
        f"(target ≤ {TARGET_LATENCY_MS:.0f} ms: {verdict})"
    )
    print(
        f"                      network    {lat['network_best_ms']:6.1f} ms best, "
        f"{lat['network_median_ms']:6.1f} ms median"
    )
    return check_exit(res.missed, ns.check)
