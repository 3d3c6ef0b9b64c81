"""One pair of the benchmark: a (method, clip, target) task through the pipeline and
every per-pair metric, returned as one row (:func:`evaluate_pair`, run by an executor in
any process or machine)."""

from __future__ import annotations

import contextlib
import math
import time
import traceback
from pathlib import Path
from typing import Any

import numpy as np

from habitsim.errors import HabitsimError
from habitsim.fileio import atomic_write, make_dirs
from habitsim.motion import Motion

from .config import PairTask
from .rows import reference_dynamics, run_row
from .tables import _finite

__all__ = ["evaluate_pair", "lost_row"]


def _row_base(task: PairTask) -> dict[str, Any]:
    return {
        "key": task.key,
        "method": task.method,
        "clip": task.clip,
        "source": task.source,
        "target": task.target,
        "action": task.action,
        "gait": task.gait,
        "pair_key": task.pair_key,
        "target_held_out": str(task.target_held_out).lower(),
        "status": "ok",
        "note": "",
        "refine_status": "",
        "track_status": "",
    }


class _NotAGait(Exception):
    pass


def evaluate_pair(task: PairTask) -> dict[str, Any]:
    """Run one (method, clip, target) task and return its row (plus ``features``).

    Never raises for a failure inside the pair: the row's ``status`` says what happened.
    """
    from habitsim.motion import load_motion
    from habitsim.pipeline import run_clip
    from habitsim.transfer_methods import MethodUnavailable, ground_truth_transfer

    t0 = time.perf_counter()
    c0 = time.process_time()
    row = _row_base(task)
    try:
        src = load_motion(task.clip_path)
        method: Any = task.method
        if task.outputs is not None:  # another method's outputs, read from a folder
            from .outputs import MethodOutputs

            method = MethodOutputs(task.method, task.outputs).method()
        if task.method_timeout_s is not None:
            method = _time_limited(method, task.method_timeout_s)
        try:
            # transfer → refine → track: the one pipeline (habitsim.pipeline); the
            # refinement check is off so the rows measure the refinement as it is
            run = run_clip(
                src,
                task.target,
                method=method,
                clip_id=Path(task.clip).stem,
                refine=task.refine,
                controller=task.controller,
                assist=task.assist,
                seed=task.seed,
                track=task.track,
                guard=False,
            )
        except MethodUnavailable as e:
            row.update(status="unavailable", note=str(e))
            return row
        out = run.transferred.motion
        ref = run.refined.motion
        assert out is not None and ref is not None  # run_clip's transfer and refine ran
        figures = run_row(run)
        row["time_transfer_s"] = figures.times["transfer"]
        row.update(_paper_metrics(task, src, out))
        try:
            gt = out if task.method == "ground_truth" else ground_truth_transfer(src, task.target)
            from .distribution import mpjpe_mm

            row["paired_mpjpe_mm"] = mpjpe_mm(out, gt)
            row["paired_mpjpe_per_leg"] = (
                row["paired_mpjpe_mm"] / 1000.0 / out.species_info.leg_length
            )
        except MethodUnavailable:
            row["paired_mpjpe_mm"] = row["paired_mpjpe_per_leg"] = math.nan
        from habitsim.metrics.biomech import biomech_metrics

        row.update(biomech_metrics(out, use_labels=False).to_dict())

        row["refine_status"] = figures.refine_status
        row["time_refine_s"] = figures.times["refine"]
        from habitsim.metrics.kinematic import KINEMATIC_KEYS

        row.update(figures.refine_columns(KINEMATIC_KEYS))
        if task.dynamic:
            # the refined clip is the tracked reference: run_clip runs without its check
            row.update(reference_dynamics(run, strict=True))
        sim_res = run.track_result
        if task.track:
            row["track_status"] = figures.track_status
            row["time_track_s"] = figures.times["track"]
            if sim_res is not None:
                row.update(figures.track_columns())
                try:
                    if not math.isfinite(_finite(row.get("biomech_score"))):
                        raise _NotAGait  # the reference is no gait (standing, sitting)
                    sim_m = sim_res.motion()
                    sb = biomech_metrics(sim_m, species=task.target, contacts=sim_m.contacts)
                    row["sim_biomech_score"] = sb.score
                    row["sim_biomech_gait"] = sb.gait
                except _NotAGait:
                    row["sim_biomech_score"] = math.nan
                    row["sim_biomech_gait"] = ""
                except Exception as e:  # noqa: BLE001
                    row["sim_biomech_score"] = math.nan
                    row["note"] = f"simulated biomech failed: {e}"
        else:
            row["track_status"] = "off"
        if task.trace:
            _write_trace(task, src, out, ref, sim_res)
    except HabitsimError as e:
        row.update(status="error", note=f"{type(e).__name__}: {e}")
    except (Exception, SystemExit) as e:  # noqa: BLE001 - in the row, the run goes on
        # (SystemExit: a plugin method that calls sys.exit must not end the whole run)
        tb = traceback.extract_tb(e.__traceback__)[-1]
        row.update(
            status="error", note=f"{type(e).__name__}: {e} ({Path(tb.filename).name}:{tb.lineno})"
        )
    row["time_total_s"] = time.perf_counter() - t0
    row["cpu_total_s"] = time.process_time() - c0
    return row


