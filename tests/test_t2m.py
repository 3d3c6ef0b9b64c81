"""Text to motion: the code set, the transformer's training and resuming, generation."""

from __future__ import annotations

import json
import zlib
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pytest
import torch
from safetensors.numpy import load_file

from habitsim.errors import UnknownSpeciesError
from habitsim.models.codegpt import CodeGPT, decoder_path, path_features
from habitsim.models.errors import (
    CheckpointError,
    CodeSetError,
    ConfigError,
    GenerationRequestError,
    MethodNotAvailableError,
)
from habitsim.models.t2m import text_to_motion
from habitsim.models.t2m_data import CODES_NAME, build_code_set, load_code_set, prompt_text
from habitsim.models.t2m_train import load_codegpt, t2m_preset, train_codegpt
from habitsim.motion import Motion

#: width of the fake sentence embeddings
DIM = 24


def fake_embed(texts: Sequence[str]) -> np.ndarray:
    """Deterministic bag-of-words embeddings (unit length): similar words, similar rows."""
    out = np.zeros((len(texts), DIM), np.float32)
    for i, t in enumerate(texts):
        for w in t.lower().replace(".", " ").replace(",", " ").split():
            rng = np.random.default_rng(zlib.crc32(w.encode()))
            out[i] += rng.standard_normal(DIM).astype(np.float32)
        out[i] /= max(float(np.linalg.norm(out[i])), 1e-6)
    return out


