"""``habitsim bench sim``: simulation speed and tracking quality per species.

The benchmark is :mod:`habitsim.evaluation.bench.sim` (raw ``mj_step`` rate against
habitsim's tracking rate, single and batched; survival of synthetic walks; tracking error
with root assistance). This module parses its options and prints one line per species
(``--json``: one JSON object per species per line), the legend and the targets.
"""

from __future__ import annotations

import argparse
import json
import math
from typing import Any

from ..controllers import CONTROLLERS
from ..evaluation.bench.sim import TARGET_ASSISTED_MPJPE_PER_LEG, TARGET_BATCH_RATIO, SimTargets
from .conventions import add_check_option, add_list_option, check_exit, format_legend


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``sim`` to the ``bench`` command group."""
    p = sub.add_parser(
        "sim",
        help="raw mj_step vs tracking rate (single, batched); survival of synthetic walks",
        description=(
            "Per species: raw mj_step rate vs habitsim tracking rate (single clip and "
            "batched over threads), survival of unassisted 5 s synthetic walks (servo, "
            "servo+stance) and tracking error with root assistance."
        ),
    )
    add_list_option(p, "--species", help="species (default: all)")
    p.add_argument(
        "--clips",
        type=int,
        default=2,
        metavar="N",
        help="walks per species for survival / assisted error (default 2)",
    )
    p.add_argument(
        "--batch",
        type=int,
        default=8,
        metavar="N",
        help="clips in the batched-rate measurement (default 8)",
    )
    p.add_argument("--threads", type=int, metavar="T", help="threads (default: CPU count)")
    p.add_argument(
        "--repeats",
        type=int,
        default=3,
        metavar="R",
        help="interleaved repetitions of the rate measurements, best kept (default 3)",
    )
    p.add_argument(
        "--duration", type=float, default=5.0, metavar="S", help="walk length [s] (default 5)"
    )
    p.add_argument("--action", default="walk", help="synthetic action (default walk)")
    p.add_argument("--no-sway", action="store_true", help="generate the walks with trunk_sway=0")
    p.add_argument(
        "--assisted-controller",
        default="servo",
        choices=CONTROLLERS,
        help="controller of the assisted runs (default servo)",
    )
    p.add_argument(
        "--skip-quality", action="store_true", help="rates only (no survival / assisted runs)"
    )
    p.add_argument("--json", action="store_true", help="one JSON object per species per line")
    add_check_option(p)
    p.set_defaults(func=_bench_sim)


_LEGEND = (
    "raw/s: mj_step per second holding the home pose; single/s: simulated steps per wall "
    "second of one track() call (in-engine servos, mujoco.rollout); python/s: the same with "
    "the controller called from Python; batch/s: track_many over the threads; b/raw: "
    f"batch/s ÷ raw/s, ≥0.5: its target ({TARGET_BATCH_RATIO})"
)
_LEGEND_QUALITY = _LEGEND + (
    "; surv, s+stc: survival (share of the walk completed) unassisted with servo and "
    "servo+stance; as.mpjpe: sim MPJPE [mm] with root assistance, /leg: per hind-leg length, "
    f"≤0.05: its target ({TARGET_ASSISTED_MPJPE_PER_LEG}); as.mg: mean assistance force / m·g"
)


def _fmt(row: dict[str, Any], targets: SimTargets) -> str:
    def g(key: str, spec: str) -> str:
        v = row.get(key)
        return (
            "n/a"
            if v is None or (isinstance(v, float) and not math.isfinite(v))
            else format(v, spec)
        )

    from ..evaluation.bench.sim import row_verdicts

    batch_ok, mpjpe_ok = row_verdicts(row, targets)
    ok = "ok" if batch_ok else "MISSED"
    text = (
        f"{row['species']:<9} {g('raw_steps_per_s', '8.0f')} {g('single_steps_per_s', '8.0f')} "
        f"{g('python_steps_per_s', '8.0f')} {g('batched_steps_per_s', '8.0f')} "
        f"{g('batched_vs_raw', '6.2f')} {ok:<6}"
    )
    if "survival_servo" in row:
        ok2 = "ok" if mpjpe_ok else "MISSED"
        text += (
            f" {g('survival_servo', '6.2f')} {g('survival_servo+stance', '6.2f')} "
            f"{g('assisted_sim_mpjpe_mm', '8.1f')} {g('assisted_sim_mpjpe_per_leg', '6.3f')} "
            f"{ok2:<6} {g('assist_force_mg', '6.2f')}"
        )
    return text


def _bench_sim(ns: argparse.Namespace, targets: SimTargets | None = None) -> int:
    """Run and print ``bench sim``; the rows are held to ``targets`` (None: the
    benchmark's, :class:`SimTargets`'s defaults; a test passes others)."""
    targets = targets or SimTargets()
    from ..evaluation.bench.machine import cpu_count, mujoco_version
    from ..evaluation.bench.sim import (
        SimOptions,
        batched_ratio,
        bench_species,
        missed_targets,
        species_of,
    )

    opts = SimOptions(
        species=tuple(ns.species or ()),
        clips=ns.clips,
        batch=ns.batch,
        threads=ns.threads,
        repeats=ns.repeats,
        duration=ns.duration,
        action=ns.action,
        sway=not ns.no_sway,
        assisted_controller=ns.assisted_controller,
        quality=not ns.skip_quality,
    )
    species, threads = species_of(opts)
    if not ns.json:
        print(
            f"bench sim: mujoco {mujoco_version()}, {threads} thread(s), {cpu_count()} "
            f"CPU(s), {ns.action} {ns.duration:g} s{' (no sway)' if ns.no_sway else ''}, "
            f"batch {ns.batch}, {ns.clips} clip(s) per species for quality"
        )
        head = (
            f"{'species':<9} {'raw/s':>8} {'single/s':>8} {'python/s':>8} {'batch/s':>8} "
            f"{'b/raw':>6} {'≥0.5':<6}"
        )
        if not ns.skip_quality:
            head += (
                f" {'surv':>6} {'s+stc':>6} {'as.mpjpe':>8} {'/leg':>6} {'≤0.05':<6} {'as.mg':>6}"
            )
        print(head)
    rows = []
    for sp in species:
        row = bench_species(sp, opts, threads)
        rows.append(row)
        if ns.json:
            print(
                json.dumps(
                    {
                        k: (None if isinstance(v, float) and not math.isfinite(v) else v)
                        for k, v in row.items()
                    }
                ),
                flush=True,
            )
        else:
            print(_fmt(row, targets), flush=True)
    if not ns.json:
        print(format_legend(_LEGEND_QUALITY if not ns.skip_quality else _LEGEND))
    if not ns.json and len(rows) > 1:
        low, median = batched_ratio(rows)
        print(f"batched/raw: min {low:.2f}, median {median:.2f} (target ≥ {targets.batch_ratio})")
    return check_exit(missed_targets(rows, targets), ns.check)
