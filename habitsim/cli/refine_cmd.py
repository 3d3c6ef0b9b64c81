"""``habitsim refine IN.npz --out OUT.npz``: make a motion physically plausible.

::

    habitsim refine IN.npz --out OUT.npz [--report R.json] [--qpos Q.npz] [--dynamics]
                           [--fallback] [--detect-contacts] [--window W] [--overlap V]
                           [--max-iter N] [--no-metrics] [--json]

Runs :func:`habitsim.refine.refine` (stage A, kinematic; stage B with ``--dynamics``) and
writes

* ``--out``: the refined motion (habitsim ``.npz``, with the contact labels used and
  ``metadata["refine"]``);
* ``--report``: the JSON report of :mod:`habitsim.refine.report` (status, iterations,
  solve time, each cost term, constraint violations, MuJoCo checks, docs/metrics.md kinematic
  and dynamic metrics before / after, the cleaned contact labels, and the ``verdict``:
  skate / jerk / penetration before and after and whether the result is worse on any;
  the summary prints it, and a result worse than its input gets a warning on stderr);
* ``--qpos``: the refined qpos trajectory of the species' model (``.npz`` with ``qpos``
  (T, nq), ``fps``, ``species`` and ``qpos_names``, one per column: ``root_x`` …
  ``root_qz`` for the free joint, then the hinge names).

Every output is written atomically, and only once the refinement has finished: the
destinations are checked before it starts, and the files appear together or not at all,
so a failed run (or one output that cannot be written) leaves no file behind.
Exit codes: 0 success; 1 IPOPT failed and ``--fallback``
wrote the input unchanged (status in the report); 2 bad input or (without
``--fallback``) a failed refinement, with ``error: ...`` on stderr.
"""

from __future__ import annotations

import argparse
import io
import json
import math
import sys
from pathlib import Path

import numpy as np

from ..errors import MotionFileError
from .conventions import add_source_options, source_options


def register(sub: argparse._SubParsersAction) -> None:
    """Add the top-level ``refine`` command."""
    from ..refine import RefineOptions

    _DEFAULTS = RefineOptions()
    p = sub.add_parser(
        "refine",
        help="refine a motion (CasADi/IPOPT): no foot sliding, penetration, hovering, "
        "joint-limit excursions or jitter",
        description=(
            "Trajectory optimisation on the species' MuJoCo model that removes foot "
            "sliding, ground penetration, hovering, joint-limit excursions and jitter while "
            "staying close to the input; --dynamics adds contact forces and centroidal "
            "dynamics."
        ),
    )
    p.add_argument("input", metavar="IN.npz", help="motion file")
    add_source_options(p, of="the motion", motion_capture=False)
    p.add_argument("--out", required=True, metavar="OUT.npz", help="refined motion file")
    p.add_argument("--report", metavar="R.json", help="write the JSON report here")
    p.add_argument("--qpos", metavar="Q.npz", help="write the refined qpos trajectory here")
    p.add_argument(
        "--dynamics",
        action="store_true",
        help="stage B: contact forces in friction pyramids + centroidal dynamics",
    )
    p.add_argument(
        "--fallback",
        action="store_true",
        help="if IPOPT fails, write the input unchanged (exit code 1) instead of failing",
    )
    p.add_argument(
        "--detect-contacts",
        action="store_true",
        help="detect contact labels even if the file has some",
    )
    p.add_argument(
        "--window",
        type=int,
        default=_DEFAULTS.window,
        metavar="W",
        help=f"window length for long clips [frames] (default {_DEFAULTS.window})",
    )
    p.add_argument(
        "--overlap",
        type=int,
        default=_DEFAULTS.overlap,
        metavar="V",
        help=f"overlap of consecutive windows [frames] (default {_DEFAULTS.overlap})",
    )
    p.add_argument(
        "--max-iter",
        type=int,
        default=200,
        metavar="N",
        help="IPOPT iteration limit per window (default 200)",
    )
    p.add_argument(
        "--no-metrics",
        action="store_true",
        help="skip the before/after docs/metrics.md metrics in the report",
    )
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.set_defaults(func=_refine)


def _check_out(path: str | None, what: str) -> None:
    if path is not None and Path(path).suffix != ".npz":
        raise MotionFileError(f"{what} must end in .npz, got {Path(path).name!r}")


def _qpos_names(model) -> list[str]:
    """One name per qpos column: ``<free joint>_x/y/z/qw/qx/qy/qz``, hinge names."""
    names = [""] * model.nq
    for j in range(model.njnt):
        a, name = int(model.jnt_qposadr[j]), model.joint(j).name
        if int(model.jnt_type[j]) == 0:  # free
            for k, suffix in enumerate(("x", "y", "z", "qw", "qx", "qy", "qz")):
                names[a + k] = f"{name}_{suffix}"
        elif int(model.jnt_type[j]) == 1:  # ball
            for k, suffix in enumerate(("qw", "qx", "qy", "qz")):
                names[a + k] = f"{name}_{suffix}"
        else:
            names[a] = name
    return names


