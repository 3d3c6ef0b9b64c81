"""``habitsim bench real --data DIR``: real motion capture through the whole pipeline.

Every clip of a folder (BVH, glTF/GLB; read by :func:`_read_source`, the one place
another format plugs in) is imported onto ``--species`` (default dog) with
:func:`habitsim.bvh_mapping.import_bvh`, resampled to ``--fps`` (default 30, the rate
the shipped model and the refinement are built for) and cut into windows of
``--seconds`` (default 4): consecutive windows from the first frame where the pelvis
moves, at most ``--windows-per-clip`` (default 1; ``all``: every whole window) per
clip; a clip shorter than one window is skipped with a note. Each window × target
(default cat, horse, camel, tiger, elephant) × method (default habit, direct) runs through
:func:`habitsim.pipeline.run_clip` (transfer → refine stage A → unassisted ``mpc``
tracking, with the refinement check), in an executor of the evaluation
(:mod:`habitsim.evaluation.executors`, ``--workers`` processes).

Per row: the import's contact F1 against the source's own feet (the importer's
``metadata["import"]["contact_f1"]``, one value per foot; "-" when the importer gives
none), the stance toe height (median height of the labelled-stance toes / leg length:
the import's own labels, and the transfer's), how the transfer's stance labels were
found, skate / jerk / penetration before and after refinement, the refinement check,
survival, sim MPJPE / leg length, the wall time per stage, and the dynamic plausibility
of the tracked reference (docs/metrics.md's ``root_residual_mg`` and
``torque_saturation`` under its stance labels: a window whose reference needs a large
"hand of god" force, or more torque than the motors have, cannot be tracked by any
controller without falling or deviating). Skating is docs/metrics.md's
``skate_mm`` (toes within 2 % of leg length of the ground count as in contact, labelled
or not); the JSON rows and the summary also give it over the labelled stance frames only
(``skate_labelled_mm_*``), the frames the refinement plants. The summary checks the
issue's targets (``met`` / ``MISSED``, as the other benchmarks print them; ``n/a`` when a
target does not apply to the run):

* refinement: skate ≤ 1 mm/frame, jerk ≤ the input's and penetration ≤ 1 mm on ≥ 95 % of
  the refined transfers;
* ≥ 90 % of the habit transfers survive the whole window unassisted under ``mpc``;
* median sim MPJPE ≤ 0.15 leg length (over the habit and direct windows; the habit
  windows' own median is shown beside it);
* habit ≥ direct on mean survival;
* transfer + refine + track of one 4 s window ≤ 10 s (median; scaled with ``--seconds``).

``--repeats K`` tracks every kept reference K times: once from the reference's own
state (the row's figures) and K − 1 times with Gaussian noise of ``--perturb`` rad/s
(default 10⁻³) on the initial joint velocities, one seed each
(:func:`habitsim.sim.track`'s ``init_noise``). A window near its balance limit survives
or falls on float-level differences (thread counts, a library version), so one run is one
sample; with repeats the two survival targets count every run (share of whole runs, mean
survival over all runs) and each row says in how many of its runs it was tracked whole.
The sim MPJPE and the wall times stay those of the unperturbed run.

A run that misses a target exits with code 1 (bad input: 2, as every command).
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import HabitsimError
from .conventions import add_frame_options, add_list_option, format_legend, split_names

if TYPE_CHECKING:  # pragma: no cover
    from ..motion import Motion

#: Default target species.
DEFAULT_TARGETS = ("cat", "horse", "camel", "tiger", "elephant")
#: Default transfer methods.
DEFAULT_METHODS = ("habit", "direct")
#: Refinement targets: skating [mm/frame] and mean penetration [mm] after refinement …
REFINE_SKATE_MM = 1.0
REFINE_PENETRATION_MM = 1.0
#: … on at least this share of the refined transfers.
REFINE_SHARE = 0.95
#: Share of habit transfers that survive the whole window unassisted under mpc.
SURVIVAL_SHARE = 0.90
#: Median sim MPJPE [leg lengths].
MPJPE_PER_LEG = 0.15
#: Transfer + refine + track of one 4 s window [s].
SECONDS_PER_4S_CLIP = 10.0
#: Initial joint-velocity noise [rad/s] of the repeated runs (``--perturb``).
PERTURB_QVEL = 1e-3
#: A window starts at the first frame whose pelvis speed (0.5 s moving average) exceeds
#: this many leg lengths per second (frame 0 when the animal never does).
MOVING_SPEED_PER_LEG = 0.25


class BenchRealError(HabitsimError, ValueError):
    """Bad input to ``bench real``: no readable clip in the folder, no clip long enough for
    a window, bad window settings."""


def _planted(motion: Any) -> str:
    """How the transfer planted its feet (``metadata["transfer"]["planted"]``):
    ``decoded`` / ``carried`` (the root path the feet were planted under), ``no`` (out of
    reach, decoded feet kept) or ``-`` (the method does not plant)."""
    p = (getattr(motion, "metadata", None) or {}).get("transfer", {}).get("planted")
    if not isinstance(p, dict):
        return "-"
    return str(p.get("root", "decoded")) if p.get("kept") else "no"


# ---------------------------------------------------------------------------- sources


def _import(
    path: Path,
    species: str,
    joint_map: Path | None = None,
    units: str | None = None,
    up: str | None = None,
) -> Motion:
    from ..bvh_mapping import import_bvh

    motion, _ = import_bvh(path, species, joint_map=joint_map, units=units, up=up)
    return motion


#: Readers of source clips by file suffix: ``reader(path, species, joint_map=, units=,
#: up=) -> Motion`` on the species' skeleton, with stance labels and
#: ``metadata["import"]`` when the importer finds them (the options as ``import-bvh``
#: takes them, None for its defaults). A glTF/GLB file gives its first animation.
SOURCE_READERS: dict[str, Callable[..., Motion]] = {
    ".bvh": _import,
    ".glb": _import,
    ".gltf": _import,
}


def _read_source(path: str | Path, species: str, **options: Any) -> Motion:
    """Read one source clip onto ``species``' skeleton, by its suffix (``options``: the
    reader's ``joint_map``, ``units``, ``up``).

    Raises:
        BenchRealError: a suffix no reader handles (lists the handled ones).
        BVHParseError / SkeletonMappingError: from the importer.
    """
    p = Path(path)
    reader = SOURCE_READERS.get(p.suffix.lower())
    if reader is None:
        raise BenchRealError(
            f"{p}: no reader for {p.suffix or 'files without a suffix'!r}; "
            f"readable: {', '.join(sorted(SOURCE_READERS))}"
        )
    return reader(p, species, **options)


def source_files(folder: str | Path) -> list[Path]:
    """The readable source clips of a folder (sorted).

    Raises:
        BenchRealError: not a folder, or no readable clip in it.
    """
    d = Path(folder)
    if not d.is_dir():
        raise BenchRealError(f"--data {d}: not a folder")
    files = sorted(p for p in d.iterdir() if p.is_file() and p.suffix.lower() in SOURCE_READERS)
    if not files:
        raise BenchRealError(
            f"--data {d}: no source clips ({', '.join(sorted(SOURCE_READERS))} files) in it"
        )
    return files


def window_starts(motion: Motion, frames: int, max_windows: int) -> list[int]:
    """Start frames of up to ``max_windows`` consecutive ``frames``-long windows, from the
    first frame where the pelvis moves (:data:`MOVING_SPEED_PER_LEG`); [] when the clip is
    shorter than one window."""
    n = motion.num_frames
    if n < frames:
        return []
    root = motion.root_positions[:, :2]
    speed = np.zeros(n)
    if n > 1:
        step = np.linalg.norm(np.diff(root, axis=0), axis=1) * motion.fps
        speed[1:] = step
        speed[0] = step[0]
    k = max(1, int(round(0.5 * motion.fps)))
    smooth = np.convolve(speed, np.ones(k) / k, mode="same")
    moving = np.flatnonzero(smooth > MOVING_SPEED_PER_LEG * motion.species_info.leg_length)
    first = int(moving[0]) if moving.size else 0
    first = min(first, n - frames)
    return [first + i * frames for i in range(max_windows) if first + (i + 1) * frames <= n]


# ---------------------------------------------------------------------------- tasks


@dataclass(frozen=True)
class WindowTask:
    """One window of a clip to one target with every method; plain data, picklable."""

    clip: str
    start_s: float
    motion: Any  # the window (a Motion)
    target: str
    methods: tuple[str, ...]
    refine: str
    controller: str
    track: bool
    guard: bool
    seed: int
    repeats: int = 1
    perturb: float = PERTURB_QVEL


def _num(v: Any) -> float | None:
    try:
        f = float(v)
    except (TypeError, ValueError):
        return None
    return f if math.isfinite(f) else None


def _import_f1(motion: Motion) -> list[float] | None:
    f1 = ((motion.metadata or {}).get("import") or {}).get("contact_f1")
    if f1 is None:
        return None
    vals = [_num(x) for x in (f1 if isinstance(f1, list | tuple) else [f1])]
    return [v for v in vals if v is not None] or None


def _reference_dynamics(run: Any) -> dict[str, float]:
    """docs/metrics.md's dynamic plausibility of the tracked reference under its stance
    labels (``root_residual_mg``, ``torque_saturation``, …): how far from what the
    animal's ground forces and motors can do the clip is; {} when it cannot be measured."""
    from ..metrics.dynamic import dynamic_metrics

    try:
        return dynamic_metrics(run.reference, run.model, run.reference_contacts)
    except HabitsimError:
        return {}


