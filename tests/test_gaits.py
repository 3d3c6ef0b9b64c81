"""The synthetic gait generator against the species' gait tables (docs/biomechanics.md)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from habitsim.errors import GaitError, UnknownSpeciesError
from habitsim.gait_stats import gait_statistics
from habitsim.gaits import ACTIONS, LOCOMOTION_ACTIONS, action_gait, available_actions, generate
from habitsim.metrics.kinematic import skate_mm
from habitsim.qpos import load_species_model, motion_to_qpos
from habitsim.rotations import quat_to_matrix
from habitsim.species import load_species, species_names

CASES = [(s, a) for s in species_names() for a in available_actions(s)]
CYCLIC = [(s, a) for s, a in CASES if a in LOCOMOTION_ACTIONS]


def _phase_error(measured: float, wanted: float) -> float:
    return abs((measured - wanted + 0.5) % 1.0 - 0.5)


@pytest.fixture(scope="module")
def clips() -> dict[tuple[str, str, int], object]:
    return {(s, a, seed): generate(s, a, seed=seed) for s, a in CASES for seed in (0, 1)}


def test_every_species_has_the_basic_actions() -> None:
    for s in species_names():
        acts = available_actions(s)
        for a in ("walk", "turn_left", "turn_right", "walk_backward", "idle", "sit"):
            assert a in acts, (s, a)
        assert set(acts) <= set(ACTIONS)
        assert any(a in acts for a in ("trot", "pace", "amble", "bound")), s


@pytest.mark.parametrize(("species", "action"), CYCLIC)
def test_cyclic_gait_matches_species_table(clips, species: str, action: str) -> None:
    sp = load_species(species)
    band = sp.gaits[action_gait(sp, action)]
    for seed in (0, 1):
        m = clips[(species, action, seed)]
        st = gait_statistics(m)
        table = dict(band.footfall)
        if action == "walk_backward":  # the footfall sequence runs in reverse
            table = {f: (-v) % 1.0 for f, v in table.items()}
        for foot, want in table.items():
            err = _phase_error(st.phase_offsets[foot], want)
            assert err < 0.05, (foot, st.phase_offsets, table)
        lo, hi = band.duty_factor
        assert lo - 1e-9 <= st.duty_factor <= hi + 1e-9
        assert band.froude[0] * 0.95 <= st.froude <= band.froude[1] * 1.05, (st.froude, band.froude)
        rel = st.relative_stride_length / (2.3 * st.froude**0.3)
        assert 0.7 <= rel <= 1.3, rel
        # planted feet do not slide and no toe goes below the ground
        assert skate_mm(m, contacts=m.contacts) < 1.0
        toes = m.global_positions()[:, m.skeleton.foot_indices]
        assert toes[..., 2].min() > -1e-6
        assert np.abs(toes[..., 2][m.contacts]).max() < 1e-3
        assert m.metadata["max_stance_reach_error_mm"] < 1.0


@pytest.mark.parametrize(
    ("species", "action"), [c for c in CASES if c[1] not in LOCOMOTION_ACTIONS]
)
def test_stationary_and_jump_actions(clips, species: str, action: str) -> None:
    m = clips[(species, action, 0)]
    pos = m.global_positions()
    toes = pos[:, m.skeleton.foot_indices]
    assert toes[..., 2].min() > -1e-3
    assert skate_mm(m, contacts=m.contacts) < 1.0
    sp = load_species(species)
    pelvis_z = m.root_positions[:, 2]
    if action == "sit":  # the hind quarters come down and stay down
        assert pelvis_z[-1] < pelvis_z[0] - 0.25 * sp.hip_height
    elif action == "jump":  # a flight phase with all four feet off the ground
        assert (~m.contacts).all(axis=1).any()
        assert pelvis_z.max() > pelvis_z[0] + 0.05 * sp.hip_height
    else:  # idle: standing, all feet planted throughout
        assert m.contacts.all()
        assert np.ptp(pelvis_z) < 0.1 * sp.hip_height


@pytest.mark.parametrize("species", species_names())
def test_trunk_moves_like_a_body_not_a_piston(clips, species: str) -> None:
    """Vertical root motion and joint ranges of the cyclic gaits stay physical.

    Walks: the pelvis rises and falls by < 8 % of hip height with peak vertical
    acceleration < 1 g; faster symmetric gaits < 2 g (a trot's vertical excursion is a
    few centimetres; before the compliant-foot generator trots demanded up to 16 g).
    The flexion hinges stay within 0.35 rad (walks) / 0.55 rad (faster gaits) of the
    species' ranges (the MJCF limits); the refinement stage removes the rest.
    """
    sp = load_species(species)
    for action in ("walk", "trot", "pace"):
        if action not in available_actions(species):
            continue
        m = clips[(species, action, 0)]
        z = m.root_positions[:, 2]
        acc = np.abs(np.diff(z, 2)) * m.fps**2 / 9.81
        if action == "walk":
            assert (z.max() - z.min()) / sp.hip_height < 0.08, (action, z.max() - z.min())
            assert acc.max() < 1.0, (action, acc.max())
        else:
            assert acc.max() < 2.0, (action, acc.max())
        qp = motion_to_qpos(m, load_species_model(species))
        model = load_species_model(species)
        for j in range(model.njnt):
            name = model.joint(j).name
            if not name.endswith("_flex") or not model.jnt_limited[j]:
                continue
            a = qp.qpos[:, model.jnt_qposadr[j]]
            lo, hi = model.jnt_range[j]
            tol = 0.35 if action == "walk" else 0.55
            assert a.min() >= lo - tol and a.max() <= hi + tol, (action, name, a.min(), a.max())


def test_slow_walks_keep_the_centre_of_mass_over_the_support(clips) -> None:
    """Tripod frames of a walk have the centre of mass inside the support triangle."""
    fractions = []
    for s in species_names():
        for seed in (0, 1):
            st = gait_statistics(clips[(s, "walk", seed)])
            fractions.append(st.statically_stable_fraction)
            assert st.statically_stable_fraction >= 0.85, (s, seed, st.statically_stable_fraction)
    assert np.mean(fractions) > 0.95
    # without the sway the same walk tips over much more often
    m0 = generate("dog", "walk", seed=0, trunk_sway=0.0, froude=0.1)
    m1 = generate("dog", "walk", seed=0, froude=0.1)
    s0, s1 = gait_statistics(m0), gait_statistics(m1)
    assert s1.statically_stable_fraction > s0.statically_stable_fraction


@pytest.mark.parametrize("action", ["turn_left", "turn_right"])
def test_turns_turn_the_right_way(clips, action: str) -> None:
    for s in ("dog", "horse", "elephant"):
        m = clips[(s, action, 0)]
        fwd = quat_to_matrix(m.rotations[:, 0])[:, :, 0]  # pelvis forward axis
        yaw = np.unwrap(np.arctan2(fwd[:, 1], fwd[:, 0]))
        turned = yaw[-1] - yaw[0]
        want = m.metadata["turn_rate"] * (m.num_frames - 1) / m.fps
        assert (turned > 0) == (action == "turn_left"), turned
        assert turned == pytest.approx(want, abs=0.1)
        assert m.metadata["turn_rate"] * (1 if action == "turn_left" else -1) > 0


def test_same_seed_identical_different_seed_differs() -> None:
    a = generate("cat", "trot", seed=11)
    b = generate("cat", "trot", seed=11)
    c = generate("cat", "trot", seed=12)
    np.testing.assert_array_equal(a.rotations, b.rotations)
    np.testing.assert_array_equal(a.root_positions, b.root_positions)
    np.testing.assert_array_equal(a.contacts, b.contacts)
    assert a.num_frames != c.num_frames or not np.allclose(a.rotations, c.rotations)


@pytest.mark.parametrize(
    ("src", "dst", "action"),
    [
        ("dog", "horse", "trot"),
        ("cat", "elephant", "walk"),
        ("horse", "cow", "turn_left"),
        ("dog", "pig", "sit"),
    ],
)
def test_paired_generation(src: str, dst: str, action: str) -> None:
    a = generate(src, action, seed=5)
    b = generate(dst, like=a)
    assert b.metadata["action"] == action and b.species == dst
    assert b.num_frames == a.num_frames and b.fps == a.fps
    assert b.metadata["froude"] == pytest.approx(a.metadata["froude"], rel=1e-9)
    assert b.metadata["turn_rate_nd"] == pytest.approx(a.metadata["turn_rate_nd"], abs=1e-12)
    if action in LOCOMOTION_ACTIONS:
        sa, sb = gait_statistics(a), gait_statistics(b)
        assert sb.froude == pytest.approx(sa.froude, rel=0.1)
        # dynamic similarity: the bigger animal covers more ground at the same Froude number
        ha, hb = load_species(src).hip_height, load_species(dst).hip_height
        assert sb.speed_mps / sa.speed_mps == pytest.approx(math.sqrt(hb / ha), rel=0.1)


def test_explicit_parameters_are_kept() -> None:
    m = generate("dog", "trot", seed=0, froude=1.0, duration_s=3.0, fps=50.0)
    assert m.num_frames == 150 and m.fps == 50.0
    assert m.metadata["froude"] == pytest.approx(1.0)
    assert gait_statistics(m).froude == pytest.approx(1.0, rel=0.05)


@pytest.mark.parametrize(
    ("args", "kwargs", "error", "match"),
    [
        (("unicorn", "walk"), {"seed": 0}, UnknownSpeciesError, "dog"),
        (("dog", "fly"), {"seed": 0}, GaitError, "walk"),
        (("elephant", "gallop"), {"seed": 0}, GaitError, "available"),
        (("dog", "walk"), {}, GaitError, "seed"),
        (("dog", "walk"), {"seed": 0, "froude": -1.0}, GaitError, "froude"),
        (("dog", "walk"), {"seed": 0, "fps": 0.0}, GaitError, "fps"),
        (("dog", "walk"), {"seed": 0, "duration_s": float("nan")}, GaitError, "duration"),
        (("dog", "turn_left"), {"seed": 0, "turn_rate": -0.5}, GaitError, "sign"),
        (("dog", "trot"), {"seed": 0, "duty_factor": 1.5}, GaitError, "duty"),
    ],
)
def test_bad_inputs(args, kwargs, error, match) -> None:
    with pytest.raises(error, match=match):
        generate(*args, **kwargs)


def test_like_must_come_from_the_generator() -> None:
    m = generate("dog", "walk", seed=0)
    m.metadata.pop("params")
    with pytest.raises(GaitError, match="like"):
        generate("cat", like=m)


def test_generator_options_default_and_override() -> None:
    """The default options make the versioned clip; a knob changes the clip; a bad knob
    is refused."""
    from dataclasses import replace

    from habitsim.gaits import GeneratorOptions

    base = generate("dog", "trot", seed=0)
    same = generate("dog", "trot", seed=0, options=GeneratorOptions())
    np.testing.assert_array_equal(base.rotations, same.rotations)
    np.testing.assert_array_equal(base.root_positions, same.root_positions)
    other = generate("dog", "trot", seed=0, options=replace(GeneratorOptions(), swing_ramp=0.3))
    assert not np.array_equal(base.rotations, other.rotations)
    short = generate("dog", "idle", seed=0, options=GeneratorOptions(duration_range_s=(1.0, 1.0)))
    assert short.num_frames == 30
    with pytest.raises(GaitError, match="retry_shrink"):
        GeneratorOptions(retry_shrink=0.0)
