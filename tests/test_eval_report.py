"""The benchmark report renders in headless Chromium: a non-empty page, no broken images."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from helpers import _typed_output_error

from habitsim.dataset import build_dataset
from habitsim.errors import OutputPathError
from habitsim.evaluation.report import ReportError, write_report
from habitsim.evaluation.runner import EvalConfig, run_benchmark

_CHECK = (
    '<script>window.addEventListener("load",()=>{const a=[...document.images];'
    "const b=a.filter(i=>!(i.complete&&i.naturalWidth>0)).length;"
    'document.body.setAttribute("data-check","images="+a.length+" broken="+b);});</script>'
)


def _chromium() -> str | None:
    for name in ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable"):
        path = shutil.which(name)
        if path:
            return path
    return None


def _browser(*args: str) -> subprocess.CompletedProcess:
    exe = _chromium()
    assert exe is not None
    return subprocess.run(
        [exe, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars", *args],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory) -> Path:
    data = tmp_path_factory.mktemp("rep_data")
    build_dataset(
        data,
        clips_per_species=12,
        seed=0,
        species=["cat", "dog", "horse"],
        workers=1,
        progress=False,
    )
    out = tmp_path_factory.mktemp("rep_run")
    cfg = EvalConfig(
        data=str(data),
        out=str(out),
        methods=("direct", "ground_truth"),
        refine="none",
        max_clips=1,
        report_pairs=1,
    )
    run_benchmark(cfg, workers=1, progress=False, report=True)
    return out


@pytest.mark.slow
def test_report_files_are_self_contained(run_dir: Path) -> None:
    html = (run_dir / "report.html").read_text(encoding="utf-8")
    md = (run_dir / "report.md").read_text(encoding="utf-8")
    assert "Table 1" in html and "FID" in html and "| direct |" in md
    srcs = re.findall(r'<img src="([^"]+)"', html)
    assert len(srcs) >= 4 and all(s.startswith("data:image/") for s in srcs)
    assert "http://" not in html and "https://" not in html and "<script" not in html
    for link in re.findall(r"\]\((report_files/[^)]+)\)", md):
        assert (run_dir / link).is_file()
    for section in (
        "Metrics per method",
        "Survival and skating",
        "Gait diagrams",
        "Tracking error",
    ):
        assert section in html


@pytest.mark.slow
def test_report_renders_in_headless_chromium(run_dir: Path, tmp_path: Path) -> None:
    if _chromium() is None:
        pytest.skip("no Chromium on this machine (apt-get install chromium)")
    page = tmp_path / "check.html"
    page.write_text(
        (run_dir / "report.html")
        .read_text(encoding="utf-8")
        .replace("</body>", _CHECK + "</body>"),
        encoding="utf-8",
    )
    dom = _browser("--virtual-time-budget=10000", "--dump-dom", page.as_uri())
    m = re.search(r'data-check="images=(\d+) broken=(\d+)"', dom.stdout)
    assert m, dom.stderr[-1000:]
    assert int(m.group(1)) >= 4 and int(m.group(2)) == 0

    shot = tmp_path / "shot.png"
    res = _browser(
        "--window-size=1280,2400", f"--screenshot={shot}", (run_dir / "report.html").as_uri()
    )
    assert shot.is_file() and shot.stat().st_size > 10_000, res.stderr[-1000:]
    from matplotlib import image

    px = image.imread(shot)
    assert px.ndim == 3 and px.shape[0] >= 1000 and float(np.std(px[..., :3])) > 0.05


def test_report_of_a_folder_without_run_is_a_clear_error(tmp_path: Path) -> None:
    with pytest.raises(ReportError, match="not a finished benchmark run"):
        write_report(tmp_path)


def test_write_report_unwritable(tmp_path: Path, eval_run: Path) -> None:
    import shutil

    from habitsim.evaluation.report import write_report

    for case in ("file", "folder_inside"):
        out = tmp_path / case
        shutil.copytree(eval_run, out)
        shutil.rmtree(out / "report_files", ignore_errors=True)
        if case == "file":
            (out / "report_files").write_text("x")
        else:  # a folder where the report's Markdown goes
            (out / "report.md").unlink(missing_ok=True)
            (out / "report.md").mkdir()
        (out / "report.html").unlink(missing_ok=True)
        with pytest.raises(OutputPathError) as ei:
            write_report(out)
        _typed_output_error(ei.value)
        assert not (out / "report.html").exists()


def test_old_figures_habitsim_did_not_write_are_kept(tmp_path: Path, eval_run: Path) -> None:
    """Clearing the old report's figures removes only files habitsim wrote."""
    import shutil

    from habitsim.evaluation.report import write_report

    out = tmp_path / "run"
    shutil.copytree(eval_run, out)
    (out / "report_files").mkdir(exist_ok=True)
    (out / "report_files" / "my_notes.txt").write_text("mine")
    (out / "report_files" / "01_old.png").mkdir()
    write_report(out)
    assert (out / "report_files" / "my_notes.txt").read_text() == "mine"
    assert (out / "report_files" / "01_old.png").is_dir()


@pytest.mark.skipif(os.geteuid() == 0, reason="the super-user writes into read-only folders")
def test_write_report_read_only(tmp_path: Path, eval_run: Path) -> None:
    import shutil

    from habitsim.evaluation.report import write_report

    out = tmp_path / "run"
    shutil.copytree(eval_run, out)
    (out / "report_files").chmod(0o555)
    try:
        with pytest.raises(OutputPathError):
            write_report(out)
    finally:
        (out / "report_files").chmod(0o755)
