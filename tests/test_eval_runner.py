"""Benchmark runner: rows, summary = mean of rows, resume after a kill, method registry."""

from __future__ import annotations

import csv
import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from helpers import EVAL_ARGS, run_cli

from habitsim.dataset import build_dataset
from habitsim.evaluation.runner import (
    PHYSICAL_COLUMNS,
    TABLE1_COLUMNS,
    VOLATILE_COLUMNS,
    EvalConfig,
    EvalError,
    plan_tasks,
    run_benchmark,
    summarize,
)
from habitsim.transfer_methods import (
    MethodUnavailable,
    UnknownMethodError,
    direct_transfer,
    get_method,
    ground_truth_transfer,
    method_names,
    register_method,
)

SPECIES = ["cat", "dog", "horse"]


@pytest.fixture(scope="module")
def data(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("eval_data")
    build_dataset(out, clips_per_species=12, seed=0, species=SPECIES, workers=1, progress=False)
    return out


def _cfg(data: Path, out: Path, **kw) -> EvalConfig:
    # servo: a fast controller for the table's mechanics (the default is mpc)
    base = dict(
        methods=("direct", "ground_truth"),
        refine="none",
        report_pairs=1,
        videos=False,
        controller="servo",
    )
    base.update(kw)
    return EvalConfig(data=str(data), out=str(out), **base)


@pytest.fixture(scope="module")
def reference_run(data: Path, tmp_path_factory):
    out = tmp_path_factory.mktemp("eval_ref")
    return run_benchmark(_cfg(data, out), workers=1, progress=False, report=False)


def _read_csv(path: Path) -> list[dict[str, str]]:
    with open(path, newline="", encoding="utf-8") as fh:
        return [
            {k: v for k, v in r.items() if k not in VOLATILE_COLUMNS} for r in csv.DictReader(fh)
        ]


@pytest.mark.slow
def test_rows_one_per_pair_and_table_layout(reference_run) -> None:
    res = reference_run
    tasks = plan_tasks(res.config)
    # 4 validation clips x 2 other species x 2 methods
    assert len(tasks) == len(res.rows) == 16
    assert {r["key"] for r in res.rows} == {t.key for t in tasks}
    assert all(r["source"] != r["target"] for r in res.rows)
    assert all(r["status"] in ("ok", "unavailable") for r in res.rows), [
        r["note"] for r in res.rows
    ]
    csv_rows = _read_csv(res.out / "rows.csv")
    assert len(csv_rows) == 16
    text = (res.out / "summary.md").read_text()
    for _, head in TABLE1_COLUMNS + PHYSICAL_COLUMNS:
        assert head in text
    # the tracking controller is a column of the table (runs with different controllers stack)
    assert "| method | controller |" in text and "| direct | servo |" in text
    assert res.table_text.splitlines()[1].split()[:2] == ["direct", "servo"]
    gt = res.summary["ground_truth"]
    assert gt["paired_mpjpe_mm"] == 0.0
    assert gt["habit_accuracy"] >= 0.8 and gt["action_accuracy"] >= 0.5
    assert res.summary["direct"]["paired_mpjpe_mm"] > 10.0
    pytest.importorskip("pyarrow")
    import pyarrow.parquet as pq

    t = pq.read_table(res.out / "rows.parquet")
    assert t.num_rows == 16 and "mpjpe_mm" in t.column_names


@pytest.mark.slow
def test_summary_equals_mean_of_rows(reference_run) -> None:
    res = reference_run
    for method, s in res.summary.items():
        ok = [r for r in res.rows if r["method"] == method and r["status"] == "ok"]
        assert s["ok"] == len(ok) and s["pairs"] == sum(r["method"] == method for r in res.rows)
        checked = 0
        for key, col in [
            ("habit_accuracy", "habit_correct"),
            ("action_accuracy", "action_correct"),
            ("mpjpe_mm", "mpjpe_mm"),
            ("skate_mm", "skate_mm"),
            ("root_residual_mg", "root_residual_mg"),
            ("survival", "survival"),
            ("biomech_score", "biomech_score"),
            ("sim_mpjpe_mm", "sim_mpjpe_mm"),
        ]:
            vals = [r.get(col) for r in ok]
            vals = [float(v) for v in vals if v is not None and math.isfinite(float(v))]
            if not vals:
                assert math.isnan(s[key])
                continue
            assert s[key] == pytest.approx(float(np.mean(vals)), rel=1e-12)
            checked += 1
        assert checked >= 5
    again = summarize(res.rows, *_real(res), seed=0, methods=list(res.summary))
    assert json.dumps(again, sort_keys=True, default=str) == json.dumps(
        res.summary, sort_keys=True, default=str
    )


def _real(res):
    with np.load(res.out / "reference_features.npz") as z:
        return z["features"], [str(s) for s in z["species"]], [str(c) for c in z["clips"]]


@pytest.mark.slow
def test_resume_after_kill_gives_the_same_table(data: Path, reference_run, tmp_path: Path) -> None:
    out = tmp_path / "killed"
    cmd = [
        sys.executable,
        "-m",
        "habitsim",
        "eval",
        "--data",
        str(data),
        "--out",
        str(out),
        "--methods",
        "direct,ground_truth",
        "--refine",
        "none",
        "--controller",
        "servo",
        "--targets",
        "all",
        "--clips-per-source",
        "all",
        "--workers",
        "1",
        "--report-pairs",
        "1",
        "--no-videos",
        "--no-report",
        "--no-progress",
    ]
    env = dict(os.environ, OMP_NUM_THREADS="1")
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        if len(list((out / "rows").glob("*.json"))) >= 5 or proc.poll() is not None:
            break
        time.sleep(0.02)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    done = len(list((out / "rows").glob("*.json")))
    assert 5 <= done < 16, f"killed after {done} rows: {proc.stderr.read().decode()[-500:]}"
    assert not (out / "summary.json").exists()

    from habitsim.errors import OutputFolderError

    with pytest.raises(OutputFolderError, match="--resume"):
        run_benchmark(_cfg(data, out), workers=1, progress=False, report=False)
    with pytest.raises(EvalError, match="refine"):
        run_benchmark(
            _cfg(data, out, refine="dynamics"), workers=1, progress=False, report=False, resume=True
        )
    res = run_benchmark(_cfg(data, out), workers=1, progress=False, report=False, resume=True)
    assert res.skipped == done and res.computed == 16 - done
    assert _read_csv(out / "rows.csv") == _read_csv(reference_run.out / "rows.csv")
    a = json.loads((out / "summary.json").read_text())["methods"]
    b = json.loads((reference_run.out / "summary.json").read_text())["methods"]
    for m in b:
        for k in VOLATILE_COLUMNS:
            a[m].pop(k, None)
            b[m].pop(k, None)
    assert a == b


def test_method_registry() -> None:
    names = method_names()
    assert {"habit", "direct", "ground_truth"} <= set(names)
    assert names.index("direct") < names.index("ground_truth")
    assert get_method("ground_truth").kind == "reference" and get_method("habit").learned
    with pytest.raises(UnknownMethodError, match="valid: .*direct"):
        get_method("hores")
    with pytest.raises(Exception, match="already registered"):
        register_method("direct", direct_transfer)


def test_ground_truth_unavailable_for_missing_action(habitsim_clip) -> None:
    pace = habitsim_clip("camel", "pace", seed=0)
    with pytest.raises(MethodUnavailable, match="pace"):
        ground_truth_transfer(pace, "horse")
    gt = ground_truth_transfer(habitsim_clip("camel", "walk", seed=0), "horse")
    assert gt.species == "horse" and gt.metadata["action"] == "walk"


def _mirror_method(source, target, *, seed=0):
    """A custom method for the registry test: direct transfer, then nothing else."""
    return direct_transfer(source, target, seed=seed)


@pytest.mark.slow
def test_custom_method_and_bad_config(data: Path, tmp_path: Path) -> None:
    if "custom_direct" not in method_names():
        register_method("custom_direct", _mirror_method, "test method")
    res = run_benchmark(
        _cfg(
            data,
            tmp_path / "c",
            methods=("custom_direct",),
            max_clips=1,
            track=False,
            dynamic=False,
        ),
        workers=1,
        progress=False,
        report=False,
    )
    assert res.summary["custom_direct"]["ok"] == 2
    with pytest.raises(UnknownMethodError):
        plan_tasks(_cfg(data, tmp_path / "d", methods=("nope",)))
    with pytest.raises(EvalError, match="refine mode"):
        _cfg(data, tmp_path / "e", refine="fast")
    with pytest.raises(EvalError, match="max_clips"):
        _cfg(data, tmp_path / "f", max_clips=0)
    with pytest.raises(Exception, match="not in the data set"):
        plan_tasks(_cfg(data, tmp_path / "g", sources=("elephant",)))


@pytest.mark.slow
def test_refine_stage_runs(data: Path, tmp_path: Path) -> None:
    cfg = _cfg(
        data,
        tmp_path / "r",
        methods=("direct",),
        refine="kinematic",
        max_clips=1,
        targets=("dog",),
        track=False,
        dynamic=False,
    )
    res = run_benchmark(cfg, workers=1, progress=False, report=False)
    (row,) = res.rows
    assert row["status"] == "ok", row["note"]
    assert row["refine_status"] not in ("", "none", "unavailable")
    assert row["time_refine_s"] > 0.0


@pytest.mark.slow
def test_defaults_measure_the_product(data: Path, tmp_path: Path) -> None:
    """With no options: habit beside the baselines, stage A, mpc; one clip per source."""
    from habitsim.cli import build_parser
    from habitsim.evaluation import runner

    ns = build_parser().parse_args(["eval"])
    assert ns.methods == ["habit", "direct", "ground_truth"] and ns.controller == "mpc"
    assert ns.refine == "kinematic" and ns.out == "eval_out" and ns.data is None
    assert ns.targets == ["cat", "horse", "camel"] and ns.clips_per_source == "1"
    cfg = EvalConfig(data=str(data), out=str(tmp_path / "o"))
    assert cfg.methods == ("habit", "direct", "ground_truth") and cfg.controller == "mpc"
    assert cfg.refine == "kinematic"
    every = plan_tasks(_cfg(data, tmp_path / "o", methods=("direct",)))
    one = plan_tasks(_cfg(data, tmp_path / "o", methods=("direct",), clips_per_source=1))
    per_source = {}
    for t in one:
        per_source.setdefault(t.source, set()).add(t.clip)
    assert all(len(c) == 1 for c in per_source.values())
    assert set(per_source) == {t.source for t in every} and len(one) < len(every)
    first = {}
    for t in every:  # the first clip of each species in manifest order
        first.setdefault(t.source, t.clip)
    assert {s: next(iter(c)) for s, c in per_source.items()} == first
    with pytest.raises(EvalError, match="clips_per_source"):
        _cfg(data, tmp_path / "o", clips_per_source=0)
    # the default data set: built on the first run, reused after
    folder = runner.default_data(tmp_path / "run", workers=1, progress=False, clips_per_species=1)
    from habitsim.dataset import load_manifest
    from habitsim.species import species_names

    assert folder == tmp_path / "run" / "data"
    assert load_manifest(folder).species_names == species_names()
    clip = folder / load_manifest(folder).clips[0].path
    stamp = clip.stat().st_mtime_ns
    runner.default_data(tmp_path / "run", workers=1, progress=False, clips_per_species=1)
    assert clip.stat().st_mtime_ns == stamp  # reused, not generated again


def test_cli_clips_per_source_must_be_a_count(tmp_path: Path, capsys) -> None:
    from habitsim.cli import main

    assert (
        main(
            [
                "eval",
                "--out",
                str(tmp_path / "o"),
                "--data",
                str(tmp_path),
                "--clips-per-source",
                "some",
                "--no-progress",
            ]
        )
        == 2
    )
    assert "--clips-per-source" in capsys.readouterr().err


@pytest.mark.parametrize(
    "tamper",
    [
        "run_list",
        "run_config_str",
        "run_deep",
        "row_list",
        "row_no_key",
        "row_wrong_key",
        "row_deep",
        "run_big_int",
        "row_big_int",
    ],
)
def test_eval_resume_tampered_state(
    tmp_path: Path, small_dataset: Path, eval_run: Path, capsys, tamper: str
) -> None:
    import json
    import shutil

    out = tmp_path / "run"
    shutil.copytree(eval_run, out)
    run, rows = out / "run.json", sorted((out / "rows").glob("*.json"))
    assert rows
    deep = "[" * 100_000 + "]" * 100_000
    if tamper == "run_list":
        run.write_text("[1, 2]")
    elif tamper == "run_config_str":
        run.write_text(json.dumps({"config": "x"}))
    elif tamper == "run_deep":
        run.write_text(deep)
    elif tamper == "row_list":
        rows[0].write_text("[1]")
    elif tamper == "row_no_key":
        rows[0].write_text(json.dumps({"status": "ok"}))
    elif tamper == "row_wrong_key":
        rows[0].write_text(json.dumps({"key": 5, "status": "ok"}))
    elif tamper == "row_deep":
        rows[0].write_text(deep)
    elif tamper == "run_big_int":  # past Python's int-conversion limit: a raw ValueError
        run.write_text('{"config": {"seed": ' + "9" * 5000 + "}}")
    elif tamper == "row_big_int":
        rows[0].write_text('{"key": "k", "n": ' + "9" * 5000 + "}")
    code, err = run_cli(
        ["eval", "--data", small_dataset, "--out", out, *EVAL_ARGS, "--resume"], capsys
    )
    assert code == 2 and err.startswith("error: ") and len(err) < 600, err


def test_eval_tables_when_no_pair_has_features(tmp_path: Path, eval_run: Path) -> None:
    """Every pair failed (an absurd clip): the tables are still written, features
    (0, 0), instead of a ValueError from reshape."""
    from habitsim.evaluation.runner import load_rows, write_tables

    rows = [{k: v for k, v in r.items() if k != "features"} for r in load_rows(eval_run)]
    for r in rows:
        r.update(status="error", note="InvalidMotionError: x")
    write_tables(tmp_path, rows)
    with np.load(tmp_path / "features.npz") as z:
        assert z["features"].shape == (0, 0) and z["keys"].shape == (0,)


def test_clips_of_one_file_name_in_two_species_folders_get_two_rows(
    data: Path, tmp_path: Path
) -> None:
    """Row keys come from the clip's path, so ``val/cat/same.npz`` and ``val/dog/same.npz``
    are two pairs, not one row for two computed pairs."""
    import shutil

    doc = json.loads((data / "manifest.json").read_text())
    clips = []
    for sp in ("cat", "dog"):
        c = next(c for c in doc["clips"] if c["species"] == sp and c["split"] == "val")
        (tmp_path / "d" / "val" / sp).mkdir(parents=True)
        shutil.copy(data / c["path"], tmp_path / "d" / "val" / sp / "same.npz")
        clips.append(dict(c, path=f"val/{sp}/same.npz"))
    doc["clips"] = clips
    (tmp_path / "d" / "manifest.json").write_text(json.dumps(doc))
    tasks = plan_tasks(_cfg(tmp_path / "d", tmp_path / "out", targets=("horse",)))
    assert len(tasks) == 4 and len({t.key for t in tasks}) == 4


def test_a_second_eval_on_one_folder_is_refused(data: Path, tmp_path: Path) -> None:
    """While another run holds --out, eval (even with --overwrite) stops before any work."""
    from helpers import hold

    from habitsim.errors import OutputBusyError

    out = tmp_path / "out"
    with hold(out) as proc:
        for kw in ({}, {"overwrite": True}, {"resume": True}):
            with pytest.raises(OutputBusyError, match=str(proc.pid)):
                run_benchmark(_cfg(data, out), workers=1, progress=False, report=False, **kw)
    assert not (out / "rows").exists()


def test_overwrite_keeps_files_habitsim_did_not_write(
    tmp_path: Path, small_dataset: Path, eval_run: Path, capsys
) -> None:
    import shutil

    out = tmp_path / "run"
    shutil.copytree(eval_run, out)
    (out / "rows" / "notes.txt").write_text("mine")
    (out / "report_files").mkdir(exist_ok=True)
    (out / "report_files" / "my_plot.png").write_text("mine")
    # files habitsim did not write: refused without --overwrite, even with --resume
    code, err = run_cli(
        ["eval", "--data", small_dataset, "--out", out, *EVAL_ARGS, "--resume"], capsys
    )
    assert code == 2 and "--overwrite" in err
    code, err = run_cli(
        ["eval", "--data", small_dataset, "--out", out, *EVAL_ARGS, "--overwrite"], capsys
    )
    assert code == 0, err
    assert (out / "rows" / "notes.txt").read_text() == "mine"
    assert (out / "report_files" / "my_plot.png").read_text() == "mine"
    assert (out / "summary.json").is_file()
