"""Transformed copies of a clip (habitsim.evaluation.bench.variants) and the robustness of
the source stance labels to them: other frame rates, speeds, proportions, toe points,
trimmed and padded starts, rig exports; fore and hind feet whose points sit at other
heights; jittery capture. The clips are a synthetic dog walk written as a foreign rig."""

from __future__ import annotations

import json

import numpy as np
import pytest
from foreign_rig import _foreign_rig

import habitsim
from habitsim.bvh import parse_bvh
from habitsim.bvh_mapping import import_bvh
from habitsim.cli import main
from habitsim.evaluation.bench.real import RealOptions, plan
from habitsim.evaluation.bench.variants import (
    MAX_DUTY_CHANGE,
    MIN_STANCE_F1,
    VARIANTS,
    VariantError,
    make_variant,
    resample_bvh,
    stance_row,
)
from habitsim.stance.labels import stance_f1
from habitsim.stance.planting import PlantingOptions, label_source_stance

#: The variants whose stance must stay the original's (noise is scored separately).
KEPT = [n for n in VARIANTS if n not in ("original", "noise")]


@pytest.fixture(scope="module")
def walk():
    return habitsim.generate("dog", "walk", seed=3, duration_s=3.0)


@pytest.fixture(scope="module")
def rig(walk):
    return _foreign_rig(walk)


@pytest.fixture(scope="module")
def original(rig):
    motion, _ = import_bvh(rig, "dog")
    return motion


def test_variants_are_deterministic_and_named(rig):
    a, b = make_variant(rig, "noise", seed=1), make_variant(rig, "noise", seed=1)
    np.testing.assert_array_equal(a.frames, b.frames)
    assert not np.array_equal(a.frames, make_variant(rig, "noise", seed=2).frames)
    assert not np.array_equal(a.frames, rig.frames)
    assert a.source == "foreign_rig~noise.bvh"
    assert all(n.startswith("Dog2:") for n in make_variant(rig, "renamed").names)
    with pytest.raises(VariantError, match="valid: original"):
        make_variant(rig, "fps7")


def test_resampling_keeps_the_pose_at_shared_instants(rig):
    half = resample_bvh(rig, rig.fps / 2)
    assert half.fps == rig.fps / 2 and half.num_frames == (rig.num_frames - 1) // 2 + 1
    np.testing.assert_allclose(half.fk(), rig.fk()[::2], atol=1e-6 * np.abs(rig.fk()).max())
    # the text round trip reads back the same clip
    back = parse_bvh(half.to_text())
    np.testing.assert_allclose(back.fk(), half.fk(), atol=1e-5 * np.abs(rig.fk()).max())


def test_geometric_variants_do_what_they_say(rig):
    up = np.array([0.0, 0.0, 1.0])  # the foreign rig is z up, in centimetres
    toe = rig.names.index("L_Toes")
    fore = rig.names.index("L_Digits")
    h0 = np.median(rig.fk()[:, [toe, fore]] @ up, axis=0)
    raised = np.median(make_variant(rig, "hind-toe-up").fk()[:, [toe, fore]] @ up, axis=0)
    np.testing.assert_allclose(raised - h0, [3.0, 0.0], atol=0.3)  # 3 cm, hind only
    short = np.median(make_variant(rig, "hind-short").fk()[:, [toe, fore]] @ up, axis=0)
    assert short[0] - h0[0] > 3.0 and abs(short[1] - h0[1]) < 1e-6
    metres = make_variant(rig, "units-m")
    np.testing.assert_allclose(metres.fk(), rig.fk() * 0.01, atol=1e-9)
    zup = make_variant(rig, "z-up")  # already z up: unchanged
    np.testing.assert_allclose(zup.fk(), rig.fk(), atol=1e-6)
    trim = make_variant(rig, "trim")
    assert trim.num_frames == rig.num_frames - round(rig.fps)
    pad = make_variant(rig, "pad")
    np.testing.assert_allclose(pad.frames[: round(rig.fps)], rig.frames[[0] * round(rig.fps)])


@pytest.mark.parametrize("name", KEPT)
def test_stance_labels_survive_the_variant(rig, original, name):
    """Per-foot duty factors within MAX_DUTY_CHANGE of the original clip's and stance F1
    ≥ MIN_STANCE_F1 against it, over the instants both clips hold."""
    motion, _ = import_bvh(make_variant(rig, name), "dog")
    row = stance_row(original, motion, name)
    assert min(row["f1"]) >= MIN_STANCE_F1, row
    assert row["duty_change"] <= MAX_DUTY_CHANGE, row


