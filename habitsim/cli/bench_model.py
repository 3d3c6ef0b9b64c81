"""``habitsim bench model``: what a model's transfers look like, on synthetic and real input.

The benchmark is :mod:`habitsim.evaluation.bench.model`: the reconstruction of the
reference clips, the gait kept and the resting stance feet of the transfers (synthetic
and real sources separately), what the frozen evaluator sees, the model's size and
latency. This module parses its options and prints them against the learning core's
targets.
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path
from typing import Any

from ..evaluation.bench.model import (
    DEFAULT_TARGETS,
    TARGET_ACTION_ACCURACY,
    TARGET_HABIT_ACCURACY,
    TARGET_LATENCY_MS,
    TARGET_PHASE_ERROR,
    TARGET_RESTING_SHARE,
    TARGET_ROOT_REL_PCT,
    TARGET_SIZE_MB,
    TARGET_TOE_SPEED,
    TARGET_WHOLE_PCT,
)
from .conventions import add_check_option, add_list_option, check_exit


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``model`` to the ``bench`` command group."""
    p = sub.add_parser(
        "model",
        help="transfer quality of a model: reconstruction, gait kept, feet at rest, size",
        description=(
            "Print a model's reference-clip reconstruction error, the footfall phase error "
            "and resting stance feet of its transfers (synthetic and real sources "
            "separately), its size and latency, against the learning core's targets."
        ),
    )
    p.add_argument("--checkpoint", type=Path, metavar="CKPT", help="default: the shipped model")
    p.add_argument(
        "--data",
        type=Path,
        metavar="DIR",
        help="synthetic data set whose --split clips are the sources (default: clips "
        "generated in memory, 2 per training species and cyclic action)",
    )
    p.add_argument("--split", default="test", help="split of --data (default test)")
    p.add_argument(
        "--max-sources",
        type=int,
        default=40,
        metavar="N",
        help="at most N synthetic sources (default 40)",
    )
    p.add_argument(
        "--real",
        type=Path,
        metavar="DIR",
        help="folder of real motion-capture files (.bvh/.glb/.gltf) of --real-species",
    )
    p.add_argument(
        "--real-species", default="dog", help="species of the --real files (default dog)"
    )
    add_list_option(
        p,
        "--targets",
        default=list(DEFAULT_TARGETS),
        metavar="SPECIES",
        help=f"target species (default {','.join(DEFAULT_TARGETS)}; a source's own is skipped)",
    )
    add_check_option(p)
    p.set_defaults(func=_bench_model)


def _row(name: str, q: dict[str, Any]) -> list[str]:
    ok_p = q["phase_error_median"] <= TARGET_PHASE_ERROR
    ok_r = q["resting_share"] >= TARGET_RESTING_SHARE
    return [
        f"  {name}: {q['transfers']} transfers",
        f"    footfall phase error   median {q['phase_error_median']:.3f} cycle over "
        f"{q['phase_measured']} stepping transfers, {100 * q['phase_error_share_ok']:.0f} % ≤ "
        f"{TARGET_PHASE_ERROR} (target median ≤ {TARGET_PHASE_ERROR}: "
        f"{'met' if ok_p else 'MISSED'})",
        f"    (on the contacts detected on the output's toes: median "
        f"{q['phase_error_feet_median']:.3f} cycle)",
        "    duty factor in the target's band  "
        + (
            f"{100 * q['duty_in_band']:.0f} %"
            if math.isfinite(q["duty_in_band"])
            else "- (the sources' gait is not known)"
        ),
        f"    stance toes at rest    {100 * q['resting_share']:.1f} % of {q['stance_frames']} "
        f"stance frames ≤ {TARGET_TOE_SPEED} leg/s (target ≥ {100 * TARGET_RESTING_SHARE:.0f} %: "
        f"{'met' if ok_r else 'MISSED'})",
        f"    (decoder alone, feet not planted: {100 * q['resting_share_decoder']:.1f} %; its "
        f"stance legs carry the body {100 * q['carried_travel_median']:.0f} % of its decoded "
        "travel, median)",
        "    stance labels          "
        + ", ".join(f"{k} {v}" for k, v in sorted(q["contact_methods"].items())),
        "    evaluator              " + _accuracy_text(q),
    ]


def _accuracy_text(q: dict[str, Any]) -> str:
    """The frozen evaluator's habit and action accuracy of a set of transfers."""
    parts = []
    for key, what, target in (
        ("habit", "habit accuracy", TARGET_HABIT_ACCURACY),
        ("action", "action accuracy", TARGET_ACTION_ACCURACY),
    ):
        acc, n = q[f"{key}_accuracy"], q[f"{key}_classified"]
        if not n:
            why = "no target it knows" if key == "habit" else "the sources' action is not known"
            parts.append(f"{what} - ({why})")
            continue
        verdict = "met" if acc >= target else "MISSED"
        parts.append(f"{what} {acc:.3f} of {n} (target ≥ {target:g}: {verdict})")
    return "; ".join(parts)


def _bench_model(ns: argparse.Namespace) -> int:
    from ..evaluation.bench.model import (
        ModelOptions,
        load,
        quality_missed,
        reconstruction,
        size_and_latency,
        source_sets,
        transfer_quality,
    )

    opts = ModelOptions(
        checkpoint=ns.checkpoint,
        data=ns.data,
        split=ns.split,
        max_sources=ns.max_sources,
        real=ns.real,
        real_species=ns.real_species,
        targets=tuple(ns.targets),
    )
    info = load(opts)
    t0 = time.perf_counter()
    print(f"bench model ({info.path}, variant {info.variant}, config {info.config})")
    whole, rel, missed = reconstruction(opts)
    print(
        f"  reference clips  reconstruction {whole:.2f} % of leg length (target ≤ "
        f"{TARGET_WHOLE_PCT:g}: {'met' if whole <= TARGET_WHOLE_PCT else 'MISSED'}), "
        f"root-relative {rel:.2f} % (target ≤ {TARGET_ROOT_REL_PCT:g}: "
        f"{'met' if rel <= TARGET_ROOT_REL_PCT else 'MISSED'})"
    )
    for name, sources in source_sets(opts):
        q = transfer_quality(sources, list(info.targets), ns.checkpoint)
        for line in _row(f"{name} sources ({len(sources)})", q):
            print(line)
        missed += quality_missed(name, q)
    size, lat, late = size_and_latency(opts, info)
    print(
        f"  model size       {size:.1f} MB (target ≤ {TARGET_SIZE_MB:g}: "
        f"{'met' if size <= TARGET_SIZE_MB else 'MISSED'}); transfer of 64 frames "
        f"{lat['end_to_end_median_ms']:.1f} ms median (target ≤ {TARGET_LATENCY_MS:g}: "
        f"{'met' if lat['end_to_end_median_ms'] <= TARGET_LATENCY_MS else 'MISSED'})"
    )
    missed += late
    print(f"  bench wall time  {time.perf_counter() - t0:.0f} s")
    return check_exit(missed, ns.check)
