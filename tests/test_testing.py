"""habitsim.testing helpers and the pytest plugin (run in a sandbox with pytester)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from helpers import UNWRITABLE, _typed_output_error

from habitsim.errors import OutputPathError
from habitsim.gaits import generate
from habitsim.testing import (
    GoldenMissingError,
    Tolerance,
    assert_matches_golden,
    assert_plausible,
    compare_figures,
    plausibility_violations,
    write_golden,
)


def test_clean_synthetic_clip_is_plausible() -> None:
    m = generate("dog", "trot", seed=0)
    assert_plausible(m, use_contacts=True)


def test_sliding_feet_are_caught_with_a_readable_message() -> None:
    m = generate("dog", "walk", seed=0)
    root = m.root_positions.copy()
    root[:, 0] += 0.01 * np.arange(m.num_frames)  # the whole body slides 1 cm per frame
    from habitsim.motion import Motion

    bad = Motion(
        species="dog", fps=m.fps, root_positions=root, rotations=m.rotations, contacts=m.contacts
    )
    viol = plausibility_violations(bad, use_contacts=True)
    assert "skate_per_leg" in viol
    with pytest.raises(AssertionError, match=r"skate_per_leg = .* > 0.002"):
        assert_plausible(bad, use_contacts=True)
    assert_plausible(bad, use_contacts=True, skate_per_leg=None)  # that bound switched off


@pytest.mark.parametrize("use_contacts", [False, True])
def test_failure_names_the_keyword_that_changes_each_bound(use_contacts: bool) -> None:
    m = generate("dog", "walk", seed=0, duration_s=1.0)
    root = m.root_positions.copy()
    root[:, 0] += 0.01 * np.arange(m.num_frames)  # stance feet slide 1 cm per frame
    root[:, 2] -= 0.002  # and sink 2 mm into the floor
    from habitsim.motion import Motion

    bad = Motion("dog", m.fps, root, m.rotations, m.contacts)
    bounds = dict(skate_per_leg=0.002, penetration_per_leg=1e-9)
    with pytest.raises(AssertionError) as info:
        assert_plausible(bad, use_contacts=use_contacts, **bounds)
    text = str(info.value)
    for key in bounds:  # each violated bound's keyword, as it is passed
        assert f"{key}=" in text
    assert "PlausibilityBounds" in text
    assert ("use_contacts=True" in text) is not use_contacts
    for key, value in bounds.items():  # raising it by that keyword passes
        bounds[key] = 10 * value + 1.0
    assert_plausible(bad, use_contacts=use_contacts, **bounds)


def test_unknown_bound_is_a_typed_error() -> None:
    from habitsim.errors import HabitsimError

    with pytest.raises(HabitsimError, match="valid"):
        assert_plausible(generate("cat", "idle", seed=0), skating=1.0)


def test_compare_figures_tolerances_and_nan() -> None:
    devs = {
        d.key: d
        for d in compare_figures(
            {"a": 1.05, "b": 2.0, "c": math.nan, "new": 1.0},
            {"a": 1.0, "b": 2.0, "c": math.nan, "gone": 3.0},
            {"a": Tolerance(abs=0.0, rel=0.1)},
        )
    }
    assert devs["a"].ok and devs["b"].ok and devs["c"].ok
    assert not devs["new"].ok and not devs["gone"].ok
    devs = {d.key: d for d in compare_figures({"a": 1.2}, {"a": 1.0}, {"a": (0.0, 0.1)})}
    assert not devs["a"].ok and devs["a"].diff == pytest.approx(0.2)


def test_golden_round_trip_and_diff(tmp_path) -> None:
    path = tmp_path / "g.json"
    with pytest.raises(GoldenMissingError, match="update-goldens"):
        assert_matches_golden({"survival": 1.0}, path)
    write_golden(
        path,
        {"survival": 1.0, "sim_mpjpe_mm": 20.0, "jerk": math.nan},
        {"sim_mpjpe_mm": {"abs": 1.0}},
    )
    doc = json.loads(path.read_text())
    assert "mujoco" in doc["versions"] and doc["figures"]["jerk"] is None
    assert_matches_golden({"survival": 1.0, "sim_mpjpe_mm": 20.9, "jerk": math.nan}, path)
    with pytest.raises(AssertionError) as e:
        assert_matches_golden({"survival": 0.0, "sim_mpjpe_mm": 20.5, "jerk": math.nan}, path)
    msg = str(e.value)
    assert "survival" in msg and "MOVED" in msg and "sim_mpjpe_mm" not in msg


@pytest.mark.slow
def test_plugin_fixtures_in_a_user_suite(pytester: pytest.Pytester) -> None:
    pytester.makepyfile(
        test_user="""
        import mujoco

        def test_model(habitsim_species_model):
            m = habitsim_species_model("cat")
            assert isinstance(m, mujoco.MjModel) and m.nu > 20

        def test_clip_plausible(habitsim_clip, habitsim_assert_plausible):
            clip = habitsim_clip("cat", "walk", seed=1)
            habitsim_assert_plausible(clip, use_contacts=True)

        def test_golden(habitsim_clip, habitsim_golden):
            clip = habitsim_clip("cat", "walk", seed=1)
            habitsim_golden({"frames": clip.num_frames, "froude": clip.metadata["froude"]})
        """
    )
    first = pytester.runpytest("-q")
    first.assert_outcomes(passed=2, failed=1)  # no golden recorded yet
    first.stdout.fnmatch_lines(["*habitsim-update-goldens*"])
    rec = pytester.runpytest("-q", "--habitsim-update-goldens")
    rec.assert_outcomes(passed=3)
    assert (pytester.path / "goldens" / "test_user" / "test_golden.json").is_file()
    again = pytester.runpytest("-q")
    again.assert_outcomes(passed=3)
    # a moved figure fails with the table
    golden = pytester.path / "goldens" / "test_user" / "test_golden.json"
    doc = json.loads(golden.read_text())
    doc["figures"]["frames"] += 10
    golden.write_text(json.dumps(doc))
    moved = pytester.runpytest("-q")
    moved.assert_outcomes(passed=2, failed=1)
    moved.stdout.fnmatch_lines(["*frames*MOVED*"])


@pytest.mark.parametrize("unwritable", UNWRITABLE, indirect=True)
def test_write_golden_unwritable(unwritable: Path) -> None:
    from habitsim.testing import write_golden

    with pytest.raises(OutputPathError) as ei:
        write_golden(unwritable / "g.json", {"x": 1.0})
    _typed_output_error(ei.value)
