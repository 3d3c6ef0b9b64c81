"""Conforming a decoded motion (habitsim.stance.conform): its policy and its typed report."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from habitsim.errors import HabitsimError
from habitsim.gaits import generate
from habitsim.stance.conform import conform
from habitsim.stance.planting import PlantReport
from habitsim.stance.policy import ConformPolicy, ConformPolicyError, resolve_policy
from habitsim.stance.report import ConformReport, PlantOutcome, PlantReason


@pytest.fixture(scope="module")
def walk():
    return generate("dog", "walk", seed=2, duration_s=2.0)


def test_policy_defaults_and_validation() -> None:
    p = ConformPolicy()
    assert resolve_policy(None) == p and resolve_policy(p) is p
    assert p.foothold_rules == (False, True) and p.heading_band == pytest.approx(math.pi / 4)
    assert all(getattr(p, s) for s in ("swing_lift", "level_trunk", "trim_to_reach"))
    with pytest.raises(AttributeError):
        p.speed_band = 2.0  # type: ignore[misc]  # frozen
    for bad in (
        {"speed_band": 0.5},
        {"walk_min_feet": 5},
        {"foothold_rules": ()},
        {"foothold_rules": [True]},
        {"plant_max_reach_per_leg": -0.1},
        {"partial_passes": -1},
        {"min_source_agreement": 1.5},
        {"heading_smooth_s": 0.0},
        {"level_max_pitch": float("nan")},
    ):
        with pytest.raises(ConformPolicyError) as err:
            replace(p, **bad)
        assert isinstance(err.value, HabitsimError) and next(iter(bad)) in str(err.value)
    # the switches' off values are valid
    replace(p, restep_min_period=math.inf, partial_passes=0, walk_min_feet=0)


def test_conform_reports_the_typed_planting_and_writes_the_metadata_from_it(walk) -> None:
    # a cat walking where the dog walks, planted on the dog's footfalls
    cat = generate("cat", like=walk)
    info = {"method": "test"}
    out, report = conform(cat, walk, info, plant=True)
    assert isinstance(report, ConformReport) and isinstance(report.planted, PlantOutcome)
    planted = report.planted
    assert planted.kept and planted.root in ("decoded", "carried")
    assert isinstance(planted.planting.report, PlantReport)
    assert planted.planting.reaches(ConformPolicy())
    # the metadata is the report's, rounded
    meta = out.metadata["transfer"]
    assert meta == report.to_metadata(info) and meta["method"] == "test"
    assert meta["planted"]["max_reach_error_per_leg"] == round(
        planted.planting.max_reach_error_per_leg, 5
    )
    assert meta["planted"]["max_pelvis_drop_per_leg"] == round(
        float(planted.planting.report.pelvis_drop.max()) / cat.species_info.leg_length, 5
    )
    assert out.num_frames == walk.num_frames and out.contacts is not None
    # without planting: nothing planted, the labels the same
    bare, none = conform(cat, walk, info)
    assert none.planted is None and bare.metadata["transfer"]["planted"] is False
    np.testing.assert_array_equal(bare.contacts, out.contacts)


def test_a_policy_switches_the_planting_rungs(walk) -> None:
    cat = generate("cat", like=walk)
    # limits no leg meets: no rule reaches, no fallback either
    strict = ConformPolicy(
        plant_max_reach_per_leg=0.0,
        plant_max_drop_per_leg=0.0,
        plant_min_speed_ratio=1.0,
        restep_min_period=math.inf,
        partial_passes=0,
        level_trunk=False,
    )
    out, report = conform(cat, walk, plant=True, policy=strict)
    assert report.planted is not None and not report.planted.kept
    assert report.planted.restep_tried is None and report.levelled is None
    assert report.planted.reason_codes[-1] is PlantReason.DECODED_FEET_KEPT
    np.testing.assert_allclose(out.rotations, conform(cat, walk)[0].rotations)
    # one foothold rule: that rule's footholds
    _, centred = conform(cat, walk, plant=True, policy=ConformPolicy(foothold_rules=(True,)))
    assert centred.planted is not None and centred.planted.planting.footholds == "centred"
