"""The text–motion evaluator: its training, checkpoint and the R-precision / MM-Dist it
is scored with."""

from __future__ import annotations

import json
import zlib
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pytest

from habitsim.evaluation.evaluator import EvaluatorError
from habitsim.evaluation.t2m_evaluator import (
    T2MEvaluatorConfig,
    load_t2m_evaluator,
    matching_distance,
    r_precision,
    train_t2m_evaluator,
)

#: width of the fake sentence embeddings
DIM = 16


def fake_embed(texts: Sequence[str]) -> np.ndarray:
    """Deterministic bag-of-words embeddings (unit length)."""
    out = np.zeros((len(texts), DIM), np.float32)
    for i, t in enumerate(texts):
        for w in t.lower().replace(".", " ").replace(",", " ").split():
            out[i] += np.random.default_rng(zlib.crc32(w.encode())).standard_normal(DIM)
        out[i] /= max(float(np.linalg.norm(out[i])), 1e-6)
    return out


TINY = T2MEvaluatorConfig(
    text_model="fake-bow",
    d_model=16,
    n_heads=2,
    n_layers=1,
    ff_dim=32,
    embed_dim=16,
    text_hidden=32,
    steps=60,
    batch_size=8,
    lr=3e-3,
    crop_s=2.0,
)


@pytest.fixture(scope="module")
def captioned(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from habitsim.captions.store import caption_dataset
    from habitsim.dataset import build_dataset

    ds = tmp_path_factory.mktemp("t2mev") / "data"
    build_dataset(ds, clips_per_species=6, species=["dog", "cat"], workers=1, progress=False)
    caption_dataset(ds, seed=0)
    return ds


def test_r_precision_of_a_perfect_embedding_is_one() -> None:
    rng = np.random.default_rng(0)
    z = rng.standard_normal((32, 8))
    assert r_precision(z, z).tolist() == [1.0, 1.0, 1.0]
    assert matching_distance(z, z) == 0.0


def test_r_precision_hand_computed() -> None:
    # 1-D embeddings: motions at 0, 1, 3, 6; texts placed so that text 0 ranks its
    # motion 1st, text 1 ranks it 2nd (motion 2 closer), text 2 3rd, text 3 4th.
    motion = np.array([[0.0], [1.0], [3.0], [6.0]])
    text = np.array([[0.0], [2.4], [0.9], [0.0]])
    # text 1 at 2.4: distances 2.4, 1.4, 0.6, 3.6 -> own motion (1.4) is 2nd
    # text 2 at 0.9: distances 0.9, 0.1, 2.1, 5.1 -> own motion (2.1) is 3rd
    # text 3 at 0.0: own motion (6) is last
    assert r_precision(text, motion).tolist() == [0.25, 0.5, 0.75]
    assert r_precision(text, motion, top_k=4)[-1] == 1.0
    assert matching_distance(text, motion) == pytest.approx((0 + 1.4 + 2.1 + 6) / 4)
    with pytest.raises(EvaluatorError):
        r_precision(text, motion[:3])


@pytest.mark.slow
def test_training_improves_retrieval_and_round_trips(captioned: Path, tmp_path: Path) -> None:
    out = tmp_path / "ev"
    rep = train_t2m_evaluator(captioned, out, TINY, embed=fake_embed, log=None)
    n = min(rep.pairs, TINY.batch_size)
    chance = 3 / n
    assert rep.retrieval["train"][2] > chance + 0.2, rep.retrieval
    ev = load_t2m_evaluator(out)
    assert ev.config.text_dim == DIM and ev.config.text_model == "fake-bow"
    zt = ev.embed_texts(["a dog walks", "a cat trots"], fake_embed)
    assert zt.shape == (2, TINY.embed_dim)
    np.testing.assert_allclose(np.linalg.norm(zt, axis=1), 1.0, rtol=1e-5)
    with pytest.raises(EvaluatorError):
        ev.embed_texts(["a dog"], lambda t: np.zeros((1, DIM + 1), np.float32))


def test_bad_checkpoints_and_configs(tmp_path: Path, captioned: Path) -> None:
    with pytest.raises(EvaluatorError):
        load_t2m_evaluator(tmp_path)
    (tmp_path / "model.safetensors").write_bytes(b"x")
    (tmp_path / "config.json").write_text(json.dumps({"kind": "other"}))
    with pytest.raises(EvaluatorError):
        load_t2m_evaluator(tmp_path)
    with pytest.raises(EvaluatorError):
        T2MEvaluatorConfig(batch_size=1)
    with pytest.raises(EvaluatorError):
        T2MEvaluatorConfig.from_dict({"nope": 1})
    nocap = tmp_path / "nocap"
    nocap.mkdir()
    with pytest.raises(EvaluatorError):
        train_t2m_evaluator(nocap, tmp_path / "o", TINY, embed=fake_embed, log=None)
    assert not (tmp_path / "o").exists()
