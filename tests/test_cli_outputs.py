"""Every command's outputs: checked before any work, written all or none, refused with a typed
error (exit 2)."""

from __future__ import annotations

from pathlib import Path

import pytest
from helpers import EVAL_ARGS, EXAMPLE_BVH, UNWRITABLE, files_under, run_cli


@pytest.mark.slow
@pytest.mark.parametrize(
    "extra",
    [["--report", "{blocker}/r.json"], ["--qpos", "{blocker}/q.npz"]],
    ids=["report", "qpos"],
)
def test_refine_unwritable_second_output_leaves_nothing(
    tmp_path: Path, motion_file: Path, capsys, extra: list[str]
) -> None:
    blocker = tmp_path / "blocker"
    blocker.write_text("a file where a folder should be")
    out = tmp_path / "ok.npz"
    extra = [e.format(blocker=blocker) for e in extra]
    code, err = run_cli(["refine", motion_file, "--out", out, *extra], capsys)
    assert code == 2 and err.startswith("error: ") and "file where a folder" in err
    assert files_under(tmp_path) == ["blocker"]


@pytest.mark.parametrize(
    "extra",
    [["--report", "{blocker}/r.json"], ["--video", "{blocker}/v.gif"]],
    ids=["report", "video"],
)
def test_track_unwritable_second_output_leaves_nothing(
    tmp_path: Path, motion_file: Path, capsys, extra: list[str]
) -> None:
    blocker = tmp_path / "blocker"
    blocker.write_text("x")
    extra = [e.format(blocker=blocker) for e in extra]
    code, err = run_cli(["track", motion_file, "--out", tmp_path / "sim.npz", *extra], capsys)
    assert code == 2 and err.startswith("error: "), err
    assert files_under(tmp_path) == ["blocker"]


def test_transfer_unwritable_bvh_leaves_nothing(tmp_path: Path, motion_file: Path, capsys) -> None:
    blocker = tmp_path / "blocker"
    blocker.write_text("x")
    code, err = run_cli(
        [
            "transfer",
            motion_file,
            "--to",
            "cat",
            "--method",
            "direct",
            "--out",
            tmp_path / "ok.npz",
            "--bvh",
            blocker / "x.bvh",
        ],
        capsys,
    )
    assert code == 2 and "file where a folder" in err
    assert files_under(tmp_path) == ["blocker"]


def test_transfer_writes_both_outputs(tmp_path: Path, motion_file: Path, capsys) -> None:
    code, _ = run_cli(
        [
            "transfer",
            motion_file,
            "--to",
            "cat",
            "--method",
            "direct",
            "--out",
            tmp_path / "ok.npz",
            "--bvh",
            tmp_path / "x.bvh",
        ],
        capsys,
    )
    assert code == 0
    assert files_under(tmp_path) == ["ok.npz", "x.bvh"]


@pytest.mark.parametrize("command", ["synth", "eval"])
def test_output_folder_under_a_file(tmp_path: Path, small_dataset: Path, capsys, command) -> None:
    blocker = tmp_path / "blocker"
    blocker.write_text("x")
    if command == "synth":
        argv = [
            "data",
            "synth",
            "--out",
            blocker / "d",
            "--species",
            "cat",
            "--clips-per-species",
            "1",
            "--workers",
            "1",
            "--no-progress",
        ]
    else:
        argv = ["eval", "--data", small_dataset, "--out", blocker / "e", *EVAL_ARGS]
    code, err = run_cli(argv, capsys)
    assert code == 2 and err.startswith("error: ") and "file where a folder" in err, err
    assert files_under(tmp_path) == ["blocker"]


@pytest.mark.parametrize("unwritable", UNWRITABLE, indirect=True)
def test_train_checked_before_training(unwritable: Path, small_dataset: Path, capsys) -> None:
    code, err = run_cli(
        ["train", "--data", small_dataset, "--out", unwritable / "ck", "--config", "small"],
        capsys,
    )
    assert code == 2 and err.startswith("error: ") and "--out" in err, err
    assert not unwritable.exists()


@pytest.mark.parametrize("where", ["report_files", "report.html", "summary.csv"])
def test_eval_outputs_checked_before_the_run(
    tmp_path: Path, small_dataset: Path, capsys, where: str
) -> None:
    """A folder where a table should be, or a file where report_files/ should be."""
    out = tmp_path / "run"
    out.mkdir()
    if where == "report_files":
        (out / where).write_text("x")
    else:
        (out / where).mkdir()
    args = [a for a in EVAL_ARGS if a != "--no-report"]
    code, err = run_cli(["eval", "--data", small_dataset, "--out", out, *args], capsys)
    assert code == 2 and err.startswith("error: ") and where in err, err
    assert not list((out / "rows").glob("*.json"))  # no pair ran


