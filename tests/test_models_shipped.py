"""The shipped ``habit`` checkpoint, the transfer API and the ``train`` / ``transfer`` CLI."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from habitsim.cli import main
from habitsim.gaits import generate
from habitsim.models import (
    load_model,
    reconstruction_error,
    shipped_checkpoint,
)
from habitsim.models.checkpoint import MODEL_FILE
from habitsim.models.evaluate import REFERENCE_CLIPS, reference_motions
from habitsim.motion import load_motion

SHIPPED = shipped_checkpoint("habit")
needs_ckpt = pytest.mark.skipif(
    SHIPPED is None, reason="no shipped habit checkpoint in this checkout"
)


pytestmark = pytest.mark.usefixtures("torch_one_thread")


@pytest.fixture(scope="module")
def trot():
    return generate("horse", "trot", seed=5, duration_s=3.0)


@needs_ckpt
def test_shipped_checkpoint_size_and_config():
    size = (SHIPPED / MODEL_FILE).stat().st_size
    assert size <= 30e6
    doc = json.loads((SHIPPED / "config.json").read_text())
    # the large preset, then two fine-tunes (the checkpoint's recipe names every stage)
    assert doc["config"]["name"].endswith("large") and doc["config"]["model"]["variant"] == "habit"
    m = doc["config"]["model"]
    assert m["path_condition"] and m["path_heading"] and m["heading_relative"]
    stages = doc["recipe"]["stages"]
    assert [st["steps"] for st in stages] == [12000, 3000, 3000]
    assert sum(st["wall_time_s"] for st in stages) == doc["recipe"]["wall_time_s"] <= 2.5 * 3600
    q = doc["config"]["model"]["quantizer"]
    assert (q["num_codes"], q["code_dim"], q["levels"]) == (512, 512, 4)
    assert doc["training"]["step"] == doc["config"]["train"]["steps"]  # trained to the end
    assert not (SHIPPED / "train_state.safetensors").exists()  # shipped without optimiser state


@needs_ckpt
def test_shipped_checkpoint_reproduces_recorded_reconstruction_error():
    ck = load_model()
    rec = ck.metrics["reference"]
    assert [tuple(c) for c in rec["clips"]] == [tuple(c) for c in REFERENCE_CLIPS]
    res = reconstruction_error(reference_motions())
    assert res["mpjpe_mm"] == pytest.approx(rec["mpjpe_mm"], rel=1e-3, abs=0.05)
    assert res["pct_leg"] == pytest.approx(rec["pct_leg"], rel=1e-3, abs=0.01)


@needs_ckpt
def test_transfer_cli(tmp_path, capsys, trot):
    src = tmp_path / "trot.npz"
    trot.save(src)
    out = tmp_path / "zebra.npz"
    bvh = tmp_path / "zebra.bvh"
    assert (
        main(
            [
                "transfer",
                str(src),
                "--to",
                "zebra",
                "--out",
                str(out),
                "--bvh",
                str(bvh),
                "--seed",
                "2",
            ]
        )
        == 0
    )
    text = capsys.readouterr().out
    assert "borrowing the habit latent of horse" in text and "zebra" in text
    m = load_motion(out)
    assert m.species == "zebra" and bvh.is_file()
    # the shipped model slopes a zebra's trunk (its legs are not the horse's): levelled,
    # and said with its pitch
    lv = m.metadata["transfer"].get("levelled")
    assert lv is not None and lv["pitch_deg"] < 0.0
    assert f"trunk pitched {lv['pitch_deg']:+.1f}°" in text
    assert main(["transfer", str(src), "--to", "cat", "--out", str(tmp_path / "x.txt")]) == 2
    assert main(["transfer", str(src), "--to", "cat", "--out", str(out), "--method", "nope"]) == 2
    assert "valid: habit" in capsys.readouterr().err
    assert main(["transfer", "--list-methods"]) == 0
    assert "direct" in capsys.readouterr().out


def test_transfer_cli_bvh_example_with_action(tmp_path, capsys):
    from importlib import resources

    from habitsim.species import load_species

    bvh = str(resources.files("habitsim.examples") / "dog_walk.bvh")
    out = tmp_path / "cat.npz"
    args = ["transfer", bvh, "--from", "dog", "--to", "cat", "--out", str(out)]
    assert main([*args, "--action", "walk"]) == 0
    m = load_motion(out)
    assert m.species == "cat" and m.num_frames == 120 and m.metadata["action"] == "walk"
    # every foot gets stance phases, at least half the cat's walking duty factor
    duty = float(np.mean(load_species("cat").gaits["walk"].duty_factor))
    assert np.all(m.contacts.mean(axis=0) >= 0.5 * duty - 1e-9)
    assert main([*args, "--action", "moonwalk"]) == 2
    assert "valid: " in capsys.readouterr().err


@pytest.mark.slow
def test_train_cli_small(tmp_path, capsys):
    from habitsim.dataset import build_dataset

    data = tmp_path / "data"
    build_dataset(
        data, clips_per_species=4, seed=1, species=["cat", "dog"], workers=1, progress=False
    )
    ck = tmp_path / "ck"
    args = [
        "train",
        "--data",
        str(data),
        "--out",
        str(ck),
        "--config",
        "small",
        "--steps",
        "2",
        "--no-progress",
        "--set",
        "train.val_every=1",
        "--set",
        "model.net.width=16",
    ]
    assert main(args) == 0
    out = capsys.readouterr().out
    assert "reference clips: reconstruction MPJPE" in out
    doc = json.loads((ck / "config.json").read_text())
    assert doc["config"]["name"] == "small" and doc["training"]["step"] == 2
    assert "reference" in doc["metrics"] and doc["text"]["model"] == "all-MiniLM-L6-v2"
    assert main(args) == 2  # refuses to overwrite
    assert "--resume" in capsys.readouterr().err
    assert (
        main(
            args[:-4]
            + [
                "--resume",
                "--steps",
                "3",
                "--set",
                "train.val_every=1",
                "--set",
                "model.net.width=16",
            ]
        )
        == 0
    )
    assert json.loads((ck / "config.json").read_text())["training"]["step"] == 3


@needs_ckpt
def test_a_posture_the_training_rigs_never_took_does_not_stop_the_decoded_gait():
    """A real rig holds its third spine and second tail joints in postures the synthetic
    training rigs never take (their rotation spread sits at the 0.01 floor). Bent 25° there,
    a dog trot still decodes as a trot because the encoders clip rotation inputs to
    ± ROTATION_INPUT_CLIP σ: its legs swing about the pelvis nearly as fast as unbent;
    unclipped, the same input decodes to legs that barely move (measured: toe speed about
    the pelvis 4.41 leg lengths/s unbent, 4.30 bent, 1.35 unclipped; the body's Froude
    number 1.46, 1.35, 0.82). Leg motion, not the body's speed, is what the test reads: a
    decoder conditioned on the source's path (``model.path_condition``) keeps the speed
    even when it loses the gait (path-conditioned model: 4.31, 4.14, 1.27 leg lengths/s at
    Froude 1.45, 1.45, 1.44)."""
    import copy
    import dataclasses
    import importlib

    from habitsim.motion import Motion
    from habitsim.rotations import quat_mul
    from habitsim.skeleton import JOINT_NAMES

    tr = importlib.import_module("habitsim.models.transfer")
    ck = load_model()
    dog = generate("dog", "trot", seed=5, duration_s=3.0)
    q = dog.rotations.copy()
    bend = np.array([np.cos(np.deg2rad(12.5)), 0.0, np.sin(np.deg2rad(12.5)), 0.0])
    for name in ("spine3", "tail2"):
        j = JOINT_NAMES.index(name)
        q[:, j] = quat_mul(np.broadcast_to(bend, q[:, j].shape), q[:, j])
    bent = Motion(dog.species, dog.fps, dog.root_positions, q, dog.contacts, dict(dog.metadata))

    def froude(m: Motion) -> float:
        v = np.linalg.norm(np.diff(m.root_positions[:, :2], axis=0), axis=1).mean() * m.fps
        return float(v * v / 9.81 / m.species_info.leg_length)

    def limbs(m: Motion) -> float:  # mean toe speed about the pelvis [leg lengths / s]
        p = m.foot_positions() - m.root_positions[:, None]
        step = np.linalg.norm(np.diff(p, axis=0), axis=-1).mean()
        return float(step * m.fps / m.species_info.leg_length)

    def decoded(m: Motion) -> Motion:
        return tr._run_network(ck, m, "dog", seed=0, temperature=1.0)[0]

    plain = decoded(dog)
    assert froude(plain) == pytest.approx(froude(dog), rel=0.1)
    assert limbs(plain) == pytest.approx(limbs(dog), rel=0.2)
    assert limbs(decoded(bent)) > 0.85 * limbs(plain)
    unclipped = dataclasses.replace(ck, model=copy.deepcopy(ck.model))
    unclipped.model.rotation_input_clip = float("inf")
    moved = tr._run_network(unclipped, bent, "dog", seed=0, temperature=1.0)[0]
    assert limbs(moved) < 0.5 * limbs(plain)  # the failure the clip prevents


@needs_ckpt
def test_the_large_preset_trains_the_shipped_models_configuration():
    """What ``habitsim train --config large`` writes as its last stage is the shipped
    checkpoint's configuration, model and schedule (only the thread count may differ)."""
    import dataclasses

    from habitsim.models.config import Config, preset
    from habitsim.models.recipe import RECIPES, stage_configs

    doc = json.loads((SHIPPED / "config.json").read_text())
    shipped = Config.from_dict(doc["config"])
    last = stage_configs(preset("large"), RECIPES["large"])[-1]
    assert last.model == shipped.model
    assert dataclasses.replace(last.train, threads=None) == dataclasses.replace(
        shipped.train, threads=None
    )
    assert [st.steps or 12000 for st in RECIPES["large"]] == [
        st["steps"] for st in doc["recipe"]["stages"]
    ]


