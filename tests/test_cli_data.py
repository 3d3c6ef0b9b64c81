"""``habitsim demo`` and ``habitsim bench data`` (small configurations)."""

from __future__ import annotations

import types
from pathlib import Path

import pytest

from habitsim.cli import bench_cmd, build_parser, main
from habitsim.dataset import MANIFEST_NAME, build_dataset, load_manifest
from habitsim.species import species_names


@pytest.mark.slow
def test_demo_runs_and_reruns(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "demo_out"
    args = [
        "demo",
        "--out",
        str(out),
        "--clips-per-species",
        "1",
        "--workers",
        "1",
        "--no-progress",
        "--data-only",
    ]
    assert main(args) == 0
    text = capsys.readouterr().out
    assert "phase err" in text and str(out) in text
    man = load_manifest(out)
    assert man.species_names == species_names()
    assert main(args) == 0
    assert f"0 generated, {len(man.clips)} reused" in capsys.readouterr().out


@pytest.mark.slow
def test_demo_rebuilds_other_configuration(tmp_path: Path) -> None:
    out = tmp_path / "demo_out"
    build_dataset(out, clips_per_species=1, seed=5, species=["cat"], workers=1, progress=False)
    assert (
        main(
            ["demo", "--out", str(out), "--clips-per-species", "1", "--no-progress", "--data-only"]
        )
        == 0
    )
    man = load_manifest(out)
    assert man.seed == 0 and len(man.species) == len(species_names())
    assert not list(out.glob("*/cat/*_0001.npz"))


@pytest.mark.slow
def test_demo_pipeline_two_sources_report_and_videos(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import json

    from habitsim.render import render_available

    out = tmp_path / "demo_out"
    assert (
        main(
            [
                "demo",
                "--out",
                str(out),
                "--clips-per-species",
                "1",
                "--workers",
                "1",
                "--no-progress",
                "--targets",
                "tiger",
            ]
        )
        == 0
    )
    text = capsys.readouterr().out
    rows = json.loads((out / "pipeline.json").read_text())
    assert [(r["source"], r["target"]) for r in rows] == [
        ("horse_trot", "tiger"),
        ("dog_walk_bvh", "tiger"),
    ]
    for r in rows:
        assert r["habit_from"] != "tiger" and "tiger" in r["retrieval"]  # held out: retrieved
        # the habit transfer labels its stance from its decoded contacts (checked against
        # the source's footfalls when the source has labels, as both sources here do)
        assert r["contacts"] == "decoded"
        assert r["refine_check"] in ("kept", "reverted", "fallback") and r["refine_note"]
        assert set(r["seconds_per_stage"]) == {"transfer", "refine", "track"}
        assert 0.0 <= r["survival_unassisted"] <= 1.0 and r["controller"] == "mpc"
        assert (out / "pipeline" / f"{r['source']}_to_tiger_refined.npz").is_file()
        if render_available():
            assert (out / "pipeline" / r["video"]).stat().st_size > 10_000
    report = (out / "report.md").read_text()
    assert "| dog_walk_bvh | tiger |" in report and "## Held-out targets" in report
    assert "## Refinement check" in report
    assert "| horse_trot | tiger |" in text  # the summary table is printed
    # with its legend under it
    table_end = text.index("| dog_walk_bvh | tiger |")
    assert text.index("survival = share of the clip", table_end) > table_end
    # the HTML report next to report.md: table, legend, plots (embedded PNG) and videos
    page = (out / "report.html").read_text()
    assert "<table>" in page and "survival = share of the clip" in page
    assert page.count('src="data:image/png;base64,') >= 1 + 2 * len(rows)  # bars, gait, error
    assert len(list((out / "report_files").glob("*.png"))) >= 1 + 2 * len(rows)
    if render_available():
        for r in rows:
            assert f'<video src="pipeline/{r["video"]}"' in page


def test_demo_on_a_file_is_an_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    f = tmp_path / "f"
    f.write_text("x")
    assert main(["demo", "--out", str(f), "--no-progress"]) == 2
    assert capsys.readouterr().err.startswith("error:")


@pytest.mark.slow
def test_bench_data_small(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "bench"
    args = [
        "bench",
        "data",
        "--clips-per-species",
        "1",
        "--workers",
        "1",
        "--no-progress",
        "--out",
        str(out),
    ]
    assert main(args) == 0
    text = capsys.readouterr().out
    for key in (
        "build wall time",
        "synthetic clips/s",
        "FK numpy frames/s",
        "FK torch f32 frames/s",
    ):
        assert key in text
    assert (out / MANIFEST_NAME).is_file()
    assert main(args) == 0  # --out replaces the earlier build, regenerating every clip
    assert f"{len(species_names())} clips" in capsys.readouterr().out


def test_bench_extra_modules(monkeypatch: pytest.MonkeyPatch) -> None:
    calls: list[object] = []
    fake = types.ModuleType("habitsim.cli.bench_fake")

    def register(sub) -> None:
        calls.append(sub)
        p = sub.add_parser("fake")
        p.set_defaults(func=lambda ns: 0)

    fake.register = register  # type: ignore[attr-defined]
    monkeypatch.setattr(bench_cmd, "_EXTRA", (*bench_cmd._EXTRA, fake))
    parser = build_parser()
    assert len(calls) == 1
    assert parser.parse_args(["bench", "fake"]).func(None) == 0
    assert parser.parse_args(["bench", "data"]).clips_per_species == 40
    for name in ("sim", "refine", "balance", "train"):  # the shipped benchmarks
        assert parser.parse_args(["bench", name]).func is not None
    assert parser.parse_args(["bench", "real", "--data", "d"]).func is not None
