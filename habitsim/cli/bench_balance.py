"""``habitsim bench balance``: balance-aware tracking without external force (issue [6/6]).

For every species (default: the training species) and action (default: walk, trot, pace,
turn — each where the species has it), ``--clips`` synthetic clips of ``--duration`` s are
tracked by :func:`habitsim.sim.track` with three controllers built by
:func:`habitsim.controllers.make_controller`, root assistance OFF:

* ``pd`` — joint PD only;
* ``balance`` — stance-force QP every control tick;
* ``mpc`` — convex single-rigid-body MPC at ``--mpc-hz`` plus the stance QP.

Printed: per species and action the survival and ``sim_mpjpe_mm`` (and per leg length)
of each controller; then the stance-QP median solve time, the MPC median solve time, the
tracking speed relative to real time with MPC, the share of (species × action) that
survive the whole clip under ``mpc``, and the issue's targets next to them. ``--refine``
first runs :func:`habitsim.refine.refine` on every clip (the issue's targets are stated
for refined motions): stage A, or with ``--refine B`` stage B, whose centroidal dynamics
give the clip a momentum the feet can supply (a fast pace's flight phases become
ballistic). ``--json`` prints one JSON object per run and a summary object.
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

#: Targets of the issue.
TARGET_STANCE_QP_MS = 0.2
TARGET_MPC_MS = 5.0
TARGET_REALTIME = 5.0
TARGET_SURVIVAL_SHARE = 0.95
TARGET_MPJPE_PER_LEG = 0.10
#: Actions benchmarked by default ("turn" is turn_left).
DEFAULT_ACTIONS = ("walk", "trot", "pace", "turn")
CONTROLLERS = ("pd", "balance", "mpc")


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``balance`` to the ``bench`` command group."""
    p = sub.add_parser(
        "balance",
        help="stance QP / MPC timing and unassisted survival: pd vs balance vs mpc",
        description=(
            "Track synthetic clips of every training species unassisted with pd, balance "
            "(stance-force QP) and mpc (convex MPC + stance QP); print survival and "
            "sim MPJPE per species, QP and MPC solve times and the real-time factor."
        ),
    )
    add_list_option(p, "--species", help="species (default: the training species)")
    add_list_option(
        p,
        "--actions",
        default=list(DEFAULT_ACTIONS),
        metavar="ACTION",
        help="actions (default: walk trot pace turn; 'turn' = turn_left)",
    )
    add_list_option(
        p,
        "--controllers",
        default=list(CONTROLLERS),
        choices=CONTROLLERS,
        metavar="CONTROLLER",
        help="controllers (default: all three)",
    )
    p.add_argument(
        "--clips", type=int, default=1, metavar="N", help="clips per species and action (default 1)"
    )
    p.add_argument(
        "--duration", type=float, default=5.0, metavar="S", help="clip length [s] (default 5)"
    )
    p.add_argument("--seed", type=int, default=0, metavar="S", help="first seed (default 0)")
    p.add_argument(
        "--mpc-hz",
        type=float,
        default=30.0,
        metavar="HZ",
        help="MPC solves per second (default 30)",
    )
    p.add_argument(
        "--control-hz",
        type=float,
        metavar="HZ",
        help="control rate of the runner (default: every simulation step; mpc: "
        "habitsim.sim.MPC_CONTROL_HZ)",
    )
    p.add_argument(
        "--refine",
        nargs="?",
        const="A",
        choices=("A", "B"),
        metavar="STAGE",
        help="refine every clip first (habitsim.refine): stage A (kinematic, the "
        "default of --refine) or B (centroidal dynamics, --refine B)",
    )
    p.add_argument("--json", action="store_true", help="one JSON object per run, then a summary")
    add_check_option(
        p,
        help="exit with code 1 when a target is MISSED (stance QP and MPC solve "
        "times, real-time factor, mpc survival share and MPJPE; default: print "
        "the verdicts, exit 0)",
    )
    p.set_defaults(func=_bench_balance)


def _action(name: str) -> str:
    return "turn_left" if name == "turn" else name


def _clean(v: Any) -> Any:
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if isinstance(v, np.generic):
        return _clean(v.item())
    return v


def run_one(
    species: str,
    motion: Any,
    controller: str,
    *,
    mpc_hz: float = 30.0,
    control_hz: float | None = None,
) -> dict[str, Any]:
    """Track one clip with one controller; the figures of the run."""
    from ..controllers import make_controller
    from ..qpos import motion_to_qpos, species_model
    from ..sim import MPC_CONTROL_HZ, track

    model = species_model(species)
    options: dict[str, Any] = {}
    if control_hz is None and controller == "mpc":
        control_hz = MPC_CONTROL_HZ  # as habitsim.sim.track runs "mpc" by name
    if control_hz is not None:
        dt = 1.0 / control_hz
        options["dt" if controller == "pd" else "control_dt"] = dt
    if controller == "mpc":
        options["rate_hz"] = mpc_hz
    if controller != "pd":
        options.update(
            qpos=motion_to_qpos(motion, model).qpos, fps=motion.fps, contacts=motion.contacts
        )
    ctl = make_controller(controller, model, species if controller != "pd" else None, **options)
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


def _clips(species: str, action: str, ns: argparse.Namespace) -> list[Any]:
    from ..gaits import generate

    out = []
    for i in range(ns.clips):
        m = generate(species, _action(action), seed=ns.seed + i, duration_s=ns.duration)
        if ns.refine:
            from ..refine import RefineOptions, refine

            r = refine(m, RefineOptions(dynamics=ns.refine == "B", metrics=False, fallback=True))
            m = r.motion
        out.append(m)
    return out


def _median(rows: list[dict[str, Any]], key: str) -> float:
    v = [r[key] for r in rows if r.get(key) is not None and math.isfinite(r[key])]
    return float(np.median(v)) if v else float("nan")


