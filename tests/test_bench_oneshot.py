"""``habitsim bench oneshot``: options, summaries, targets, and one tiny run."""

from __future__ import annotations

import math

import pytest

from habitsim.evaluation.bench.oneshot import (
    OneshotError,
    OneshotOptions,
    OneshotResult,
    PairRow,
    column_summary,
    oneshot_checks,
    run_oneshot,
)


@pytest.mark.parametrize(
    "bad",
    [
        {"species": ()},
        {"ks": (0,)},
        {"sources": -1},
        {"physics": -2},
        {"duration_s": 0.0},
    ],
)
def test_bad_options_are_typed_errors(bad: dict) -> None:
    with pytest.raises(OneshotError):
        run_oneshot(OneshotOptions(**bad))


def test_column_summary_means_and_habit_accuracy() -> None:
    rows = [
        PairRow("cat", "K=1", "dog walk", "walk", 10.0, 4.0, 0.1, 0.02, "cat"),
        PairRow("cat", "K=1", "cow trot", "trot", 20.0, 6.0, 0.3, 0.04, "dog"),
        PairRow("tiger", "K=1", "cow trot", "trot", 30.0, 8.0, 0.2, math.nan, "cat"),
    ]
    rows[0].survival, rows[0].sim_mpjpe_per_leg = 1.0, 0.05
    s = column_summary(rows, known=("cat", "dog"))
    assert s["pairs"] == 3 and s["paired_pct"] == pytest.approx(20.0)
    assert s["pose_pct"] == pytest.approx(6.0) and s["phase_error"] == pytest.approx(0.2)
    assert s["duty_error"] == pytest.approx(0.03)  # the NaN left out
    assert s["judged"] == 2 and s["habit_accuracy"] == pytest.approx(0.5)  # tiger unknown
    assert s["physics_runs"] == 1 and s["survival"] == 1.0


def _result(retrieval: float, k1: float, k10: float, oracle: float) -> OneshotResult:
    res = OneshotResult(columns=("retrieval", "K=1", "K=10", "oracle"))
    for col, v in (("retrieval", retrieval), ("K=1", k1), ("K=10", k10), ("oracle", oracle)):
        res.rows.append(PairRow("cat", col, "dog walk", "walk", 50.0, v, predicted="cat"))
    res.fits["cat"] = {"oracle": {"method": "prior"}}
    res.summaries = {
        "all": {
            c: column_summary([r for r in res.rows if r.column == c], ("cat",)) for c in res.columns
        }
    }
    return res


def test_targets_met_and_missed() -> None:
    opts = OneshotOptions(species=("cat",), ks=(1, 10))
    met = {t.name: t.verdict for t in oneshot_checks(_result(20.0, 14.0, 11.0, 10.0), opts)}
    assert set(met.values()) == {"met"} and len(met) == 3
    missed = {t.name: t.verdict for t in oneshot_checks(_result(20.0, 18.0, 13.0, 10.0), opts)}
    assert missed["K=1 pose MPJPE below retrieval's"] == "MISSED"
    assert missed["K=10 pose MPJPE over the oracle's"] == "MISSED"
    assert missed["K=1 habit accuracy"] == "met"


@pytest.mark.slow
def test_tiny_run_has_every_column_and_ground_truth() -> None:
    opts = OneshotOptions(species=("cat",), ks=(1,), sources=2)
    res = run_oneshot(opts)
    assert res.neighbours == {"cat": "dog"}  # the retrieval among the other species
    assert [r.column for r in res.rows] == ["retrieval"] * 2 + ["K=1"] * 2 + ["oracle"] * 2
    fit = res.fits["cat"]["K=1"]
    assert (
        fit["k"] == 1 and fit["habit_species"] == "dog" and fit["fit_loss"] < fit["fit_loss_start"]
    )
    assert set(res.summaries) == {"all", "trained"}  # the checkpoint trained on the cat
    for col in ("retrieval", "K=1", "oracle"):
        s = res.summaries["all"][col]
        assert s["pairs"] == 2 and 0 < s["pose_pct"] < s["paired_pct"]
        assert s["judged"] == 2 and math.isfinite(s["fid"]) and 0 <= s["one_nna"] <= 1
    k1 = [r.pose_pct for r in res.rows if r.column == "K=1"]
    oracle = [r.pose_pct for r in res.rows if r.column == "oracle"]
    assert k1 != oracle  # the latent changes the transfer
    assert res.per_species["cat"]["K=1"] == pytest.approx(sum(k1) / 2)
    assert [t.name for t in oneshot_checks(res, opts)] == [
        "K=1 pose MPJPE below retrieval's",
        "K=1 habit accuracy",
    ]
