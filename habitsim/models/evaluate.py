"""Reconstruction error of a checkpoint on whole clips (the figure a checkpoint records).

MPJPE here is the mean Euclidean distance [mm] between the global joint positions of a
clip and of its reconstruction by :func:`~habitsim.models.transfer.reconstruct` (root
path integrated from the decoded velocities, so root drift counts), over all frames and
joints; ``pct_leg`` divides it by the species' leg length (hind-leg length, docs/metrics.md).
``root_relative_mm`` removes each frame's pelvis position first (pose error only).

:data:`REFERENCE_CLIPS` are a few fixed synthetic clips made by
:func:`habitsim.gaits.generate` (deterministic): ``habitsim train`` records their error in
the checkpoint's ``config.json`` and a test checks that the shipped model reproduces it.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from ..motion import Motion
from .transfer import load_model, reconstruct

__all__ = [
    "REFERENCE_CLIPS",
    "reference_motions",
    "clip_mpjpe",
    "reconstruction_error",
    "record_reference_error",
]

#: (species, action, seed) of the fixed reference clips.
REFERENCE_CLIPS: tuple[tuple[str, str, int], ...] = (
    ("horse", "trot", 101),
    ("cat", "walk", 102),
    ("dog", "gallop", 103),
    ("elephant", "walk", 104),
    ("goat", "turn_left", 105),
    ("bear", "sit", 106),
)


def reference_motions() -> list[Motion]:
    """The :data:`REFERENCE_CLIPS` as motions (30 fps)."""
    from ..gaits import generate

    return [generate(s, a, seed=seed) for s, a, seed in REFERENCE_CLIPS]


def clip_mpjpe(a: Motion, b: Motion) -> dict[str, float]:
    """MPJPE between two motions of the same species and length: ``mpjpe_mm``,
    ``root_relative_mm``, ``pct_leg``, ``root_relative_pct_leg``."""
    if a.species != b.species or a.num_frames != b.num_frames:
        raise ValueError("clip_mpjpe needs two motions of the same species and length")
    pa, pb = a.global_positions(), b.global_positions()
    e = float(np.linalg.norm(pa - pb, axis=-1).mean())
    rr = float(np.linalg.norm((pa - pa[:, :1]) - (pb - pb[:, :1]), axis=-1).mean())
    leg = a.species_info.leg_length
    return {
        "mpjpe_mm": e * 1000.0,
        "root_relative_mm": rr * 1000.0,
        "pct_leg": 100.0 * e / leg,
        "root_relative_pct_leg": 100.0 * rr / leg,
    }


def reconstruction_error(
    motions: Iterable[Motion], checkpoint: str | Path | None = None, variant: str = "habit"
) -> dict[str, Any]:
    """Mean reconstruction errors over clips (each clip weighs the same), on one thread.

    Returns:
        ``mpjpe_mm``, ``root_relative_mm``, ``pct_leg`` (means), ``clips`` (count) and
        ``per_clip`` (list of dicts with ``species`` and the three figures).
    """
    rows = []
    for m in motions:  # reconstruct runs on one thread: the same figures on every machine
        r = reconstruct(m, checkpoint, variant)
        rows.append({"species": m.species, "action": m.metadata.get("action"), **clip_mpjpe(m, r)})
    if not rows:
        raise ValueError("reconstruction_error needs at least one motion")
    keys = ("mpjpe_mm", "root_relative_mm", "pct_leg", "root_relative_pct_leg")
    out: dict[str, Any] = {k: float(np.mean([r[k] for r in rows])) for k in keys}
    out["clips"] = len(rows)
    out["per_clip"] = rows
    return out


def record_reference_error(checkpoint: str | Path) -> dict[str, Any]:
    """Compute the reference clips' reconstruction error and store it in ``config.json``
    (``metrics.reference``)."""
    from .train import record_metrics

    ck = load_model(checkpoint)
    res = reconstruction_error(reference_motions(), checkpoint, ck.config.model.variant)
    rec = {
        "clips": [list(c) for c in REFERENCE_CLIPS],
        "mpjpe_mm": round(res["mpjpe_mm"], 4),
        "root_relative_mm": round(res["root_relative_mm"], 4),
        "pct_leg": round(res["pct_leg"], 4),
        "root_relative_pct_leg": round(res["root_relative_pct_leg"], 4),
    }
    record_metrics(checkpoint, {"reference": rec})
    return rec