@pytest.mark.parametrize("unwritable", UNWRITABLE, indirect=True)
def test_demo_checked_before_work(unwritable: Path, tmp_path: Path, capsys) -> None:
    code, err = run_cli(["demo", "--out", unwritable / "demo", "--no-progress"], capsys)
    assert code == 2 and err.startswith("error: "), err
    assert not unwritable.exists()


@pytest.mark.parametrize("blocked", ["pipeline", "report_files", "report.md"])
def test_demo_pipeline_outputs_checked_before_the_data_set(
    tmp_path: Path, capsys, blocked: str
) -> None:
    out = tmp_path / "demo"
    out.mkdir()
    if blocked == "report.md":
        (out / blocked).mkdir()
    else:
        (out / blocked).write_text("x")
    code, err = run_cli(["demo", "--out", out, "--no-progress"], capsys)
    assert code == 2 and err.startswith("error: ") and blocked in err, err
    assert files_under(out) == [blocked]  # the data set was not built


@pytest.mark.parametrize("unwritable", UNWRITABLE, indirect=True)
def test_synth_into_unwritable_folder(unwritable: Path, capsys) -> None:
    argv = ["data", "synth", "--species", "cat", "--clips-per-species", "1", "--workers", "1"]
    code, err = run_cli([*argv, "--no-progress", "--out", unwritable / "d"], capsys)
    assert code == 2 and err.startswith("error: "), err
    assert not unwritable.exists()


@pytest.mark.parametrize("unwritable", UNWRITABLE, indirect=True)
@pytest.mark.parametrize("command", ["import-bvh", "export-bvh"])
def test_bvh_commands_checked_before_work(
    unwritable: Path, motion_file: Path, capsys, command: str
) -> None:
    if command == "import-bvh":
        argv = ["data", "import-bvh", EXAMPLE_BVH, "--species", "dog"]
        argv += ["--out", unwritable / "m.npz"]
    else:
        argv = ["data", "export-bvh", motion_file, "--out", unwritable / "m.bvh"]
    code, err = run_cli(argv, capsys)
    assert code == 2 and err.startswith("error: ") and "--out" in err, err
    assert not unwritable.exists()


@pytest.mark.parametrize("flag", ["--out", "--report", "--video"])
def test_retarget_outputs_checked_together(
    tmp_path: Path, motion_file: Path, capsys, flag: str
) -> None:
    blocker = tmp_path / "blocker"
    blocker.write_text("x")
    paths = {
        "--out": tmp_path / "q.npz",
        "--report": tmp_path / "r.json",
        "--video": tmp_path / "v.gif",
    }
    paths[flag] = blocker / paths[flag].name
    argv = ["retarget", motion_file, "--robot", tmp_path / "missing.xml", "--feet", "a,b,c,d"]
    argv += ["--track", *(x for k, p in paths.items() for x in (k, p))]
    code, err = run_cli(argv, capsys)
    assert code == 2 and "file where a folder" in err and flag in err, err
    assert files_under(tmp_path) == ["blocker"]


@pytest.mark.parametrize(
    "argv, match",
    [
        (["transfer", "{m}", "--to", "cat", "--out", "{t}/o.npz", "--seed", str(2**64)], "--seed"),
        (["transfer", "{m}", "--to", "cat", "--out", "{t}/o.npz", "--seed", "-1"], "--seed"),
        (
            ["transfer", "{m}", "--to", "cat", "--out", "{t}/o.npz", "--temperature", "0"],
            "--temperature",
        ),
        (
            ["transfer", "{m}", "--to", "cat", "--out", "{t}/o.npz", "--temperature", "-1"],
            "--temperature",
        ),
        (
            ["transfer", "{m}", "--to", "cat", "--out", "{t}/o.npz", "--temperature", "nan"],
            "--temperature",
        ),
        (["track", "{m}", "--settle", "1e9"], "--settle"),
        (["track", "{m}", "--control-hz", "inf"], "--control-hz"),
        (["data", "synth", "--out", "{t}/d", "--fps", "100000"], "fps"),
        (["data", "synth", "--out", "{t}/d", "--fps", "0.001"], "fps"),
        (["data", "synth", "--out", "{t}/d", "--seed", str(2**64)], "--seed"),
        (["eval", "--data", "{t}", "--out", "{t}/e", "--workers", "100000"], "--workers"),
    ],
)
def test_cli_argument_bounds(tmp_path: Path, motion_file: Path, capsys, argv, match) -> None:
    argv = [a.format(m=motion_file, t=tmp_path) for a in argv]
    code, err = run_cli(argv, capsys)
    assert code == 2 and err.startswith("error: ") and match in err, err
    assert "valid" in err
    assert files_under(tmp_path) == []