def _walking_stance(motion: Any) -> dict[str, Any] | None:
    """What :func:`habitsim.models.transfer.walking_stance` did to a transfer's labels
    (None: not applied)."""
    how = ((motion.metadata or {}).get("transfer") or {}).get("contacts") or {}
    return how.get("walking_stance") if isinstance(how, dict) else None


def run_window(task: WindowTask) -> list[dict[str, Any]]:
    """Every method of one (window, target) through the pipeline: one row per method.

    A failure inside a row (a typed error or a bug) becomes ``status = "error"`` with the
    message in ``note``; the benchmark goes on.
    """
    from ..evaluation.methods import MethodUnavailable
    from ..gait_stats import peak_froude
    from ..pipeline import run_clip, stance_toe_height, track_reference

    src = task.motion
    f1 = _import_f1(src)
    base = {
        "clip": task.clip,
        "start_s": task.start_s,
        "frames": src.num_frames,
        "fps": src.fps,
        "species": src.species,
        "target": task.target,
        "import_contact_f1": f1,
        "import_contact_f1_mean": None if f1 is None else float(np.mean(f1)),
        "source_labels": src.contacts is not None,
        "stance_toe_height_import": _num(stance_toe_height(src, src.contacts)),
        "source_froude_peak": peak_froude(src),
        "source_flight_share": None
        if src.contacts is None
        else float((~np.asarray(src.contacts, bool).any(axis=1)).mean()),
    }
    rows = []
    for method in task.methods:
        row: dict[str, Any] = {**base, "method": method, "status": "ok", "note": ""}
        t0 = time.perf_counter()
        try:
            run = run_clip(
                src,
                task.target,
                method=method,
                refine=task.refine,
                controller=task.controller,
                seed=task.seed,
                track=task.track,
                guard=task.guard,
            )
        except MethodUnavailable as e:
            row.update(status="unavailable", note=str(e))
            rows.append(row)
            continue
        except Exception as e:  # noqa: BLE001 - recorded in the row, the run goes on
            msg = str(e) if isinstance(e, HabitsimError) else f"{type(e).__name__}: {e}"
            row.update(status="error", note=msg, time_total_s=time.perf_counter() - t0)
            rows.append(row)
            continue
        a, b = run.transferred.metrics, run.refined.metrics
        tm = run.tracked.metrics
        runs: list[float] = []
        t_rep = time.perf_counter()
        if run.track_result is not None:
            runs.append(float(run.track_result.survival))
            for i in range(1, task.repeats):
                try:
                    again = track_reference(
                        run,
                        controller=task.controller,
                        seed=task.seed + i,
                        init_noise=task.perturb,
                    )
                except HabitsimError as e:
                    row["note"] = f"repeat {i} failed: {e}"
                    continue
                runs.append(float(again.survival))
        t_rep = time.perf_counter() - t_rep
        dyn = _reference_dynamics(run) if task.track else {}
        row.update(
            {
                "contacts_method": run.transferred.contacts_method,
                "walking_stance": _walking_stance(run.transferred.motion),
                "planted": _planted(run.transferred.motion),
                "stance_toe_height_transfer": _num(a.get("stance_toe_height_per_leg")),
                "stance_toe_height_refined": _num(b.get("stance_toe_height_per_leg")),
                "skate_mm_before": _num(a.get("skate_mm")),
                "skate_mm_after": _num(b.get("skate_mm")),
                "skate_labelled_mm_before": _num(a.get("skate_labelled_mm")),
                "skate_labelled_mm_after": _num(b.get("skate_labelled_mm")),
                "jerk_before": _num(a.get("jerk")),
                "jerk_after": _num(b.get("jerk")),
                "penetration_mm_before": _num(a.get("penetration_mm")),
                "penetration_mm_after": _num(b.get("penetration_mm")),
                "refine_status": run.refined.status,
                "refine_check": run.refine_verdict,
                "refine_note": run.refine_note,
                "track_status": run.tracked.status,
                "survival": _num(tm.get("survival")),
                "survival_runs": runs or None,
                "whole_runs": sum(x >= 1.0 for x in runs) if runs else None,
                "time_repeats_s": t_rep,
                "reference_residual_mg": _num(dyn.get("root_residual_mg")),
                "reference_torque_saturation": _num(dyn.get("torque_saturation")),
                "sim_mpjpe_per_leg": _num(tm.get("sim_mpjpe_per_leg")),
                "contact_f1_sim": _num(tm.get("contact_f1")),
                **{f"time_{k}_s": v for k, v in run.times.items()},
                "time_total_s": time.perf_counter() - t0 - t_rep,
            }
        )
        rows.append(row)
    return rows


