"""Benchmark report: one self-contained HTML page and a Markdown twin.

:func:`write_report` reads a run folder written by
:func:`habitsim.evaluation.runner.run_benchmark` (``run.json``, ``rows/``,
``summary.json``, ``traces/``) and writes

* ``report.html`` — everything embedded (PNG figures and GIF videos as base64 data
  URIs, inline CSS, no scripts, no external files): it can be mailed or archived alone;
* ``report.md`` — the same text and table, figures linked from ``report_files/``.

Content: the summary table (the paper's Table 1 layout plus physical columns), per-method
bar charts of every summary metric, per-method heatmaps of survival and skating over
(source species, target species), gait diagrams (footfall timelines from foot contacts)
of the source, transferred, refined and simulated motion for the report pairs,
tracking-error curves of those pairs, and videos of the simulated runs when
:mod:`habitsim.render` produced them. Missing stages (no tracking, no refinement) are
said so in the page instead of plotted.

Plots use matplotlib's Agg backend (no display needed).
"""

from __future__ import annotations

import base64
import html
import io
import math
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from habitsim.errors import HabitsimError
from habitsim.fileio import atomic_write, atomic_write_text, check_writable, make_dirs
from habitsim.folders import remove_written
from habitsim.jsonfile import load_json
from habitsim.species import FEET

__all__ = ["ReportError", "write_report", "SUMMARY_PLOT_METRICS"]

#: Summary metrics drawn as per-method bar charts (key, title).
SUMMARY_PLOT_METRICS = (
    ("fid", "FID ↓"),
    ("intra_fid", "Intra-FID ↓"),
    ("downstream_fid", "Downstream FID ↓"),
    ("diversity", "Diversity (line: real)"),
    ("one_nna", "1-NNA (0.5 ideal)"),
    ("mpjpe_mm", "MPJPE vs source [mm]"),
    ("paired_mpjpe_mm", "paired MPJPE [mm] ↓"),
    ("habit_accuracy", "habit accuracy ↑"),
    ("action_accuracy", "action accuracy ↑"),
    ("biomech_score", "biomech score ↓"),
    ("skate_mm", "skate [mm] ↓"),
    ("penetration_mm", "penetration [mm] ↓"),
    ("float_mm", "float [mm] ↓"),
    ("root_residual_mg", "root residual [m·g] ↓"),
    ("survival", "survival ↑"),
    ("sim_mpjpe_mm", "sim MPJPE [mm] ↓"),
    ("cost_of_transport", "cost of transport"),
)
_COLORS = ("#4477aa", "#ee6677", "#228833", "#ccbb44", "#66ccee", "#aa3377", "#bbbbbb")


class ReportError(HabitsimError, ValueError):
    """A folder that is not a finished benchmark run."""


def _plt():
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def _png(fig) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90, bbox_inches="tight")
    _plt().close(fig)
    return buf.getvalue()


def _short(v: float) -> str:
    return "0" if abs(v) < 5e-4 else f"{v:.2g}"


def _f(v: Any) -> float:
    try:
        x = float(v)
    except (TypeError, ValueError):
        return math.nan
    return x if math.isfinite(x) else math.nan


# ---------------------------------------------------------------------------- figures