def summarise(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Timing medians, real-time factor and survival shares over the runs."""
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
        cases: dict[tuple[str, str], list[float]] = {}
        for r in rc:
            cases.setdefault((r["species"], r["action"]), []).append(r["survival"])
        out[f"survival_share_{c}"] = float(np.mean([min(v) >= 1.0 for v in cases.values()]))
        out[f"mean_survival_{c}"] = float(np.mean([r["survival"] for r in rc]))
        survived = [r for r in rc if r["survival"] >= 1.0]
        out[f"mpjpe_per_leg_{c}"] = _median(survived, "sim_mpjpe_per_leg")
        out[f"cases_{c}"] = len(cases)
    return out


def _fmt_row(
    species: str, action: str, by: dict[str, dict[str, Any]], controllers: list[str]
) -> str:
    cells = []
    for c in controllers:
        r = by.get(c)
        if r is None:
            cells.append(f"{'-':>19}")
        else:
            cells.append(
                f"{r['survival']:5.2f} {r['sim_mpjpe_mm']:7.1f} {r['sim_mpjpe_per_leg']:5.3f}"
            )
    return f"{species:<9} {action:<10} " + "  ".join(cells)


def _verdict(ok: bool) -> str:
    return "met" if ok else "MISSED"


def _bench_balance(ns: argparse.Namespace) -> int:
    import mujoco

    from ..errors import HabitsimError
    from ..gaits import available_actions
    from ..sim import MPC_CONTROL_HZ
    from ..species import load_species, training_species

    if ns.clips < 1 or not ns.duration > 0 or not ns.mpc_hz > 0:
        raise HabitsimError("--clips, --duration and --mpc-hz must be positive")
    species = (
        [load_species(s).name for s in ns.species]
        if ns.species
        else [s.name for s in training_species()]
    )
    controllers = list(ns.controllers)
    if not ns.json:
        print(
            f"bench balance: mujoco {mujoco.__version__}, {os.cpu_count()} CPU(s), "
            f"{ns.clips} clip(s) × {ns.duration:g} s per species and action, "
            f"MPC {ns.mpc_hz:g} Hz, control "
            + (
                f"every step (mpc {MPC_CONTROL_HZ:g} Hz)"
                if ns.control_hz is None
                else f"{ns.control_hz:g} Hz"
            )
            + ", "
            + (f"stage-{ns.refine} refined" if ns.refine else "synthetic")
            + " clips, no external force"
        )
        head = "  ".join(f"{c + ' surv mpjpe /leg':>19}" for c in controllers)
        print(f"{'species':<9} {'action':<10} {head}")
    rows: list[dict[str, Any]] = []
    for sp in species:
        have = available_actions(sp)
        for action in ns.actions:
            if _action(action) not in have:
                continue
            for motion in _clips(sp, action, ns):
                by = {}
                for c in controllers:
                    row = run_one(sp, motion, c, mpc_hz=ns.mpc_hz, control_hz=ns.control_hz)
                    row["action"] = action
                    rows.append(row)
                    by[c] = row
                    if ns.json:
                        print(json.dumps({k: _clean(v) for k, v in row.items()}), flush=True)
                if not ns.json:
                    print(_fmt_row(sp, action, by, controllers), flush=True)
    summary = summarise(rows)
    missed = missed_targets(summary, controllers)
    if ns.json:
        print(json.dumps({"summary": {k: _clean(v) for k, v in summary.items()}}))
        return check_exit(missed, ns.check)
    print(
        format_legend(
            "(per controller: surv = share of the clip completed before a fall; "
            "mpjpe = sim MPJPE [mm] against the reference; /leg = the same per "
            "hind-leg length)"
        )
    )
    qp, mpc = summary["stance_qp_median_ms"], summary["mpc_median_ms"]
    rt = summary.get("realtime_factor_mpc", float("nan"))
    print()
    print(
        f"stance QP median solve      {qp:8.3f} ms   (target ≤ {TARGET_STANCE_QP_MS} ms: "
        f"{_verdict(qp <= TARGET_STANCE_QP_MS)})"
    )
    if "mpc" in controllers:
        print(
            f"MPC median solve            {mpc:8.3f} ms   (target ≤ {TARGET_MPC_MS} ms: "
            f"{_verdict(mpc <= TARGET_MPC_MS)})"
        )
        print(
            f"tracking speed with MPC     {rt:8.2f} × real time   (target ≥ {TARGET_REALTIME}: "
            f"{_verdict(rt >= TARGET_REALTIME)})"
        )
    for c in controllers:
        share = summary.get(f"survival_share_{c}", float("nan"))
        line = (
            f"{c:<8} survival 1.0 in {share * 100:5.1f} % of {summary.get(f'cases_{c}', 0)} "
            f"species × action; mean survival {summary.get(f'mean_survival_{c}', 0):.2f}; "
            f"median sim MPJPE/leg (survived) "
            f"{summary.get(f'mpjpe_per_leg_{c}', float('nan')):.3f}"
        )
        if c == "mpc":
            line += (
                f"   (targets ≥ {TARGET_SURVIVAL_SHARE * 100:.0f} %: "
                f"{_verdict(share >= TARGET_SURVIVAL_SHARE)}; "
                f"MPJPE ≤ {TARGET_MPJPE_PER_LEG}: "
                f"{_verdict(summary.get('mpjpe_per_leg_mpc', 1.0) <= TARGET_MPJPE_PER_LEG)})"
            )
        print(line)
    for c in controllers:
        rtc = summary.get(f"realtime_factor_{c}", float("nan"))
        print(f"tracking speed {c:<8}     {rtc:8.2f} × real time")
    return check_exit(missed, ns.check)


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
