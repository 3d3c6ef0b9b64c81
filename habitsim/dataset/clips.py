"""One clip of a build: generated (or reused when resuming), measured, as its manifest
entry; runs in worker processes.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import DatasetError, HabitsimError, OutputPathError
from ..gaits import GENERATOR_VERSION, draw_chain, generate, generate_chain
from ..motion import Motion, load_motion
from ..species import FEET
from .records import CHAIN_ACTION, MEASURED_KEYS, ClipEntry, ClipJob


def _finite(x: Any) -> float | None:
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


def _phase_error(measured: dict[str, Any], planned: dict[str, Any] | None) -> float | None:
    """Mean circular distance [stride] between measured and planned footfall phases."""
    if not planned:
        return None
    errs = []
    for f in FEET:
        if f == "LH" or measured.get(f) is None or f not in planned:
            continue
        d = (float(measured[f]) - float(planned[f])) % 1.0
        errs.append(min(d, 1.0 - d))
    return float(np.mean(errs)) if errs else None


def _measure(m: Motion) -> dict[str, float | None]:
    from ..gait_stats import gait_statistics
    from ..metrics.kinematic import kinematic_metrics

    gs = gait_statistics(m).to_dict()
    km = kinematic_metrics(m)
    out: dict[str, float | None] = {}
    for k in MEASURED_KEYS:
        if k == "phase_error":
            out[k] = _phase_error(gs["phase_offsets"], m.metadata.get("footfall"))
        else:
            out[k] = _finite(gs[k] if k in gs else km[k])
    return out


def _matches(m: Motion, job: ClipJob) -> bool:
    """True if a motion on disk is exactly the clip ``job`` asks for."""
    meta = m.metadata
    return (
        m.species == job.species
        and m.fps == job.fps
        and meta.get("generator") == "habitsim.gaits"
        and meta.get("generator_version") == GENERATOR_VERSION
        and meta.get("action") == job.action
        and meta.get("seed") == job.seed
        and meta.get("pair_key") == job.pair_key
    )


def _make_clip(root: str, job: ClipJob, resume: bool) -> tuple[dict[str, Any], bool]:
    """Generate (or, resuming, reuse) one clip, measure it and return its manifest entry.

    Runs in worker processes; every failure comes back as a :class:`DatasetError`
    naming the clip (plain exceptions pickle reliably; some typed ones do not), except a
    clip that could not be written (:class:`OutputPathError`, its path in the message).
    """
    path = Path(root) / job.path
    try:
        m: Motion | None = None
        if resume and path.is_file():
            try:
                m = load_motion(path)
            except HabitsimError:  # unreadable or invalid: generate it again
                m = None
            if m is not None and not _matches(m, job):
                m = None
        generated = m is None
        if m is None:
            if job.action == CHAIN_ACTION:
                steps = draw_chain(job.species, job.seed)
                clip = generate_chain(job.species, steps, seed=job.seed, fps=job.fps)
            else:
                clip = generate(job.species, job.action, seed=job.seed, fps=job.fps)
            clip.metadata["pair_key"] = job.pair_key
            clip.save(path)
            # Measure the file as written, so a resumed build measures the same numbers.
            m = load_motion(path)
        meta = m.metadata
        entry = ClipEntry(
            path=job.path,
            split=job.split,
            species=job.species,
            held_out=job.held_out,
            action=job.action,
            gait=str(meta["gait"]),
            index=job.index,
            pair_index=job.pair_index,
            pair_key=job.pair_key,
            seed=job.seed,
            speed_mps=float(meta["speed_mps"]),
            froude=float(meta["froude"]),
            duty_factor=float(meta["duty_factor"]),
            turn_rate=float(meta["turn_rate"]),
            turn_rate_nd=float(meta["turn_rate_nd"]),
            duration_s=float(meta["duration_s"]),
            frames=int(meta["frames"]),
            fps=job.fps,
            measured=_measure(m),
        )
    except OutputPathError:  # a clip that could not be written (a full disk): as it is
        raise
    except Exception as e:  # noqa: BLE001 - re-raised typed, with the clip named
        raise DatasetError(
            f"clip {job.path} (species {job.species}, action {job.action}, seed {job.seed}) "
            f"failed: {type(e).__name__}: {e}"
        ) from e
    return entry.to_dict(), generated
