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
    from habitsim.models.t2m_data import CompositionOptions, build_code_set
    from habitsim.models.t2m_train import t2m_preset, train_codegpt

    root = tmp_path_factory.mktemp("bt2m")
    ds = root / "data"
    build_dataset(ds, clips_per_species=11, species=["dog", "cat"], workers=1, progress=False)
    caption_dataset(ds, seed=0)
    ev = root / "ev"
    train_t2m_evaluator(ds, ev, TINY, embed=fake_embed, log=None)
    # two species: hold out one of them per action (the default needs three)
    held = CompositionOptions(min_species=2, min_actions=1)
    build_code_set(ds, root / "codes", embed=fake_embed, text_model="fake-bow", compositions=held)
    ck = root / "ck"
    cfg = t2m_preset("tiny").replace(**{"train.steps": 2, "train.val_every": 1})
    train_codegpt(root / "codes", ck, cfg, log=lambda s: None)
    return ds, ev, ck


def test_held_out_compositions_are_deterministic_and_leave_both_halves_in_training() -> None:
    from habitsim.models.t2m_data import CompositionOptions, held_out_compositions

    pairs = [(sp, a) for sp in ("cat", "cow", "dog", "fox") for a in ("trot", "walk", "jump")]
    pairs.remove(("fox", "jump"))
    held = held_out_compositions(pairs)
    assert held == held_out_compositions(list(reversed(pairs)))
    assert len(held) == 3 and len({a for _, a in held}) == 3  # one pair per action
    kept = set(pairs) - set(held)
    for sp, a in held:  # the species and the action both stay in training
        assert any(s == sp for s, _ in kept) and any(x == a for _, x in kept)
    assert len({sp for sp, _ in held}) == 3  # spread over the species
    # an action of too few species is never held out
    assert held_out_compositions([("cat", "walk"), ("dog", "walk")]) == []
    # a species keeps min_actions (2) of its actions: one pair at most of cat, cow, dog
    # (three actions each) and none of fox (two)
    two = held_out_compositions(pairs, CompositionOptions(per_action=2, min_species=3))
    assert len(two) == 3 and sorted(sp for sp, _ in two) == ["cat", "cow", "dog"]
    more = held_out_compositions(pairs, CompositionOptions(2, min_species=3, min_actions=1))
    assert len(more) == 6 and all(any(x == a for _, x in set(pairs) - set(more)) for _, a in more)


@pytest.mark.slow  # the module's data set, code set, evaluator and checkpoint (about 20 s)
def test_code_set_records_its_held_out_compositions(setup: tuple[Path, Path, Path]) -> None:
    from habitsim.models.t2m_data import COMPOSE_SPLIT, load_code_set

    ds, ev, ck = setup
    cs = load_code_set(ds.parent / "codes")
    held = {tuple(p) for p in cs.meta["compositions"]}
    assert held
    compose = cs.split(COMPOSE_SPLIT)
    assert compose and all(c.species in ("dog", "cat") for c in compose)
    man = json.loads((ds / "manifest.json").read_text())
    action = {c["path"]: c["action"] for c in man["clips"]}
    # every train clip of a held-out pair, and nothing else, is out of training
    assert {(c.species, action[c.source]) for c in compose} == held
    assert all((c.species, action[c.source]) not in held for c in cs.split("train"))


def test_splits_prompts() -> None:
    from habitsim.evaluation.bench.t2m_splits import human_prompts, unsupported_prompts

    hp = human_prompts()
    test = [h for h in hp if h.supported]
    assert len(hp) == 2381 and len(test) > 800
    assert all(h.species and not h.action.startswith("unsupported") for h in test)
    assert {"run", "turn", "walk", "trot", "jump"} <= {h.action for h in test}
    out = unsupported_prompts()
    assert len(out) == len(hp) - len(test) and any(not h.species for h in out)


@pytest.mark.slow
def test_rows_per_split_ground_truth_first(setup: tuple[Path, Path, Path]) -> None:
    ds, ev, ck = setup
    opts = T2MBenchOptions(
        guidances=(0.0, 2.0),
        batch_size=2,
        limit=2,
        unsupported=3,
        physics=1,
        physics_seconds=1.0,
    )
    res = run_t2m(ev, checkpoint=ck, options=opts, embed=fake_embed)
    assert Path(res.data) == ds
    for split in ("val", "compose", "paraphrase"):
        rows = [(r.name, r.guidance) for r in res.rows if r.split == split]
        assert rows == [("ground truth", None), ("generator", 0.0), ("generator", 2.0)]
    assert [(r.name, r.guidance) for r in res.rows if r.split == "human"] == [
        ("generator", 0.0),
        ("generator", 2.0),
    ]
    for r in res.rows:
        assert r.clips == 2 and 0.0 <= r.prompt_agreement <= 1.0
        if r.split != "human":
            assert len(r.r_precision) == 3 and r.fid >= 0 and r.mm_dist >= 0
    # the real clips show the actions their captions name (the measurement's ceiling)
    assert all(r.prompt_agreement == 1.0 for r in res.rows if r.guidance is None)
    assert [p.split for p in res.physics] == ["val", "compose", "paraphrase", "human"]
    for p in res.physics:
        assert p.clips <= 1 and (p.clips == 0 or 0.0 <= p.mean_survival <= 1.0)
    u = res.unsupported
    assert u is not None and u.prompts == 3 and u.refused + u.warned + u.silent == 3
    checks = t2m_checks(res, opts)
    names = [c.name for c in checks]
    assert any(n.startswith("compose: R-precision") for n in names)
    assert any(n.startswith("human: prompt agreement") for n in names)
    only_gt = run_t2m(
        ev,
        data=ds,
        options=T2MBenchOptions(splits=("val",), batch_size=2, limit=2),
        embed=fake_embed,
    )
    assert len(only_gt.rows) == 1 and only_gt.rows[0] == res.rows[0]
    with pytest.raises(BenchT2MError):
        run_t2m(ev, options=opts, embed=fake_embed)


@pytest.mark.slow
def test_command_line(setup: tuple[Path, Path, Path], monkeypatch, capsys, tmp_path) -> None:
    import habitsim.models.text as text_mod
    from habitsim.cli import main

    monkeypatch.setattr(text_mod, "embed_texts", lambda texts, model="": fake_embed(texts))
    ds, ev, ck = setup
    args = ["bench", "t2m", "--evaluator", str(ev), "--checkpoint", str(ck)]
    args += ["--guidance", "1", "--batch-size", "2", "--limit", "2", "--unsupported", "0"]
    assert main([*args, "--splits", "val,human"]) == 0
    out = capsys.readouterr().out
    lines = [s for s in out.splitlines() if "ground truth" in s or "generator" in s]
    assert lines[0].split()[:3] == ["val", "ground", "truth"] and "g=1" in lines[1]
    assert lines[2].split()[0] == "human"
    assert main([*args, "--splits", "val", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert [r["name"] for r in doc["rows"]] == ["ground truth", "generator"]
    assert {t["verdict"] for t in doc["targets"]} <= {"met", "MISSED", "n/a"}
    assert main(["bench", "t2m", "--evaluator", str(tmp_path)]) == 2
    out2 = tmp_path / "ev2"
    cmd = ["t2m", "train-evaluator", "--data", str(ds), "--out", str(out2), "--steps", "0"]
    assert main(cmd) == 2 and not out2.exists()