@pytest.fixture(scope="module")
def code_set(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from habitsim.captions.store import caption_dataset
    from habitsim.dataset import build_dataset

    root = tmp_path_factory.mktemp("t2m")
    ds = root / "data"
    build_dataset(ds, clips_per_species=11, species=["dog", "cat"], workers=1, progress=False)
    caption_dataset(ds, seed=0)
    build_code_set(ds, root / "codes", embed=fake_embed, text_model="fake-bow")
    return root / "codes"


@pytest.fixture(scope="module")
def trained(code_set: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("ckpt") / "t2m"
    cfg = t2m_preset("tiny").replace(
        **{"train.steps": 6, "train.checkpoint_every": 3, "train.val_every": 2}
    )
    train_codegpt(code_set, out, cfg, log=lambda s: None)
    return out


def _gen(ckpt: Path, **kw) -> Motion:
    args = {"seed": 0, "checkpoint": ckpt, "embed": fake_embed, **kw}
    text = args.pop("text", "A dog trots to the left.")
    species = args.pop("species", "dog")
    seconds = args.pop("seconds", 4.0)
    return text_to_motion(text, species, seconds, **args)


def test_code_set_holds_every_captioned_clip_and_resumes(code_set: Path, tmp_path: Path) -> None:
    cs = load_code_set(code_set)
    doc = json.loads((code_set / CODES_NAME).read_text())
    assert cs.species == ["cat", "dog"] and cs.levels == 4 and cs.path_dim == 4
    assert cs.meta["text_form"] == "species_neutral"
    assert len(cs.clips) == len(doc["clips"]) >= 8
    for c in cs.clips:
        assert c.codes.shape == (c.steps, 4) and c.path.shape == (c.steps, 4)
        assert c.text.shape == (len(c.captions), DIM)
        # embedded as the generator will read prompts: species words replaced
        assert np.allclose(c.text, fake_embed(prompt_text(c.captions, "species_neutral")))
        assert not np.allclose(c.text, fake_embed(c.captions))
        assert c.codes.min() >= 0 and c.codes.max() < cs.num_codes
    # a rebuild keeps every clip file as it is (nothing re-encoded)
    files = sorted((code_set / "clips").rglob("*.safetensors"))
    before = load_file(str(files[0]))
    stamps = {f: f.stat().st_mtime_ns for f in files}
    data = Path(doc["dataset"])
    again = build_code_set(data, code_set, embed=fake_embed, text_model="fake-bow")
    assert len(again.clips) == len(cs.clips)
    assert {f: f.stat().st_mtime_ns for f in files} == stamps
    # a broken clip file is re-encoded, bit for bit
    files[0].write_bytes(b"broken")
    build_code_set(data, code_set, embed=fake_embed, text_model="fake-bow")
    after = load_file(str(files[0]))
    assert all(np.array_equal(before[k], after[k]) for k in ("codes", "path", "text"))


def test_code_set_bad_input(tmp_path: Path, code_set: Path, small_dataset: Path) -> None:
    data = Path(json.loads((code_set / CODES_NAME).read_text())["dataset"])
    with pytest.raises(CodeSetError):  # a data set without captions.json
        build_code_set(small_dataset, tmp_path / "z", embed=fake_embed, text_model="bow")
    assert not (tmp_path / "z" / CODES_NAME).exists()
    with pytest.raises(CodeSetError):
        build_code_set(data, tmp_path / "x", embed=fake_embed)  # no text_model name
    with pytest.raises(CodeSetError):
        load_code_set(tmp_path / "nothing")
    with pytest.raises(CodeSetError):
        build_code_set(data, tmp_path / "y", embed=lambda t: np.zeros((1, 3)), text_model="b")
    with pytest.raises(CodeSetError):
        build_code_set(data, tmp_path / "w", embed=fake_embed, text_model="b", text_form="x")
    assert not (tmp_path / "w" / CODES_NAME).exists()


def test_path_features_round_trip() -> None:
    rng = np.random.default_rng(0)
    psi = np.cumsum(rng.uniform(-0.5, 0.5, 20))
    path = np.stack([rng.normal(size=20), rng.normal(size=20), np.cos(psi), np.sin(psi)], 1)
    back = decoder_path(torch.from_numpy(path_features(path)).double(), 4).numpy()
    np.testing.assert_allclose(back, path, atol=1e-6)


def test_training_is_seeded_and_resumes_to_the_same_weights(
    code_set: Path, trained: Path, tmp_path: Path
) -> None:
    cfg = t2m_preset("tiny").replace(
        **{"train.steps": 6, "train.checkpoint_every": 3, "train.val_every": 2}
    )
    wa = load_codegpt(trained).model.state_dict()
    # interrupted after 2 steps, resumed to 6 == 6 straight steps
    r = tmp_path / "r"
    train_codegpt(code_set, r, cfg, stop_at=2, log=lambda s: None)
    assert json.loads((r / "config.json").read_text())["training"]["step"] == 2
    res = train_codegpt(code_set, r, cfg, resume=True, log=lambda s: None)
    assert res.steps == 6
    wr = load_codegpt(r).model.state_dict()
    assert all(torch.equal(wa[k], wr[k]) for k in wa)
    # another seed gives other weights; a checkpoint is never silently replaced
    o = train_codegpt(
        code_set, tmp_path / "o", cfg.replace(**{"train.seed": 1, "train.steps": 2}), log=print
    )
    wo = load_codegpt(o.out_dir).model.state_dict()
    assert not all(torch.equal(wa[k], wo[k]) for k in wa)
    with pytest.raises(CheckpointError):
        train_codegpt(code_set, r, cfg, log=lambda s: None)
    with pytest.raises(CheckpointError):  # another model shape cannot resume
        train_codegpt(
            code_set, r, cfg.replace(**{"model.d_model": 16}), resume=True, log=lambda s: None
        )
    with pytest.raises(ConfigError):
        t2m_preset("huge")


def test_the_best_validation_step_is_kept(code_set: Path, trained: Path) -> None:
    assert load_code_set(code_set).split("val")  # the data set has val clips
    hist = json.loads((trained / "config.json").read_text())["training"]["history"]
    best = json.loads((trained / "best" / "config.json").read_text())["training"]
    assert best["step"] == min(hist, key=lambda h: h["val_ce"])["step"]
    assert load_codegpt(trained / "best").model.levels == 4


def test_generate_length_species_and_labels(trained: Path) -> None:
    m = _gen(trained)
    ck = load_codegpt(trained)
    assert isinstance(m, Motion) and m.species == "dog" and m.fps == ck.fps
    assert m.num_frames == 120 and m.contacts is not None and m.contacts.shape == (120, 4)
    info = m.metadata["text_to_motion"]
    assert info["text"] == "A dog trots to the left." and info["seed"] == 0
    assert info["habit_species"] == "dog" and info["retrieval"] is None
    assert np.isfinite(m.rotations).all() and np.isfinite(m.root_positions).all()
    short = _gen(trained, species="cat", seconds=0.9)
    assert short.species == "cat" and short.num_frames == 28  # 7 code steps of 4 frames


def test_the_prompt_is_read_species_neutral_as_the_captions_were(trained: Path) -> None:
    # the species comes from the habit input: the words of the animal do not change the
    # codes drawn; the words of the action do
    a = _gen(trained, text="A dog trots to the left.", seed=5)
    b = _gen(trained, text="A kitten trots to the left.", seed=5)
    c = _gen(trained, text="A dog gallops to the left.", seed=5)
    assert load_codegpt(trained).meta["text_form"] == "species_neutral"
    assert np.array_equal(a.rotations, b.rotations)
    assert not np.array_equal(a.rotations, c.rotations)


def test_held_out_species_borrows_a_habit_by_retrieval(trained: Path) -> None:
    m = _gen(trained, species="tiger", seconds=2.0)
    info = m.metadata["text_to_motion"]
    assert m.species == "tiger"
    assert info["code_species"] in ("cat", "dog") and info["code_retrieval"]["neighbour"]
    assert info["habit_species"] != "tiger" and info["retrieval"]["explanation"]


def test_same_seed_same_motion_and_guidance_matters(trained: Path) -> None:
    a, b = _gen(trained, seed=3), _gen(trained, seed=3)
    assert np.array_equal(a.rotations, b.rotations)
    assert np.array_equal(a.root_positions, b.root_positions)
    c = _gen(trained, seed=4)
    assert not np.array_equal(a.rotations, c.rotations)
    g0, g3 = _gen(trained, seed=3, guidance=0.0), _gen(trained, seed=3, guidance=3.0)
    assert not np.array_equal(g0.rotations, g3.rotations)
    greedy = _gen(trained, temperature=0.0, top_k=5)
    assert greedy.num_frames == 120


@pytest.mark.parametrize(
    ("kw", "code"),
    [
        ({"text": "   "}, "empty_text"),
        ({"text": "a dog walks " * 100}, "text_too_long"),
        ({"text": "\ud800 a dog"}, "bad_text"),  # a lone surrogate (found by the fuzzer)
        ({"seconds": 0.01}, "length_out_of_range"),
        ({"seconds": 60.0}, "length_out_of_range"),
        ({"seconds": float("nan")}, "length_out_of_range"),
        ({"temperature": -1.0}, "bad_sampling"),
        ({"guidance": float("inf")}, "bad_sampling"),
        ({"top_k": 0}, "bad_sampling"),
    ],
)
def test_bad_requests_raise_typed_errors(trained: Path, kw: dict, code: str) -> None:
    with pytest.raises(GenerationRequestError) as e:
        _gen(trained, **kw)
    assert e.value.code == code


def test_unknown_species_and_missing_checkpoint(trained: Path, monkeypatch) -> None:
    with pytest.raises(UnknownSpeciesError) as e:
        _gen(trained, species="unicorn")
    assert "dog" in e.value.known
    monkeypatch.delenv("HABITSIM_MODELS_DIR", raising=False)
    with pytest.raises(MethodNotAvailableError):
        text_to_motion("a dog walks", "dog", 2.0, embed=fake_embed)


def test_model_shapes(trained: Path) -> None:
    ck = load_codegpt(trained)
    model: CodeGPT = ck.model
    b, t = 2, 5
    codes = torch.zeros(b, t, model.levels, dtype=torch.long)
    logits, path = model(
        torch.zeros(b, DIM),
        torch.tensor([True, False]),
        torch.zeros(b, model.habit_dim),
        codes,
        torch.zeros(b, t, model.pf_dim),
        torch.tensor([t, t]),
    )
    assert len(logits) == 4 and logits[0].shape == (b, t, model.num_codes)
    assert path is not None and path.shape == (b, t, 3)


def test_prompt_agreement_per_guidance(trained: Path) -> None:
    from habitsim.models.t2m_eval import prompt_agreement

    rows = prompt_agreement(trained, (0.0, 3.0), split="train", limit=2, embed=fake_embed)
    assert [r.guidance for r in rows] == [0.0, 3.0]
    for r in rows:
        assert r.clips == 2 and 0.0 <= r.action <= 1.0 and 0.0 <= r.turning <= 1.0
        assert 0.0 <= r.no_action <= 1.0 and set(r.to_dict()) >= {"action", "speed_error_mps"}
    with pytest.raises(CodeSetError):
        prompt_agreement(trained, split="test", embed=fake_embed)


def test_command_line(code_set: Path, trained: Path, tmp_path: Path, monkeypatch, capsys) -> None:
    import habitsim.models.text as text_mod
    from habitsim.cli import main
    from habitsim.motion import load_motion

    monkeypatch.setattr(text_mod, "embed_texts", lambda texts, model="": fake_embed(texts))
    data = json.loads((code_set / CODES_NAME).read_text())["dataset"]
    assert main(["t2m", "codes", data, "--out", str(tmp_path / "codes")]) == 0
    assert load_code_set(tmp_path / "codes").species == ["cat", "dog"]
    ck = tmp_path / "ck"
    args = ["t2m", "train", "--codes", str(code_set), "--out", str(ck), "--config", "tiny"]
    assert main([*args, "--steps", "2"]) == 0
    assert load_codegpt(ck).meta["training"]["step"] == 2
    out = tmp_path / "dog.npz"
    gen = ["t2m", "generate", "a dog walks", "--checkpoint", str(trained)]
    assert main([*gen, "--out", str(out), "--seconds", "2", "--guidance", "3"]) == 0
    m = load_motion(out)
    assert m.species == "dog" and m.num_frames == 60
    capsys.readouterr()
    bad = tmp_path / "bad.npz"
    assert main([*gen, "--out", str(bad), "--seconds", "100"]) == 2
    assert capsys.readouterr().err.startswith("error:")
    assert not bad.exists()
    ck_args = ["--checkpoint", str(trained), "--out", str(bad)]
    for text, species in [
        ("a unicorn trots", "unicorn"),  # unknown species: refused with the known ones
        ("a unicorn trots", None),  # the text names no catalog species and none given
        ("a cat trots", "dog"),  # the text and --species disagree
    ]:
        capsys.readouterr()
        extra = [] if species is None else ["--species", species]
        assert main(["t2m", "generate", text, *extra, *ck_args]) == 2
        err = capsys.readouterr().err
        assert err.startswith("error:") and "Traceback" not in err
        assert "unicorn" not in text or "horse" in err  # the known species are listed
        assert not bad.exists()
    # an action habitsim does not make: a clip and a warning naming what it shows
    swim = tmp_path / "swim.npz"
    assert (
        main(
            [
                "t2m",
                "generate",
                "the kitten swims",
                "--checkpoint",
                str(trained),
                "--out",
                str(swim),
                "--seconds",
                "2",
            ]
        )
        == 0
    )
    out_err = capsys.readouterr()
    assert load_motion(swim).species == "cat"
    assert "warning: the prompt names no action habitsim makes" in out_err.err
    assert "the generated clip shows" in out_err.err and "it shows" in out_err.out


def test_run_text_species_from_the_text_and_warnings(trained: Path) -> None:
    import warnings

    from habitsim.captions.prompts import PromptWarning
    from habitsim.errors import PromptError
    from habitsim.pipeline import run_text

    kw = {"seconds": 2.0, "checkpoint": trained, "embed": fake_embed}
    with warnings.catch_warnings(record=True) as got:
        warnings.simplefilter("always")
        tr = run_text("Two horses trot along", **kw)
    assert tr.species == "horse" and tr.generated.species == "horse"
    assert tr.reading.actions == ("trot",) and tr.run.method == "text_to_motion"
    assert tr.run.tracked.status == "off" and tr.run.refine == "none"
    # the transfer stage is the identity: the pipeline's source is the generated clip
    assert tr.run.transferred.motion is not None
    np.testing.assert_allclose(
        tr.run.transferred.motion.rotations, tr.generated.rotations, 0, 1e-12
    )
    assert np.array_equal(tr.run.reference.root_positions, tr.generated.root_positions)
    # a warning exactly when the measured clip is not a trot, naming what it shows
    shown = [str(w.message) for w in got if issubclass(w.category, PromptWarning)]
    assert (tr.facts is not None and tr.facts.action == "trot") == (not shown)
    assert list(tr.warnings) == shown
    for note in shown:
        assert note.startswith("the prompt asks for trot; the generated clip shows")
    # the species argument serves a text that names none, and must agree with one that does
    assert run_text("an animal walks", "cat", **kw).species == "cat"
    assert run_text("a puppy walks", "dog", **kw).species == "dog"
    for text, sp, code in [
        ("an animal walks", None, "no_species"),
        ("a dog chases a cat", None, "several_species"),
        ("a puppy walks", "cat", "species_conflict"),
    ]:
        with pytest.raises(PromptError) as e:
            run_text(text, sp, **kw)
        assert e.value.code == code and "horse" in e.value.known
    with pytest.raises(UnknownSpeciesError):
        run_text("an animal walks", "unicorn", **kw)
    with pytest.raises(GenerationRequestError):
        run_text("   ", "dog", **kw)
    # an action habitsim does not make: generated all the same, with the warning
    with pytest.warns(PromptWarning, match="names no action habitsim makes"):
        swim = run_text("a dog swims across a river", **kw)
    assert swim.generated.num_frames == 60 and len(swim.warnings) == 1


@pytest.mark.slow  # a refinement and a tracking run (about 25 s)
def test_run_text_refines_and_tracks_through_the_pipeline(trained: Path) -> None:
    from habitsim.pipeline import run_text

    tr = run_text(
        "a dog walks",
        seconds=1.0,
        checkpoint=trained,
        embed=fake_embed,
        refine="kinematic",
        track=True,
        guard=False,
    )
    run = tr.run
    assert run.refine == "A" and run.refine_result is not None
    assert run.refined.motion is not None and run.refined.motion.species == "dog"
    assert run.tracked.status in ("ok", "fell") and run.track_result is not None
    assert 0.0 <= run.track_result.survival <= 1.0
    # the tracking followed the refined labels (the pipeline's labels travel)
    frames = tr.generated.num_frames
    assert run.refined.contacts is not None and run.refined.contacts.shape == (frames, 4)


def test_a_user_species_is_generated_on_its_own_skeleton(
    trained: Path, tmp_path: Path, monkeypatch
) -> None:
    from foreign_rig import user_dog

    from habitsim.skeleton import get_skeleton
    from habitsim.species import USER_CATALOG_ENV, load_species

    monkeypatch.setenv(USER_CATALOG_ENV, str(user_dog(tmp_path, "clipdog", scale=1.2)))
    m = _gen(trained, species="clipdog", seconds=2.0)
    info = m.metadata["text_to_motion"]
    assert m.species == "clipdog" and info["species"] == "clipdog"
    assert info["code_species"] in ("cat", "dog") and info["habit_species"] in ("cat", "dog")
    assert info["retrieval"]["neighbour"] == info["habit_species"]
    own, dog = load_species("clipdog").segments, load_species("dog").segments
    assert own["trunk"] == pytest.approx(1.2 * dog["trunk"], rel=0.05)  # its rig's
    assert not np.allclose(m.skeleton.offsets, get_skeleton("dog").offsets)
    with pytest.raises(UnknownSpeciesError) as e:
        _gen(trained, species="clipcat")
    assert "clipdog" in e.value.known and "dog" in e.value.known


def test_a_lone_surrogate_is_no_text_to_embed() -> None:
    from habitsim.models.errors import TextEncoderError
    from habitsim.models.text import embed_texts

    with pytest.raises(TextEncoderError, match="lone surrogate"):
        embed_texts(["\udfff"], cache=False)


_GENERATE = """
import sys
sys.path.insert(0, {tests!r})
from test_t2m import fake_embed
from habitsim.models.t2m import text_to_motion
m = text_to_motion("A dog trots to the left.", "dog", 4.0, seed=1, checkpoint={ckpt!r},
                   embed=fake_embed, temperature=1.0)
m.save(sys.argv[1])
"""


@pytest.mark.slow
def test_generation_is_byte_identical_across_thread_counts(trained: Path, tmp_path: Path) -> None:
    """The same request in processes whose BLAS / OpenMP / torch start with 1 and 2
    threads (and twice with 2) writes the same bytes."""
    import os
    import subprocess
    import sys

    script = tmp_path / "gen.py"
    script.write_text(_GENERATE.format(tests=str(Path(__file__).parent), ckpt=str(trained)))
    outs = []
    for i, n in enumerate(["1", "2", "2"]):
        env = {**os.environ, "OMP_NUM_THREADS": n, "OPENBLAS_NUM_THREADS": n, "MKL_NUM_THREADS": n}
        out = tmp_path / f"g{i}.npz"
        subprocess.run([sys.executable, str(script), str(out)], env=env, check=True, timeout=300)
        outs.append(out.read_bytes())
    assert outs[0] == outs[1] == outs[2]
