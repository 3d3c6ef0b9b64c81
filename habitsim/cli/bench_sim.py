"""``habitsim bench sim``: simulation speed and tracking quality per species.

For every species (or ``--species``), in one run:

* ``raw`` — the model's raw ``mj_step`` rate [steps/s]: a Python loop of ``mj_step`` on
  the servo model holding the home pose (contacts active, the same physics cost as
  tracking);
* ``single`` — habitsim's tracking rate for one clip [simulated steps/s, wall time of the
  whole :func:`habitsim.sim.track` call: reference, simulation, falls, metrics], in-engine
  servos through ``mujoco.rollout``; ``python`` — the same clip with the controller called
  from Python every step;
* ``batched`` — :func:`habitsim.sim.track_many` over ``--batch`` clips and ``--threads``
  threads [total simulated steps/s]; target: ≥ 50 % of ``raw``;
* survival of ``--clips`` synthetic 5 s walks, unassisted, with ``servo`` and
  ``servo+stance``;
* ``sim_mpjpe_per_leg`` of the same walks with root assistance
  (``--assisted-controller``, default ``servo``, plus :func:`habitsim.sim.root_assist`);
  target: ≤ 0.05 (5 % of the hind-leg length), and the assistance it took
  (``assist_force_mg``).

Rates run every clip to its end (no stop at a fall) so they count the same steps; the
four rate measurements are repeated ``--repeats`` times, interleaved, and the best of each
is kept, so a busy machine disturbs the ratio less.
``--json`` prints one JSON object per species per line.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time
from typing import Any

import numpy as np

from .conventions import add_check_option, add_list_option, check_exit, format_legend

#: Batched tracking must reach this share of the raw mj_step rate.
TARGET_BATCH_RATIO = 0.5
#: Assisted tracking error target, share of the hind-leg length.
TARGET_ASSISTED_MPJPE_PER_LEG = 0.05


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
    from ..controllers import CONTROLLERS

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


def raw_step_rate(model: Any, seconds: float = 2.0) -> float:
    """mj_step calls per second on ``model`` holding its home pose (Python loop)."""
    import mujoco

    from ..mjutils import home_qpos
    from ..sim import servo_targets

    d = mujoco.MjData(model)
    d.qpos[:] = home_qpos(model)
    d.ctrl[:] = servo_targets(model, d.qpos)[0]
    n = int(round(seconds / model.opt.timestep))
    for _ in range(200):  # warm-up (contacts settle, caches)
        mujoco.mj_step(model, d)
    t0 = time.perf_counter()
    for _ in range(n):
        mujoco.mj_step(model, d)
    return n / (time.perf_counter() - t0)


def _clips(species: str, n: int, ns: argparse.Namespace, seed0: int = 0) -> list[Any]:
    from ..gaits import generate

    extra: dict[str, Any] = {"trunk_sway": 0.0} if ns.no_sway else {}
    return [
        generate(species, ns.action, seed=seed0 + i, duration_s=ns.duration, **extra)
        for i in range(n)
    ]


def _steps(result: Any) -> int:
    return int(round(result.sim_time_s / result.model.opt.timestep))


def bench_species(species: str, ns: argparse.Namespace, threads: int) -> dict[str, Any]:
    """All figures of one species (see the module docstring)."""
    from ..qpos import species_model
    from ..sim import track, track_many

    model = species_model(species, servos=True)
    out: dict[str, Any] = {"species": species, "threads": threads}
    batch = _clips(species, max(ns.batch, 1), ns, seed0=100)
    clip = batch[0]

    def rate(fn: Any) -> float:
        t0 = time.perf_counter()
        res = fn()
        steps = sum(_steps(x) for x in (res if isinstance(res, list) else [res]))
        return steps / (time.perf_counter() - t0)

    # interleaved repetitions, best of each: a loaded machine slows single runs at random
    best: dict[str, float] = {}
    for _ in range(max(ns.repeats, 1)):
        for key, fn in (
            ("raw_steps_per_s", lambda: raw_step_rate(model, 1.0)),
            ("single_steps_per_s", lambda: rate(lambda: track(clip, stop_on_fall=False))),
            (
                "python_steps_per_s",
                lambda: rate(lambda: track(clip, stop_on_fall=False, use_rollout=False)),
            ),
            (
                "batched_steps_per_s",
                lambda: rate(lambda: track_many(batch, stop_on_fall=False, threads=threads)),
            ),
        ):
            best[key] = max(best.get(key, 0.0), fn())
    out.update(best)
    out["batched_vs_raw"] = out["batched_steps_per_s"] / out["raw_steps_per_s"]
    out["single_vs_raw"] = out["single_steps_per_s"] / out["raw_steps_per_s"]
    if ns.skip_quality:
        return out
    walks = _clips(species, max(ns.clips, 1), ns)
    for name in ("servo", "servo+stance"):
        res = track_many(walks, controller=name, threads=threads)
        out[f"survival_{name}"] = float(np.mean([x.survival for x in res]))
    res = track_many(walks, controller=ns.assisted_controller, assist="root", threads=threads)
    out["assisted_survival"] = float(np.mean([x.survival for x in res]))
    out["assisted_sim_mpjpe_mm"] = float(np.mean([x.metrics["sim_mpjpe_mm"] for x in res]))
    out["assisted_sim_mpjpe_per_leg"] = float(
        np.mean([x.metrics["sim_mpjpe_per_leg"] for x in res])
    )
    out["assist_force_mg"] = float(np.mean([x.metrics["assist_force_mg"] for x in res]))
    return out


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


def _fmt(row: dict[str, Any]) -> str:
    def g(key: str, spec: str) -> str:
        v = row.get(key)
        return (
            "n/a"
            if v is None or (isinstance(v, float) and not math.isfinite(v))
            else format(v, spec)
        )

    ok = "ok" if row["batched_vs_raw"] >= TARGET_BATCH_RATIO else "MISSED"
    text = (
        f"{row['species']:<9} {g('raw_steps_per_s', '8.0f')} {g('single_steps_per_s', '8.0f')} "
        f"{g('python_steps_per_s', '8.0f')} {g('batched_steps_per_s', '8.0f')} "
        f"{g('batched_vs_raw', '6.2f')} {ok:<6}"
    )
    if "survival_servo" in row:
        mp = row["assisted_sim_mpjpe_per_leg"]
        ok2 = "ok" if mp <= TARGET_ASSISTED_MPJPE_PER_LEG else "MISSED"
        text += (
            f" {g('survival_servo', '6.2f')} {g('survival_servo+stance', '6.2f')} "
            f"{g('assisted_sim_mpjpe_mm', '8.1f')} {g('assisted_sim_mpjpe_per_leg', '6.3f')} "
            f"{ok2:<6} {g('assist_force_mg', '6.2f')}"
        )
    return text


def _bench_sim(ns: argparse.Namespace) -> int:
    import mujoco

    from ..errors import HabitsimError
    from ..species import load_species, species_names

    species = [load_species(s).name for s in ns.species] if ns.species else species_names()
    threads = int(ns.threads or os.cpu_count() or 1)
    if threads < 1 or ns.batch < 1 or ns.clips < 1 or not ns.duration > 0:
        raise HabitsimError("--threads, --batch, --clips and --duration must be positive")
    if not ns.json:
        print(
            f"bench sim: mujoco {mujoco.__version__}, {threads} thread(s), {os.cpu_count()} "
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
        row = bench_species(sp, ns, threads)
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
            print(_fmt(row), flush=True)
    if not ns.json:
        print(format_legend(_LEGEND_QUALITY if not ns.skip_quality else _LEGEND))
    if not ns.json and len(rows) > 1:
        ratio = [r["batched_vs_raw"] for r in rows]
        print(
            f"batched/raw: min {min(ratio):.2f}, median {float(np.median(ratio)):.2f} "
            f"(target ≥ {TARGET_BATCH_RATIO})"
        )
    return check_exit(missed_targets(rows), ns.check)


def missed_targets(rows: list[dict[str, Any]]) -> list[str]:
    """The targets the rows miss (batched rate; assisted error where measured)."""
    missed = []
    for r in rows:
        if not r["batched_vs_raw"] >= TARGET_BATCH_RATIO:
            missed.append(
                f"{r['species']} batched/raw {r['batched_vs_raw']:.2f} < {TARGET_BATCH_RATIO}"
            )
        mp = r.get("assisted_sim_mpjpe_per_leg")
        if mp is not None and not mp <= TARGET_ASSISTED_MPJPE_PER_LEG:
            missed.append(
                f"{r['species']} assisted MPJPE/leg {mp:.3f} > {TARGET_ASSISTED_MPJPE_PER_LEG}"
            )
    return missed
