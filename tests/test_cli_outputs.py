"""Every command's outputs: checked before any work, written all or none, refused with a typed
error (exit 2)."""

from __future__ import annotations

import errno
import io
import os
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


# --------------------------------------------------------------------------- a full disk


class _FullDisk(io.FileIO):
    """A file on a disk that is full after its first few bytes (``ENOSPC``)."""

    room = 64

    def write(self, b) -> int:  # type: ignore[override]
        if self.room <= 0:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        n = super().write(bytes(memoryview(b).cast("B")[: self.room]))
        self.room -= n
        return n


def _fill_disk_at(monkeypatch: pytest.MonkeyPatch, match: str, nth: int) -> None:
    """The ``nth`` file habitsim.fileio opens whose (temporary) path contains ``match``
    finds the disk full after a few bytes; every other file is written as usual."""
    from habitsim import fileio

    seen = [0]

    def fake_open(file, mode="r", **kw):
        if match in str(file) and "w" in mode:
            seen[0] += 1
            if seen[0] == nth:
                buffered = io.BufferedWriter(_FullDisk(file, "w"))
                return buffered if "b" in mode else io.TextIOWrapper(buffered, **kw)
        return open(file, mode, **kw)

    monkeypatch.setattr(fileio, "open", fake_open, raising=False)


def _fake_ffmpeg(folder: Path) -> Path:
    """An ffmpeg that stops on a full disk while encoding: it reads a little of the frames,
    leaves a truncated file and exits 1; any other use runs the real ffmpeg."""
    import imageio_ffmpeg

    script = folder / "ffmpeg"
    script.write_text(
        "#!/bin/sh\nfor a; do last=$a; done\n"
        'case "$*" in\n'
        '  *"-i -"*) head -c 100000 >/dev/null; head -c 24000 /dev/zero >"$last"; exit 1;;\n'
        f'  *) exec "{imageio_ffmpeg.get_ffmpeg_exe()}" "$@";;\n'
        "esac\n"
    )
    script.chmod(0o755)
    return script