# ---------------------------------------------------------------------------- targets


def survival_runs(row: dict[str, Any]) -> list[float]:
    """Survival of every tracking run of a row (the unperturbed run first; one run
    without ``--repeats``)."""
    runs = row.get("survival_runs")
    if runs:
        return [float(x) for x in runs]
    return [] if row.get("survival") is None else [float(row["survival"])]


def _verdict(ok: bool | None) -> str:
    return "n/a" if ok is None else ("met" if ok else "MISSED")


def evaluate_targets(
    rows: Sequence[dict[str, Any]],
    *,
    seconds: float,
    refine: str = "A",
    controller: str = "mpc",
    tracked: bool = True,
) -> list[dict[str, Any]]:
    """The issue's targets over the rows: name, measured value, target, verdict.

    Verdicts are ``met``, ``MISSED`` or ``n/a`` (the run does not measure it: no
    refinement, no tracking, another controller, a method missing).
    """
    ok = [r for r in rows if r.get("status") == "ok"]
    out: list[dict[str, Any]] = []

    # refinement
    ref = [r for r in ok if refine != "none"]
    good = [
        r
        for r in ref
        if (r.get("skate_mm_after") is not None and r["skate_mm_after"] <= REFINE_SKATE_MM)
        and (
            r.get("penetration_mm_after") is not None
            and r["penetration_mm_after"] <= REFINE_PENETRATION_MM
        )
        and (
            r.get("jerk_after") is not None
            and r.get("jerk_before") is not None
            and r["jerk_after"] <= r["jerk_before"] * (1 + 1e-9)
        )
    ]
    share = len(good) / len(ref) if ref else None
    out.append(
        {
            "name": "refinement: skate ≤ 1 mm/frame, jerk ≤ input, penetration ≤ 1 mm",
            "value": share,
            "shown": "-" if share is None else f"{100 * share:.0f} % of {len(ref)}",
            "target": f"≥ {100 * REFINE_SHARE:.0f} % of transfers",
            "verdict": _verdict(None if share is None else share >= REFINE_SHARE),
        }
    )

    # survival of habit transfers under mpc, unassisted (every run of every window)
    trk = [r for r in ok if tracked and r.get("survival") is not None]
    habit = [r for r in trk if r["method"] == "habit"]
    applies = tracked and controller == "mpc" and habit
    hruns = [x for r in habit for x in survival_runs(r)]
    share = (sum(x >= 1.0 for x in hruns) / len(hruns)) if applies else None
    shown = "-"
    if share is not None:
        shown = f"{100 * share:.0f} % of {len(habit)}"
        if len(hruns) > len(habit):
            shown = f"{100 * share:.0f} % of {len(hruns)} runs"
    out.append(
        {
            "name": "habit transfers surviving unassisted (mpc)",
            "value": share,
            "shown": shown,
            "target": f"≥ {100 * SURVIVAL_SHARE:.0f} %",
            "verdict": _verdict(None if share is None else share >= SURVIVAL_SHARE),
        }
    )

    # median sim MPJPE, over every tracked window (habit and direct); the habit windows'
    # own median is shown beside it
    e = [r["sim_mpjpe_per_leg"] for r in trk if r.get("sim_mpjpe_per_leg") is not None]
    med = float(np.median(e)) if e else None
    eh = [r["sim_mpjpe_per_leg"] for r in habit if r.get("sim_mpjpe_per_leg") is not None]
    shown = "-" if med is None else f"{med:.3f} of {len(e)}"
    if med is not None and eh:
        shown += f" (habit {float(np.median(eh)):.3f})"
    out.append(
        {
            "name": "median sim MPJPE / leg length, all tracked windows",
            "value": med,
            "shown": shown,
            "target": f"≤ {MPJPE_PER_LEG}",
            "verdict": _verdict(None if med is None else med <= MPJPE_PER_LEG),
        }
    )

    # habit ≥ direct on survival
    direct = [r for r in trk if r["method"] == "direct"]
    if habit and direct:
        sh = float(np.mean([x for r in habit for x in survival_runs(r)]))
        sd = float(np.mean([x for r in direct for x in survival_runs(r)]))
        shown, verdict, value = f"{sh:.2f} vs {sd:.2f}", _verdict(sh >= sd - 1e-9), sh - sd
    else:
        shown, verdict, value = "-", "n/a", None
    out.append(
        {
            "name": "habit ≥ direct on mean survival",
            "value": value,
            "shown": shown,
            "target": "habit ≥ direct",
            "verdict": verdict,
        }
    )

    # time per clip
    limit = SECONDS_PER_4S_CLIP * seconds / 4.0
    tt = [sum(r.get(f"time_{k}_s") or 0.0 for k in ("transfer", "refine", "track")) for r in ok]
    med = float(np.median(tt)) if tt else None
    out.append(
        {
            "name": f"transfer + refine + track of one {seconds:g} s window (median)",
            "value": med,
            "shown": "-" if med is None else f"{med:.1f} s",
            "target": f"≤ {limit:.1f} s" + ("" if seconds == 4 else " (10 s per 4 s)"),
            "verdict": _verdict(None if med is None else med <= limit),
        }
    )
    return out