def _summary_bars(summary: dict[str, dict[str, Any]]) -> bytes | None:
    metrics = [
        (k, t)
        for k, t in SUMMARY_PLOT_METRICS
        if any(math.isfinite(_f(s.get(k))) for s in summary.values())
    ]
    if not metrics:
        return None
    plt = _plt()
    methods = list(summary)
    ncol = 4
    nrow = math.ceil(len(metrics) / ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(3.2 * ncol, 2.4 * nrow), squeeze=False)
    for ax, (k, title) in zip(axes.flat, metrics, strict=False):
        vals = [_f(summary[m].get(k)) for m in methods]
        ax.bar(
            range(len(methods)),
            np.nan_to_num(vals, nan=0.0),
            color=[_COLORS[i % len(_COLORS)] for i in range(len(methods))],
        )
        for i, v in enumerate(vals):
            ax.text(
                i,
                0 if math.isnan(v) else v,
                "n/a" if math.isnan(v) else ("0" if abs(v) < 5e-4 else f"{v:.3g}"),
                ha="center",
                va="bottom",
                fontsize=7,
            )
        if k == "diversity":
            real = [_f(s.get("diversity_real")) for s in summary.values()]
            real = [r for r in real if math.isfinite(r)]
            if real:
                ax.axhline(real[0], color="k", ls="--", lw=1)
        if k == "one_nna":
            ax.axhline(0.5, color="k", ls="--", lw=1)
        ax.set_title(title, fontsize=9)
        ax.set_xticks(range(len(methods)))
        ax.set_xticklabels(methods, rotation=30, ha="right", fontsize=8)
        ax.tick_params(axis="y", labelsize=7)
    for ax in list(axes.flat)[len(metrics) :]:
        ax.axis("off")
    fig.tight_layout()
    return _png(fig)


def _heatmaps(rows: Sequence[dict[str, Any]], method: str) -> bytes | None:
    mr = [r for r in rows if r["method"] == method and r["status"] == "ok"]
    if not mr:
        return None
    sources = sorted({r["source"] for r in mr})
    targets = sorted({r["target"] for r in mr})
    plt = _plt()
    fig, axes = plt.subplots(
        1, 2, figsize=(2.0 + 0.55 * len(targets) * 2, 1.5 + 0.4 * len(sources)), squeeze=False
    )
    for ax, (key, title, cmap) in zip(
        axes[0],
        (("survival", "survival ↑", "RdYlGn"), ("skate_mm", "skate [mm] ↓", "viridis_r")),
        strict=True,
    ):
        mat = np.full((len(sources), len(targets)), np.nan)
        for i, s in enumerate(sources):
            for j, t in enumerate(targets):
                v = [_f(r.get(key)) for r in mr if r["source"] == s and r["target"] == t]
                v = [x for x in v if math.isfinite(x)]
                if v:
                    mat[i, j] = float(np.mean(v))
        if np.all(np.isnan(mat)):
            ax.text(
                0.5, 0.5, f"{key}: not measured", ha="center", va="center", transform=ax.transAxes
            )
            ax.axis("off")
            continue
        kw = {"vmin": 0.0, "vmax": 1.0} if key == "survival" else {}
        im = ax.imshow(np.ma.masked_invalid(mat), cmap=cmap, aspect="auto", **kw)
        for i in range(len(sources)):
            for j in range(len(targets)):
                if math.isfinite(mat[i, j]):
                    ax.text(j, i, _short(mat[i, j]), ha="center", va="center", fontsize=6)
        ax.set_xticks(range(len(targets)))
        ax.set_xticklabels(targets, rotation=45, ha="right", fontsize=7)
        ax.set_yticks(range(len(sources)))
        ax.set_yticklabels(sources, fontsize=7)
        ax.set_xlabel("target", fontsize=8)
        ax.set_ylabel("source", fontsize=8)
        ax.set_title(f"{method}: {title}", fontsize=9)
        fig.colorbar(im, ax=ax, fraction=0.046, pad=0.04)
    fig.tight_layout()
    return _png(fig)


def _gait_diagram(panels: list[tuple[str, np.ndarray]], fps: float, title: str) -> bytes:
    plt = _plt()
    fig, axes = plt.subplots(
        len(panels), 1, figsize=(7.5, 0.95 * len(panels) + 0.6), squeeze=False, sharex=True
    )
    for ax, (name, c) in zip(axes[:, 0], panels, strict=True):
        c = np.asarray(c, bool)
        for f in range(c.shape[1]):
            d = np.diff(np.concatenate([[0], c[:, f].astype(int), [0]]))
            starts, stops = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
            ax.broken_barh(
                [(a / fps, (b - a) / fps) for a, b in zip(starts, stops, strict=True)],
                (c.shape[1] - 1 - f - 0.4, 0.8),
                color=_COLORS[f % len(_COLORS)],
            )
        ax.set_yticks(range(c.shape[1]))
        ax.set_yticklabels(list(reversed(FEET[: c.shape[1]])), fontsize=7)
        ax.set_ylim(-0.6, c.shape[1] - 0.4)
        ax.set_ylabel(name, fontsize=8, rotation=0, ha="right", va="center")
        ax.tick_params(axis="x", labelsize=7)
    axes[-1, 0].set_xlabel("time [s] (bars: foot in contact)", fontsize=8)
    axes[0, 0].set_title(title, fontsize=9)
    fig.tight_layout()
    return _png(fig)


