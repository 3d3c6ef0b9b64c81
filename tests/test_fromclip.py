"""A species made from one clip (habitsim.fromclip, ``habitsim species from-clip``): the
rig's segments measured, the species file and models written into a user catalog,
the model standing, and the new species usable where a catalog species is."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from foreign_rig import _foreign_rig

import habitsim
from habitsim.cli import main
from habitsim.errors import (
    ClipMeasureError,
    SpeciesNameClashError,
    SpeciesNameError,
    UnknownSpeciesError,
)
from habitsim.fromclip import FromClipOptions, mass_rule
from habitsim.fromclip.make import StandingError, species_from_clip
from habitsim.source import SourceOptions
from habitsim.species import (
    USER_CATALOG_ENV,
    load_species,
    species_names,
    user_species,
)

#: Largest relative error of a measured segment against the rig's own.
SEGMENT_TOLERANCE = 0.05
#: Seconds the command may take for a species on 2 cores (the issue's target).
TARGET_SECONDS = 30.0


@pytest.fixture(scope="module")
def rig_file(tmp_path_factory) -> Path:
    """A dog walk written as a foreign rig (cm, other names, helper joints)."""
    walk = habitsim.generate("dog", "walk", seed=3, duration_s=2.0)
    path = tmp_path_factory.mktemp("rig") / "walk.bvh"
    path.write_text(_foreign_rig(walk).to_text(), encoding="utf-8")
    return path


@pytest.fixture(scope="module")
def made(rig_file, tmp_path_factory):
    """``mydog`` made from the rig into a user catalog folder."""
    catalog = tmp_path_factory.mktemp("catalog")
    return species_from_clip(rig_file, "mydog", catalog=catalog)


def _leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir()) if folder.exists() else []


def test_segments_within_five_percent_of_the_rig(made) -> None:
    dog, sp = load_species("dog"), made.species
    for key, value in dog.segments.items():
        assert sp.segments[key] == pytest.approx(value, rel=SEGMENT_TOLERANCE), key
    assert set(made.measure.measured) >= {"trunk", "neck", "head", "tail", "hind_upper"}
    assert made.draft.estimated == ()
    assert sp.hip_height == pytest.approx(made.measure.hip_height, rel=SEGMENT_TOLERANCE)
    assert made.seconds < TARGET_SECONDS


def test_files_written_and_the_model_stands(made) -> None:
    assert made.file.is_file() and made.file.name == "mydog.toml"
    for name in ("mydog.xml", "mydog_torque.xml", "scene.xml", "scene_torque.xml"):
        assert (made.models / name).is_file(), name
    assert made.stand.passed
    assert made.stand.lowest >= 0.95 * made.stand.home_height
    assert _leftovers(made.file.parent) == ["mydog", "mydog.toml"]  # no temporary folder
    sp = made.species
    assert sp.user_catalog == made.file.parent and sp.held_out and sp.cousin == "dog"
    assert sp.posture == "digitigrade"
    k, b, _ = mass_rule()
    assert sp.mass_kg == pytest.approx(k * np.sqrt(0.55 * made.measure.hip_height) ** b, rel=1e-3)


@pytest.mark.slow  # a transfer and a model compile: about 6 s
def test_user_species_usable_like_a_catalog_one(made, monkeypatch) -> None:
    from habitsim.qpos import load_species_model, motion_to_qpos

    monkeypatch.setenv(USER_CATALOG_ENV, str(made.file.parent))
    sp = load_species("mydog")
    assert sp.user_catalog == made.file.parent
    assert "mydog" in species_names(include_user=True)
    assert "mydog" not in species_names()  # the built-in catalog alone
    walk = habitsim.generate("mydog", "walk", seed=1, duration_s=1.0)
    assert walk.species == "mydog"
    model = load_species_model("mydog")
    assert motion_to_qpos(walk, model).qpos.shape == (walk.num_frames, model.nq)
    src = habitsim.generate("dog", "trot", seed=2, duration_s=1.0)
    out = habitsim.transfer(src, to="mydog", method="direct")
    assert out.species == "mydog" and out.num_frames == src.num_frames


def test_name_errors_leave_nothing(rig_file, made, tmp_path) -> None:
    with pytest.raises(SpeciesNameClashError) as e:
        species_from_clip(rig_file, "dog", catalog=tmp_path)
    assert e.value.name == "dog"
    with pytest.raises(SpeciesNameError):
        species_from_clip(rig_file, "My-Dog", catalog=tmp_path)
    with pytest.raises(SpeciesNameClashError):  # already in that user catalog
        species_from_clip(rig_file, "mydog", catalog=made.file.parent)
    assert _leftovers(tmp_path) == []


def test_clip_errors_are_typed(rig_file, tmp_path) -> None:
    short = SourceOptions(span=habitsim.source.Span(0.0, 0.1))
    with pytest.raises(ClipMeasureError) as e:
        species_from_clip(rig_file, "tiny", catalog=tmp_path, source=short)
    assert e.value.code == "short"
    no_legs = SourceOptions(joint_map={"pelvis": "Hips_jnt", "spine3": "Chest"}, up="z")
    with pytest.raises(ClipMeasureError) as e:
        species_from_clip(rig_file, "nolegs", catalog=tmp_path, source=no_legs)
    assert e.value.code == "legs"
    with pytest.raises(UnknownSpeciesError):
        species_from_clip(rig_file, "odd", catalog=tmp_path, like="nosuch")
    assert _leftovers(tmp_path) == []


def test_a_model_that_does_not_stand_writes_nothing(rig_file, tmp_path) -> None:
    strict = FromClipOptions(stand_height_share=0.99999, stand_upright_deg=1e-6)
    with pytest.raises(StandingError) as e:
        species_from_clip(rig_file, "wobbly", catalog=tmp_path, options=strict)
    assert not e.value.check.passed
    assert _leftovers(tmp_path) == []


def test_a_user_file_named_like_a_built_in_species_is_a_clash(made, tmp_path) -> None:
    text = made.file.read_text(encoding="utf-8").replace('name = "mydog"', 'name = "dog"')
    (tmp_path / "dog.toml").write_text(text, encoding="utf-8")
    with pytest.raises(SpeciesNameClashError) as e:
        user_species([tmp_path])
    assert e.value.name == "dog" and len(e.value.places) == 2


def test_command_line(rig_file, tmp_path, capsys) -> None:
    catalog = tmp_path / "cat"
    argv = ["species", "from-clip", str(rig_file), "--name", "clipdog", "--catalog", str(catalog)]
    assert main([*argv, "--mass", "20", "--json"]) == 0
    assert '"mass_kg": 20.0' in capsys.readouterr().out
    assert main(argv) == 2  # the name is taken now
    assert main([*argv[:4], "dog", *argv[5:]]) == 2
    assert _leftovers(catalog) == ["clipdog", "clipdog.toml"]


@pytest.mark.slow
def test_from_clip_is_byte_identical_across_runs_and_thread_counts(rig_file, tmp_path) -> None:
    """``habitsim species from-clip`` in processes whose BLAS and OpenMP start with 1 and
    2 threads writes the same species file and the same MJCF models, byte for byte."""
    import os
    import subprocess
    import sys

    trees = []
    for i, n in enumerate(["1", "2"]):
        catalog = tmp_path / f"c{i}"
        env = {**os.environ, "OMP_NUM_THREADS": n, "OPENBLAS_NUM_THREADS": n}
        argv = [sys.executable, "-m", "habitsim", "species", "from-clip", str(rig_file)]
        argv += ["--name", "clipdog", "--catalog", str(catalog)]
        subprocess.run(argv, env=env, check=True, timeout=300, capture_output=True)
        files = sorted(p for p in catalog.rglob("*") if p.is_file())
        trees.append({str(p.relative_to(catalog)): p.read_bytes() for p in files})
    assert "clipdog.toml" in trees[0] and any(k.endswith(".xml") for k in trees[0])
    assert trees[0] == trees[1]