def exit_code(targets: Sequence[dict[str, Any]]) -> int:
    """1 when a target is MISSED, else 0."""
    return 1 if any(t["verdict"] == "MISSED" for t in targets) else 0


# ---------------------------------------------------------------------------- printing


def _f(v: Any, nd: int = 2) -> str:
    return "-" if v is None or (isinstance(v, float) and not math.isfinite(v)) else f"{v:.{nd}f}"


_HEAD = (
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
    "the runs of the window tracked whole, and their mean survival)"
)


def format_row(r: dict[str, Any]) -> str:
    """One printed line of a row."""
    name = f"{Path(r['clip']).stem}@{r['start_s']:g}"
    lead = f"{name[:24]:24s} {r['target']:9s} {r['method']:6s}"
    if r["status"] != "ok":
        return f"{lead} {r['status']}: {r['note']}"
    toe = r.get("stance_toe_height_import")
    runs = survival_runs(r)
    tail = ""
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


def _median(rows: Sequence[dict[str, Any]], key: str) -> float | None:
    v = [r[key] for r in rows if r.get(key) is not None]
    return float(statistics.median(v)) if v else None


def _per_target_survival(rows: Sequence[dict[str, Any]]) -> list[str]:
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


def _per_regime_survival(rows: Sequence[dict[str, Any]]) -> list[str]:
    """Survival of each method split by the gait regime of the source window: its peak
    Froude number (:func:`habitsim.gait_stats.peak_froude`) at or below
    :data:`~habitsim.gait_stats.GALLOP_FROUDE` (walks, trots, ambles) or above it
    (gallops). Nothing without tracking or without the Froude numbers."""
    from ..gait_stats import GALLOP_FROUDE, PEAK_SPAN_S

    runs: dict[tuple[str, bool], list[list[float]]] = {}
    for r in rows:
        fr = _num(r.get("source_froude_peak"))
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