def _full_disk_cases() -> list:
    """(argv, file that fails, nth such write, what must not exist afterwards, argv that
    resumes (it must then finish) or None); paths: {t} the test's folder, {m} a motion,
    {d} a data set."""
    synth = ["data", "synth", "--species", "cat", "--clips-per-species", "1", "--workers", "1"]
    train = ["train", "--data", "{d}", "--out", "{t}/ck", "--config", "small", "--steps", "4"]
    train += ["--set", "train.checkpoint_every=2", "--set", "train.val_every=2", "--no-progress"]
    transfer = ["transfer", "{m}", "--to", "cat", "--method", "direct", "--out", "{t}/o.npz"]
    slow = pytest.mark.slow
    return [
        pytest.param(
            [*transfer, "--bvh", "{t}/o.bvh"], "o.bvh", 1, "o.npz", None, id="transfer"
        ),
        pytest.param(
            ["refine", "{m}", "--out", "{t}/r.npz", "--qpos", "{t}/q.npz",
             "--report", "{t}/r.json"],
            "r.json", 1, "r.npz", None, id="refine", marks=slow,
        ),
        pytest.param(
            ["track", "{m}", "--out", "{t}/sim.npz", "--report", "{t}/r.json"],
            "sim.npz", 1, "r.json", None, id="track",
        ),
        pytest.param(
            ["track", "{m}", "--video", "{t}/v.mp4"], "ffmpeg", 1, "v.mp4", None,
            id="track-video", marks=slow,
        ),
        pytest.param(
            ["retarget", "{m}", "--robot", "{go2}", "--out", "{t}/q.npz"], "q.npz", 1, "q.npz",
            None, id="retarget",
        ),
        pytest.param(
            ["eval", "--data", "{d}", "--out", "{t}/e", *EVAL_ARGS], "rows.csv", 1, "e/rows.csv",
            ["eval", "--data", "{d}", "--out", "{t}/e", *EVAL_ARGS, "--resume"], id="eval",
            marks=slow,
        ),
        pytest.param(
            [*synth, "--out", "{t}/s", "--no-progress"], ".npz", 1, "s/manifest.json",
            [*synth, "--out", "{t}/s", "--no-progress"], id="data-synth",
        ),
        pytest.param(
            ["data", "import-bvh", "--dir", "{bvh}", "--species", "dog", "--out", "{t}/i"],
            "manifest", 1, "i/manifest.json", None, id="data-import-bvh-dir",
        ),
        pytest.param(
            ["data", "export-bvh", "{m}", "--out", "{t}/x.bvh"], "x.bvh", 1, "x.bvh", None,
            id="data-export-bvh",
        ),
        pytest.param(
            ["data", "captions", "{t}/ds"], "captions", 1, "ds/captions.json", None,
            id="data-captions",
        ),
        pytest.param(
            train, "model.safetensors", 2, None, [*train, "--resume"], id="train",
            marks=slow,
        ),
        pytest.param(
            ["train-evaluator", "--data", "{d}", "--out", "{t}/ev", "--epochs", "1",
             "--no-progress"],
            "config.json", 1, "ev/config.json", None, id="train-evaluator", marks=slow,
        ),
        pytest.param(
            ["score", "{m}", "--species", "dog", "--no-evaluator", "--no-dynamic",
             "--out", "{t}/sc"],
            "scores.json", 1, "sc/scores.csv", None, id="score",
        ),
        pytest.param(
            ["bench", "data", "--clips-per-species", "1", "--workers", "1", "--out", "{t}/b",
             "--no-progress"],
            "manifest", 1, "b/manifest.json", None, id="bench-data",
        ),
        pytest.param(
            ["demo", "--out", "{t}/demo", "--clips-per-species", "1", "--workers", "1",
             "--no-progress", "--data-only"],
            "manifest", 1, "demo/manifest.json",
            ["demo", "--out", "{t}/demo", "--clips-per-species", "1", "--workers", "1",
             "--no-progress", "--data-only"],
            id="demo",
        ),
    ]  # fmt: skip


@pytest.mark.parametrize("argv, match, nth, absent, again", _full_disk_cases())
def test_full_disk_on_every_writing_command(
    tmp_path: Path,
    motion_file: Path,
    small_dataset: Path,
    capsys,
    monkeypatch,
    argv: list[str],
    match: str,
    nth: int,
    absent: str | None,
    again: list[str] | None,
) -> None:
    """A full disk while writing: a typed error with exit code 1 naming the output, nothing
    half-written under its name, no temporary left; a command that resumes then finishes."""
    import shutil

    t = tmp_path / "t"
    t.mkdir()
    bvh = tmp_path / "bvh"
    bvh.mkdir()
    shutil.copy(EXAMPLE_BVH, bvh / "walk.bvh")
    if "captions" in argv:
        shutil.copytree(small_dataset, t / "ds")
    go2 = Path(__file__).parent / "robots" / "unitree_go2" / "scene.xml"
    fill = {"t": t, "m": motion_file, "d": small_dataset, "bvh": bvh, "go2": go2}
    if match == "ffmpeg":
        from habitsim.render import render_available

        if not render_available():
            pytest.skip("no OpenGL backend to render with")
        monkeypatch.setenv("IMAGEIO_FFMPEG_EXE", str(_fake_ffmpeg(tmp_path)))
    else:
        _fill_disk_at(monkeypatch, match, nth)
    code, err = run_cli([a.format(**fill) for a in argv], capsys)
    assert code == 1 and err.startswith("error: ") and "Traceback" not in err, err
    assert absent is None or not (t / absent).exists()  # train: its last checkpoint stays
    left = [p for p in t.rglob(".*") if p.name != ".habitsim-written"]
    assert left == [], left  # no temporary file, no lock
    if again is not None:
        monkeypatch.undo()
        code, err = run_cli([a.format(**fill) for a in again], capsys)
        assert code == 0, err
