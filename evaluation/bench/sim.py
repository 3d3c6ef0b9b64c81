"""``habitsim bench sim``: simulation speed and tracking quality per species.

For every species, :func:`bench_species` measures:

* ``raw`` — the model's raw ``mj_step`` rate [steps/s]: a Python loop of ``mj_step`` on
  the servo model holding the home pose (contacts active, the same physics cost as
  tracking; :func:`raw_step_rate`);
* ``single`` — habitsim's tracking rate for one clip [simulated steps/s, wall time of the
  whole :func:`habitsim.sim.track` call: reference, simulation, falls, metrics], in-engine
  servos through ``mujoco.rollout``; ``python`` — the same clip with the controller called
  from Python every step;
* ``batched`` — :func:`habitsim.sim.track_many` over ``batch`` clips and ``threads``
  threads [total simulated steps/s]; target: ≥ 50 % of ``raw``;
* survival of ``clips`` synthetic walks, unassisted, with ``servo`` and ``servo+stance``;
* ``sim_mpjpe_per_leg`` of the same walks with root assistance (``assisted_controller``,
  default ``servo``, plus :func:`habitsim.sim.root_assist`); target: ≤ 0.05 (5 % of the
  hind-leg length), and the assistance it took (``assist_force_mg``).

Rates run every clip to its end (no stop at a fall) so they count the same steps; the
four rate measurements are repeated ``repeats`` times, interleaved, and the best of each
is kept, so a busy machine disturbs the ratio less.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = [
    "SimOptions",
    "SimTargets",
    "batched_ratio",
    "bench_species",
    "missed_targets",
    "raw_step_rate",
    "row_verdicts",
    "species_of",
]

#: Benchmark target: batched tracking reaches this share of the raw mj_step rate
#: [unitless].
TARGET_BATCH_RATIO = 0.5
#: Benchmark target: assisted tracking error [share of the hind-leg length].
TARGET_ASSISTED_MPJPE_PER_LEG = 0.05


@dataclass(frozen=True)
class SimTargets:
    """The targets a ``bench sim`` run is held to (default: the benchmark's own).

    Attributes:
        batch_ratio: least batched/raw rate ratio [unitless].
        assisted_mpjpe_per_leg: largest assisted tracking error [share of leg length].
    """

    batch_ratio: float = TARGET_BATCH_RATIO
    assisted_mpjpe_per_leg: float = TARGET_ASSISTED_MPJPE_PER_LEG


#: One species' figures, a JSON object: ``species``, ``threads``, the rates
#: ``raw_steps_per_s``, ``single_steps_per_s``, ``python_steps_per_s``,
#: ``batched_steps_per_s`` [steps/s], ``batched_vs_raw``, ``single_vs_raw``; with the
#: quality runs ``survival_servo``, ``survival_servo+stance``, ``assisted_survival``,
#: ``assisted_sim_mpjpe_mm`` [mm], ``assisted_sim_mpjpe_per_leg``, ``assist_force_mg``.
SimRow = dict[str, Any]


@dataclass(frozen=True)
class SimOptions:
    """What a ``bench sim`` run does.

    Attributes:
        species: species (empty: every species of the catalog).
        clips: walks per species for survival and the assisted error.
        batch: clips in the batched-rate measurement.
        threads: threads (None: the CPU count).
        repeats: interleaved repetitions of the rate measurements, best kept.
        duration: walk length [s].
        action: synthetic action.
        sway: generate the walks with their trunk sway (False: ``trunk_sway=0``).
        assisted_controller: controller of the assisted runs.
        quality: also run the survival and assisted runs (False: rates only).
    """

    species: tuple[str, ...] = ()
    clips: int = 2
    batch: int = 8
    threads: int | None = None
    repeats: int = 3
    duration: float = 5.0
    action: str = "walk"
    sway: bool = True
    assisted_controller: str = "servo"
    quality: bool = True


def species_of(options: SimOptions) -> tuple[list[str], int]:
    """The species a run covers and its thread count.

    Raises:
        HabitsimError: non-positive threads, batch, clips or duration. UnknownSpeciesError.
    """
    from habitsim.errors import HabitsimError
    from habitsim.species import load_species, species_names

    o = options
    species = [load_species(s).name for s in o.species] if o.species else species_names()
    threads = int(o.threads or os.cpu_count() or 1)
    if threads < 1 or o.batch < 1 or o.clips < 1 or not o.duration > 0:
        raise HabitsimError("--threads, --batch, --clips and --duration must be positive")
    return species, threads


def raw_step_rate(model: Any, seconds: float = 2.0) -> float:
    """mj_step calls per second on ``model`` holding its home pose (Python loop)."""
    import mujoco

    from habitsim.mjutils import home_qpos
    from habitsim.sim import servo_targets

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


def _clips(species: str, n: int, options: SimOptions, seed0: int = 0) -> list[Any]:
    from habitsim.gaits import generate

    extra: dict[str, Any] = {} if options.sway else {"trunk_sway": 0.0}
    return [
        generate(species, options.action, seed=seed0 + i, duration_s=options.duration, **extra)
        for i in range(n)
    ]


def _steps(result: Any) -> int:
    return int(round(result.sim_time_s / result.model.opt.timestep))


def bench_species(species: str, options: SimOptions, threads: int) -> SimRow:
    """All figures of one species (see the module docstring)."""
    from habitsim.qpos import species_model
    from habitsim.sim import track, track_many

    model = species_model(species, servos=True)
    out: SimRow = {"species": species, "threads": threads}
    batch = _clips(species, max(options.batch, 1), options, seed0=100)
    clip = batch[0]

    def rate(fn: Any) -> float:
        t0 = time.perf_counter()
        res = fn()
        steps = sum(_steps(x) for x in (res if isinstance(res, list) else [res]))
        return steps / (time.perf_counter() - t0)

    # interleaved repetitions, best of each: a loaded machine slows single runs at random
    best: dict[str, float] = {}
    for _ in range(max(options.repeats, 1)):
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
    if not options.quality:
        return out
    walks = _clips(species, max(options.clips, 1), options)
    for name in ("servo", "servo+stance"):
        res = track_many(walks, controller=name, threads=threads)
        out[f"survival_{name}"] = float(np.mean([x.survival for x in res]))
    res = track_many(walks, controller=options.assisted_controller, assist="root", threads=threads)
    out["assisted_survival"] = float(np.mean([x.survival for x in res]))
    out["assisted_sim_mpjpe_mm"] = float(np.mean([x.metrics["sim_mpjpe_mm"] for x in res]))
    out["assisted_sim_mpjpe_per_leg"] = float(
        np.mean([x.metrics["sim_mpjpe_per_leg"] for x in res])
    )
    out["assist_force_mg"] = float(np.mean([x.metrics["assist_force_mg"] for x in res]))
    return out


def batched_ratio(rows: list[SimRow]) -> tuple[float, float]:
    """Lowest and median batched/raw rate ratio over the species."""
    ratio = [r["batched_vs_raw"] for r in rows]
    return min(ratio), float(np.median(ratio))


def missed_targets(rows: list[SimRow], targets: SimTargets = SimTargets()) -> list[str]:
    """The targets the rows miss (batched rate; assisted error where measured)."""
    missed = []
    for r in rows:
        if not r["batched_vs_raw"] >= targets.batch_ratio:
            missed.append(
                f"{r['species']} batched/raw {r['batched_vs_raw']:.2f} < {targets.batch_ratio}"
            )
        mp = r.get("assisted_sim_mpjpe_per_leg")
        if mp is not None and not mp <= targets.assisted_mpjpe_per_leg:
            missed.append(
                f"{r['species']} assisted MPJPE/leg {mp:.3f} > {targets.assisted_mpjpe_per_leg}"
            )
    return missed


def row_verdicts(row: SimRow, targets: SimTargets = SimTargets()) -> tuple[bool, bool | None]:
    """Whether a species meets the batched-rate target, and the assisted-error target
    (None when the quality runs did not run)."""
    mp = row.get("assisted_sim_mpjpe_per_leg")
    return (
        row["batched_vs_raw"] >= targets.batch_ratio,
        None if mp is None else mp <= targets.assisted_mpjpe_per_leg,
    )
