"""The data set's measured statistics per species × action: ``stats.csv`` and the
table of ``stats.md`` / ``habitsim data synth``.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from ..gaits import ACTIONS
from .records import STATS_COLUMNS, ClipEntry, DatasetManifest, StatsRow


def _mean(values: Iterable[float | None]) -> float:
    v = [x for x in values if x is not None and math.isfinite(x)]
    return float(np.mean(v)) if v else math.nan


def stats_rows(manifest: DatasetManifest) -> list[StatsRow]:
    """Per species × action means of the clips' measured statistics.

    Rows are ordered by species name, then action in :data:`~habitsim.gaits.ACTIONS`
    order (chained clips, action ``chain``, last). ``*_target`` columns are the
    generator's planned values.
    """
    groups: dict[tuple[str, str], list[ClipEntry]] = {}
    for c in manifest.clips:
        groups.setdefault((c.species, c.action), []).append(c)
    rows = []

    def order(key: tuple[str, str]) -> tuple[str, int]:
        return key[0], ACTIONS.index(key[1]) if key[1] in ACTIONS else len(ACTIONS)

    for sp, action in sorted(groups, key=order):
        cs = groups[(sp, action)]

        def m(key: str, cs: list[ClipEntry] = cs) -> float:
            return _mean(c.measured.get(key) for c in cs)

        rows.append(
            StatsRow(
                species=sp,
                action=action,
                gait=cs[0].gait,
                held_out=cs[0].held_out,
                clips=len(cs),
                froude_target=_mean(c.froude for c in cs),
                froude=m("froude"),
                duty_factor_target=_mean(c.duty_factor for c in cs),
                duty_factor=m("duty_factor"),
                relative_stride_length=m("relative_stride_length"),
                phase_error=m("phase_error"),
                skate_mm=m("skate_mm"),
                penetration_mm=m("penetration_mm"),
                statically_stable_fraction=m("statically_stable_fraction"),
            )
        )
    return rows


def _csv_cell(v: Any) -> str:
    """A CSV cell: booleans as true/false, floats with 6 significant digits, NaN empty."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return f"{v:.6g}" if math.isfinite(v) else ""
    return str(v)


def _stats_csv(rows: list[StatsRow]) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(STATS_COLUMNS)
    for r in rows:
        w.writerow([_csv_cell(getattr(r, k)) for k in STATS_COLUMNS])
    return buf.getvalue()


#: (column header, StatsRow field, number format) of the printed tables.
_TABLE: tuple[tuple[str, str, str], ...] = (
    ("species", "species", ""),
    ("action", "action", ""),
    ("gait", "gait", ""),
    ("n", "clips", ""),
    ("Fr plan", "froude_target", ".3g"),
    ("Fr", "froude", ".3g"),
    ("duty plan", "duty_factor_target", ".3f"),
    ("duty", "duty_factor", ".3f"),
    ("stride/h", "relative_stride_length", ".3g"),
    ("phase err", "phase_error", ".4f"),
    ("skate mm", "skate_mm", ".2f"),
    ("pen mm", "penetration_mm", ".2f"),
    ("stable", "statically_stable_fraction", ".2f"),
)


def _fmt(v: Any, spec: str) -> str:
    if isinstance(v, float):
        return f"{v:{spec}}" if math.isfinite(v) else "-"
    return str(v)


def format_stats_table(rows: Sequence[StatsRow], markdown: bool = False) -> str:
    """The statistics as an aligned plain-text table (or a Markdown table).

    Columns: species, action, gait, clip count, planned and measured Froude number and
    duty factor, relative stride length λ/h, footfall phase error [stride], skating
    [mm], penetration [mm], statically stable fraction. Undefined values print as ``-``.
    """
    header = [h for h, _, _ in _TABLE]
    body = []
    for r in rows:
        name = r.species + (" (held out)" if r.held_out and markdown else "*" if r.held_out else "")
        body.append([name] + [_fmt(getattr(r, f), spec) for _, f, spec in _TABLE[1:]])
    if markdown:
        lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
        lines += ["| " + " | ".join(c) + " |" for c in body]
        return "\n".join(lines)
    widths = [max(len(x) for x in col) for col in zip(header, *body, strict=False)]
    fmt = [f"{{:<{w}}}" if i < 3 else f"{{:>{w}}}" for i, w in enumerate(widths)]
    lines = [
        "  ".join(f.format(c) for f, c in zip(fmt, row, strict=True)) for row in [header, *body]
    ]
    if any(r.held_out for r in rows):
        lines.append("* held-out species (test split only)")
    return "\n".join(lines)


def _stats_markdown(rows: list[StatsRow], man: DatasetManifest) -> str:
    counts = man.split_counts()
    return (
        "# Synthetic gait data set: measured statistics\n\n"
        f"seed {man.seed}, {man.fps:g} fps, {man.clips_per_species} clips per species, "
        f"{len(man.species)} species, {len(man.clips)} clips "
        f"(train {counts['train']}, val {counts['val']}, test {counts['test']}), "
        f"generator version {man.generator_version}.\n\n"
        "Means per species × action of the measured statistics of the written clips "
        "(`habitsim.gait_stats.gait_statistics`, "
        "`habitsim.metrics.kinematic.kinematic_metrics`); "
        "'plan' columns are the generator's targets, phase err is the mean circular distance "
        "between measured and planned footfall phases [stride], '-' = undefined "
        "(e.g. no steps). For `jump`, 'Fr plan' is the take-off Froude number while 'Fr' "
        "averages the whole clip (stand, jump, land).\n\n"
        + format_stats_table(rows, markdown=True)
        + "\n"
    )
