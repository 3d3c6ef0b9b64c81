"""Feature version 3 of the learning core: decoded contacts, the stance and contact terms,
quantizer dropout, speed augmentation and how a transfer labels its stance."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from habitsim.contacts import contacts_from_feet
from habitsim.gaits import generate
from habitsim.models.config import QuantizerConfig
from habitsim.models.data import ClipSet, feature_stats, speed_variant
from habitsim.models.features import (
    C_DIM,
    C_INDEX,
    FEAT_DIM,
    FEATURE_VERSION,
    Q_DIM,
    canonical_window,
    clip_arrays,
    decoded_contacts,
    window_positions,
)
from habitsim.models.quantizer import EMAQuantizer, residual_quantize
from habitsim.models.train import _contact_loss, _stance_loss
from habitsim.motion import Motion
from habitsim.species import load_species
from habitsim.stance.policy import ConformPolicy
from habitsim.stance.schedule import transfer_contacts

pytestmark = pytest.mark.usefixtures("torch_one_thread")


def test_windows_carry_the_clips_stance_labels():
    m = generate("dog", "trot", seed=4, duration_s=2.0)
    assert FEATURE_VERSION == 3 and FEAT_DIM == C_INDEX + C_DIM
    c = clip_arrays(m)
    np.testing.assert_array_equal(c.contacts.astype(bool), m.contacts)
    f, valid, _ = canonical_window(c, 5, 32)
    assert valid.all()
    np.testing.assert_array_equal(decoded_contacts(f), m.contacts[5:37])
    # a clip without labels gets the ones detected on its own toes
    bare = Motion(m.species, m.fps, m.root_positions, m.rotations)
    det = contacts_from_feet(bare.foot_positions(), m.fps, m.species_info.leg_length)
    np.testing.assert_array_equal(clip_arrays(bare).contacts.astype(bool), det)


def test_feature_stats_leave_the_contact_logits_unscaled():
    clips = [clip_arrays(generate(s, "walk", seed=1, duration_s=1.5)) for s in ("cat", "horse")]
    mean, std = feature_stats(ClipSet(clips, [None, None], ["walk", "walk"], 30.0), 16)
    assert mean.shape == (FEAT_DIM,)
    np.testing.assert_array_equal(mean[C_INDEX:], 0.0)
    np.testing.assert_array_equal(std[C_INDEX:], 1.0)
    assert np.all(std[:C_INDEX] >= 1e-2) and np.any(mean[:Q_DIM] != 0.0)


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


def test_quantizer_dropout_keeps_only_the_first_levels():
    torch.manual_seed(0)
    cfg = QuantizerConfig(num_codes=8, code_dim=4, levels=3)
    levels = [EMAQuantizer(cfg, reset=False) for _ in range(3)]
    for q in levels:
        q.eval()
        with torch.no_grad():
            q.codebook.copy_(torch.randn(8, 4))
            q.initialized.fill_(True)
    f = torch.randn(2, 4, 5)
    full = residual_quantize(levels, f, sample=False, update=False)
    part = residual_quantize(levels, f, sample=False, update=False, n_levels=torch.tensor([1, 3]))
    first = levels[0](f, sample=False, update=False).quantized
    torch.testing.assert_close(part.quantized[0], first[0])
    torch.testing.assert_close(part.quantized[1], full.quantized[1])
    assert not torch.allclose(part.quantized[0], full.quantized[0])
    torch.testing.assert_close(part.level_indices, full.level_indices)  # every level still ran


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


def test_transfer_labels_come_from_the_decoded_contacts_checked_against_the_source():
    src = generate("dog", "trot", seed=5, duration_s=2.0)
    out = Motion("horse", src.fps, src.root_positions * 2.0, src.rotations)
    labels, info = transfer_contacts(out, src, src.contacts)
    assert info["method"] == "decoded" and info["source_f1"] == [1.0] * 4
    np.testing.assert_array_equal(labels, src.contacts)
    # a decoded foot that disagrees with the source's footfalls takes the source's schedule
    bad = src.contacts.copy()
    bad[:, 2] = ~bad[:, 2]
    labels, info = transfer_contacts(out, src, bad)
    assert info["source_f1"][2] < ConformPolicy().min_source_agreement <= min(info["source_f1"][:2])
    assert info["feet_from_source"] == ["LH"]
    np.testing.assert_array_equal(labels, src.contacts)
    # a decoded foot that stands far longer than the source's (a high F1 all the same)
    # takes the source's schedule too
    long = src.contacts.copy()
    long[:, 0] |= np.roll(long[:, 0], 4) | np.roll(long[:, 0], 8)
    labels, info = transfer_contacts(out, src, long)
    assert info["duty"][0] - info["source_duty"][0] > ConformPolicy().max_duty_gap
    assert info["feet_from_source"] == ["LF"]
    np.testing.assert_array_equal(labels, src.contacts)
    # without decoded contacts (direct) the source's schedule is used as such
    labels, info = transfer_contacts(out, src)
    assert info["method"] == "source"
    np.testing.assert_array_equal(labels, src.contacts)


def test_bench_model_phase_error_and_resting_feet():
    from habitsim.evaluation.bench.model import phase_error as _phase_error
    from habitsim.evaluation.bench.model import resting_share as _resting_share

    src = {"LF": 0.5, "RF": 0.0, "RH": 0.5, "LH": 0.0}
    assert _phase_error(src, src) == 0.0
    assert _phase_error({"LF": 0.75, "RF": 0.9, "RH": 0.4}, src) == pytest.approx(0.15)
    assert _phase_error({"LF": float("nan"), "RF": 0.0, "RH": 0.5}, src) == pytest.approx(0.5 / 3)
    assert math.isnan(_phase_error(src, {"LF": float("nan")}))
    m = generate("dog", "walk", seed=2, duration_s=2.0)
    rest, stance = _resting_share(m)
    assert stance > 0 and rest / stance > 0.9  # the generator plants its stance feet
    slid = Motion(m.species, m.fps, m.root_positions * [1.3, 1.0, 1.0], m.rotations, m.contacts)
    rest2, stance2 = _resting_share(slid)
    assert stance2 == stance and rest2 / stance2 < 0.5


def test_bench_model_reports_the_evaluators_habit_and_action_accuracy(monkeypatch):
    """``bench model`` asks the frozen evaluator what each transfer looks like: habit
    accuracy over targets the evaluator knows, action accuracy over sources with an action."""
    import importlib
    from types import SimpleNamespace

    from habitsim.cli import bench_model
    from habitsim.evaluation.bench.model import transfer_quality

    ev_mod = importlib.import_module("habitsim.evaluation.evaluator")
    seen: list[str] = []

    class FakeEvaluator:
        config = SimpleNamespace(species=("horse", "dog"), actions=("walk", "trot"))

        def predict(self, motions):
            motions = list(motions)
            seen.extend(m.species for m in motions)
            # right species and action for the horse, wrong ones for everything else
            sp = [m.species if m.species == "horse" else "dog" for m in motions]
            acts = ["walk" if s == "horse" else "trot" for s in sp]
            return SimpleNamespace(species=sp, actions=acts)

    monkeypatch.setattr(ev_mod, "load_evaluator", lambda *a, **k: FakeEvaluator())
    walk = generate("dog", "walk", seed=3, duration_s=2.5)
    unlabelled = Motion(walk.species, walk.fps, walk.root_positions, walk.rotations, walk.contacts)
    q = transfer_quality([walk, unlabelled], ["horse", "cat", "giraffe"])
    assert q["transfers"] == 6 and sorted(seen) == sorted(["horse", "cat", "giraffe"] * 2)
    # habit: only the horse is a species the evaluator knows; both horse transfers right
    assert q["habit_classified"] == 2 and q["habit_accuracy"] == 1.0
    # action: only the labelled walk's three transfers count; the horse one is right
    assert q["action_classified"] == 3 and q["action_accuracy"] == pytest.approx(1 / 3)
    text = bench_model._accuracy_text(q)
    assert "habit accuracy 1.000 of 2 (target ≥ 0.95: met)" in text
    assert "action accuracy 0.333 of 3 (target ≥ 0.85: MISSED)" in text
    q0 = {**q, "action_classified": 0, "action_accuracy": math.nan}
    assert "action accuracy - (the sources' action is not known)" in bench_model._accuracy_text(q0)