def _error_curves(curves: list[tuple[str, np.ndarray, float]], title: str) -> bytes:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6.5, 2.6))
    for i, (name, e, fps) in enumerate(curves):
        ax.plot(np.arange(len(e)) / fps, e, label=name, color=_COLORS[i % len(_COLORS)], lw=1.2)
    ax.set_xlabel("time [s]", fontsize=8)
    ax.set_ylabel("mean joint error [mm]", fontsize=8)
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=7)
    ax.tick_params(labelsize=7)
    fig.tight_layout()
    return _png(fig)


# ---------------------------------------------------------------------------- page


class _Page:
    """Collects sections for both outputs."""

    def __init__(self, files: Path):
        self.html: list[str] = []
        self.md: list[str] = []
        self.files = files
        self.n = 0

    def heading(self, text: str, level: int = 2) -> None:
        self.html.append(f"<h{level}>{html.escape(text)}</h{level}>")
        self.md.append("#" * level + " " + text + "\n")

    def para(self, text: str) -> None:
        self.html.append(f"<p>{html.escape(text)}</p>")
        self.md.append(text + "\n")

    def image(self, data: bytes, name: str, alt: str, mime: str = "image/png") -> None:
        self.n += 1
        ext = "gif" if mime == "image/gif" else "png"
        fname = f"{self.n:02d}_{name}.{ext}"
        make_dirs(self.files, "report folder")
        with atomic_write(self.files / fname) as fh:
            fh.write(data)
        b64 = base64.b64encode(data).decode("ascii")
        self.html.append(
            f'<figure><img src="data:{mime};base64,{b64}" alt="{html.escape(alt)}">'
            f"<figcaption>{html.escape(alt)}</figcaption></figure>"
        )
        self.md.append(f"![{alt}]({self.files.name}/{fname})\n")

    def video(self, rel: str, alt: str) -> None:
        """A video file next to the page (``rel``: its path relative to the page); linked,
        not embedded, in both outputs."""
        src = html.escape(rel, quote=True)
        self.html.append(
            f'<figure><video src="{src}" controls loop muted preload="metadata" '
            f'width="480"></video><figcaption>{html.escape(alt)} '
            f'(<a href="{src}">{html.escape(rel)}</a>)</figcaption></figure>'
        )
        self.md.append(f"[{alt}]({rel})\n")

    def document(self, title: str) -> str:
        """The HTML page (inline CSS, no scripts)."""
        body = "\n".join(self.html)
        return (
            f'<!DOCTYPE html><html lang="en"><head><meta charset="utf-8">'
            f"<title>{html.escape(title)}</title><style>{_CSS}</style></head>"
            f"<body>{body}</body></html>\n"
        )

    def table(self, head: list[str], body: list[list[str]]) -> None:
        h = "".join(f"<th>{html.escape(x)}</th>" for x in head)
        b = "".join(
            "<tr>" + "".join(f"<td>{html.escape(x)}</td>" for x in r) + "</tr>" for r in body
        )
        self.html.append(f"<table><thead><tr>{h}</tr></thead><tbody>{b}</tbody></table>")
        self.md.append("| " + " | ".join(head) + " |")
        self.md.append("|" + "|".join(["---"] + ["---:"] * (len(head) - 1)) + "|")
        self.md += ["| " + " | ".join(r) + " |" for r in body]
        self.md.append("")


