"""``habitsim bench balance``: balance-aware tracking without external force.

The benchmark is :mod:`habitsim.evaluation.bench.balance`: synthetic clips of every
species and action tracked unassisted with the torque controllers of the registry (``pd``,
``balance``, ``mpc``). This module parses its options and prints, per species and action,
the survival and ``sim_mpjpe_mm`` (and per leg length) of each controller; then the
stance-QP and MPC median solve times, the tracking speed relative to real time, the share
of (species × action) that survive the whole clip under ``mpc``, and the issue's targets
next to them. ``--json`` prints one JSON object per run and a summary object.
"""

from __future__ import annotations

import argparse
import json
from typing import Any

from ..evaluation.bench.balance import (
    CONTROLLERS,
    DEFAULT_ACTIONS,
    TARGET_MPC_MS,
    TARGET_MPJPE_PER_LEG,
    TARGET_REALTIME,
    TARGET_STANCE_QP_MS,
    TARGET_SURVIVAL_SHARE,
)
from .conventions import add_check_option, add_list_option, check_exit, format_legend


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
        "habitsim.sim.TrackOptions.mpc_control_hz)",
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
    from ..evaluation.bench.balance import (
        BalanceOptions,
        cases,
        json_clean,
        missed_targets,
        species_of,
        summarise,
    )
    from ..evaluation.bench.machine import cpu_count, mujoco_version
    from ..sim import TrackOptions

    controllers = list(ns.controllers)
    opts = BalanceOptions(
        species=tuple(ns.species or ()),
        actions=tuple(ns.actions),
        controllers=tuple(controllers),
        clips=ns.clips,
        duration=ns.duration,
        seed=ns.seed,
        mpc_hz=ns.mpc_hz,
        control_hz=ns.control_hz,
        refine=ns.refine,
    )
    species = species_of(opts)
    if not ns.json:
        print(
            f"bench balance: mujoco {mujoco_version()}, {cpu_count()} CPU(s), "
            f"{ns.clips} clip(s) × {ns.duration:g} s per species and action, "
            f"MPC {ns.mpc_hz:g} Hz, control "
            + (
                f"every step (mpc {TrackOptions().mpc_control_hz:g} Hz)"
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
    for case in cases(opts, species):
        for c in controllers:
            rows.append(case.rows[c])
            if ns.json:
                print(json.dumps({k: json_clean(v) for k, v in case.rows[c].items()}), flush=True)
        if not ns.json:
            print(_fmt_row(case.species, case.action, case.rows, controllers), flush=True)
    summary = summarise(rows)
    missed = missed_targets(summary, controllers)
    if ns.json:
        print(json.dumps({"summary": {k: json_clean(v) for k, v in summary.items()}}))
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
