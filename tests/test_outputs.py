"""Another method's outputs read from a folder (:mod:`habitsim.evaluation.outputs`,
``habitsim eval --method NAME=DIR``) and docs/evaluation.md's worked example of it and of
a plugin method."""

from __future__ import annotations

import csv
import re
import shlex
import sys
import tomllib
from pathlib import Path

import pytest
from helpers import EVAL_ARGS, install_plugin

from habitsim.cli import main
from habitsim.errors import UnknownSpeciesError
from habitsim.evaluation.outputs import (
    MethodOutputs,
    OutputsError,
    parse_method_outputs,
    stray_outputs,
)
from habitsim.evaluation.score import ScoreError
from habitsim.gaits import generate
from habitsim.transfer_methods import METHODS

DOC = Path(__file__).resolve().parents[1] / "docs" / "evaluation.md"
#: Flags that make a documented eval quick here (no tracking, one process, no report).
QUICK = ["--workers", "1", "--refine", "none", "--no-track", "--no-dynamic", "--no-report"]
QUICK += ["--no-progress", "--report-pairs", "0", "--no-videos"]


def _rows(out: Path) -> list[dict[str, str]]:
    with open(out / "rows.csv") as fh:
        return list(csv.DictReader(fh))


@pytest.fixture
def walk():
    return generate("dog", "walk", seed=0, duration_s=0.5)


def test_a_pair_reads_its_file(tmp_path: Path, walk) -> None:
    (tmp_path / "dog").mkdir()
    walk.save(tmp_path / "dog" / "cat_walk_0000.npz")
    mine = MethodOutputs("mine", str(tmp_path))
    out = mine(walk, "dog", clip_id="cat_walk_0000")
    assert out.species == "dog" and out.metadata["method"] == "mine"
    with pytest.raises(OutputsError):
        mine(walk, "dog", clip_id="cat_trot_0001")  # no such file
    with pytest.raises(OutputsError):
        mine(walk, "dog")  # no clip id
    (tmp_path / "cat").mkdir()
    walk.save(tmp_path / "cat" / "dog_walk_0000.npz")  # a dog where a cat belongs
    with pytest.raises(ScoreError):
        mine(walk, "cat", clip_id="dog_walk_0000")
    (tmp_path / "dog" / "cat_walk_0000.bvh").write_text("HIERARCHY")
    with pytest.raises(OutputsError):
        mine.path("dog", "cat_walk_0000")  # two files for one pair


def test_method_folders_are_checked(tmp_path: Path) -> None:
    for bad in ("mine", "mine=", "Mine=" + str(tmp_path), "x=" + str(tmp_path / "none")):
        with pytest.raises(OutputsError):
            parse_method_outputs(bad)
    with pytest.raises(OutputsError):
        parse_method_outputs(f"direct={tmp_path}")  # a registered method's name
    assert parse_method_outputs(f"mine={tmp_path}") == MethodOutputs("mine", str(tmp_path))
    with pytest.raises(UnknownSpeciesError):
        MethodOutputs("mine", str(tmp_path))(None, "unicorn", clip_id="a")


def test_stray_outputs(tmp_path: Path) -> None:
    for rel in ("dog/cat_walk_0000.npz", "dog/other.npz", "kitty/cat_walk_0000.npz", "a.npz"):
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text("")
    (tmp_path / "dog" / "cat_walk_0000.txt").write_text("")
    got = stray_outputs(MethodOutputs("mine", str(tmp_path)), {"cat_walk_0000"})
    assert got == ["a.npz", "dog/cat_walk_0000.txt", "dog/other.npz", "kitty/cat_walk_0000.npz"]


@pytest.mark.slow
def test_a_bad_output_is_an_error_row_and_exit_1(small_dataset: Path, tmp_path: Path) -> None:
    """The pair's file is a cat where a dog belongs: a typed error in its row, the other
    method's rows and the tables whole, exit code 1."""
    from habitsim.dataset import load_manifest

    clip = load_manifest(small_dataset).select(split="train")[0]
    assert clip.species == "cat"
    (tmp_path / "mine" / "dog").mkdir(parents=True)
    generate("cat", "walk", seed=0, duration_s=0.5).save(
        tmp_path / "mine" / "dog" / f"{Path(clip.path).stem}.npz"
    )
    out = tmp_path / "run"
    args = ["eval", "--data", small_dataset, "--out", out, *EVAL_ARGS]
    assert main([str(a) for a in [*args, "--method", f"mine={tmp_path / 'mine'}"]]) == 1
    rows = {r["method"]: r for r in _rows(out)}
    assert rows["direct"]["status"] == "ok"
    assert rows["mine"]["status"] == "error" and rows["mine"]["note"].startswith("ScoreError")
    assert (out / "summary.md").is_file()


def _block(lang: str, marker: str) -> str:
    blocks = re.findall(rf"^```{lang}\n(.*?)^```", DOC.read_text(), re.M | re.S)
    found = [b for b in blocks if marker in b]
    assert len(found) == 1, f"docs/evaluation.md: no single ```{lang} block with {marker!r}"
    return found[0]


def _eval_command(marker: str) -> list[str]:
    lines = [ln for ln in _block("bash", marker).splitlines() if ln.startswith("habitsim eval")]
    return shlex.split(lines[0])[1:]


@pytest.mark.slow
def test_the_documented_example_runs(tmp_path: Path, monkeypatch) -> None:
    """docs/evaluation.md's folder of outputs and plugin package, run as written (plus
    flags that make the run quick): both methods' rows in the table, no error."""
    monkeypatch.chdir(tmp_path)
    exec(compile(_block("python", 'Path("mine")'), "evaluation.md", "exec"), {})
    assert main([*_eval_command("--method mine=mine"), *QUICK]) == 0
    rows = _rows(tmp_path / "bench")
    assert {r["method"] for r in rows} == {"direct", "mine"}
    assert all(r["status"] == "ok" for r in rows)

    toml = tomllib.loads(_block("toml", "habitsim.methods"))
    entries = toml["project"]["entry-points"]["habitsim.methods"]
    install_plugin(
        tmp_path / "site", "my_methods", "my_methods", _block("python", "# my_methods.py"), entries
    )
    monkeypatch.syspath_prepend(str(tmp_path / "site"))
    monkeypatch.setattr(METHODS, "_methods", dict(METHODS._methods))
    monkeypatch.setattr(METHODS, "_plugins_loaded", False)
    assert main([*_eval_command("mirrored_direct"), "--overwrite", *QUICK]) == 0
    rows = _rows(tmp_path / "bench")
    assert {r["method"] for r in rows} == {"direct", "mirrored_direct"}
    assert all(r["status"] == "ok" for r in rows)
    monkeypatch.delitem(sys.modules, "my_methods")
