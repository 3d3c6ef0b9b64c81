"""The benchmark's tables: row files (``rows/<key>.json``), ``rows.csv`` /
``rows.parquet`` / ``features.npz``, and the summary table in the paper's Table 1 layout
plus the physical columns (shared by the runner and the report)."""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from habitsim.fileio import atomic_write, atomic_write_text
from habitsim.jsonfile import load_json

from .config import EvalError

__all__ = [
    "ROW_ID_COLUMNS",
    "VOLATILE_COLUMNS",
    "TABLE1_COLUMNS",
    "PHYSICAL_COLUMNS",
    "load_rows",
    "write_tables",
    "format_table",
    "tracking_label",
]

#: Identity / status columns of a row (strings), in order.
ROW_ID_COLUMNS = (
    "key",
    "method",
    "clip",
    "source",
    "target",
    "action",
    "gait",
    "pair_key",
    "target_held_out",
    "status",
    "note",
    "refine_status",
    "track_status",
    "pred_species",
    "pred_action",
    "biomech_gait",
    "sim_biomech_gait",
)
#: Columns whose values change from run to run (timings): left out of comparisons.
VOLATILE_COLUMNS = (
    "time_transfer_s",
    "time_refine_s",
    "time_track_s",
    "time_total_s",
    "cpu_total_s",
    "realtime_factor",
)
#: Summary columns of the paper's Table 1 (set metrics + content), in display order.
TABLE1_COLUMNS = (
    ("fid", "FID ↓"),
    ("intra_fid", "Intra-FID ↓"),
    ("downstream_fid", "Downstream ↓"),
    ("diversity", "Diversity →"),
    ("diversity_real", "(real)"),
    ("one_nna", "1-NNA →0.5"),
    ("mpjpe_mm", "MPJPE mm"),
    ("paired_mpjpe_mm", "paired MPJPE mm ↓"),
    ("habit_accuracy", "habit acc ↑"),
    ("action_accuracy", "action acc ↑"),
)
#: Physical summary columns added to Table 1.
PHYSICAL_COLUMNS = (
    ("skate_mm", "skate mm ↓"),
    ("penetration_mm", "penetr. mm ↓"),
    ("float_mm", "float mm ↓"),
    ("root_residual_mg", "root resid. mg ↓"),
    ("survival", "survival ↑"),
    ("sim_mpjpe_mm", "sim MPJPE mm ↓"),
    ("cost_of_transport", "CoT"),
    ("biomech_score", "biomech ↓"),
)


def _finite(x: Any) -> float:
    try:
        v = float(x)
    except (TypeError, ValueError):
        return math.nan
    return v if math.isfinite(v) else math.nan


def _row_path(out: Path, key: str) -> Path:
    return out / "rows" / f"{key}.json"


def load_rows(out: str | Path) -> list[dict[str, Any]]:
    """Every finished row of a run folder (with ``features``), sorted by key."""
    folder = Path(out) / "rows"
    rows = []
    for p in sorted(folder.glob("*.json")):
        try:
            row = load_json(p, "row file", error=EvalError)
        except EvalError as e:
            raise EvalError(f"{e}; delete it to recompute the pair") from None
        if (
            not isinstance(row, dict)
            or not isinstance(row.get("key"), str)
            or not isinstance(row.get("status"), str)
            or row["key"] != p.stem
        ):
            raise EvalError(
                f"{p}: not a row of this run (a JSON object with the string 'key' {p.stem!r} "
                "and a 'status'); delete it to recompute the pair"
            )
        rows.append(row)
    return rows


def _columns(rows: Sequence[dict[str, Any]]) -> list[str]:
    cols = [c for c in ROW_ID_COLUMNS]
    extra = sorted({k for r in rows for k in r} - set(cols) - {"features"})
    return cols + extra


def _cell(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, float):
        return "" if math.isnan(v) else repr(v)
    return str(v)


def _num(v: Any) -> float:
    return math.nan if v is None or v == "" else _finite(v)


def write_tables(out: str | Path, rows: Sequence[dict[str, Any]]) -> list[Path]:
    """Write rows.csv (and rows.parquet with pyarrow) and features.npz atomically."""
    out = Path(out)
    rows = sorted(rows, key=lambda r: r["key"])
    cols = _columns(rows)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(cols)
    for r in rows:
        w.writerow([_cell(r.get(c)) for c in cols])
    atomic_write_text(out / "rows.csv", buf.getvalue())
    written = [out / "rows.csv"]
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        pass
    else:
        data = {}
        for c in cols:
            vals = [r.get(c) for r in rows]
            if c in ROW_ID_COLUMNS or any(isinstance(v, str) for v in vals if v is not None):
                data[c] = pa.array([None if v is None else str(v) for v in vals], pa.string())
            else:
                data[c] = pa.array([_num(v) for v in vals], pa.float64())
        with atomic_write(out / "rows.parquet") as fh:
            pq.write_table(pa.table(data), fh)
        written.append(out / "rows.parquet")
    feats = [(r["key"], r["features"]) for r in rows if r.get("features")]
    # (0, 0) when no pair has features (every pair failed): a table of no rows
    features = (
        np.array([f for _, f in feats], dtype=np.float64).reshape(len(feats), -1)
        if feats
        else np.zeros((0, 0))
    )
    with atomic_write(out / "features.npz") as fh:
        np.savez_compressed(fh, keys=np.array([k for k, _ in feats], dtype=str), features=features)
    written.append(out / "features.npz")
    return written


def _fmt(v: Any) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "—"
    if isinstance(v, int):
        return str(v)
    a = abs(v)
    if a == 0:
        return "0"
    if a >= 100:
        return f"{v:.1f}"
    if a >= 1:
        return f"{v:.2f}"
    return f"{v:.3f}"


def format_table(
    summary: dict[str, dict[str, Any]], markdown: bool = True, controller: str | None = None
) -> str:
    """The summary in the paper's Table 1 layout plus the physical columns (and, given the
    run's tracking ``controller``, a column naming it, so tables of runs with different
    controllers can be stacked)."""
    cols = [("pairs", "pairs")] + list(TABLE1_COLUMNS) + list(PHYSICAL_COLUMNS)
    lead = ["method"] + (["controller"] if controller is not None else [])
    head = lead + [h for _, h in cols]
    tag = [controller] if controller is not None else []
    body = [[m] + tag + [_fmt(s.get(k)) for k, _ in cols] for m, s in summary.items()]
    if markdown:
        lines = [
            "| " + " | ".join(head) + " |",
            "|" + "|".join(["---"] * len(lead) + ["---:"] * len(cols)) + "|",
        ]
        lines += ["| " + " | ".join(r) + " |" for r in body]
        return "\n".join(lines)
    widths = [max(len(x[i]) for x in [head] + body) for i in range(len(head))]

    def fmt(r: list[str]) -> str:
        cells = zip(r, widths, strict=True)
        return "  ".join(c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(cells))

    return "\n".join([fmt(head)] + [fmt(r) for r in body])


def tracking_label(controller: str, assist: bool, track: bool) -> str:
    """The tracking column of a run: the controller (``+assist`` with root assistance)."""
    if not track:
        return "—"
    return controller + ("+assist" if assist else "")