def _g(x: object, spec: str = ".4g") -> str:
    """A report figure for the summary: ``n/a`` for a missing (None / NaN) one (a report
    of an absurd input can hold those)."""
    if isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x):
        return format(x, spec)
    return "n/a"


def _summary(rep: dict) -> str:
    from ..refine.cleaning import CleaningRecord

    lines = [
        f"refine: {rep['species']}, {rep['frames']} frames, stage {rep['stage']}: "
        f"{rep['status']} in {rep['iterations']} iterations, "
        f"{_g(rep['solve_time_s'], '.2f')} s solve ({len(rep['windows'])} window(s))",
        f"  max constraint violation {_g(rep['max_constraint_violation'], '.2e')}; stance drift "
        f"{_g(rep['checks']['stance_drift_max_mm'], '.3f')} mm, penetration "
        f"{_g(rep['checks']['penetration_max_mm'], '.3f')} mm",
        "  cost: " + ", ".join(f"{k} {_g(v, '.3g')}" for k, v in rep["cost"].items()),
    ]
    before, after = rep.get("metrics_before"), rep.get("metrics_after")
    if before and after:
        keys = (
            "penetration_mm",
            "float_mm",
            "skate_mm",
            "jerk",
            "joint_limit_violation_rad",
            "root_residual_mg",
        )
        lines.append("  metric                       before      after")
        for k in keys:
            if k in before and k in after and before[k] is not None and after[k] is not None:
                lines.append(f"  {k:26s} {_g(before[k], '9.4g'):>9s}  {_g(after[k], '9.4g'):>9s}")
    cl = CleaningRecord.from_report(rep)
    if cl is not None and cl.frames_changed:
        parts = [
            f"{foot} " + ", ".join(f"{v} {k}" for k, v in ch.items() if v)
            for foot, ch in cl.feet
            if ch.changed
        ]
        lines.append(
            f"  contact labels cleaned: {cl.frames_changed} frame(s) changed ("
            + "; ".join(parts)
            + ")"
        )
    for g in rep.get("guard") or []:
        lines.append(
            f"  guard: first result worse on {', '.join(g['worse'])}; solved again with "
            "smoother weights"
        )
    v = rep.get("verdict")
    if v:
        verdict_keys = ("skate_mm", "jerk", "penetration_mm")
        lines.append(
            "  verdict: "
            + ", ".join(f"{k} {_g(v['before'][k])} → {_g(v['after'][k])}" for k in verdict_keys)
            + (" — not worse than the input" if v["ok"] else f" — WORSE on {', '.join(v['worse'])}")
        )
    if "residual_mg" in rep:
        lines.append(
            f"  model root residual / m·g: mean {_g(rep['residual_mg']['mean'], '.3f')}, "
            f"max {_g(rep['residual_mg']['max'], '.3f')}"
        )
    return "\n".join(lines)


def _refine(ns: argparse.Namespace) -> int:
    from ..fileio import output_transaction

    _check_out(ns.out, "--out")
    _check_out(ns.qpos, "--qpos")
    # every destination is checked before the work, and the files appear together or not at all
    with output_transaction({"--out": ns.out, "--qpos": ns.qpos, "--report": ns.report}):
        return _refine_outputs(ns)


def _refine_outputs(ns: argparse.Namespace) -> int:
    from ..fileio import atomic_write, atomic_write_text
    from ..motion import load_motion
    from ..qpos import species_model
    from ..refine import RefineOptions, refine

    motion = source_options(ns).span.cut(load_motion(ns.input), what=str(ns.input))
    contacts = motion.detect_contacts() if ns.detect_contacts else None
    opts = RefineOptions(
        dynamics=ns.dynamics,
        fallback=ns.fallback,
        window=ns.window,
        overlap=ns.overlap,
        max_iter=ns.max_iter,
        metrics=not ns.no_metrics,
    )
    res = refine(motion, opts, contacts=contacts)
    rep = dict(res.report, input=str(ns.input))
    text = json.dumps(rep, indent=2, allow_nan=False)
    qbuf = None
    if ns.qpos is not None:
        model = species_model(motion.species)
        buf = io.BytesIO()
        np.savez_compressed(
            buf,
            qpos=res.qpos,
            fps=np.array(res.fps),
            species=np.array(motion.species),
            qpos_names=np.array(_qpos_names(model)),
        )
        qbuf = buf.getvalue()
    # everything computed: write the outputs (each atomically)
    res.motion.save(ns.out)
    if qbuf is not None:
        with atomic_write(ns.qpos) as fh:
            fh.write(qbuf)
    if ns.report is not None:
        atomic_write_text(ns.report, text + "\n")
    print(text if ns.json else _summary(rep))
    if not res.success:
        print(
            f"warning: refinement failed ({res.status}); wrote the input unchanged", file=sys.stderr
        )
        return 1
    verdict = res.report.get("verdict")
    if verdict and not verdict["ok"]:
        print(
            f"warning: the refined clip is worse than the input on {', '.join(verdict['worse'])}",
            file=sys.stderr,
        )
    return 0
