"""``habitsim motion stats FILE [--json]``: gait statistics and kinematic metrics of a motion.

Plain output is an aligned two-column table (per-foot values in LF, RF, LH, RH order);
``--json`` prints one JSON object whose numbers are finite or ``null``:

* ``file``, ``species``, ``fps``, ``num_frames``, ``contacts_source`` (``labels`` when
  the file carries contact labels, else ``detected``);
* every key of :meth:`habitsim.gait_stats.GaitStats.to_dict` (per-foot values are
  objects keyed ``LF, RF, LH, RH``);
* every key of :data:`habitsim.metrics.kinematic.KINEMATIC_KEYS`.

A missing or unreadable file raises :class:`~habitsim.errors.MotionFileError`, which the
CLI turns into ``error: ...`` and exit code 2.
"""

from __future__ import annotations

import argparse
import json
import math
from typing import Any

from ..species import FEET


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``stats`` to the ``motion`` command group."""
    p = sub.add_parser(
        "stats",
        help="gait statistics and kinematic plausibility metrics of a motion file",
        description=(
            "Report duration, speed, Froude number, duty factor, footfall phase offsets, "
            "stride, static stability margin and the kinematic and dynamic metrics "
            "(definitions: docs/metrics.md)."
        ),
    )
    p.add_argument("file", metavar="FILE", help="motion file (.npz)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=_stats)


def _clean(v: Any) -> Any:
    if isinstance(v, dict):
        return {k: _clean(x) for k, x in v.items()}
    if isinstance(v, float):
        return v if math.isfinite(v) else None
    return v


def motion_stats(path: str) -> dict[str, Any]:
    """The report of ``habitsim motion stats`` as a JSON-ready dict.

    Args:
        path: motion file.

    Raises:
        MotionFileError, InvalidMotionError, UnknownSpeciesError: a bad file.
    """
    from ..gait_stats import gait_statistics
    from ..metrics.dynamic import dynamic_metrics
    from ..metrics.kinematic import kinematic_metrics
    from ..motion import load_motion

    m = load_motion(path)
    out: dict[str, Any] = {
        "file": str(path),
        "species": m.species,
        "fps": m.fps,
        "num_frames": m.num_frames,
        "contacts_source": "labels" if m.contacts is not None else "detected",
    }
    out.update(gait_statistics(m).to_dict())
    out.update(kinematic_metrics(m))
    out.update(dynamic_metrics(m))
    return _clean(out)


def _fmt(v: Any) -> str:
    if v is None:
        return "n/a"
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


_ROWS: list[tuple[str, str]] = [
    ("species", ""),
    ("fps", "Hz"),
    ("num_frames", ""),
    ("contacts_source", ""),
    ("duration_s", "s"),
    ("speed_mps", "m/s"),
    ("froude", ""),
    ("duty_factor", ""),
    ("duty_factor_per_foot", ""),
    ("stride_period_s", "s"),
    ("stride_period_per_foot", "s"),
    ("stride_frequency_hz", "Hz"),
    ("stride_length_m", "m"),
    ("relative_stride_length", ""),
    ("phase_offsets", "stride"),
    ("stability_margin_min_m", "m"),
    ("stability_margin_mean_m", "m"),
    ("stability_margin_per_leg", ""),
    ("statically_stable_fraction", ""),
    ("hip_height_m", "m"),
    ("leg_length_m", "m"),
    ("penetration_mm", "mm"),
    ("float_mm", "mm"),
    ("skate_mm", "mm"),
    ("skate_ratio", ""),
    ("jerk", "m/s^3"),
    ("bone_length_error_mm", "mm"),
    ("joint_limit_violation_rad", "rad"),
    ("penetration_per_leg", ""),
    ("float_per_leg", ""),
    ("skate_per_leg", ""),
    ("bone_length_error_per_leg", ""),
    ("root_residual_mg", "m·g"),
    ("root_residual_torque_mgl", "m·g·L"),
    ("torque_saturation", ""),
]


def format_table(report: dict[str, Any]) -> str:
    """Aligned plain-text table of a :func:`motion_stats` report."""
    lines = [f"motion {report['file']}"]
    width = max(len(k) for k, _ in _ROWS)
    for key, unit in _ROWS:
        v = report.get(key)
        if isinstance(v, dict):
            text = "  ".join(f"{f}={_fmt(v.get(f))}" for f in FEET)
        else:
            text = _fmt(v)
        lines.append(f"  {key:<{width}}  {text}{'  ' + unit if unit else ''}")
    return "\n".join(lines)


def _stats(ns: argparse.Namespace) -> int:
    report = motion_stats(ns.file)
    if ns.json:
        print(json.dumps(report, allow_nan=False, sort_keys=False))
    else:
        print(format_table(report))
    return 0
