"""Distribution metrics, MPJPE and biomechanical consistency on cases with known answers."""

from __future__ import annotations

import math

import numpy as np
import pytest

from habitsim.evaluation.distribution import (
    FIDError,
    diversity,
    downstream_fid,
    fid,
    frechet_distance,
    intra_fid,
    mpjpe_mm,
    one_nna,
    transfer_mpjpe_mm,
)
from habitsim.metrics.biomech import BIOMECH_KEYS, biomech_metrics
from habitsim.transfer_methods import direct_transfer

# ---------------------------------------------------------------------------- FID


def test_fid_identical_sets_is_zero() -> None:
    x = np.random.default_rng(0).normal(size=(200, 8))
    assert abs(fid(x, x)) < 1e-8


@pytest.mark.slow
def test_fid_same_distribution_is_small_and_one_nna_half() -> None:
    rng = np.random.default_rng(1)
    a = rng.normal(size=(3000, 4))
    b = rng.normal(size=(3000, 4))
    assert fid(a, b) < 0.02
    assert one_nna(a, b) == pytest.approx(0.5, abs=0.04)


def test_one_nna_disjoint_clusters_is_one() -> None:
    rng = np.random.default_rng(2)
    real = rng.normal(size=(100, 3))
    gen = rng.normal(size=(80, 3)) + 50.0
    assert one_nna(real, gen) == 1.0
    assert one_nna(real, gen, balance=True) == 1.0


def test_one_nna_duplicates_read_as_memorisation() -> None:
    x = np.random.default_rng(3).normal(size=(50, 3))
    assert one_nna(x, x.copy()) == 0.0


def test_one_nna_balance_subsamples_larger_set() -> None:
    rng = np.random.default_rng(4)
    real = rng.normal(size=(40, 2))
    gen = rng.normal(size=(400, 2))
    # unbalanced: generated samples mostly see generated neighbours → far from 0.5
    assert one_nna(real, gen) > 0.7
    assert one_nna(real, gen, balance=True, seed=1) == pytest.approx(0.5, abs=0.15)


def _closed_form(mu1, s1, mu2, s2) -> float:
    # commuting covariances (same eigenvectors): Tr(S1+S2-2(S1 S2)^½) = Σ(√λ1 − √λ2)²
    w1, v = np.linalg.eigh(s1)
    w2 = np.diag(v.T @ s2 @ v)
    return float(np.sum((mu1 - mu2) ** 2) + np.sum((np.sqrt(w1) - np.sqrt(w2)) ** 2))


def test_frechet_distance_matches_closed_form() -> None:
    rng = np.random.default_rng(5)
    q, _ = np.linalg.qr(rng.normal(size=(5, 5)))
    s1 = q @ np.diag([1.0, 2.0, 0.5, 3.0, 0.1]) @ q.T
    s2 = q @ np.diag([2.0, 0.3, 0.5, 1.0, 4.0]) @ q.T
    mu1, mu2 = rng.normal(size=5), rng.normal(size=5)
    assert frechet_distance(mu1, s1, mu2, s2) == pytest.approx(
        _closed_form(mu1, s1, mu2, s2), rel=1e-9
    )
    # 1-D: (μ1-μ2)² + (σ1-σ2)²
    assert frechet_distance([0.0], [[4.0]], [3.0], [[1.0]]) == pytest.approx(9.0 + 1.0)


def test_fid_of_gaussian_samples_approaches_closed_form() -> None:
    rng = np.random.default_rng(6)
    s1, s2 = np.diag([1.0, 4.0, 0.25]), np.diag([2.0, 1.0, 1.0])
    mu1, mu2 = np.zeros(3), np.array([1.0, -1.0, 0.5])
    a = rng.multivariate_normal(mu1, s1, 40000)
    b = rng.multivariate_normal(mu2, s2, 40000)
    assert fid(a, b) == pytest.approx(_closed_form(mu1, s1, mu2, s2), rel=0.03)


def test_fid_singular_covariance_is_finite() -> None:
    rng = np.random.default_rng(7)
    a, b = rng.normal(size=(4, 16)), rng.normal(size=(5, 16))  # N < D: singular Σ
    v = fid(a, b)
    assert math.isfinite(v) and v > 0


def test_fid_rejects_bad_input() -> None:
    with pytest.raises(FIDError, match="at least 2"):
        fid(np.zeros((1, 3)), np.zeros((5, 3)))
    with pytest.raises(FIDError, match="NaN"):
        fid(np.full((3, 2), np.nan), np.zeros((3, 2)))
    with pytest.raises(FIDError, match="feature sizes"):
        fid(np.zeros((3, 2)), np.zeros((3, 4)))


