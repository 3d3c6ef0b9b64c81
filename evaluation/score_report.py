"""The report of ``habitsim score --report``: ``report.html`` (self-contained) and
``report.md`` (figures in ``report_files/``), built with the benchmark report's page and
gait-diagram machinery (:mod:`habitsim.evaluation.report`).

Content: how the files were scored (the stance rule, refinement, tracking), the table of
:meth:`habitsim.evaluation.score.ScoreResult.table_text`, the files that could not be
scored and why, and a gait diagram per scored file: the stance the metrics used and,
when tracked, the simulated foot contacts.
"""

from __future__ import annotations

from pathlib import Path

from habitsim.fileio import atomic_write_text, make_dirs

from .report import _gait_diagram, _Page, clear_figures
from .score import ScoreResult, check_outputs

__all__ = ["write_score_report"]


def write_score_report(result: ScoreResult, out: str | Path, max_figures: int = 24) -> list[Path]:
    """Write ``report.html`` and ``report.md`` of a scoring into the folder ``out``.

    Args:
        result: :func:`habitsim.evaluation.score.score_files`' result.
        out: the folder.
        max_figures: gait diagrams drawn at most (the first scored files).

    Returns:
        The two report paths.

    Raises:
        OutputPathError: a report path that cannot be written (checked first).
    """
    folder = Path(out)
    check_outputs(folder, report=True)
    make_dirs(folder, "--out")
    files = folder / "report_files"
    clear_figures(files)
    page = _Page(files)
    o = result.options
    page.heading("habitsim score", 1)
    page.para(
        f"{len(result.rows)} file(s), {len(result.errors)} not scored. Judged "
        + ("as they are (no refinement)" if o.refine == "none" else f"after {o.refine} refinement")
        + "; "
        + (f"tracked unassisted with {o.controller}." if o.track else "not tracked.")
    )
    for line in result.stance_lines():
        page.para(line)
    cols = result.columns()
    page.heading("Scores")
    table = result.table_text(markdown=True).splitlines()
    body = [[c.strip() for c in line.strip("|").split("|")] for line in table[2:]]
    page.table([h for _, h in cols], body)
    page.para("Every column of every file: scores.csv and scores.json beside this report.")
    if result.errors:
        page.heading("Not scored")
        for r in result.errors:
            page.para(f"{r['file']}: {r['error']}: {r['note']}")
    drawn = [r for r in result.rows if r["file"] in result.traces][:max_figures]
    if drawn:
        page.heading("Gait diagrams")
        for r in drawn:
            tr = result.traces[r["file"]]
            panels = [(r.get("stance", "stance"), tr["stance"])]
            if "simulated" in tr:
                panels.append(("simulated", tr["simulated"]))
            page.image(
                _gait_diagram(panels, float(r["fps"]), r["file"]),
                "gait",
                f"{r['file']}: foot contacts ({r.get('stance', '')})",
            )
    html_path, md_path = folder / "report.html", folder / "report.md"
    atomic_write_text(html_path, page.document("habitsim score"))
    atomic_write_text(md_path, "\n".join(page.md) + "\n")
    return [html_path, md_path]
