"""One pipeline path: transfer keeps the source's footfalls, the labels travel from stage
to stage, refinement that makes a clip track worse is reported and not kept, one model
cache."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from habitsim.contacts import (
    drop_short_runs,
    fill_support,
    lengthen_stance,
    warp_contacts,
)
from habitsim.errors import InvalidMotionError
from habitsim.gaits import generate
from habitsim.pipeline import PipelineError, refine_mode, run_clip, stance_toe_height
from habitsim.stance.labels import stance_runs

pytestmark = pytest.mark.usefixtures("torch_one_thread")


@pytest.fixture(scope="module")
def walk():
    return generate("dog", "walk", seed=2, duration_s=2.0)


# ---------------------------------------------------------------------------- contacts


def test_drop_short_runs_and_warp() -> None:
    c = np.array([[1, 1, 0, 1, 1, 0, 0, 1, 0, 0, 1]], bool).T
    out = drop_short_runs(c, 2)[:, 0].astype(int).tolist()
    # the one-frame gap is filled, the lone stance frames are removed (also at the end)
    assert out == [1, 1, 1, 1, 1, 0, 0, 0, 0, 0, 0]
    lab = np.zeros((10, 4), bool)
    lab[2:6] = True
    np.testing.assert_array_equal(warp_contacts(lab, 10), lab)
    w = warp_contacts(lab, 19)  # twice the frames over the same span
    assert w.shape == (19, 4) and w[:, 0].sum() == 8 and w[4:11, 0].all()


def test_lengthen_stance_keeps_the_middles_of_the_runs() -> None:
    c = np.zeros((60, 3), bool)
    c[10:20, 0] = c[40:50, 0] = True  # stands 1/3 of the clip
    c[0:6, 1] = True  # a run at the clip's start, 10 %
    c[:45, 2] = True  # already stands 75 %
    out = lengthen_stance(c, 0.5)
    # foot 0: 3 frames more at both ends of both runs, 32 of 60 (2 more give 28 < 30)
    assert stance_runs(out[:, :1]) == [[(7, 23), (37, 53)]]
    # foot 1 grows inward only; foot 2 is kept; nothing else changes
    assert stance_runs(out[:, 1:2]) == [[(0, 30)]]
    np.testing.assert_array_equal(out[:, 2], c[:, 2])
    np.testing.assert_array_equal(lengthen_stance(c, 0.0), c)
    with pytest.raises(InvalidMotionError, match="min_share"):
        lengthen_stance(c, 1.5)
    with pytest.raises(InvalidMotionError, match="shape"):
        lengthen_stance(c[:, 0], 0.5)


def test_fill_support_lengthens_the_nearest_run() -> None:
    c = np.zeros((30, 4), bool)
    c[0:10, 0] = c[12:30, 0] = True  # foot 0 lifts for frames 10-11
    c[0:8, 1] = True  # foot 1 lifted off at frame 8 ...
    c[15:30, 1] = True  # ... and lands again at 15
    c[:, 2] = False  # foot 2 never stands
    c[0:3, 3] = c[25:30, 3] = True
    out = fill_support(c, 2)
    assert (out.sum(axis=1) >= 2).all()
    assert (out | ~c).all()  # stance only grows
    # frames 8-14 had one foot or none: each short frame took the nearest run, one frame
    # at a time (foot 1 held on from frame 8, foot 0 from frame 10, foot 1 again from 12):
    # both gaps close, feet 2 and 3 are untouched
    assert out[:, 0].all() and out[:, 1].all()
    np.testing.assert_array_equal(out[:, 3], c[:, 3])
    np.testing.assert_array_equal(out[:, 2], c[:, 2])
    # a frame no run can reach stays short
    lone = np.zeros((5, 2), bool)
    lone[:, 0] = True
    np.testing.assert_array_equal(fill_support(lone, 2), lone)
    np.testing.assert_array_equal(fill_support(c, 0), c)
    with pytest.raises(InvalidMotionError, match="min_feet"):
        fill_support(c, 5)
    with pytest.raises(InvalidMotionError, match="shape"):
        fill_support(c[:, 0], 2)


# ---------------------------------------------------------------------------- pipeline


def test_refine_modes() -> None:
    assert [refine_mode(m) for m in ("none", "A", "B", "kinematic", "dynamics")] == [
        "none",
        "A",
        "B",
        "A",
        "B",
    ]
    with pytest.raises(PipelineError, match="valid: .*A"):
        refine_mode("fast")
    with pytest.raises(PipelineError, match="Motion"):
        run_clip("not a motion", "cat")  # type: ignore[arg-type]


def test_labels_travel_without_refinement(walk) -> None:
    run = run_clip(walk, "cat", method="direct", refine="none", track=False)
    assert run.transferred.contacts_method == "source"
    np.testing.assert_array_equal(run.transferred.contacts, walk.contacts)
    assert run.refined.contacts is run.transferred.contacts and run.refined.status == "none"
    assert run.refine_verdict == "none" and run.tracked.status == "off"
    assert set(run.times) == {"transfer", "refine", "track"}
    assert run.transferred.qpos.shape == (walk.num_frames, run.model.nq)
    assert run.source.contacts_method == "labels"
    assert run.source.metrics["stance_toe_height_per_leg"] == pytest.approx(
        stance_toe_height(walk, walk.contacts)
    )


@pytest.mark.slow
def test_refined_labels_reach_tracking_and_a_worse_refinement_is_reverted(
    walk, monkeypatch
) -> None:
    import habitsim.pipeline as pl

    run = run_clip(walk, "cat", method="direct", refine="A", controller="servo")
    assert run.refined.status != "none" and run.refine_result is not None
    np.testing.assert_array_equal(run.refined.contacts, run.transferred.contacts)
    # tracking got the refined labels as its reference schedule, detected nothing itself
    np.testing.assert_array_equal(run.track_result.reference_contacts, run.refined.contacts)
    assert run.refine_verdict in ("kept", "reverted")  # the refinement succeeded
    assert run.tracked.metrics["survival"] == run.track_result.survival
    monkeypatch.setattr(pl, "_worse", lambda refined, plain, *_: "survival 0.10 < 1.00 unrefined")
    bad = run_clip(walk, "cat", method="direct", refine="A", controller="servo")
    assert bad.refine_verdict == "reverted" and bad.refine_note
    assert bad.track_result is bad.input_track_result and bad.reference is bad.transferred.motion
    np.testing.assert_array_equal(bad.track_result.reference_contacts, bad.transferred.contacts)


def test_worse_rule() -> None:
    from habitsim.pipeline import GuardOptions, _worse

    def res(s: float, e: float) -> SimpleNamespace:
        return SimpleNamespace(survival=s, metrics={"sim_mpjpe_per_leg": e})

    assert "survival" in _worse(res(0.5, 0.01), res(1.0, 0.2))
    assert "MPJPE" in _worse(res(1.0, 0.20), res(1.0, 0.10))
    assert _worse(res(1.0, 0.105), res(1.0, 0.10)) is None  # not clearly higher
    assert _worse(res(1.0, 0.5), res(0.5, 0.01)) is None  # survives longer
    strict = GuardOptions(mpjpe_ratio=1.0, mpjpe_margin_per_leg=0.0)  # any rise is worse
    assert "MPJPE" in _worse(res(1.0, 0.105), res(1.0, 0.10), strict)


def test_one_model_cache_and_explicit_track_contacts(walk) -> None:
    from habitsim.qpos import species_model
    from habitsim.sim import SimulationError, _species_model, track

    assert species_model("dog") is species_model("dog", False) is _species_model("dog", False)
    assert species_model("dog", servos=True) is _species_model("dog", True)
    with pytest.raises(SimulationError, match=r"contacts must have shape \(60, 4\)"):
        track(walk.slice(0, 60), contacts=np.ones((10, 4), bool))