@pytest.mark.slow
def test_train_cli_staged_large_and_single_run(tmp_path, capsys, monkeypatch):
    """``--config large`` runs the preset's stages (here shortened to one step each) into
    CKPT/stages/ and CKPT, prints every stage and records the recipe; ``--single-run``
    trains the final model in one run; a clashing ``--set`` is refused before training."""
    from habitsim.dataset import build_dataset
    from habitsim.models import recipe

    short = tuple(dataclasses.replace(st, steps=1) for st in recipe.RECIPES["large"])
    monkeypatch.setitem(recipe.RECIPES, "large", short)
    data = tmp_path / "data"
    build_dataset(
        data, clips_per_species=3, seed=1, species=["cat", "dog"], workers=1, progress=False
    )
    small = ["--no-progress", "--threads", "1"] + [
        a
        for kv in (
            "model.net.width=16",
            "model.quantizer.num_codes=16",
            "model.quantizer.code_dim=16",
            "train.batch_size=2",
            "train.warmup_steps=0",
        )
        for a in ("--set", kv)
    ]
    ck = tmp_path / "ck"
    base = ["train", "--data", str(data), "--config", "large"]
    assert main([*base, "--out", str(ck), *small]) == 0
    out = capsys.readouterr().out
    assert "3 stages, 3 steps" in out and "stages/2-heading" in out
    doc = json.loads((ck / "config.json").read_text())
    assert (
        doc["config"]["model"]["heading_relative"]
        and doc["config"]["name"] == "large:heading-relative"
    )
    assert [st["name"] for st in doc["recipe"]["stages"]] == ["path", "heading", "heading-relative"]
    assert "reference" in doc["metrics"]
    assert (ck / "stages" / "1-path" / "model.safetensors").is_file()
    assert main([*base, "--out", str(ck), *small]) == 2  # refuses to overwrite
    assert "--resume" in capsys.readouterr().err
    one = tmp_path / "one"
    assert main([*base, "--out", str(one), "--single-run", "--steps", "1", *small]) == 0
    m = json.loads((one / "config.json").read_text())["config"]["model"]
    assert m["path_condition"] and m["path_heading"] and m["heading_relative"]
    assert not (one / "stages").exists()
    capsys.readouterr()
    bad = [*base, "--out", str(tmp_path / "bad"), "--set", "model.path_heading=false", *small]
    assert main(bad) == 2
    assert "--single-run" in capsys.readouterr().err and not (tmp_path / "bad").exists()
