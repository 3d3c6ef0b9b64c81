"""The shipped frozen evaluator: loading, invariances, accuracy floors, checkpoints."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest
from helpers import UNWRITABLE, _typed_output_error

from habitsim.dataset import build_dataset, iter_clips
from habitsim.errors import OutputPathError
from habitsim.evaluation.evaluator import (
    DEFAULT_EVALUATOR_DIR,
    EvaluatorConfig,
    EvaluatorError,
    canonical_heading,
    evaluator_input,
    load_evaluator,
    resample_motion,
    train_evaluator,
)
from habitsim.motion import Motion
from habitsim.rotations import quat_mul

#: Accuracy floors on clips the evaluator never saw (README of the shipped evaluator
#: lists the figures measured at training time: 1.00 / 0.98 on its test split).
SPECIES_FLOOR = 0.9
ACTION_FLOOR = 0.85
HELD_OUT_ACTION_FLOOR = 0.8


@pytest.fixture(scope="module")
def fresh_data(tmp_path_factory) -> Path:
    """Seed 1: no clip of it was in the evaluator's (seed 0) training split."""
    out = tmp_path_factory.mktemp("ev_data")
    build_dataset(out, clips_per_species=5, seed=1, workers=1, progress=False)
    return out


def test_shipped_files_and_config() -> None:
    for name in ("model.safetensors", "config.json", "README.md"):
        assert (DEFAULT_EVALUATOR_DIR / name).is_file()
    ev = load_evaluator()
    assert ev.feature_dim == ev.config.feature_dim == 32
    assert "horse" in ev.config.species and "giraffe" not in ev.config.species
    meta = json.loads((DEFAULT_EVALUATOR_DIR / "config.json").read_text())
    assert meta["accuracy"]["test"]["species"] >= SPECIES_FLOOR


@pytest.mark.slow
def test_accuracy_on_unseen_clips_above_floor(fresh_data: Path) -> None:
    ev = load_evaluator()
    motions, sp, ac, held = [], [], [], []
    for entry, m in iter_clips(fresh_data):
        motions.append(m)
        sp.append(entry.species)
        ac.append(entry.action)
        held.append(entry.held_out)
    p = ev.predict(motions)
    seen = [i for i, h in enumerate(held) if not h]
    unseen_sp = [i for i, h in enumerate(held) if h]
    species_acc = np.mean([p.species[i] == sp[i] for i in seen])
    action_acc = np.mean([p.actions[i] == ac[i] for i in seen])
    held_action_acc = np.mean([p.actions[i] == ac[i] for i in unseen_sp])
    assert species_acc >= SPECIES_FLOOR, species_acc
    assert action_acc >= ACTION_FLOOR, action_acc
    assert held_action_acc >= HELD_OUT_ACTION_FLOOR, held_action_acc
    assert p.features.shape == (len(motions), 32) and np.all(np.isfinite(p.features))


def test_features_ignore_heading_and_are_deterministic(habitsim_clip) -> None:
    m = habitsim_clip("dog", "turn_left", seed=4)
    yaw = 1.1
    qz = np.array([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])
    rot = np.array(
        [[math.cos(yaw), -math.sin(yaw), 0], [math.sin(yaw), math.cos(yaw), 0], [0, 0, 1]]
    )
    q = m.rotations.copy()
    q[:, 0] = quat_mul(np.broadcast_to(qz, q[:, 0].shape), q[:, 0])
    turned = Motion(m.species, m.fps, m.root_positions @ rot.T + [3.0, -2.0, 0.0], q)
    ev = load_evaluator()
    a, b = ev.features([m, turned])
    assert np.allclose(a, b, atol=1e-4)
    assert np.array_equal(ev.features([m])[0], ev.features([m])[0])
    c = canonical_heading(turned)
    assert np.allclose(c.root_positions[0, :2], 0.0)


