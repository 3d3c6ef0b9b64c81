"""The printed report of ``habitsim bench real``: one line per row (:func:`format_row`
under :data:`HEAD`), the :data:`LEGEND`, and the summary per method with the targets
(:func:`format_summary`)."""

from __future__ import annotations

import math
import statistics
from collections import Counter
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..rows import finite_or_none
from .real import RealRow, survival_runs
from .targets import TargetCheck

__all__ = ["HEAD", "LEGEND", "format_row", "format_summary"]


def _f(v: Any, nd: int = 2) -> str:
    return "-" if v is None or (isinstance(v, float) and not math.isfinite(v)) else f"{v:.{nd}f}"


HEAD = (
    f"{'clip@start':24s} {'target':9s} {'method':6s} {'F1 imp':>6s} {'toe/L':>6s} "
    f"{'contacts':8s} {'skate mm b→a':>13s} {'jerk b→a':>15s} {'pen mm b→a':>11s} "
    f"{'check':9s} {'surv':>4s} {'MPJPE/L':>7s} {'t xfer/ref/trk s':>16s}"
)


#: Printed under the table of runs.
LEGEND = (
    "(F1 imp: contact F1 of the import against the source's own stance; toe/L: median "
    "stance toe height per hind-leg length; contacts: how the stance labels were found; "
    "b→a: before → after refinement (skate, pen: mm; jerk: m/s³); check: the refinement "
    "check (kept, reverted, fallback); surv: share of the window tracked before a fall; "
    "MPJPE/L: sim MPJPE per hind-leg length; t: wall time of transfer / refine / track [s]; "
    "Fr: the source window's peak Froude number over 0.5 s (above 2.5 a gallop); "
    "resid: residual root force [m·g] the tracked reference needs beyond what its stance "
    "feet can push, docs/metrics.md's root_residual_mg; whole k/K runs: with --repeats, "
    "the runs of the window tracked whole, and their mean survival; short window: a clip "
    "shorter than --seconds, run as one shorter window)"
)


def format_row(r: RealRow) -> str:
    """One printed line of a row."""
    name = f"{Path(r['clip']).stem}@{r['start_s']:g}"
    lead = f"{name[:24]:24s} {r['target']:9s} {r['method']:6s}"
    short = f"  short window {r['window_s']:.2f} s" if r.get("short_window") else ""
    if r["status"] != "ok":
        return f"{lead} {r['status']}: {r['note']}{short}"
    toe = r.get("stance_toe_height_import")
    runs = survival_runs(r)
    tail = short
    if r.get("source_froude_peak") is not None:
        tail += f"  Fr {r['source_froude_peak']:.1f}"
    if r.get("reference_residual_mg") is not None:
        tail += f"  resid {r['reference_residual_mg']:.2f}"
    if len(runs) > 1:
        tail += f"  whole {sum(x >= 1.0 for x in runs)}/{len(runs)} runs (mean {np.mean(runs):.2f})"
    return (
        f"{lead} {_f(r.get('import_contact_f1_mean')):>6s} {_f(toe, 3):>6s} "
        f"{str(r.get('contacts_method'))[:8]:8s} "
        f"{_f(r.get('skate_mm_before'), 1):>6s}→{_f(r.get('skate_mm_after'), 1):<6s} "
        f"{_f(r.get('jerk_before'), 0):>7s}→{_f(r.get('jerk_after'), 0):<7s} "
        f"{_f(r.get('penetration_mm_before'), 1):>5s}→{_f(r.get('penetration_mm_after'), 1):<5s} "
        f"{str(r.get('refine_check'))[:9]:9s} {_f(r.get('survival')):>4s} "
        f"{_f(r.get('sim_mpjpe_per_leg'), 3):>7s} "
        f"{_f(r.get('time_transfer_s'), 1)}/{_f(r.get('time_refine_s'), 1)}/"
        f"{_f(r.get('time_track_s'), 1)}{tail}"
    )


def _median(rows: Sequence[RealRow], key: str) -> float | None:
    v = [r[key] for r in rows if r.get(key) is not None]
    return float(statistics.median(v)) if v else None


def _per_target_survival(rows: Sequence[RealRow]) -> list[str]:
    """One line per target: the mean survival of each method over every tracking run of
    its windows (where habit and direct part), or nothing without tracking."""
    runs: dict[tuple[str, str], list[float]] = {}
    for r in rows:
        if r.get("status") == "ok" and survival_runs(r):
            runs.setdefault((str(r.get("target")), r["method"]), []).extend(survival_runs(r))
    if not runs:
        return []
    methods = list(dict.fromkeys(m for _, m in runs))
    lines = [f"  mean survival per target over every run ({' / '.join(methods)}):"]
    for tgt in dict.fromkeys(t for t, _ in runs):
        cells = [f"{np.mean(runs[tgt, m]):.2f}" if (tgt, m) in runs else "-" for m in methods]
        lines.append(f"    {tgt:10s} {' / '.join(cells)}")
    return lines