def format_summary(rows: Sequence[dict[str, Any]], targets: Sequence[dict[str, Any]]) -> str:
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
        lines.append(
            f"  {t['name']:62s} {t['shown']:>14s}   (target {t['target']}: {t['verdict']})"
        )
    return "\n".join(lines)


# ---------------------------------------------------------------------------- command


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``real`` to the ``bench`` command group."""
    p = sub.add_parser(
        "real",
        help="real motion capture (BVH or glTF/GLB clips) through transfer → refine → track",
        description=(
            "Import every BVH or glTF/GLB clip (its first animation) of DIR onto --species, "
            "cut it into windows of --seconds, and run each window × target × method "
            "through the pipeline (transfer, refinement stage A, unassisted tracking); "
            "print one line per run, a summary and the issue's targets. Exit code 1 when "
            "a target is MISSED, 2 on bad input."
        ),
    )
    p.add_argument(
        "--data", required=True, metavar="DIR", help="folder of .bvh, .glb or .gltf clips"
    )
    add_list_option(
        p,
        "--targets",
        default=list(DEFAULT_TARGETS),
        metavar="SPECIES",
        help=f"target species (default {','.join(DEFAULT_TARGETS)})",
    )
    add_list_option(
        p,
        "--methods",
        default=list(DEFAULT_METHODS),
        metavar="METHOD",
        help=f"transfer methods (default {','.join(DEFAULT_METHODS)})",
    )
    p.add_argument(
        "--species",
        default="dog",
        metavar="NAME",
        help="skeleton the clips are imported onto (default dog)",
    )
    p.add_argument(
        "--map",
        type=Path,
        default=None,
        dest="joint_map",
        metavar="FILE",
        help="joint-map file for every clip, as import-bvh --map takes it",
    )
    add_frame_options(p, "every clip")
    p.add_argument(
        "--seconds", type=float, default=4.0, metavar="S", help="window length [s] (default 4)"
    )
    p.add_argument(
        "--windows-per-clip",
        type=_windows_per_clip,
        default=1,
        metavar="N",
        help=(
            "consecutive windows per clip, from where the animal moves (default 1; all: "
            "every whole window)"
        ),
    )
    p.add_argument(
        "--fps",
        type=float,
        default=30.0,
        metavar="HZ",
        help="frame rate the clips are resampled to (default 30; 0 keeps theirs)",
    )
    p.add_argument(
        "--refine", default="A", choices=("none", "A", "B"), help="refinement stage (default A)"
    )
    p.add_argument(
        "--controller",
        default="mpc",
        metavar="NAME",
        help="unassisted tracking controller (default mpc)",
    )
    p.add_argument("--no-track", action="store_true", help="skip the MuJoCo tracking")
    p.add_argument(
        "--no-check",
        action="store_true",
        help="do not track the unrefined transfer to check the refinement",
    )
    p.add_argument("--seed", type=int, default=0, metavar="S", help="seed (default 0)")
    p.add_argument(
        "--repeats",
        type=int,
        default=1,
        metavar="K",
        help=(
            "track every kept reference K times: once as is, K-1 times from initial joint "
            "velocities perturbed by --perturb (seeds S+1..S+K-1); the survival targets "
            "count every run (default 1)"
        ),
    )
    p.add_argument(
        "--perturb",
        type=float,
        default=PERTURB_QVEL,
        metavar="RAD_S",
        help=(
            f"initial joint-velocity noise of the repeated runs [rad/s] (default {PERTURB_QVEL:g})"
        ),
    )
    p.add_argument(
        "--workers",
        type=int,
        default=None,
        metavar="W",
        help="worker processes (default: CPU count; 1 = in this process)",
    )
    p.add_argument("--json", metavar="OUT", help="also write the rows and targets here")
    p.set_defaults(func=_bench_real)


def _windows_per_clip(text: str) -> int | str:
    """``--windows-per-clip``: a count, or ``all``."""
    if text.strip().lower() == "all":
        return "all"
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"invalid --windows-per-clip {text!r}; valid: a count >= 1 or 'all'"
        ) from None


def _split(text: str | Sequence[str]) -> list[str]:
    return split_names(text)


def plan(ns: argparse.Namespace) -> tuple[list[WindowTask], list[str]]:
    """The tasks of a run and the notes on skipped clips (every input checked first).

    Raises:
        BenchRealError / UnknownSpeciesError / UnknownMethodError: see the module.
    """
    from ..controllers import CONTROLLERS
    from ..evaluation.methods import get_method
    from ..motion import resample_motion
    from ..pipeline import refine_mode
    from ..sim import SimulationError
    from ..species import load_species

    if not (math.isfinite(ns.seconds) and ns.seconds > 0):
        raise BenchRealError(f"--seconds must be > 0, got {ns.seconds}")
    every = ns.windows_per_clip == "all"
    if not every and not (isinstance(ns.windows_per_clip, int) and ns.windows_per_clip >= 1):
        raise BenchRealError(
            f"--windows-per-clip must be >= 1 or 'all', got {ns.windows_per_clip!r}"
        )
    if not (math.isfinite(ns.fps) and ns.fps >= 0):
        raise BenchRealError(f"--fps must be >= 0, got {ns.fps}")
    repeats = int(getattr(ns, "repeats", 1))
    perturb = float(getattr(ns, "perturb", PERTURB_QVEL))
    if repeats < 1:
        raise BenchRealError(f"--repeats must be >= 1, got {repeats}")
    if not (math.isfinite(perturb) and perturb > 0):
        raise BenchRealError(f"--perturb must be a finite rate > 0 [rad/s], got {perturb}")
    if ns.controller not in CONTROLLERS:
        from ..errors import unknown_choice

        raise SimulationError(unknown_choice("controller", ns.controller, CONTROLLERS))
    species = load_species(ns.species).name
    targets = [load_species(t).name for t in _split(ns.targets)]
    methods = _split(ns.methods)
    if not targets:
        raise BenchRealError("--targets names no species")
    if not methods:
        raise BenchRealError("--methods names no method")
    for method in methods:
        get_method(method)  # UnknownMethodError listing the registered ones
    mode = refine_mode(ns.refine)
    files = source_files(ns.data)
    options = {"joint_map": ns.joint_map, "units": ns.units, "up": ns.up}
    if ns.joint_map is not None:
        from ..bvh_mapping import load_joint_map

        load_joint_map(ns.joint_map)  # a bad map file fails here, not once per clip
    notes: list[str] = []
    windows: list[tuple[str, float, Any]] = []
    for f in files:
        try:
            m = _read_source(f, species, **options)
        except HabitsimError as e:
            notes.append(f"{f.name}: skipped, import failed: {e}")
            continue
        if ns.fps > 0:
            m = resample_motion(m, ns.fps)
        frames = int(round(ns.seconds * m.fps))
        starts = window_starts(m, frames, m.num_frames if every else ns.windows_per_clip)
        if not starts:
            notes.append(
                f"{f.name}: skipped, {m.num_frames} frames ({m.duration:.2f} s) is "
                f"shorter than one {ns.seconds:g} s window ({frames} frames)"
            )
            continue
        for s in starts:
            windows.append((f.name, round(s / m.fps, 3), m.slice(s, s + frames)))
    if not windows:
        raise BenchRealError(
            f"--data {ns.data}: no clip gives a {ns.seconds:g} s window; " + "; ".join(notes)
        )
    tasks = [
        WindowTask(
            clip,
            start,
            w,
            t,
            tuple(methods),
            mode,
            ns.controller,
            not ns.no_track,
            not ns.no_check,
            ns.seed,
            repeats,
            perturb,
        )
        for t in targets  # grouped by target: a process keeps few built refinement problems
        for clip, start, w in windows
    ]
    return tasks, notes


def _bench_real(ns: argparse.Namespace) -> int:
    from ..evaluation.executors import make_executor
    from ..fileio import atomic_write_text, json_safe

    t0 = time.perf_counter()
    tasks, notes = plan(ns)
    clips = len({t.clip for t in tasks})
    wins = len({(t.clip, t.start_s) for t in tasks})
    targets = list(dict.fromkeys(t.target for t in tasks))
    methods = list(tasks[0].methods)
    print(
        f"bench real: {wins} window(s) of {ns.seconds:g} s from {clips} clip(s) of {ns.data} "
        f"(imported onto {ns.species}, {ns.fps:g} fps) × {', '.join(targets)} × "
        f"{', '.join(methods)}; refine {tasks[0].refine}; "
        + (f"tracking unassisted ({ns.controller})" if not ns.no_track else "no tracking")
        + (
            f"; {tasks[0].repeats} runs per window (the first as is, the others with "
            f"{tasks[0].perturb:g} rad/s initial joint-velocity noise)"
            if tasks[0].repeats > 1 and not ns.no_track
            else ""
        )
    )
    for n in notes:
        print(f"  note: {n}")
    print(_HEAD, flush=True)
    rows: list[dict[str, Any]] = []
    ex = make_executor("local", workers=ns.workers)
    try:
        for _, result in ex.map_unordered(run_window, tasks):
            for r in result:
                rows.append(r)
                print(format_row(r), flush=True)
    finally:
        ex.close()
    order = {(t.clip, t.start_s, t.target): i for i, t in enumerate(tasks)}
    rows.sort(
        key=lambda r: (order[(r["clip"], r["start_s"], r["target"])], methods.index(r["method"]))
    )
    verdicts = evaluate_targets(
        rows,
        seconds=ns.seconds,
        refine=tasks[0].refine,
        controller=ns.controller,
        tracked=not ns.no_track,
    )
    print(format_legend(LEGEND))
    print(format_summary(rows, verdicts))
    wall = time.perf_counter() - t0
    print(f"bench real finished in {wall:.1f} s ({len(rows)} runs)")
    if ns.json:
        doc = {
            "kind": "habitsim.bench.real",
            "config": {k: v for k, v in vars(ns).items() if k != "func"},
            "notes": notes,
            "rows": rows,
            "targets": verdicts,
            "wall_time_s": wall,
        }
        atomic_write_text(ns.json, json.dumps(json_safe(doc), indent=2) + "\n")
        print(f"rows written to {ns.json}")
    return exit_code(verdicts)
