"""Chained clips of the gait generator (habitsim.gaits.chain)."""

from __future__ import annotations

import numpy as np
import pytest

from habitsim.errors import GaitError
from habitsim.gaits import (
    allowed_transitions,
    available_actions,
    chain_min_duration,
    draw_chain,
    generate,
    generate_chain,
    speed_ladder,
)
from habitsim.metrics.kinematic import kinematic_metrics, skate_mm


def _chain(species: str, steps: list[tuple[str, float]], seed: int = 3):
    steps = [(a, max(d, chain_min_duration(species, a))) for a, d in steps]
    return generate_chain(species, steps, seed=seed)


@pytest.fixture(scope="module")
def speeds_up():
    return _chain("dog", [("walk", 2.0), ("trot", 2.0), ("gallop", 2.0)])


@pytest.fixture(scope="module")
def sits_down():
    return _chain("dog", [("walk", 2.0), ("turn_left", 2.0), ("stop", 2.0), ("sit", 3.0)])


def test_speed_ladder_and_transitions_follow_the_species() -> None:
    assert speed_ladder("horse") == ["walk", "trot", "canter", "gallop"]
    assert speed_ladder("camel") == ["walk", "pace", "gallop"]
    horse = allowed_transitions("horse")
    assert horse["walk"] == ["trot", "turn_left", "turn_right", "stop"]
    assert "gallop" not in horse["walk"] and "stop" not in horse["gallop"]
    assert horse["stop"] == ["idle", "sit"] and horse["sit"] == []
    for sp in ("dog", "bear", "elephant", "rabbit"):
        have = set(available_actions(sp)) | {"stop"}
        for a, nxt in allowed_transitions(sp).items():
            assert a in have and set(nxt) <= have, (sp, a)


def test_segments_and_transitions_in_the_metadata(speeds_up) -> None:
    ch = speeds_up.metadata["chain"]
    assert [s["action"] for s in ch["segments"]] == ["walk", "trot", "gallop"]
    assert [s["gait"] for s in ch["segments"]] == ["walk", "trot", "rotary_gallop"]
    ends = [s["end_s"] for s in ch["segments"]]
    assert ends[-1] == pytest.approx(speeds_up.num_frames / speeds_up.fps)
    speeds = [s["mean_speed_mps"] for s in ch["segments"]]
    assert speeds[0] < speeds[1] < speeds[2]
    for tr, bnd in zip(ch["transitions"], ends[:-1], strict=True):
        assert tr["start_s"] < bnd < tr["end_s"]
        assert 0.3 < tr["end_s"] - tr["start_s"] < 1.5
    assert speeds_up.metadata["action"] == "chain"
    assert speeds_up.metadata["gait"] == "walk+trot+rotary_gallop"


def test_stance_feet_stay_planted_through_the_changes(speeds_up, sits_down) -> None:
    for m in (speeds_up, sits_down):
        assert skate_mm(m, m.contacts) < 1e-6
        km = kinematic_metrics(m)
        assert km["penetration_mm"] < 0.5
        # the height criterion (as for every clip) stays within single clips' figures
        assert km["skate_mm"] < 3.0
        assert m.metadata["max_stance_reach_error_mm"] < 0.5


def test_stop_then_sit_comes_to_rest_and_sits(sits_down) -> None:
    m = sits_down
    seg = {s["action"]: s for s in m.metadata["chain"]["segments"]}
    t = np.arange(m.num_frames) / m.fps
    root = m.root_positions
    after = t >= seg["sit"]["start_s"]
    travel = np.linalg.norm(np.diff(root[after, :2], axis=0), axis=-1).sum()
    single = generate("dog", "sit", seed=3).root_positions
    single_travel = np.linalg.norm(np.diff(single[:, :2], axis=0), axis=-1).sum()
    assert travel < 1.5 * single_travel  # the trunk's shift of sitting down only
    assert m.contacts[after].all()
    assert root[-1, 2] < 0.85 * root[0, 2]  # the pelvis came down
    yaw_turned = m.metadata["chain"]["segments"][1]["turn_rate"]
    assert yaw_turned > 0  # a left turn


def test_a_chain_is_seeded() -> None:
    steps = [("walk", 1.5), ("trot", 1.5)]
    a = generate_chain("cat", steps, seed=5)
    b = generate_chain("cat", steps, seed=5)
    c = generate_chain("cat", steps, seed=6)
    np.testing.assert_array_equal(a.rotations, b.rotations)
    assert not np.allclose(a.rotations, c.rotations)


def test_a_start_from_standing() -> None:
    m = _chain("dog", [("idle", 1.5), ("walk", 2.0)])
    t = np.arange(m.num_frames) / m.fps
    assert m.contacts[t < 1.4].all()
    assert np.linalg.norm(m.root_positions[-1, :2] - m.root_positions[0, :2]) > 0.5


@pytest.mark.parametrize(
    ("steps", "code"),
    [
        ([("walk", 3.0), ("gallop", 3.0)], "cannot go from"),
        ([("gallop", 3.0), ("stop", 5.0)], "cannot go from"),
        ([("sit", 5.0), ("walk", 3.0)], "cannot start"),
        ([("walk", 3.0)], "at least two"),
        ([("walk", 3.0), ("canter", 3.0)], "has no action"),
        ([("walk", 3.0), ("jump", 3.0)], "cannot be chained"),
        ([("walk", 0.1), ("trot", 3.0)], "at least"),
        ([("walk", 3.0), ("stop", 5.0), ("idle", 2.0), ("walk", 3.0)], "cannot go from"),
    ],
)
def test_chains_the_species_cannot_make_raise(steps, code) -> None:
    with pytest.raises(GaitError, match=code):
        generate_chain("dog", steps, seed=0)


def test_the_error_lists_the_allowed_followers() -> None:
    with pytest.raises(GaitError) as e:
        generate_chain("horse", [("walk", 4.0), ("gallop", 4.0)], seed=0)
    for a in allowed_transitions("horse")["walk"]:
        assert a in str(e.value)


def test_drawn_chains_are_valid_and_seeded() -> None:
    for sp in ("dog", "horse", "elephant", "rabbit"):
        allowed = allowed_transitions(sp)
        for seed in range(12):
            ch = draw_chain(sp, seed)
            assert ch == draw_chain(sp, seed)
            assert 2 <= len(ch) <= 5
            for (a, _), (b, _) in zip(ch, ch[1:], strict=False):
                assert b in allowed[a]
            for a, d in ch:
                assert d >= chain_min_duration(sp, a)


def test_single_clips_are_unchanged_by_the_chain_options() -> None:
    # the chain knobs live in GeneratorOptions: single clips must not depend on them
    import dataclasses

    from habitsim.gaits import GeneratorOptions

    opts = dataclasses.replace(GeneratorOptions(), chain_transition_strides=3.0, chain_blend_s=1)
    a = generate("dog", "trot", seed=2)
    b = generate("dog", "trot", seed=2, options=opts)
    np.testing.assert_array_equal(a.rotations, b.rotations)
