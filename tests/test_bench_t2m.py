"""``habitsim bench t2m``: the batched R-precision, the table's rows and the command."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from test_t2m_evaluator import TINY, fake_embed

from habitsim.evaluation.bench.t2m import (
    BenchT2MError,
    T2MBenchOptions,
    batched_r_precision,
    run_t2m,
    t2m_checks,
)


def test_batched_r_precision_drops_the_incomplete_batch() -> None:
    rng = np.random.default_rng(0)
    z = rng.standard_normal((70, 6))
    rp, batches = batched_r_precision(z, z, 32, 3, seed=0)
    assert batches == 2 and rp.tolist() == [1.0, 1.0, 1.0]
    # all texts at 0; only text 3 sits on its motion. Texts 0-2 see motion 3 closer than
    # their own, and the two other motions at the same distance as their own (a tie does
    # not push the true motion down): their motion ranks 2nd.
    text = np.zeros((4, 1))
    motion = np.array([[1.0], [1.0], [1.0], [0.0]])
    rp, batches = batched_r_precision(text, motion, 4, 3, seed=1)
    assert batches == 1 and rp.tolist() == [0.25, 1.0, 1.0]
    with pytest.raises(BenchT2MError):
        batched_r_precision(z[:10], z[:10], 32, 3, seed=0)


@pytest.fixture(scope="module")
def setup(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, Path]:
    from habitsim.captions.store import caption_dataset
    from habitsim.dataset import build_dataset
    from habitsim.evaluation.t2m_evaluator import train_t2m_evaluator
    from habitsim.models.t2m_data import build_code_set
    from habitsim.models.t2m_train import t2m_preset, train_codegpt

    root = tmp_path_factory.mktemp("bt2m")
    ds = root / "data"
    build_dataset(ds, clips_per_species=11, species=["dog", "cat"], workers=1, progress=False)
    caption_dataset(ds, seed=0)
    ev = root / "ev"
    train_t2m_evaluator(ds, ev, TINY, embed=fake_embed, log=None)
    build_code_set(ds, root / "codes", embed=fake_embed, text_model="fake-bow")
    ck = root / "ck"
    cfg = t2m_preset("tiny").replace(**{"train.steps": 2, "train.val_every": 1})
    train_codegpt(root / "codes", ck, cfg, log=lambda s: None)
    return ds, ev, ck


@pytest.mark.slow
def test_ground_truth_first_then_each_guidance(setup: tuple[Path, Path, Path]) -> None:
    ds, ev, ck = setup
    opts = T2MBenchOptions(guidances=(0.0, 2.0), batch_size=2, limit=2)
    res = run_t2m(ev, checkpoint=ck, options=opts, embed=fake_embed)
    assert Path(res.data) == ds and res.batches == 1
    assert [(r.name, r.guidance) for r in res.rows] == [
        ("ground truth", None),
        ("generator", 0.0),
        ("generator", 2.0),
    ]
    for r in res.rows:
        assert r.clips == 2 and len(r.r_precision) == 3 and r.fid >= 0 and r.mm_dist >= 0
    checks = t2m_checks(res, opts)
    assert len(checks) == 4 and all(c.verdict in ("met", "MISSED") for c in checks)
    only_gt = run_t2m(ev, data=ds, options=opts, embed=fake_embed)
    assert len(only_gt.rows) == 1 and only_gt.rows[0] == res.rows[0]
    with pytest.raises(BenchT2MError):
        run_t2m(ev, options=opts, embed=fake_embed)
    with pytest.raises(BenchT2MError):
        run_t2m(ev, data=ds, options=T2MBenchOptions(batch_size=500), embed=fake_embed)


@pytest.mark.slow
def test_command_line(setup: tuple[Path, Path, Path], monkeypatch, capsys, tmp_path) -> None:
    import habitsim.models.text as text_mod
    from habitsim.cli import main

    monkeypatch.setattr(text_mod, "embed_texts", lambda texts, model="": fake_embed(texts))
    ds, ev, ck = setup
    args = ["bench", "t2m", "--evaluator", str(ev), "--checkpoint", str(ck)]
    args += ["--guidance", "1", "--batch-size", "2", "--limit", "2"]
    assert main(args) == 0
    out = capsys.readouterr().out
    lines = [s for s in out.splitlines() if "ground truth" in s or "generator" in s]
    assert lines[0].strip().startswith("ground truth") and "g=1" in lines[1]
    assert main([*args, "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert [r["name"] for r in doc["rows"]] == ["ground truth", "generator"]
    assert {t["verdict"] for t in doc["targets"]} <= {"met", "MISSED"}
    assert main(["bench", "t2m", "--evaluator", str(tmp_path)]) == 2
    out2 = tmp_path / "ev2"
    cmd = ["t2m", "train-evaluator", "--data", str(ds), "--out", str(out2), "--steps", "0"]
    assert main(cmd) == 2 and not out2.exists()