def _time_limited(method: Any, seconds: float) -> Any:
    """The method with every call stopped after ``seconds`` (a
    :class:`~habitsim.errors.TimeLimitError`: ``method X exceeded N s``)."""
    import dataclasses

    from habitsim.timelimit import call_with_time_limit
    from habitsim.transfer_methods import METHODS

    m = METHODS[method] if isinstance(method, str) else method

    def limited(motion: Motion, target: str, **options: Any) -> Motion:
        what = f"method {m.name!r}"
        return call_with_time_limit(lambda: m(motion, target, **options), seconds, what)

    return dataclasses.replace(m, fn=limited)


def lost_row(task: PairTask, note: str) -> dict[str, Any]:
    """The row of a pair whose worker process died every time it ran it."""
    row = _row_base(task)
    row.update(status="error", note=note)
    return row


def _paper_metrics(task: PairTask, src: Motion, out: Motion) -> dict[str, Any]:
    from .distribution import transfer_mpjpe_mm
    from .evaluator import load_evaluator

    ev = load_evaluator(task.evaluator)
    p = ev.predict([out])
    known = task.target in ev.config.species
    r: dict[str, Any] = {
        "pred_species": p.species[0],
        "pred_action": p.actions[0],
        "habit_correct": float(p.species[0] == task.target) if known else math.nan,
        "action_correct": float(p.actions[0] == task.action),
        "features": [float(x) for x in p.features[0]],
        "frames": out.num_frames,
    }
    r["mpjpe_mm"] = transfer_mpjpe_mm(out, src)
    r["mpjpe_per_leg"] = r["mpjpe_mm"] / 1000.0 / out.species_info.leg_length
    return r


def _per_frame_error_mm(sim_res: Any) -> np.ndarray:
    from habitsim.qpos import qpos_joint_positions

    q = np.asarray(sim_res.qpos)
    ref = np.asarray(sim_res.reference_qpos)[: len(q)]
    a = qpos_joint_positions(sim_res.model, q)
    b = qpos_joint_positions(sim_res.model, ref)
    return np.linalg.norm(a - b, axis=-1).mean(1) * 1000.0


def _write_trace(task: PairTask, src: Motion, out: Motion, ref: Motion, sim_res: Any) -> None:
    """Contacts, tracking error and motions of a report pair (traces/<key>/)."""
    folder = Path(task.out) / "traces" / task.key
    make_dirs(folder)
    arrays: dict[str, Any] = {  # arrays for np.savez_compressed
        "fps": np.array(out.fps),
        "source_contacts": src.contacts if src.contacts is not None else src.detect_contacts(),
        "transferred_contacts": out.detect_contacts(),
        "reference_contacts": ref.detect_contacts(),
    }
    out.save(folder / "transferred.npz")
    if sim_res is not None:
        arrays["simulated_contacts"] = np.asarray(sim_res.contacts, bool)
        arrays["tracking_error_mm"] = _per_frame_error_mm(sim_res)
        with contextlib.suppress(Exception):
            sim_res.motion().save(folder / "simulated.npz")
        if task.videos:
            _render(sim_res, folder / "simulated.gif")
    with atomic_write(folder / "trace.npz") as fh:
        np.savez_compressed(fh, **arrays)


def _render(sim_res: Any, path: Path) -> None:
    """A small GIF of the simulated run, if rendering works here (else nothing): the
    reference as a ghost beside the body, stance feet marked."""
    from habitsim import render

    with contextlib.suppress(Exception):
        if not render.render_available():
            return
        q = np.asarray(sim_res.qpos)
        step = max(1, int(round(sim_res.fps / 15.0)))
        render.render_video(
            sim_res.model,
            q[::step],
            sim_res.fps / step,
            path,
            width=320,
            height=240,
            reference=np.asarray(sim_res.reference_qpos)[: len(q)][::step],
            contacts=np.asarray(sim_res.contacts)[::step],
            reference_contacts=np.asarray(sim_res.reference_contacts)[: len(q)][::step],
            species=sim_res.species,
        )
