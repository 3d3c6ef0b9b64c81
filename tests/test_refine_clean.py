"""Refinement leaves clean input alone: only what violates a target moves
(docs/refine.md, "What moves and what does not")."""

from __future__ import annotations

import numpy as np
import pytest

import habitsim
from habitsim.metrics.kinematic import skate_mm
from habitsim.qpos import motion_to_qpos
from habitsim.refine import RefineOptions, inject_artefacts, refine
from habitsim.refine.cache import _species_model
from habitsim.refine.clearance import swing_clearance
from habitsim.refine.filtering import jitter_autocorr
from habitsim.refine.model_facts import model_info
from habitsim.refine.verdict import input_change


def _walk(frames: int = 64, seed: int = 7) -> habitsim.Motion:
    return habitsim.generate("dog", "walk", seed=seed, fps=30.0, duration_s=frames / 30.0)


def test_jitter_is_told_from_smooth_motion():
    """The pre-filter's test: frame-to-frame noise leaves an anti-correlated remainder,
    a clean gait a smooth one."""
    clean = _walk(90)
    model = _species_model("dog")
    info = model_info(model)
    f_c = RefineOptions().cutoff_hz(clean.species_info.leg_length)
    assert f_c is not None
    threshold = RefineOptions().jitter_autocorr
    assert threshold is not None

    def score(m: habitsim.Motion) -> float:
        return jitter_autocorr(motion_to_qpos(m, model).qpos, info, m.fps, f_c)

    assert score(clean) >= threshold
    assert score(inject_artefacts(clean, ["jitter"], seed=1)) < threshold
    with pytest.raises(habitsim.HabitsimError):
        RefineOptions(jitter_autocorr=2.0)


def test_a_still_swing_toe_stays_down_a_moving_one_is_lifted():
    """A foot the input lifts a frame after its label is pinned on the ground, not lifted
    to the clearance; one that moves while low still gets the clearance."""
    t, leg = 30, 0.6
    c = np.ones((t, 4), bool)
    c[10:20] = False  # one swing run per foot
    toes = np.zeros((t, 4, 3))
    toes[10:20, :, 2] = 0.05  # high in swing …
    toes[10, :, 2] = 0.001  # … except its first frame, still on the foothold
    toes[10, 1, 0] = 0.05  # foot 1 moves 5 cm there (a skate)
    plain, _ = swing_clearance(c, 30.0, leg)
    floor, pins = swing_clearance(c, 30.0, leg, toes=toes, still=0.01 * leg)
    full = 0.025 * leg
    assert plain[10, 0] == pytest.approx(full)  # without the input's toes: lifted
    assert floor[10, 0] == 0.0 and pins[9, 0]  # still: on the ground, pinned
    assert floor[10, 1] == pytest.approx(full) and not pins[9, 1]  # moving: lifted
    assert np.allclose(floor[11:19, 0], plain[11:19, 0])  # the rest of the swing as before


def test_a_four_second_clip_is_one_window():
    opts = RefineOptions()
    assert [w.length for w in opts.plan(120)] == [120]
    assert len(opts.plan(121)) == 2 and {w.length for w in opts.plan(121)} == {100}


@pytest.mark.slow
def test_refining_a_clean_clip_moves_it_by_under_one_percent_of_leg_length():
    clean = _walk()
    res = refine(clean, RefineOptions(metrics=False))
    change = input_change(clean, res.motion)
    assert res.success and change["max"] <= 0.01
    assert res.report["change_per_leg"]["max"] == pytest.approx(change["max"])
    assert res.report["filter"]["applied"] is False
    assert skate_mm(res.motion) <= skate_mm(clean) + 0.05


@pytest.mark.slow
def test_an_injected_skate_is_still_removed():
    clean = _walk()
    bad = inject_artefacts(clean, ["slide"], seed=2)
    res = refine(bad, RefineOptions(metrics=False))
    assert skate_mm(bad) > 1.0
    assert res.success and skate_mm(res.motion) <= 0.05
    assert res.report["checks"]["stance_drift_max_mm"] <= 0.1