def _walking_feet(fps: float, heights=(0.0, 0.0, 0.0, 0.0), t_s: float = 4.0, seed=None):
    """Four feet walking at 1 m/s (stride 0.5 s, duty 0.6, 6 cm swings), each foot's
    point ``heights`` [m] above its sole; Gaussian jitter of 4 mm with ``seed``."""
    t = int(t_s * fps)
    tt = np.arange(t) / fps
    feet, truth = [], []
    rng = None if seed is None else np.random.default_rng(seed)
    for k, phase in enumerate((0.0, 0.5, 0.25, 0.75)):
        ph = (tt / 0.5 + phase) % 1.0
        stance = ph < 0.6
        sw = np.clip((ph - 0.6) / 0.4, 0, 1)
        step = np.floor(tt / 0.5 + phase)
        x = step * 0.5 + np.where(stance, 0.0, 0.5 * (3 * sw**2 - 2 * sw**3)) + 0.3 * k
        z = heights[k] + np.where(stance, 0.0, 0.06 * np.sin(np.pi * sw))
        p = np.stack([x, np.zeros(t), z], -1)
        if rng is not None:
            p = p + rng.normal(0.0, 0.004, p.shape)
        feet.append(p[:, None])
        truth.append(stance)
    return feet, np.stack(truth, axis=1)


def test_hind_points_higher_than_fore_points_keep_their_stance():
    # the hind feet's points sit 0.2 leg lengths higher above their soles than the fore
    # feet's (another rig's toe tips): each pair stands on its own floor
    fps, leg = 60.0, 0.6
    feet, truth = _walking_feet(fps, (0.0, 0.0, 0.12, 0.12))
    st = label_source_stance(feet, fps, leg)
    assert np.all(stance_f1(st.contacts, truth) >= 0.95)
    np.testing.assert_allclose(st.floors[2:] - st.floors[:2], 0.12, atol=0.01)
    # a whole pair held higher than pair_spread_per_leg is not stance
    feet, _ = _walking_feet(fps, (0.0, 0.0, 0.25, 0.25))
    st = label_source_stance(feet, fps, leg)
    assert not st.contacts[:, 2:].any()
    # nor, with the pairs' spread switched off, is the pair at 0.2 leg lengths
    feet, _ = _walking_feet(fps, (0.0, 0.0, 0.12, 0.12))
    st = label_source_stance(feet, fps, leg, PlantingOptions(pair_spread_per_leg=0.0))
    assert st.contacts[:, 2:].mean() < 0.1


def test_jittery_capture_keeps_its_stance():
    # 4 mm of jitter at 120 fps: a velocity over a fixed 0.05 s span finds the stance;
    # frame-to-frame differences (a span of one frame) lose much of it
    fps, leg = 120.0, 0.6
    feet, truth = _walking_feet(fps, seed=0)
    st = label_source_stance(feet, fps, leg)
    assert np.all(stance_f1(st.contacts, truth) >= 0.9), stance_f1(st.contacts, truth)
    frame = label_source_stance(feet, fps, leg, PlantingOptions(velocity_span_s=1e-3))
    assert stance_f1(frame.contacts, truth).mean() < stance_f1(st.contacts, truth).mean()


def test_bench_variants_command(tmp_path, rig, capsys):
    (tmp_path / "walk.bvh").write_text(rig.to_text())
    out = tmp_path / "v.json"
    code = main(
        [
            "bench",
            "variants",
            "--data",
            str(tmp_path),
            "--variants",
            "original,fps24,hind-toe-up",
            "--json",
            str(out),
            "--check",
        ]
    )
    text = capsys.readouterr().out
    assert code == 0, text
    doc = json.loads(out.read_text())
    assert [r["variant"] for r in doc["rows"]] == ["original", "fps24", "hind-toe-up"]
    assert doc["rows"][1]["fps"] == 24.0
    assert all(t["verdict"] == "met" for t in doc["targets"])
    assert main(["bench", "variants", "--data", str(tmp_path), "--variants", "nope"]) == 2


def test_bench_real_plans_the_variants(tmp_path, rig):
    (tmp_path / "walk.bvh").write_text(rig.to_text())
    p = plan(
        RealOptions(
            data=tmp_path,
            targets=("cat",),
            methods=("direct",),
            seconds=1.5,
            variants=("original", "fps24", "trim"),
        )
    )
    assert [t.clip for t in p.tasks] == [
        "walk~original.bvh",
        "walk~fps24.bvh",
        "walk~trim.bvh",
    ]
    with pytest.raises(VariantError):
        plan(RealOptions(data=tmp_path, variants=("nope",)))
