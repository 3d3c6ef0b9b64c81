"""Training, determinism, resuming and checkpoint validation of the learning core."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch
from helpers import UNWRITABLE, _typed_output_error

from habitsim.dataset import build_dataset
from habitsim.errors import HabitsimError, OutputPathError
from habitsim.gaits import generate
from habitsim.models.checkpoint import MODEL_FILE, load_checkpoint, save_checkpoint
from habitsim.models.config import preset
from habitsim.models.data import ClipSet, WindowSampler, feature_stats, speed_variant
from habitsim.models.errors import CheckpointError, TrainingDataError
from habitsim.models.features import (
    C_INDEX,
    FEAT_DIM,
    Q_DIM,
    canonical_window,
    clip_arrays,
    window_positions,
)
from habitsim.models.train import (
    _contact_loss,
    _stance_loss,
    build_untrained,
    compute_losses,
    train,
)
from habitsim.species import load_species, species_names

SPECIES = ("cat", "dog", "horse")


pytestmark = pytest.mark.usefixtures("torch_one_thread")


def _fake_text(dim: int = 16) -> dict[str, np.ndarray]:
    return {
        n: np.random.default_rng(i).standard_normal(dim).astype(np.float32)
        for i, n in enumerate(species_names())
    }


def _tiny_config(steps: int = 6, **changes):
    cfg = preset("small").replace(
        **{
            "model.window": 16,
            "model.net.width": 16,
            "model.quantizer.num_codes": 16,
            "model.quantizer.code_dim": 8,
            "model.habit.d_model": 8,
            "model.habit.ff": 16,
            "model.text.proj_dim": 8,
            "train.steps": steps,
            "train.batch_size": 4,
            "train.val_every": 3,
            "train.checkpoint_every": 3,
            "train.warmup_steps": 0,
            "train.position_weight": 0.5,
        }
    )
    return cfg.replace(**changes) if changes else cfg


def _tiny_clipset() -> ClipSet:
    clips, keys, acts = [], [], []
    for sp in SPECIES:
        for k, a in enumerate(("walk", "trot")):
            clips.append(clip_arrays(generate(sp, a, seed=10 + k, duration_s=1.2)))
            keys.append(f"{a}:{10 + k}")
            acts.append(a)
    return ClipSet(clips, keys, acts, 30.0)


@pytest.fixture(scope="module")
def tiny_data(tmp_path_factory):
    out = tmp_path_factory.mktemp("models") / "data"
    build_dataset(
        out, clips_per_species=10, seed=3, species=list(SPECIES), workers=1, progress=False
    )
    return out


@pytest.mark.slow
def test_loss_falls_on_a_tiny_set():
    cfg = _tiny_config().replace(**{"train.lr": 1e-2, "model.net.width": 32})
    data = _tiny_clipset()
    model = build_untrained(cfg, list(SPECIES), _fake_text(), feature_stats(data, cfg.model.window))
    sampler = WindowSampler(data, cfg.model.window, np.random.default_rng(0))
    batch = sampler.sample(8)  # the same batch every step: the loss must fall
    opt = torch.optim.AdamW(model.parameters(), lr=cfg.train.lr)
    gen = torch.Generator().manual_seed(0)
    losses = []
    for _ in range(80):
        loss, logs = compute_losses(model, batch, cfg, gen, 30.0)
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(logs["rec_q"] + logs["rec_v"])
    assert batch.pair_x.shape[0] > 0  # the paired term was exercised
    assert np.mean(losses[-5:]) < 0.6 * np.mean(losses[:5])


def test_total_loss_is_the_sum_of_its_parts():
    cfg = _tiny_config()
    data = _tiny_clipset()
    model = build_untrained(cfg, list(SPECIES), _fake_text(), feature_stats(data, cfg.model.window))
    batch = WindowSampler(data, cfg.model.window, np.random.default_rng(1)).sample(6)
    _, logs = compute_losses(model, batch, cfg, torch.Generator().manual_seed(0), 30.0)
    t = cfg.train
    total = (
        logs["rec_q"]
        + t.alpha * logs["rec_v"]
        + t.beta * logs["commit"]
        + t.kl_weight * logs["kl"]
        + t.position_weight * logs["pos"]
        + t.contact_weight * logs["contact"]
        + t.stance_weight * logs["stance"]
        + t.paired_weight * logs["paired"]
    )
    assert logs["loss"] == pytest.approx(total, rel=1e-5)
    assert logs["contact"] > 0 and logs["stance"] > 0  # an untrained decoder: both terms live


def test_position_loss_separates_root_path_from_pose():
    from habitsim.models.features import Q_DIM, canonical_window, clip_arrays
    from habitsim.models.train import _position_loss

    m = generate("dog", "trot", seed=2, duration_s=1.5)
    x = torch.from_numpy(canonical_window(clip_arrays(m), 0, 32)[0]).double()[None]
    valid = torch.ones(1, 32, dtype=torch.bool)
    assert float(_position_loss(x, x, valid, ["dog"], 30.0, 0.05)[0]) == 0.0
    # a root-velocity bias moves the path only: the loss is the pelvis path's error alone
    drift = x.clone()
    drift[..., Q_DIM] += 0.1  # Froude units, forward
    h = load_species("dog").hip_height
    err = 0.1 * math.sqrt(9.81 * h) / 30.0 * torch.arange(32.0).double() / h  # [hip heights]
    sl1 = torch.where(err < 0.05, 0.5 * err**2 / 0.05, err - 0.025)
    expect = float((sl1 / 3.0).mean())  # mean over x, y, z of the pelvis; y, z exact
    got = float(_position_loss(drift, x, valid, ["dog"], 30.0, 0.05)[0])
    assert got == pytest.approx(expect, rel=1e-6)


def test_root_velocity_weight_adds_the_pelvis_channels_term():
    from habitsim.models.features import H_INDEX, Q_DIM
    from habitsim.models.train import _recon_terms

    g = torch.Generator().manual_seed(0)
    target = torch.randn(2, 8, H_INDEX + 1, generator=g, dtype=torch.float64)
    valid = torch.ones(2, 8, dtype=torch.bool)
    pelvis = target.clone()
    pelvis[..., Q_DIM : Q_DIM + 3] += 1.0  # error on the pelvis velocity only
    other = target.clone()
    other[..., Q_DIM + 3 : Q_DIM + 6] += 1.0  # the same error on another joint's velocity
    base, heavy = _tiny_config(), _tiny_config(**{"train.root_velocity_weight": 2.0})
    lv_base = float(_recon_terms(pelvis, target, valid, base)[1])
    lv_heavy = float(_recon_terms(pelvis, target, valid, heavy)[1])
    # smooth-L1 of 1.0 at beta 0.05 is 0.975 per channel; the extra term averages 3 channels
    assert lv_heavy - lv_base == pytest.approx(2.0 * (1.0 - 0.025), rel=1e-9)
    assert float(_recon_terms(other, target, valid, heavy)[1]) == pytest.approx(
        float(_recon_terms(other, target, valid, base)[1]), rel=1e-12
    )


def test_learning_rate_schedules():
    from habitsim.models.errors import ConfigError
    from habitsim.models.train import lr_at

    step_cfg = _tiny_config(
        steps=100, **{"train.lr": 1e-3, "train.lr_final": 1e-5, "train.warmup_steps": 10}
    )
    assert lr_at(0, step_cfg) == pytest.approx(1e-4)  # warm-up
    assert lr_at(79, step_cfg) == 1e-3 and lr_at(80, step_cfg) == 1e-5  # lr_drop = 0.8
    cos = step_cfg.replace(**{"train.lr_schedule": "cosine"})
    rates = [lr_at(i, cos) for i in range(100)]
    assert rates[10] == pytest.approx(1e-3) and rates[99] == pytest.approx(1e-5)
    assert rates[:10] == [lr_at(i, step_cfg) for i in range(10)]  # same warm-up
    assert all(a >= b for a, b in zip(rates[10:], rates[11:], strict=False))  # falls monotonically
    assert rates[54] == pytest.approx(0.5 * (1e-3 + 1e-5), rel=0.02)  # half-way: the mean
    with pytest.raises(ConfigError, match="lr_schedule must be one of step, cosine"):
        step_cfg.replace(**{"train.lr_schedule": "linear"}).validate()


@pytest.mark.slow
def test_same_seed_same_weights_and_resume(tiny_data, tmp_path):
    text = _fake_text()
    cfg = _tiny_config(steps=6)
    a = train(
        tiny_data, tmp_path / "a", cfg, progress=False, log=lambda s: None, text_embeddings=text
    )
    b = train(
        tiny_data, tmp_path / "b", cfg, progress=False, log=lambda s: None, text_embeddings=text
    )
    wa = load_checkpoint(a.out_dir).model.state_dict()
    wb = load_checkpoint(b.out_dir).model.state_dict()
    assert all(torch.equal(wa[k], wb[k]) for k in wa)
    c = train(
        tiny_data,
        tmp_path / "c",
        cfg.replace(**{"train.seed": 1}),
        progress=False,
        log=lambda s: None,
        text_embeddings=text,
    )
    wc = load_checkpoint(c.out_dir).model.state_dict()
    assert not all(torch.equal(wa[k], wc[k]) for k in wa)
    # 3 steps, then resume to 6 == 6 straight steps
    train(
        tiny_data,
        tmp_path / "r",
        cfg.replace(**{"train.steps": 3}),
        progress=False,
        log=lambda s: None,
        text_embeddings=text,
    )
    r = train(
        tiny_data,
        tmp_path / "r",
        cfg,
        resume=True,
        progress=False,
        log=lambda s: None,
        text_embeddings=text,
    )
    assert r.steps == 6
    wr = load_checkpoint(r.out_dir).model.state_dict()
    for k in wa:
        torch.testing.assert_close(wr[k], wa[k], atol=1e-6, rtol=1e-5)
    doc = json.loads((a.out_dir / "config.json").read_text())
    assert [h["step"] for h in doc["training"]["history"]] == [3, 6]
    assert "val_mpjpe_mm" in doc["training"]["history"][-1]
    # an existing checkpoint is never silently replaced
    with pytest.raises(CheckpointError, match="--resume"):
        train(
            tiny_data, tmp_path / "a", cfg, progress=False, log=lambda s: None, text_embeddings=text
        )
    # resuming with another model is refused
    with pytest.raises(CheckpointError, match="cannot resume"):
        train(
            tiny_data,
            tmp_path / "a",
            cfg.replace(**{"model.net.width": 8}),
            resume=True,
            progress=False,
            log=lambda s: None,
            text_embeddings=text,
        )


def test_training_needs_training_species(tmp_path):
    out = tmp_path / "held"
    build_dataset(out, clips_per_species=2, seed=0, species=["tiger"], workers=1, progress=False)
    with pytest.raises(TrainingDataError):
        train(
            out,
            tmp_path / "ck",
            _tiny_config(),
            progress=False,
            log=lambda s: None,
            text_embeddings=_fake_text(),
        )


# ---------------------------------------------------------------------------- checkpoints


@pytest.fixture()
def saved(tmp_path):
    cfg = _tiny_config()
    data = _tiny_clipset()
    model = build_untrained(cfg, list(SPECIES), _fake_text(), feature_stats(data, cfg.model.window))
    out = save_checkpoint(tmp_path / "ck", model, cfg, {"fps": 30.0, "text": {"model": "custom"}})
    return out, model


def test_checkpoint_round_trip(saved):
    path, model = saved
    ck = load_checkpoint(path)
    sd = model.state_dict()
    assert all(torch.equal(ck.model.state_dict()[k], sd[k]) for k in sd)
    assert ck.fps == 30.0 and list(ck.model.species) == list(SPECIES)
    assert not ck.model.training


def test_corrupt_checkpoint_is_rejected(saved, tmp_path):
    path, _ = saved
    f = path / MODEL_FILE
    data = bytearray(f.read_bytes())
    data[len(data) // 2] ^= 0xFF
    f.write_bytes(bytes(data))
    with pytest.raises(CheckpointError, match="corrupt.*SHA-256"):
        load_checkpoint(path)
    f.write_bytes(b"not a safetensors file")
    with pytest.raises(CheckpointError, match="not a readable safetensors"):
        load_checkpoint(path, verify=False)
    assert issubclass(CheckpointError, HabitsimError)


def test_checkpoint_config_mismatch_is_rejected(saved):
    path, _ = saved
    doc = json.loads((path / "config.json").read_text())
    doc["config"]["model"]["net"]["width"] = 24
    (path / "config.json").write_text(json.dumps(doc))
    with pytest.raises(
        CheckpointError, match="does not match config.json.*shape mismatch.*encoder"
    ):
        load_checkpoint(path)


def test_checkpoint_species_mismatch_is_rejected(saved):
    path, _ = saved
    doc = json.loads((path / "config.json").read_text())
    doc["species"] = ["cat", "dog"]
    (path / "config.json").write_text(json.dumps(doc))
    with pytest.raises(CheckpointError, match="unexpected tensors.*horse"):
        load_checkpoint(path)


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda d: d.update(format_version=99), "format_version 99"),
        (lambda d: d.update(format="something.else"), "not a habitsim model checkpoint"),
        (lambda d: d["config"]["model"].update(variant="best"), "unknown variant"),
        (lambda d: d.pop("species"), "missing key 'species'"),
        (lambda d: d.update(species=["unicorn"]), "unicorn"),
        (lambda d: d.pop("feature_version"), "motion feature version 1.*retrain"),
        (lambda d: d.update(feature_version=7), "motion feature version 7"),
    ],
)
def test_bad_checkpoint_config_is_rejected(saved, edit, message):
    path, _ = saved
    doc = json.loads((path / "config.json").read_text())
    edit(doc)
    (path / "config.json").write_text(json.dumps(doc))
    with pytest.raises(CheckpointError, match=message):
        load_checkpoint(path)


def test_missing_files_are_named(saved, tmp_path):
    path, _ = saved
    with pytest.raises(CheckpointError, match="no such checkpoint folder"):
        load_checkpoint(tmp_path / "nowhere")
    other = tmp_path / "copy"
    shutil.copytree(path, other)
    (other / MODEL_FILE).unlink()
    with pytest.raises(CheckpointError, match="missing model.safetensors"):
        load_checkpoint(other)
    (other / "config.json").write_text("{not json")
    with pytest.raises(CheckpointError, match="not valid JSON"):
        load_checkpoint(other)
    (other / "config.json").unlink()
    with pytest.raises(CheckpointError, match="missing config.json"):
        load_checkpoint(other)


@pytest.mark.slow
def test_export_drops_training_state(tiny_data, tmp_path):
    from habitsim.models.checkpoint import export_checkpoint

    cfg = _tiny_config(steps=3)
    r = train(
        tiny_data,
        tmp_path / "ck",
        cfg,
        progress=False,
        log=lambda s: None,
        text_embeddings=_fake_text(),
    )
    assert (r.out_dir / "train_state.safetensors").is_file()
    out = export_checkpoint(r.out_dir, tmp_path / "shipped", {"note": "x"})
    assert sorted(p.name for p in out.iterdir()) == ["config.json", "model.safetensors"]
    doc = json.loads((out / "config.json").read_text())
    assert list(doc["files"]) == ["model.safetensors"] and doc["note"] == "x"
    with pytest.raises(CheckpointError, match="no training state"):
        train(
            tiny_data,
            out,
            cfg.replace(**{"train.steps": 4}),
            resume=True,
            progress=False,
            log=lambda s: None,
            text_embeddings=_fake_text(),
        )


@pytest.mark.slow
def test_fine_tune_starts_from_the_checkpoint(tiny_data, tmp_path):
    text = _fake_text()
    cfg = _tiny_config(steps=3)
    base = train(
        tiny_data, tmp_path / "base", cfg, progress=False, log=lambda s: None, text_embeddings=text
    )
    w0 = load_checkpoint(base.out_dir).model.state_dict()
    ft_cfg = cfg.replace(**{"train.steps": 1, "train.lr": 1e-9, "train.lr_final": 1e-9})
    ft = train(
        tiny_data, tmp_path / "ft", ft_cfg, progress=False, log=lambda s: None, init=base.out_dir
    )
    ck = load_checkpoint(ft.out_dir)
    w1 = ck.model.state_dict()
    enc = [k for k in w0 if k.startswith("encoder.")]
    # one step at a negligible rate: the weights are the base's, not a fresh draw
    assert max(float((w1[k] - w0[k]).abs().max()) for k in enc) < 1e-6
    torch.testing.assert_close(w1["feat_std"], w0["feat_std"])
    torch.testing.assert_close(w1["text_table"], w0["text_table"])
    doc = json.loads((ft.out_dir / "config.json").read_text())
    assert doc["init"]["checkpoint"] == str(base.out_dir)
    with pytest.raises(CheckpointError, match="model configuration differs"):
        train(
            tiny_data,
            tmp_path / "bad",
            ft_cfg.replace(**{"model.net.width": 8}),
            progress=False,
            log=lambda s: None,
            init=base.out_dir,
        )


def test_fine_tune_adds_the_heading_to_a_path_conditioned_checkpoint(tiny_data, tmp_path):
    """``model.path_heading`` may be switched on when fine-tuning a path-conditioned
    checkpoint: the decoder's weights on the new heading channels start at zero, so on a
    path whose heading stays the window's the fine-tune starts from the base's decoder
    exactly; on a checkpoint without the path it stays refused."""
    text = _fake_text()
    cfg = _tiny_config(steps=3, **{"model.path_condition": True})
    base = train(
        tiny_data, tmp_path / "base", cfg, progress=False, log=lambda s: None, text_embeddings=text
    )
    b = load_checkpoint(base.out_dir).model
    ft_cfg = cfg.replace(
        **{
            "model.path_heading": True,
            "train.steps": 1,
            "train.lr": 1e-12,
            "train.lr_final": 1e-12,
            "train.input_noise": 0.0,
        }
    )
    ft = train(
        tiny_data, tmp_path / "ft", ft_cfg, progress=False, log=lambda s: None, init=base.out_dir
    )
    m = load_checkpoint(ft.out_dir).model
    assert m.cfg.path_heading and m.path_dim == b.path_dim + 2
    w = m.state_dict()["decoder.inp.weight"]
    c = cfg.model.quantizer.code_dim
    assert float(w[:, c + 2 : c + 4].abs().max()) < 1e-6  # the heading channels start at zero
    clip = generate("cat", "trot", seed=0, duration_s=1.0)
    x = torch.from_numpy(canonical_window(clip_arrays(clip), 0, cfg.model.window)[0][None])
    x[..., :4] = torch.tensor([1.0, 0.0, 0.0, 0.0])  # a heading that stays the window's
    with torch.no_grad():
        codes = b.quantize(b.encode(x), sample=False, update=False).quantized
        cond = b.condition(["cat"], b.posterior(x, ["cat"])[0])
        torch.testing.assert_close(
            m.decode(codes, cond, m.path(x)), b.decode(codes, cond, b.path(x)), atol=1e-4, rtol=0
        )
    plain = train(
        tiny_data,
        tmp_path / "plain",
        _tiny_config(steps=1),
        progress=False,
        log=lambda s: None,
        text_embeddings=text,
    )
    with pytest.raises(CheckpointError, match="model configuration differs"):
        train(
            tiny_data,
            tmp_path / "bad",
            ft_cfg,
            progress=False,
            log=lambda s: None,
            init=plain.out_dir,
        )


def test_clip_sets_add_up_and_the_sampler_follows_its_weights():
    a = _tiny_clipset()
    both = a + a
    assert len(both.clips) == 2 * len(a.clips) and both.pair_keys == a.pair_keys * 2
    with pytest.raises(TrainingDataError, match="cannot mix clips at 30 fps with clips at 60"):
        a + ClipSet(a.clips, a.pair_keys, a.actions, 60.0)

    # the horse's clips in a second set: all the weight on it, every window is a horse's
    def part(keep):
        idx = [i for i, c in enumerate(a.clips) if keep(c.species)]
        return ClipSet(
            [a.clips[i] for i in idx],
            [a.pair_keys[i] for i in idx],
            [a.actions[i] for i in idx],
            30.0,
        )

    first, second = part(lambda s: s != "horse"), part(lambda s: s == "horse")
    mixed = first + second
    for w_second, want in ((1.0, {"horse"}), (0.0, {"cat", "dog"})):
        w = np.r_[np.full(len(first.clips), 1.0 - w_second), np.full(len(second.clips), w_second)]
        sampler = WindowSampler(mixed, 16, np.random.default_rng(0), paired=False, weights=w)
        assert set(sampler.sample(24).species) == want


@pytest.mark.slow
def test_fine_tune_rehearses_a_second_data_set(tiny_data, tmp_path):
    """A fine-tune on one species' clips can mix in another data set's clips of the
    model's species; validation stays on the fine-tune data's own clips."""
    text = _fake_text()
    cfg = _tiny_config(steps=2)
    base = train(
        tiny_data, tmp_path / "base", cfg, progress=False, log=lambda s: None, text_embeddings=text
    )
    one = tmp_path / "one"
    build_dataset(
        one, clips_per_species=10, seed=4, species=[SPECIES[0]], workers=1, progress=False
    )
    ft_cfg = cfg.replace(**{"train.steps": 2})
    lines: list[str] = []
    ft = train(
        one,
        tmp_path / "ft",
        ft_cfg,
        progress=False,
        log=lines.append,
        init=base.out_dir,
        rehearse=tiny_data,
        rehearse_share=0.5,
    )
    doc = json.loads((ft.out_dir / "config.json").read_text())
    assert doc["data"]["rehearse"] == {"dir": str(tiny_data.resolve()), "share": 0.5}
    alone = train(
        one, tmp_path / "ft1", ft_cfg, progress=False, log=lambda s: None, init=base.out_dir
    )
    mixed_n = doc["data"]["train_clips"]
    alone_n = json.loads((alone.out_dir / "config.json").read_text())["data"]["train_clips"]
    assert mixed_n > alone_n  # the rehearsal set's clips were added
    assert f"of {len(SPECIES)} species" in lines[0]
    with pytest.raises(TrainingDataError, match=r"rehearse_share must be in \(0, 1\)"):
        train(
            one,
            tmp_path / "bad",
            ft_cfg,
            progress=False,
            log=lambda s: None,
            init=base.out_dir,
            rehearse=tiny_data,
            rehearse_share=1.0,
        )
    assert not (tmp_path / "bad").exists() or not any((tmp_path / "bad").iterdir())


def _tiny_stages():
    from habitsim.models.recipe import Stage

    return (
        Stage("path", {"model.path_condition": True}),
        Stage("heading", {"model.path_heading": True}, steps=2, lr=3e-4),
        Stage("heading-relative", {"model.heading_relative": True}, steps=2, lr=3e-4),
    )


@pytest.mark.slow
def test_a_staged_recipe_is_its_stages_trained_by_hand_and_resumes(tiny_data, tmp_path):
    """``train_staged`` gives the weights of the documented commands run one after the
    other (a fine-tune per stage from the previous checkpoint), records the recipe in the
    final checkpoint, resumes an interrupted stage, and refuses an existing run or an
    override of an option the recipe sets, before training anything."""
    from habitsim.cli.train_cmd import _finetune_config
    from habitsim.models.errors import ConfigError
    from habitsim.models.recipe import stage_configs, stage_folders, train_staged

    text = _fake_text()
    base = _tiny_config(steps=3)
    quiet = {"progress": False, "log": lambda s: None}
    res = train_staged(
        tiny_data, tmp_path / "staged", base, _tiny_stages(), text_embeddings=text, **quiet
    )
    # the same by hand: the preset with the path, then two fine-tunes of the previous stage
    a = train(
        tiny_data,
        tmp_path / "a",
        base.replace(**{"model.path_condition": True}),
        text_embeddings=text,
        **quiet,
    )
    b_cfg = _finetune_config(str(a.out_dir), base).replace(
        **{"model.path_heading": True, "train.steps": 2, "train.lr": 3e-4}
    )
    b = train(tiny_data, tmp_path / "b", b_cfg, init=a.out_dir, **quiet)
    c_cfg = _finetune_config(str(b.out_dir), base).replace(
        **{"model.heading_relative": True, "train.steps": 2, "train.lr": 3e-4}
    )
    c = train(tiny_data, tmp_path / "c", c_cfg, init=b.out_dir, **quiet)
    ws = load_checkpoint(res.out_dir).model.state_dict()
    wc = load_checkpoint(c.out_dir).model.state_dict()
    assert ws.keys() == wc.keys() and all(torch.equal(ws[k], wc[k]) for k in ws)
    final = load_checkpoint(res.out_dir).config.model
    assert final.path_condition and final.path_heading and final.heading_relative
    # the earlier stages are checkpoints of their own, the recipe is recorded
    folders = stage_folders(res.out_dir, _tiny_stages())
    assert folders[-1] == res.out_dir and all((f / "config.json").is_file() for f in folders)
    doc = json.loads((res.out_dir / "config.json").read_text())
    rec = doc["recipe"]
    assert [st["steps"] for st in rec["stages"]] == [3, 2, 2] and res.steps == 7
    assert [st["lr"] for st in rec["stages"]] == [base.train.lr, 3e-4, 3e-4]
    assert (
        rec["stages"][0]["checkpoint"] == "stages/1-path" and rec["stages"][-1]["checkpoint"] == "."
    )
    assert rec["wall_time_s"] == sum(st["wall_time_s"] for st in rec["stages"])
    assert doc["init"]["checkpoint"] == str(folders[1])
    # an existing run is refused before stage 1 trains again
    before = (folders[0] / MODEL_FILE).stat().st_mtime_ns
    with pytest.raises(CheckpointError, match="--resume"):
        train_staged(tiny_data, res.out_dir, base, _tiny_stages(), text_embeddings=text, **quiet)
    assert (folders[0] / MODEL_FILE).stat().st_mtime_ns == before
    with pytest.raises(ConfigError, match="model.path_heading.*--single-run"):
        stage_configs(base, _tiny_stages(), {"model.path_heading": False})
    # interrupted in stage 1 after one step, resumed: the uninterrupted run's weights
    r_out = tmp_path / "resumed"
    first = stage_configs(base, _tiny_stages())[0]
    train(
        tiny_data,
        stage_folders(r_out, _tiny_stages())[0],
        first.replace(**{"train.steps": 1}),
        text_embeddings=text,
        **quiet,
    )
    r = train_staged(
        tiny_data, r_out, base, _tiny_stages(), text_embeddings=text, resume=True, **quiet
    )
    wr = load_checkpoint(r.out_dir).model.state_dict()
    for k in ws:
        torch.testing.assert_close(wr[k], ws[k], atol=1e-6, rtol=1e-5)
    # resuming a finished run trains nothing and keeps every weight
    again = train_staged(
        tiny_data, r_out, base, _tiny_stages(), text_embeddings=text, resume=True, **quiet
    )
    w2 = load_checkpoint(again.out_dir).model.state_dict()
    assert all(torch.equal(w2[k], wr[k]) for k in wr)


def test_the_large_preset_is_the_shipped_models_recipe():
    """``--config large`` trains the shipped model's stages: the path from scratch on the
    preset's schedule, then the heading and the heading-relative output, 3000 steps each at
    lr 3e-4; ``--single-run`` switches every option on from the first step."""
    from habitsim.models.recipe import RECIPES, single_run_config, stage_configs

    large = preset("large")
    cfgs = stage_configs(large, RECIPES["large"])
    assert [c.train.steps for c in cfgs] == [12000, 3000, 3000]
    assert [c.train.lr for c in cfgs] == [large.train.lr, 3e-4, 3e-4]
    assert [
        (c.model.path_condition, c.model.path_heading, c.model.heading_relative) for c in cfgs
    ] == [
        (True, False, False),
        (True, True, False),
        (True, True, True),
    ]
    assert cfgs[0].train == large.train and cfgs[1].train.warmup_steps == 100
    one = single_run_config(large, RECIPES["large"])
    assert one.model == cfgs[-1].model and one.train == large.train
    assert stage_configs(large, RECIPES["large"], first_steps=50)[0].train.steps == 50


@pytest.mark.slow
def test_bench_train_plans_every_stage_of_the_large_preset(monkeypatch):
    """``habitsim bench train --config large`` times the recipe's final model (the path
    options on) and plans the steps of all three stages."""
    import importlib

    from habitsim.evaluation.bench.train import training_throughput

    mod = importlib.import_module("habitsim.models.train")
    seen = []
    real = mod.build_untrained

    def spy(cfg, *args, **kwargs):
        seen.append(cfg.model)
        return real(cfg, *args, **kwargs)

    monkeypatch.setattr(mod, "build_untrained", spy)
    tp = training_throughput("large", steps=1)
    assert len(seen) == 1 and seen[0].heading_relative and seen[0].path_heading
    assert tp["planned_steps"] == 18000.0
    assert tp["planned_minutes"] == pytest.approx(18000 * tp["s_per_step"] / 60.0)


@pytest.mark.parametrize("unwritable", UNWRITABLE, indirect=True)
def test_save_checkpoint_unwritable(unwritable: Path) -> None:
    from habitsim.models import shipped_checkpoint
    from habitsim.models.checkpoint import export_checkpoint, load_checkpoint, save_checkpoint

    src = shipped_checkpoint()
    ck = load_checkpoint(src)
    with pytest.raises(OutputPathError) as ei:
        save_checkpoint(unwritable / "ck", ck.model, ck.config, {"fps": 30.0})
    _typed_output_error(ei.value)
    with pytest.raises(OutputPathError) as ei:
        export_checkpoint(src, unwritable / "shipped")
    _typed_output_error(ei.value)
    assert not unwritable.exists()


def test_contact_loss_rewards_the_right_logits():
    x = torch.zeros(1, 6, FEAT_DIM)
    x[0, :3, C_INDEX:] = 1.0
    valid = torch.ones(1, 6, dtype=torch.bool)
    right, wrong = x.clone(), x.clone()
    right[..., C_INDEX:] = torch.where(x[..., C_INDEX:] > 0.5, 6.0, -6.0)
    wrong[..., C_INDEX:] = -right[..., C_INDEX:]
    assert float(_contact_loss(right, x, valid)) < 0.01
    assert float(_contact_loss(wrong, x, valid)) > 5.0
    # padded frames do not count
    assert float(_contact_loss(wrong, x, torch.zeros(1, 6, dtype=torch.bool))) == 0.0


def test_stance_loss_measures_sliding_stance_toes():
    m = generate("dog", "walk", seed=2, duration_s=2.0)
    x = torch.from_numpy(canonical_window(clip_arrays(m), 0, 48)[0]).double()[None]
    valid = torch.ones(1, 48, dtype=torch.bool)
    pos = window_positions(x, ["dog"], 30.0)
    clean = float(_stance_loss(pos, x, valid, ["dog"], 30.0, 0.05))
    # a root-velocity bias of b (Froude units) slides every toe at b·√(g·h) / leg per second
    b = 0.2
    drift = x.clone()
    drift[..., Q_DIM] += b
    slid = float(
        _stance_loss(window_positions(drift, ["dog"], 30.0), x, valid, ["dog"], 30.0, 0.05)
    )
    sp = load_species("dog")
    v = b * math.sqrt(9.81 * sp.hip_height) / sp.leg_length
    assert clean < 0.02  # the generator's planted feet rest
    assert slid == pytest.approx(clean + (v - 0.025), abs=0.03)
    # no stance frame, no term
    none = x.clone()
    none[..., C_INDEX:] = 0.0
    assert float(_stance_loss(pos, none, valid, ["dog"], 30.0, 0.05)) == 0.0


def test_speed_variant_plays_the_clip_faster_with_its_labels():
    m = generate("horse", "trot", seed=3, duration_s=2.0)
    fast = speed_variant(m, 1.25)
    assert fast.fps == m.fps
    assert fast.num_frames == int(round((m.num_frames - 1) / 1.25)) + 1
    assert fast.contacts is not None and fast.contacts.shape == (fast.num_frames, 4)
    assert abs(fast.contacts.mean() - m.contacts.mean()) < 0.05  # same duty factor
    v0 = np.linalg.norm(np.diff(m.root_positions[:, :2], axis=0), axis=1).mean()
    v1 = np.linalg.norm(np.diff(fast.root_positions[:, :2], axis=0), axis=1).mean()
    assert v1 / v0 == pytest.approx(1.25, rel=0.03)


def test_checkpoint_config_out_of_bounds_is_typed(tmp_path) -> None:
    from habitsim.models.checkpoint import load_checkpoint

    (tmp_path / "config.json").write_text('{"format": "x", "steps": ' + "9" * 5000 + "}")
    with pytest.raises(CheckpointError):
        load_checkpoint(tmp_path)
