"""A user species (``habitsim species from-clip``) works where a catalog one does: the
pipeline, ``habitsim eval --targets``, ``habitsim bench real --targets``, another method's
outputs; an unknown name lists the built-in and the user species; the benchmarks' default
lists stay the built-in catalog's."""

from __future__ import annotations

import csv
from pathlib import Path

import pytest
from foreign_rig import user_dog
from helpers import EVAL_ARGS

from habitsim.bvh import write_bvh
from habitsim.cli import main
from habitsim.dataset import build_dataset
from habitsim.evaluation.outputs import MethodOutputs, stray_outputs
from habitsim.gaits import generate
from habitsim.pipeline import run_clip
from habitsim.species import USER_CATALOG_ENV, all_species, species_names


@pytest.fixture(scope="module")
def catalog(tmp_path_factory) -> Path:
    """A user catalog holding ``userdog`` (a dog walk's rig scaled by 1.1)."""
    return user_dog(tmp_path_factory.mktemp("user"), "userdog", scale=1.1)


@pytest.fixture
def user_env(catalog: Path, monkeypatch) -> Path:
    monkeypatch.setenv(USER_CATALOG_ENV, str(catalog))
    return catalog


@pytest.fixture(scope="module")
def data(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("data")
    build_dataset(out, clips_per_species=1, seed=0, species=["dog"], workers=1, progress=False)
    return out


def _rows(out: Path) -> list[dict[str, str]]:
    with open(out / "rows.csv", newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def test_default_lists_stay_built_in(user_env: Path) -> None:
    assert "userdog" in species_names(include_user=True)
    assert "userdog" not in species_names()
    assert "userdog" not in [s.name for s in all_species()]


def test_run_clip_onto_a_user_species(user_env: Path) -> None:
    src = generate("dog", "trot", seed=1, duration_s=1.0)
    run = run_clip(src, target="userdog", method="direct", refine="none", track=False)
    assert run.target == "userdog"
    assert run.transferred.motion is not None and run.transferred.motion.species == "userdog"
    assert run.refined.motion is not None and run.refined.motion.species == "userdog"


def _eval_argv(data: Path, out: Path, *extra: str) -> list[str]:
    args = list(EVAL_ARGS)
    args[args.index("--targets") + 1] = "userdog"
    return ["eval", "--data", str(data), "--out", str(out), *args, *extra]


@pytest.mark.slow  # a kinematic refinement and the evaluator's features: about 20 s
def test_eval_targets_a_user_species(user_env: Path, data: Path, tmp_path: Path) -> None:
    argv = _eval_argv(data, tmp_path / "run", "--sources", "dog")
    argv[argv.index("--refine") + 1] = "kinematic"
    assert main(argv) == 0
    rows = _rows(tmp_path / "run")
    assert [(r["target"], r["method"]) for r in rows] == [("userdog", "direct")]
    assert rows[0]["status"] == "ok" and rows[0]["refine_status"] == "Solve_Succeeded"
    assert float(rows[0]["mpjpe_mm"]) >= 0.0


def test_unknown_targets_list_the_user_species(
    user_env: Path, data: Path, tmp_path: Path, capsys
) -> None:
    assert main(_eval_argv(data, tmp_path / "run", "--targets", "userdgo")) == 2
    err = capsys.readouterr().err
    assert "userdgo" in err and "userdog" in err and "horse" in err
    clips = tmp_path / "clips"
    clips.mkdir()
    write_bvh(generate("dog", "walk", seed=3, duration_s=2.0), clips / "walk.bvh")
    assert main(["bench", "real", "--data", str(clips), "--targets", "userdgo"]) == 2
    err = capsys.readouterr().err
    assert "userdog" in err and "horse" in err


def test_bench_real_targets_a_user_species(user_env: Path, tmp_path: Path, capsys) -> None:
    clips = tmp_path / "clips"
    clips.mkdir()
    write_bvh(generate("dog", "walk", seed=3, duration_s=2.0), clips / "walk.bvh")
    argv = ["bench", "real", "--data", str(clips), "--targets", "userdog", "--methods"]
    argv += ["direct", "--seconds", "2", "--refine", "none", "--no-track", "--workers", "1"]
    main(argv)  # exit 1 or 0 by the targets; the run is what is checked
    out = capsys.readouterr().out
    assert "userdog" in out and "rows 1/1" in out


def test_outputs_of_another_method_for_a_user_species(user_env: Path, tmp_path: Path) -> None:
    for species in ("userdog", "nosuch"):
        (tmp_path / species).mkdir()
        (tmp_path / species / "c1.npz").write_bytes(b"")
    stray = stray_outputs(MethodOutputs("mine", str(tmp_path)), {"c1"})
    assert stray == ["nosuch/c1.npz"]


def test_demo_checks_its_targets_before_any_work(user_env: Path, tmp_path: Path, capsys) -> None:
    out = tmp_path / "demo"
    argv = ["demo", "--out", str(out), "--no-progress", "--workers", "1"]
    assert main([*argv, "--targets", "cat,userdgo"]) == 2
    err = capsys.readouterr().err
    assert "userdgo" in err and "userdog" in err and "tiger" in err
    assert not out.exists()  # refused before the data set was built