def test_resample_keeps_duration(habitsim_clip) -> None:
    m = habitsim_clip("cat", "walk", seed=0)
    r = resample_motion(m, 60.0)
    assert r.fps == 60.0 and abs(r.duration - m.duration) <= 1.0 / 30.0
    assert evaluator_input(r).shape[0] == evaluator_input(m).shape[0]


def test_corrupt_or_mismatched_checkpoints_are_rejected(tmp_path: Path) -> None:
    bad = tmp_path / "bad"
    shutil.copytree(DEFAULT_EVALUATOR_DIR, bad)
    (bad / "model.safetensors").write_bytes(b"not a safetensors file")
    with pytest.raises(EvaluatorError, match="safetensors"):
        load_evaluator(bad)
    wrong = tmp_path / "wrong"
    shutil.copytree(DEFAULT_EVALUATOR_DIR, wrong)
    meta = json.loads((wrong / "config.json").read_text())
    meta["config"]["feature_dim"] = 16
    (wrong / "config.json").write_text(json.dumps(meta))
    with pytest.raises(EvaluatorError, match="does not fit"):
        load_evaluator(wrong)
    with pytest.raises(EvaluatorError, match="config.json"):
        load_evaluator(tmp_path / "missing")
    with pytest.raises(EvaluatorError, match="divisible"):
        EvaluatorConfig(d_model=30, n_heads=4)


@pytest.mark.slow
def test_train_evaluator_writes_a_loadable_checkpoint(tmp_path: Path) -> None:
    data = tmp_path / "d"
    build_dataset(
        data, clips_per_species=4, seed=0, species=["horse", "cat"], workers=1, progress=False
    )
    cfg = EvaluatorConfig(
        epochs=1, crops_per_clip=1, d_model=16, n_heads=2, ff_dim=16, feature_dim=8
    )
    rep = train_evaluator(data, tmp_path / "ev", cfg, progress=False, log=None)
    assert set(rep.accuracy) >= {"train"} and len(rep.losses) == 1
    # same seed, same data ⇒ the same weights
    from safetensors.numpy import load_file

    train_evaluator(data, tmp_path / "ev2", cfg, progress=False, log=None)
    a = load_file(str(tmp_path / "ev" / "model.safetensors"))
    b = load_file(str(tmp_path / "ev2" / "model.safetensors"))
    assert a.keys() == b.keys()
    for k in a:
        np.testing.assert_array_equal(a[k], b[k])
    ev = load_evaluator(tmp_path / "ev")
    assert ev.config.species == ("cat", "horse") and ev.feature_dim == 8
    assert "| train" in (tmp_path / "ev" / "README.md").read_text()


def test_every_public_name_of_the_evaluation_package_resolves() -> None:
    import habitsim.evaluation as ev_pkg

    for name in ev_pkg.__all__:
        assert getattr(ev_pkg, name) is not None, name
    with pytest.raises(AttributeError):
        ev_pkg.no_such_name  # noqa: B018


@pytest.mark.parametrize("unwritable", UNWRITABLE, indirect=True)
def test_evaluator_unwritable(unwritable: Path, small_dataset: Path) -> None:
    from habitsim.evaluation.evaluator import load_evaluator, save_evaluator, train_evaluator

    calls = []
    with pytest.raises(OutputPathError) as ei:  # refused before training
        train_evaluator(small_dataset, unwritable / "e", progress=False, log=calls.append)
    _typed_output_error(ei.value)
    assert calls == []
    ev = load_evaluator()
    with pytest.raises(OutputPathError) as ei:
        save_evaluator(
            ev.model,
            unwritable / "e",
            accuracy={},
            data_dir=small_dataset,
            seed=0,
            clips_per_species=1,
            wall_time_s=0.0,
            final_loss=0.0,
        )
    _typed_output_error(ei.value)
    assert not unwritable.exists()


def test_evaluator_config_out_of_bounds_is_typed(tmp_path: Path) -> None:
    (tmp_path / "config.json").write_text('{"kind": "habitsim.evaluator", "x": ' + "9" * 5000 + "}")
    with pytest.raises(EvaluatorError):
        load_evaluator(tmp_path)