def test_intra_and_downstream_fid_average_per_category() -> None:
    rng = np.random.default_rng(8)
    real = np.concatenate(
        [rng.normal(size=(30, 2)), rng.normal(size=(30, 2)) + 5.0, rng.normal(size=(3, 2))]
    )
    real_lab = ["a"] * 30 + ["b"] * 30 + ["c"] * 3
    gen = np.concatenate([rng.normal(size=(20, 2)) + 1.0, rng.normal(size=(20, 2)) + 4.0])
    gen_tgt = ["a"] * 20 + ["b"] * 20
    expect = np.mean([fid(gen[:20], real[:30]), fid(gen[20:], real[30:60])])
    assert intra_fid(gen, gen_tgt, real, real_lab) == pytest.approx(expect)
    # downstream: per (source, target), same category skipped, targets with < 5 real skipped
    src = ["b"] * 10 + ["c"] * 10 + ["a"] * 10 + ["b"] * 10
    expect_ds = np.mean(
        [fid(gen[:10], real[:30]), fid(gen[10:20], real[:30]), fid(gen[20:30], real[30:60])]
    )
    assert downstream_fid(gen, src, gen_tgt, real, real_lab) == pytest.approx(expect_ds)
    only_c = downstream_fid(gen[:5], ["a"] * 5, ["c"] * 5, real, real_lab)
    assert math.isnan(only_c)


def test_diversity_known_distance_and_pair_count() -> None:
    two = np.array([[0.0, 0.0], [3.0, 4.0]])
    assert diversity(two) == pytest.approx(5.0)
    x = np.random.default_rng(9).normal(size=(50, 3))
    assert diversity(x, seed=1) == diversity(x, seed=1)
    assert diversity(x, n_pairs=100, seed=1) == diversity(x, seed=1)  # N ≤ 300 → 100 pairs


# ---------------------------------------------------------------------------- MPJPE


def test_mpjpe_known_offset(habitsim_clip) -> None:
    m = habitsim_clip("dog", "walk", seed=0)
    assert mpjpe_mm(m, m) == 0.0
    shifted = m.slice(0)
    shifted.root_positions = shifted.root_positions + np.array([0.06, 0.08, 0.0])
    assert mpjpe_mm(m, shifted) == pytest.approx(100.0)
    other = habitsim_clip("cat", "walk", seed=0)
    with pytest.raises(Exception, match="same skeleton"):
        mpjpe_mm(m, other)


def test_transfer_mpjpe_of_self_transfer_is_zero(habitsim_clip) -> None:
    m = habitsim_clip("horse", "trot", seed=1)
    assert transfer_mpjpe_mm(direct_transfer(m, "horse"), m) == pytest.approx(0.0, abs=1e-9)


# ---------------------------------------------------------------------------- biomech


@pytest.mark.parametrize(
    ("species", "action"),
    [("horse", "trot"), ("camel", "pace"), ("dog", "walk"), ("cat", "gallop")],
)
def test_biomech_own_species_scores_near_zero(habitsim_clip, species: str, action: str) -> None:
    m = habitsim_clip(species, action, seed=3)
    r = biomech_metrics(m)
    assert r.score < 0.5, r
    # geometric contact detection (no labels) stays close too
    m2 = m.slice(0)
    m2.contacts = None
    assert biomech_metrics(m2).score < 1.0


def test_biomech_mismatched_species_scores_higher(habitsim_clip) -> None:
    trot = habitsim_clip("horse", "trot", seed=3)
    pace = habitsim_clip("camel", "pace", seed=3)
    own_t, own_p = biomech_metrics(trot).score, biomech_metrics(pace).score
    # a horse trot against the camel's habits (a pacer without a trot), and vice versa
    assert biomech_metrics(trot, species="camel").score > own_t + 2.0
    assert biomech_metrics(pace, species="horse").score > own_p + 2.0
    # a small cat's walk copied onto an elephant: Froude scales with the size ratio
    cat = habitsim_clip("cat", "trot", seed=3)
    big = direct_transfer(cat, "elephant")
    assert biomech_metrics(big).score > biomech_metrics(cat).score + 1.0


def test_biomech_total_equals_sum_of_parts(habitsim_clip) -> None:
    r = biomech_metrics(habitsim_clip("dog", "gallop", seed=2), species="horse")
    parts = r.froude_error + r.duty_error + r.phase_error + r.stride_error
    assert r.score == parts
    assert r.per_gait[r.gait] == r.score == min(r.per_gait.values())
    assert set(r.to_dict()) == set(BIOMECH_KEYS)


def test_biomech_standing_clip_is_not_a_gait(habitsim_clip) -> None:
    r = biomech_metrics(habitsim_clip("dog", "idle", seed=0))
    assert r.gait == "" and math.isnan(r.score)
