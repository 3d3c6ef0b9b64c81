"""The benchmark's summary: per method, the set metrics (evaluator features of its
transfers against the real clips of the targets) and the means of its rows;
``summary.json`` / ``summary.csv`` / ``summary.md``."""

from __future__ import annotations

import contextlib
import csv
import io
import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from habitsim.fileio import atomic_write, atomic_write_text, json_safe

from .config import EvalConfig
from .planning import _manifest
from .tables import ROW_ID_COLUMNS, VOLATILE_COLUMNS, _cell, _num, format_table, tracking_label

__all__ = ["summarize"]

_SET_METRICS = ("fid", "intra_fid", "downstream_fid", "diversity", "diversity_real", "one_nna")


def _nanmean(vals: Sequence[float]) -> float:
    v = [x for x in vals if math.isfinite(x)]
    return float(np.mean(v)) if v else math.nan


def _reference_features(
    cfg: EvalConfig, targets: Sequence[str]
) -> tuple[np.ndarray, list[str], list[str]]:
    """Evaluator features, species and clip paths of the real clips of the targets
    (cached in the run folder); a target without clips in the data set (a user species)
    has none."""
    from habitsim.dataset import iter_clips

    from .evaluator import load_evaluator

    path = Path(cfg.out) / "reference_features.npz"
    ev = load_evaluator(cfg.evaluator)
    man = _manifest(cfg)
    tag = json.dumps(
        {
            "data": cfg.data,
            "seed": man.seed,
            "n": len(man.clips),
            "split": cfg.reference_split,
            "evaluator": str(ev.path),
            "targets": sorted(targets),
        },
        sort_keys=True,
    )
    if path.is_file():
        with np.load(path, allow_pickle=False) as z:
            if str(z["tag"]) == tag:
                return (z["features"], [str(s) for s in z["species"]], [str(c) for c in z["clips"]])
    motions, species, clips = [], [], []
    splits = [x.strip() for x in cfg.reference_split.split(",") if x.strip()]
    in_data = set(man.species_names)  # a user species has no clips of its own in it
    for t in sorted(x for x in targets if x in in_data):
        have: list[str | None] = [sp for sp in splits if man.select(split=sp, species=t)]
        for sp in have or [None]:
            for e, m in iter_clips(man, split=sp, species=t):
                motions.append(m)
                species.append(t)
                clips.append(e.path)
    feats = ev.features(motions) if motions else np.zeros((0, ev.feature_dim))
    with atomic_write(path) as fh:
        np.savez_compressed(
            fh,
            tag=np.array(tag),
            features=feats,
            species=np.array(species, dtype=str),
            clips=np.array(clips, dtype=str),
        )
    return feats, species, clips


def summarize(
    rows: Sequence[dict[str, Any]],
    real_features: np.ndarray | None = None,
    real_species: Sequence[str] | None = None,
    real_clips: Sequence[str] | None = None,
    *,
    seed: int = 0,
    methods: Sequence[str] | None = None,
) -> dict[str, dict[str, Any]]:
    """One summary per method: set metrics (with real features) and means of its rows.

    Args:
        rows: benchmark rows (with ``features`` for the set metrics).
        real_features: (M, D) evaluator features of the real reference clips.
        real_species: (M,) their species.
        real_clips: (M,) their clip paths (unused by the metrics; kept with the features).
        seed: seed of the diversity pairs and the 1-NNA balancing.
        methods: order of the methods (default: as they appear in the rows).

    Returns:
        method → {"pairs", "ok", "unavailable", "error", set metrics…, row means…}.
    """
    from .distribution import FIDError, diversity, downstream_fid, fid, intra_fid, one_nna

    if methods is None:
        methods = list(dict.fromkeys(r["method"] for r in rows))
    numeric = sorted(
        {
            k
            for r in rows
            for k, v in r.items()
            if k not in ROW_ID_COLUMNS
            and k not in VOLATILE_COLUMNS
            and k != "features"
            and (isinstance(v, int | float) and not isinstance(v, bool) or v is None)
        }
    )
    out: dict[str, dict[str, Any]] = {}
    for m in methods:
        mr = [r for r in rows if r["method"] == m]
        ok = [r for r in mr if r["status"] == "ok"]
        s: dict[str, Any] = {
            "pairs": len(mr),
            "ok": len(ok),
            "unavailable": sum(r["status"] == "unavailable" for r in mr),
            "error": sum(r["status"] == "error" for r in mr),
        }
        for k in numeric:
            s[k] = _nanmean([_num(r.get(k)) for r in ok])
        s["habit_accuracy"] = s.pop("habit_correct", math.nan)
        s["action_accuracy"] = s.pop("action_correct", math.nan)
        for k in _SET_METRICS:
            s[k] = math.nan
        fr = [r for r in ok if r.get("features")]
        if fr and real_features is not None and len(real_features) >= 2:
            g = np.array([r["features"] for r in fr], dtype=np.float64)
            rs = list(real_species or [])
            with contextlib.suppress(FIDError):
                if len(g) >= 2:
                    s["fid"] = fid(g, real_features)
            with contextlib.suppress(FIDError):
                s["intra_fid"] = intra_fid(g, [r["target"] for r in fr], real_features, rs)
            with contextlib.suppress(FIDError):
                s["downstream_fid"] = downstream_fid(
                    g, [r["source"] for r in fr], [r["target"] for r in fr], real_features, rs
                )
            if len(g) >= 2:
                s["diversity"] = diversity(g, seed=seed)
            s["diversity_real"] = diversity(real_features, seed=seed)
            s["one_nna"] = one_nna(real_features, g, balance=True, seed=seed)
            s["real_clips"] = int(len(real_features))
        out[m] = s
    return out


def _controller_label(cfg: EvalConfig) -> str:
    return tracking_label(cfg.controller, cfg.assist, cfg.track)


def _write_summary(
    out: Path,
    summary: dict[str, dict[str, Any]],
    cfg: EvalConfig,
    wall_time_s: float,
    cpu_time_s: float = math.nan,
) -> None:
    doc = {
        "config": cfg.to_dict(),
        "wall_time_s": wall_time_s,
        # CPU seconds of every pair (all runs of a resumed benchmark); / cores ≈ wall time
        # on an otherwise idle machine
        "cpu_time_s": cpu_time_s,
        "methods": json_safe(summary),
    }
    atomic_write_text(
        out / "summary.json",
        json.dumps(
            json_safe(doc),
            indent=2,
            sort_keys=True,
        )
        + "\n",
    )
    keys = sorted({k for s in summary.values() for k in s})
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["method"] + keys)
    for m, s in summary.items():
        w.writerow([m] + [_cell(s.get(k)) for k in keys])
    atomic_write_text(out / "summary.csv", buf.getvalue())
    text = (
        f"# habitsim benchmark\n\nData `{cfg.data}`, split `{cfg.split}`, refine "
        f"`{cfg.refine}`, controller `{cfg.controller}`"
        f"{' with root assistance' if cfg.assist else ', unassisted'}.\n\n"
        + format_table(summary, controller=_controller_label(cfg))
        + "\n"
    )
    atomic_write_text(out / "summary.md", text)
