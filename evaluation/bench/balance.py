"""``habitsim bench balance``: balance-aware tracking without external force.

For every species (default: the training species) and action (default: walk, trot, pace,
turn — each where the species has it), ``clips`` synthetic clips of ``duration`` s are
tracked by :func:`habitsim.sim.track`, root assistance OFF, with every controller of the
registry that drives the torque motors (:data:`CONTROLLERS`: ``pd`` — joint PD only;
``balance`` — stance-force QP every control tick; ``mpc`` — convex single-rigid-body MPC
at ``mpc_hz`` plus the stance QP), each built by
:func:`habitsim.controllers.make_controller`.

Measured (:func:`summarise`): the stance-QP and MPC median solve times [ms], the
tracking speed relative to real time per controller, the share of (species × action) that
survive the whole clip, the mean survival and the median sim MPJPE per leg length of the
runs that survived; :func:`missed_targets` holds them against the issue's targets.
``refine`` first runs :func:`habitsim.refine.refine` on every clip (the targets are stated
for refined motions): stage A, or stage B, whose centroidal dynamics give the clip a
momentum the feet can supply (a fast pace's flight phases become ballistic).
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

from habitsim.controllers import REGISTRY

__all__ = [
    "CONTROLLERS",
    "BalanceCase",
    "BalanceOptions",
    "cases",
    "json_clean",
    "missed_targets",
    "run_one",
    "species_of",
    "summarise",
]

#: Targets of the issue: stance-QP and MPC median solve time [ms], tracking speed with
#: MPC [× real time], share of (species × action) surviving under mpc, median sim MPJPE
#: under mpc [leg lengths].
TARGET_STANCE_QP_MS = 0.2
TARGET_MPC_MS = 5.0
TARGET_REALTIME = 5.0
TARGET_SURVIVAL_SHARE = 0.95
TARGET_MPJPE_PER_LEG = 0.10
#: Actions benchmarked by default ("turn" is turn_left).
DEFAULT_ACTIONS = ("walk", "trot", "pace", "turn")
#: The controllers compared: every registry entry that drives the torque motors.
CONTROLLERS: tuple[str, ...] = tuple(n for n, s in REGISTRY.items() if s.actuators == "torque")

#: One tracking run's figures, a JSON object: ``species``, ``action``, ``seed``,
#: ``controller``, ``survival`` (share of the clip), ``fell``, ``fall_reason``,
#: ``sim_mpjpe_mm`` [mm], ``sim_mpjpe_per_leg``, ``assist_force_mg``, ``sim_time_s`` /
#: ``wall_time_s`` [s], ``realtime_factor``, ``stance_qp_median_ms`` / ``mpc_median_ms``
#: [ms], ``controller_failures``.
BalanceRow = dict[str, Any]


@dataclass(frozen=True)
class BalanceOptions:
    """What a ``bench balance`` run does.

    Attributes:
        species: species (empty: the training species).
        actions: actions (``turn`` = ``turn_left``); one a species lacks is skipped.
        controllers: controllers to compare (names of :data:`CONTROLLERS`).
        clips: clips per species and action.
        duration: clip length [s].
        seed: seed of the first clip (the next ones count up).
        mpc_hz: MPC solves per second [Hz].
        control_hz: control rate of the runner [Hz] (None: every simulation step; mpc:
            :attr:`habitsim.sim.TrackOptions.mpc_control_hz`).
        refine: refine every clip first: ``A``, ``B``, or None.
    """

    species: tuple[str, ...] = ()
    actions: tuple[str, ...] = DEFAULT_ACTIONS
    controllers: tuple[str, ...] = CONTROLLERS
    clips: int = 1
    duration: float = 5.0
    seed: int = 0
    mpc_hz: float = 30.0
    control_hz: float | None = None
    refine: str | None = None


@dataclass(frozen=True)
class BalanceCase:
    """One clip of a species and action, tracked with every controller.

    Attributes:
        species, action: the case (``action`` as asked, ``turn`` for ``turn_left``).
        rows: controller → the run's figures (:data:`BalanceRow`).
    """

    species: str
    action: str
    rows: dict[str, BalanceRow]


def _action(name: str) -> str:
    return "turn_left" if name == "turn" else name


def run_one(
    species: str,
    motion: Any,
    controller: str,
    *,
    mpc_hz: float = 30.0,
    control_hz: float | None = None,
) -> BalanceRow:
    """Track one clip with one controller; the figures of the run."""
    from habitsim.controllers import controller_spec, make_controller
    from habitsim.qpos import motion_to_qpos, species_model
    from habitsim.sim import TrackOptions, track

    spec = controller_spec(controller)
    model = species_model(species)
    options: dict[str, Any] = {}
    if control_hz is None and controller == "mpc":
        control_hz = TrackOptions().mpc_control_hz  # as habitsim.sim.track runs "mpc" by name
    if control_hz is not None:
        dt = 1.0 / control_hz
        options["control_dt" if spec.planned else "dt"] = dt
    if controller == "mpc":
        options["rate_hz"] = mpc_hz
    if spec.planned:
        options.update(
            qpos=motion_to_qpos(motion, model).qpos, fps=motion.fps, contacts=motion.contacts
        )
    ctl = make_controller(controller, model, species if spec.planned else None, **options)
    t0 = time.perf_counter()
    res = track(motion, controller=ctl, model=model, control_hz=control_hz)
    wall = time.perf_counter() - t0
    st = res.controller_stats
    return {
        "species": species,
        "action": str(motion.metadata.get("action", "?")) if motion.metadata else "?",
        "seed": motion.metadata.get("seed") if motion.metadata else None,
        "controller": controller,
        "survival": float(res.survival),
        "fell": bool(res.failed),
        "fall_reason": res.fall_reason or res.unstable_reason,
        "sim_mpjpe_mm": float(res.metrics["sim_mpjpe_mm"]),
        "sim_mpjpe_per_leg": float(res.metrics["sim_mpjpe_per_leg"]),
        "assist_force_mg": float(res.metrics["assist_force_mg"]),
        "sim_time_s": float(res.sim_time_s),
        "wall_time_s": wall,
        "realtime_factor": float(res.sim_time_s) / wall if wall > 0 else float("nan"),
        "stance_qp_median_ms": float(st.get("stance_qp_median_ms", float("nan"))),
        "mpc_median_ms": float(st.get("mpc_median_ms", float("nan"))),
        "controller_failures": int(st.get("failures", 0)),
    }


def _clips(species: str, action: str, options: BalanceOptions) -> list[Any]:
    from habitsim.gaits import generate

    out = []
    for i in range(options.clips):
        m = generate(species, _action(action), seed=options.seed + i, duration_s=options.duration)
        if options.refine:
            from habitsim.refine import RefineOptions, refine

            r = refine(
                m, RefineOptions(dynamics=options.refine == "B", metrics=False, fallback=True)
            )
            m = r.motion
        out.append(m)
    return out


def species_of(options: BalanceOptions) -> list[str]:
    """The species a run covers (catalog names).

    Raises:
        HabitsimError: non-positive clips, duration or MPC rate. UnknownSpeciesError.
    """
    from habitsim.errors import HabitsimError
    from habitsim.species import load_species, training_species

    if options.clips < 1 or not options.duration > 0 or not options.mpc_hz > 0:
        raise HabitsimError("--clips, --duration and --mpc-hz must be positive")
    if options.species:
        return [load_species(s).name for s in options.species]
    return [s.name for s in training_species()]


def cases(options: BalanceOptions, species: list[str]) -> Iterator[BalanceCase]:
    """Every clip of every species (:func:`species_of`) and action, tracked with every
    controller, as each finishes."""
    from habitsim.gaits import available_actions

    for sp in species:
        have = available_actions(sp)
        for action in options.actions:
            if _action(action) not in have:
                continue
            for motion in _clips(sp, action, options):
                by: dict[str, BalanceRow] = {}
                for c in options.controllers:
                    row = run_one(
                        sp, motion, c, mpc_hz=options.mpc_hz, control_hz=options.control_hz
                    )
                    row["action"] = action
                    by[c] = row
                yield BalanceCase(sp, action, by)


def _median(rows: list[BalanceRow], key: str) -> float:
    v = [r[key] for r in rows if r.get(key) is not None and math.isfinite(r[key])]
    return float(np.median(v)) if v else float("nan")


def summarise(rows: list[BalanceRow]) -> dict[str, Any]:
    """Timing medians [ms], real-time factor and survival shares over the runs.

    Returns:
        ``stance_qp_median_ms``, ``mpc_median_ms``, and per controller ``c`` that ran:
        ``realtime_factor_c``, ``survival_share_c`` (share of species × action whose every
        clip survived whole), ``mean_survival_c``, ``mpjpe_per_leg_c`` (median over the
        runs that survived), ``cases_c``.
    """
    out: dict[str, Any] = {
        "stance_qp_median_ms": _median(
            [r for r in rows if r["controller"] != "pd"], "stance_qp_median_ms"
        ),
        "mpc_median_ms": _median([r for r in rows if r["controller"] == "mpc"], "mpc_median_ms"),
    }
    for c in CONTROLLERS:
        rc = [r for r in rows if r["controller"] == c]
        if not rc:
            continue
        sim = sum(r["sim_time_s"] for r in rc)
        wall = sum(r["wall_time_s"] for r in rc)
        out[f"realtime_factor_{c}"] = sim / wall if wall > 0 else float("nan")
        by_case: dict[tuple[str, str], list[float]] = {}
        for r in rc:
            by_case.setdefault((r["species"], r["action"]), []).append(r["survival"])
        out[f"survival_share_{c}"] = float(np.mean([min(v) >= 1.0 for v in by_case.values()]))
        out[f"mean_survival_{c}"] = float(np.mean([r["survival"] for r in rc]))
        survived = [r for r in rc if r["survival"] >= 1.0]
        out[f"mpjpe_per_leg_{c}"] = _median(survived, "sim_mpjpe_per_leg")
        out[f"cases_{c}"] = len(by_case)
    return out


def missed_targets(summary: dict[str, Any], controllers: list[str]) -> list[str]:
    """The targets a summary misses, as the printed verdicts judge them (a figure that
    was not measured, NaN, counts as missed only for a controller that ran)."""
    missed = []
    qp = summary["stance_qp_median_ms"]
    if any(c != "pd" for c in controllers) and not qp <= TARGET_STANCE_QP_MS:
        missed.append(f"stance QP median {qp:.3f} ms > {TARGET_STANCE_QP_MS} ms")
    if "mpc" in controllers:
        mpc = summary["mpc_median_ms"]
        rt = summary.get("realtime_factor_mpc", float("nan"))
        share = summary.get("survival_share_mpc", float("nan"))
        mp = summary.get("mpjpe_per_leg_mpc", float("nan"))
        if not mpc <= TARGET_MPC_MS:
            missed.append(f"MPC median {mpc:.3f} ms > {TARGET_MPC_MS} ms")
        if not rt >= TARGET_REALTIME:
            missed.append(f"MPC tracking {rt:.2f} × real time < {TARGET_REALTIME}")
        if not share >= TARGET_SURVIVAL_SHARE:
            missed.append(f"mpc survival share {share:.2f} < {TARGET_SURVIVAL_SHARE}")
        if not mp <= TARGET_MPJPE_PER_LEG:
            missed.append(f"mpc MPJPE/leg {mp:.3f} > {TARGET_MPJPE_PER_LEG}")
    return missed


def json_clean(v: Any) -> Any:
    """A figure for JSON: non-finite floats as None, numpy scalars as Python ones."""
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if isinstance(v, np.generic):
        return json_clean(v.item())
    return v
