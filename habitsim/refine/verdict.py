"""The refinement's verdict: does the result make a docs/metrics.md metric worse than the input?

Shared by the solver (its guard redoes a solve whose result is worse) and the report
(``verdict``), below both.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..metrics.kinematic import jerk, penetration_mm, skate_mm
from ..motion import Motion

__all__ = ["WORSE_TOLERANCE", "VERDICT_METRICS", "compare_metrics", "input_change"]

#: How much worse than the input a metric of the result may be before the report's
#: verdict calls it worse: absolute [mm] for the lengths, relative for the jerk.
WORSE_TOLERANCE = {"skate_mm": 0.05, "penetration_mm": 0.05, "jerk": 1e-3}
#: The metrics of the verdict (:func:`compare_metrics`).
VERDICT_METRICS = ("skate_mm", "jerk", "penetration_mm")


def compare_metrics(motion_in: Motion, motion_out: Motion) -> dict[str, Any]:
    """docs/metrics.md's ``skate_mm``, ``jerk`` and ``penetration_mm`` (the functions of
    :mod:`habitsim.metrics.kinematic`, literal definitions) of the input and of the
    result, and which of them the result makes worse (beyond :data:`WORSE_TOLERANCE`).

    Returns:
        ``before`` / ``after`` (key → value), ``worse`` (keys, in
        :data:`VERDICT_METRICS` order) and ``ok`` (nothing worse).
    """
    out: dict[str, Any] = {"before": {}, "after": {}}
    for tag, mo in (("before", motion_in), ("after", motion_out)):
        pos = mo.global_positions()
        out[tag] = {
            "skate_mm": skate_mm(mo, positions=pos),
            "jerk": jerk(mo, positions=pos),
            "penetration_mm": penetration_mm(mo, positions=pos),
        }
    worse = []
    for k in VERDICT_METRICS:
        b, a = out["before"][k], out["after"][k]
        if not (np.isfinite(a) and np.isfinite(b)):
            continue
        tol = WORSE_TOLERANCE[k] * (abs(b) if k == "jerk" else 1.0)
        if a > b + tol:
            worse.append(k)
    out["worse"] = worse
    out["ok"] = not worse
    return out


def input_change(motion_in: Motion, motion_out: Motion) -> dict[str, float]:
    """How far the result lies from the input, in leg lengths.

    Per frame the mean over the joints of their position change ‖p_out − p_in‖ / L
    (the change of the frame's pose), and of that its ``max`` and ``median`` over the
    frames; ``joint_max``: the largest change of any one joint in any frame.
    """
    a, b = motion_in.global_positions(), motion_out.global_positions()
    d = np.linalg.norm(b - a, axis=-1) / motion_in.species_info.leg_length
    per_frame = d.mean(axis=1)
    return {
        "max": float(per_frame.max()),
        "median": float(np.median(per_frame)),
        "joint_max": float(d.max()),
    }