_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;margin:24px;color:#222;
max-width:1400px}
table{border-collapse:collapse;font-size:12px;margin:8px 0}
th,td{border:1px solid #ccc;padding:3px 6px;text-align:right}
th:first-child,td:first-child{text-align:left}
th{background:#f0f0f0}
figure{margin:12px 0}
img{max-width:100%;border:1px solid #eee}
figcaption{font-size:12px;color:#555}
"""


def _load_run(out: Path) -> tuple[dict[str, Any], dict[str, Any], list[dict[str, Any]]]:
    from .tables import load_rows

    for name in ("run.json", "summary.json"):
        if not (out / name).is_file():
            raise ReportError(f"{out} is not a finished benchmark run (missing {name})")
    run = load_json(out / "run.json", "run file", error=ReportError)
    summary = load_json(out / "summary.json", "run summary", error=ReportError)
    if not isinstance(run, dict) or not isinstance(run.get("config"), dict):
        raise ReportError(f"{out / 'run.json'}: not a benchmark run file (no 'config' object)")
    if not isinstance(summary, dict):
        raise ReportError(f"{out / 'summary.json'}: not a run summary (not a JSON object)")
    return run["config"], summary, load_rows(out)


def check_report_outputs(out: str | Path) -> None:
    """Check that ``report.html``, ``report.md`` and ``report_files/`` of a run folder can
    be written, without writing anything.

    Raises:
        OutputPathError: naming the path and the reason.
    """
    out = Path(out)
    for name in ("report.html", "report.md"):
        check_writable(out / name, "report")
    check_writable(out / "report_files" / "01_figure.png", "report folder")


def clear_figures(files: Path) -> None:
    """Remove the figures of an earlier report from ``files``: only files habitsim wrote
    (listed in the output folder's record, :mod:`habitsim.folders`); anything else is
    left alone.

    Raises:
        OutputPathError: a figure that cannot be removed (a read-only folder).
    """
    if not files.is_dir() or os.path.islink(files):
        return
    remove_written(sorted(files.glob("*")), "report folder")


def write_report(out: str | Path) -> list[Path]:
    """Write ``report.html`` and ``report.md`` (+ ``report_files/``) for a run folder.

    Returns:
        The two report paths.

    Raises:
        ReportError: the folder holds no finished run.
    """
    from .tables import PHYSICAL_COLUMNS, TABLE1_COLUMNS, _fmt, tracking_label

    out = Path(out)
    cfg, summary_doc, rows = _load_run(out)
    summary: dict[str, dict[str, Any]] = summary_doc["methods"]
    check_report_outputs(out)
    page = _Page(out / "report_files")
    clear_figures(out / "report_files")

    page.heading("habitsim benchmark", 1)
    n_ok = sum(r["status"] == "ok" for r in rows)
    page.para(
        f"Data {cfg['data']} (split {cfg['split']}), methods {', '.join(summary)}, "
        f"refinement {cfg['refine']}, tracking "
        + (
            "off"
            if not cfg["track"]
            else f"{cfg['controller']} "
            + ("with root assistance" if cfg["assist"] else "unassisted")
        )
        + f"; {len(rows)} rows ({n_ok} ok); wall time {summary_doc.get('wall_time_s', 0):.0f} s."
    )
    statuses = sorted(
        {
            (r["method"], r.get("refine_status", ""), r.get("track_status", ""))
            for r in rows
            if r["status"] == "ok"
        }
    )
    refine_states = sorted({s[1] for s in statuses if s[1]})
    track_states = sorted({s[2].split(":")[0] for s in statuses if s[2]})
    page.para(
        f"Refinement status seen: {', '.join(refine_states) or '—'}; "
        f"tracking status seen: {', '.join(track_states) or '—'}."
    )

    page.heading("Summary (Table 1 layout, physical columns added)")
    cols = [("pairs", "pairs"), ("ok", "ok")] + list(TABLE1_COLUMNS) + list(PHYSICAL_COLUMNS)
    tracking = tracking_label(cfg["controller"], cfg["assist"], cfg["track"])
    page.table(
        ["method", "controller"] + [h for _, h in cols],
        [[m, tracking] + [_fmt(s.get(k)) for k, _ in cols] for m, s in summary.items()],
    )
    page.para(
        "Set metrics on the frozen evaluator's features against the real clips of the "
        "target species; diversity of the real clips in the '(real)' column; every other "
        "column is the mean over the method's pairs. MPJPE is against the source scaled to "
        "the target's size, paired MPJPE against the synthetic ground truth."
    )

    img = _summary_bars(summary)
    if img:
        page.heading("Metrics per method")
        page.image(img, "metrics", "summary metrics per method")

    page.heading("Survival and skating per species pair")
    for m in summary:
        img = _heatmaps(rows, m)
        if img:
            page.image(img, f"heatmap_{m}", f"{m}: mean survival and skate_mm per (source, target)")

    _trace_sections(page, out, rows, list(summary), bool(cfg.get("videos", True)))

    errors = [r for r in rows if r["status"] == "error"]
    if errors:
        page.heading("Errors")
        page.table(["pair", "message"], [[r["key"], r["note"][:200]] for r in errors[:50]])

    atomic_write_text(out / "report.html", page.document("habitsim benchmark"))
    atomic_write_text(out / "report.md", "\n".join(page.md) + "\n")
    return [out / "report.html", out / "report.md"]


def _trace_sections(
    page: _Page, out: Path, rows: list[dict[str, Any]], methods: list[str], videos_on: bool
) -> None:
    traces = out / "traces"
    by_pair: dict[tuple[str, str], dict[str, Path]] = {}
    for r in rows:
        d = traces / r["key"]
        if r["status"] == "ok" and (d / "trace.npz").is_file():
            by_pair.setdefault((r["clip"], r["target"]), {})[r["method"]] = d
    if not by_pair:
        return
    page.heading("Gait diagrams (footfall timelines from foot contacts)")
    curves_sections = []
    for (clip, target), dirs in sorted(by_pair.items()):
        source_done = False
        panels: list[tuple[str, np.ndarray]] = []
        curves: list[tuple[str, np.ndarray, float]] = []
        fps = 30.0
        for m in methods:
            if m not in dirs:
                continue
            with np.load(dirs[m] / "trace.npz", allow_pickle=False) as z:
                t = {k: z[k] for k in z.files}
            fps = float(t["fps"])
            if not source_done:
                panels.append(("source", t["source_contacts"]))
                source_done = True
            panels.append((f"{m}", t["transferred_contacts"]))
            if not np.array_equal(t["reference_contacts"], t["transferred_contacts"]):
                panels.append((f"{m} refined", t["reference_contacts"]))
            if "simulated_contacts" in t:
                panels.append((f"{m} sim", t["simulated_contacts"]))
            if "tracking_error_mm" in t:
                curves.append((m, t["tracking_error_mm"], fps))
        title = f"{Path(clip).stem} → {target}"
        page.image(
            _gait_diagram(panels, fps, title),
            f"gait_{Path(clip).stem}_{target}",
            f"gait diagram: {title}",
        )
        curves_sections.append((title, curves, dirs))
    page.heading("Tracking error over time")
    any_curve = False
    for title, curves, _dirs in curves_sections:
        if curves:
            any_curve = True
            page.image(
                _error_curves(curves, title),
                f"err_{len(page.html)}",
                f"tracking error (simulated vs reference joints): {title}",
            )
    if not any_curve:
        page.para("No tracking runs (tracking off or habitsim.sim unavailable).")
    videos = [
        (title, m, d / "simulated.gif")
        for title, _c, dirs in curves_sections
        for m, d in dirs.items()
        if (d / "simulated.gif").is_file()
    ]
    page.heading("Videos of the simulated runs")
    if not videos:
        page.para(
            "No videos: rendering was switched off (--no-videos)."
            if not videos_on
            else "No videos (no tracking runs, or habitsim.render / an OpenGL backend is "
            "unavailable here)."
        )
    for title, m, p in videos:
        page.image(p.read_bytes(), f"video_{m}", f"{m}: {title} (simulated)", mime="image/gif")
