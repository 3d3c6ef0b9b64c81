"""The model benchmark (habitsim.evaluation.bench.model, ``habitsim bench model``): phase
error, resting feet and the evaluator's accuracy."""

from __future__ import annotations

import math

import pytest

from habitsim.gaits import generate
from habitsim.motion import Motion


@pytest.mark.usefixtures("torch_one_thread")
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


@pytest.mark.usefixtures("torch_one_thread")
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