def _per_regime_survival(rows: Sequence[RealRow]) -> list[str]:
    """Survival of each method split by the gait regime of the source window: its peak
    Froude number (:func:`habitsim.gait_stats.peak_froude`) at or below
    :data:`~habitsim.gait_stats.GALLOP_FROUDE` (walks, trots, ambles) or above it
    (gallops). Nothing without tracking or without the Froude numbers."""
    from habitsim.gait_stats import GALLOP_FROUDE, PEAK_SPAN_S

    runs: dict[tuple[str, bool], list[list[float]]] = {}
    for r in rows:
        fr = finite_or_none(r.get("source_froude_peak"))
        if r.get("status") == "ok" and survival_runs(r) and fr is not None:
            runs.setdefault((r["method"], fr > GALLOP_FROUDE), []).append(survival_runs(r))
    if not runs:
        return []
    lines = [
        f"  survival per gait regime of the source window (peak Froude number over "
        f"{PEAK_SPAN_S:g} s; trot → gallop near Fr {GALLOP_FROUDE:g}):"
    ]
    for m in dict.fromkeys(m for m, _ in runs):
        cells = []
        for fast, label in ((False, f"Fr ≤ {GALLOP_FROUDE:g}"), (True, f"Fr > {GALLOP_FROUDE:g}")):
            win = runs.get((m, fast), [])
            flat = [x for w in win for x in w]
            cells.append(
                f"{label}: {len(win)} window(s), whole runs {sum(x >= 1.0 for x in flat)}/"
                f"{len(flat)}, mean survival {_f(float(np.mean(flat)) if flat else None)}"
            )
        lines.append(f"    {m:8s} " + "; ".join(cells))
    return lines


def format_summary(rows: Sequence[RealRow], targets: Sequence[TargetCheck]) -> str:
    """Per-method figures, wall time per stage and the targets block."""
    lines = ["", "summary per method (medians over the windows; survival: mean):"]
    for m in dict.fromkeys(r["method"] for r in rows):
        mr = [r for r in rows if r["method"] == m]
        ok = [r for r in mr if r["status"] == "ok"]
        surv = [r["survival"] for r in ok if r.get("survival") is not None]
        f1 = [r["import_contact_f1_mean"] for r in ok if r.get("import_contact_f1_mean")]
        how = Counter(str(r.get("contacts_method")) for r in ok)
        planted = Counter(str(r.get("planted")) for r in ok)
        checks = Counter(str(r.get("refine_check")) for r in ok)
        lines.append(
            f"  {m:8s} rows {len(ok)}/{len(mr)}; import F1 "
            f"{_f(float(np.mean(f1)) if f1 else None)}; toe/L import "
            f"{_f(_median(ok, 'stance_toe_height_import'), 3)}, transfer "
            f"{_f(_median(ok, 'stance_toe_height_transfer'), 3)}; skate "
            f"{_f(_median(ok, 'skate_mm_before'), 1)}→{_f(_median(ok, 'skate_mm_after'), 1)} mm"
            f" (labelled stance only {_f(_median(ok, 'skate_labelled_mm_before'), 1)}→"
            f"{_f(_median(ok, 'skate_labelled_mm_after'), 1)});"
            f" jerk {_f(_median(ok, 'jerk_before'), 0)}→{_f(_median(ok, 'jerk_after'), 0)};"
            f" penetration {_f(_median(ok, 'penetration_mm_before'), 1)}→"
            f"{_f(_median(ok, 'penetration_mm_after'), 1)} mm"
        )
        runs = [survival_runs(r) for r in ok if survival_runs(r)]
        if any(len(x) > 1 for x in runs):
            flat = [x for rr in runs for x in rr]
            every = sum(all(x >= 1.0 for x in rr) for rr in runs)
            never = sum(not any(x >= 1.0 for x in rr) for rr in runs)
            lines.append(
                f"           over every run ({len(flat)}): survival {np.mean(flat):.2f}, "
                f"whole runs {sum(x >= 1.0 for x in flat)}/{len(flat)}; windows whole in "
                f"every run {every}/{len(runs)}, in none {never}/{len(runs)}"
            )
        lines.append(
            f"           survival {_f(float(np.mean(surv)) if surv else None)} "
            f"(whole window {sum(s >= 1.0 for s in surv)}/{len(surv)}); sim MPJPE/L "
            f"{_f(_median(ok, 'sim_mpjpe_per_leg'), 3)}; contacts "
            + ", ".join(f"{k} {v}" for k, v in sorted(how.items()))
            + f" (walking stance {sum(r.get('walking_stance') is not None for r in ok)})"
            + "; planted "
            + ", ".join(f"{k} {v}" for k, v in sorted(planted.items()))
            + "; refinement check "
            + ", ".join(f"{k} {v}" for k, v in sorted(checks.items()))
        )
        lines.append(
            f"           tracked reference: residual root force "
            f"{_f(_median(ok, 'reference_residual_mg'))} m·g, torque beyond the motors on "
            f"{_f(_median(ok, 'reference_torque_saturation'))} of its frames (medians)"
        )
        lines.append(
            f"           wall time per stage [s]: transfer {_f(_median(ok, 'time_transfer_s'))},"
            f" refine {_f(_median(ok, 'time_refine_s'))}, track "
            f"{_f(_median(ok, 'time_track_s'))} (with the check's run of the unrefined "
            f"clip), total {_f(_median(ok, 'time_total_s'))}"
        )
    lines += _per_target_survival(rows)
    lines += _per_regime_survival(rows)
    reverted = [r for r in rows if r.get("refine_check") == "reverted"]
    for r in reverted:
        lines.append(
            f"  refinement reverted: {Path(r['clip']).stem}@{r['start_s']:g} → "
            f"{r['target']} ({r['method']}): {r['refine_note']}"
        )
    lines += ["", "targets:"]
    for t in targets:
        lines.append(f"  {t.name:62s} {t.shown:>14s}   (target {t.target}: {t.verdict})")
    return "\n".join(lines)
