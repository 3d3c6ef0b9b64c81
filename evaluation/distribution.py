"""Distribution metrics of docs/metrics.md ("Behave Your Motion", Sec. 4.1.2) and MPJPE.

The set metrics work on feature matrices (N, D) — in the benchmark the penultimate
features of the frozen evaluator (:mod:`habitsim.evaluation.evaluator`) — so they are
plain numerics, testable on hand-made Gaussians:

==================  ===========================================================================
key                 definition
==================  ===========================================================================
``fid``             ‖μ₁−μ₂‖² + Tr(Σ₁ + Σ₂ − 2(Σ₁Σ₂)^½) of Gaussian fits (unbiased covariance);
                    when ``sqrtm`` is not finite it is retried with ε = 1e-6 added to both
                    diagonals; an imaginary part above 1e-3 raises :class:`FIDError`
``intra_fid``       mean over categories of the FID between generated and real samples of
                    that category (categories with fewer than ``min_samples`` generated or
                    real samples are skipped)
``downstream_fid``  mean over (source, target) category pairs, source ≠ target, of the FID
                    between the motions transferred from source to target and the target's
                    real samples; targets with fewer than 5 real samples and pairs with fewer
                    than 2 transferred samples are skipped
``diversity``       mean Euclidean distance between the features of 300 random pairs (100
                    when N ≤ 300), pairs drawn with a seeded generator
``one_nna``         1-NN two-sample accuracy (Lopez-Paz & Oquab 2017): real samples labelled
                    1, generated 0; each sample is predicted by the label of its nearest
                    *other* sample (Euclidean); accuracy over all samples. 0.5 = the two sets
                    are indistinguishable, 1.0 = fully separated
``mpjpe_mm``        mean over frames and joints of the distance between the global joint
                    positions of two motions on the same skeleton [mm] (frames beyond the
                    shorter motion ignored)
==================  ===========================================================================

For transfer (:func:`transfer_mpjpe_mm`): ``mpjpe_mm`` compares the transferred motion
with the *source* motion scaled to the target's size (source joint positions × h_t/h_s,
h = hip height, the same scaling the ``direct`` method applies to the root), i.e. how
much of the content moved; ``paired_mpjpe_mm`` compares it with the paired ground-truth
target motion (same skeleton, no scaling or alignment).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Hashable, Sequence

import numpy as np
import scipy.linalg

from habitsim.errors import HabitsimError, InvalidMotionError
from habitsim.motion import Motion

__all__ = [
    "FIDError",
    "DIVERSITY_PAIRS",
    "DIVERSITY_PAIRS_SMALL",
    "SQRTM_EPS",
    "MAX_IMAG",
    "gaussian_stats",
    "frechet_distance",
    "fid",
    "intra_fid",
    "downstream_fid",
    "diversity",
    "one_nna",
    "mpjpe_mm",
    "transfer_mpjpe_mm",
]

#: Number of random pairs of ``diversity`` (docs/metrics.md) …
DIVERSITY_PAIRS = 300
#: … and when the set has at most 300 samples.
DIVERSITY_PAIRS_SMALL = 100
#: Diagonal offset of the ``sqrtm`` retry.
SQRTM_EPS = 1e-6
#: Largest tolerated imaginary part of ``sqrtm(Σ₁Σ₂)``.
MAX_IMAG = 1e-3
#: Fewest real samples of a category used by ``downstream_fid`` (docs/metrics.md).
DOWNSTREAM_MIN_REAL = 5


class FIDError(HabitsimError, ValueError):
    """Features that give no meaningful Fréchet distance (too few samples, non-finite
    values, or a matrix square root with a large imaginary part)."""


def _features(x: np.ndarray, name: str, min_rows: int = 1) -> np.ndarray:
    a = np.asarray(x, dtype=np.float64)
    if a.ndim != 2:
        raise FIDError(f"{name} must be a (N, D) matrix, got shape {a.shape}")
    if a.shape[0] < min_rows:
        raise FIDError(f"{name} needs at least {min_rows} samples, got {a.shape[0]}")
    if not np.all(np.isfinite(a)):
        raise FIDError(f"{name} contains NaN or inf")
    return a


def gaussian_stats(features: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean (D,) and unbiased covariance (D, D) of (N, D) features (N ≥ 2)."""
    f = _features(features, "features", 2)
    return f.mean(0), np.atleast_2d(np.cov(f, rowvar=False))


def frechet_distance(
    mu1: np.ndarray, sigma1: np.ndarray, mu2: np.ndarray, sigma2: np.ndarray, eps: float = SQRTM_EPS
) -> float:
    """Fréchet distance between N(μ₁, Σ₁) and N(μ₂, Σ₂).

    Raises:
        FIDError: shape mismatch, or an imaginary part of the square root > 1e-3.
    """
    mu1, mu2 = np.atleast_1d(mu1).astype(np.float64), np.atleast_1d(mu2).astype(np.float64)
    s1, s2 = np.atleast_2d(sigma1).astype(np.float64), np.atleast_2d(sigma2).astype(np.float64)
    if mu1.shape != mu2.shape or s1.shape != s2.shape or s1.shape != (mu1.size, mu1.size):
        raise FIDError(
            f"mismatched Gaussian shapes {mu1.shape}, {s1.shape}, {mu2.shape}, {s2.shape}"
        )
    diff = mu1 - mu2
    with warnings.catch_warnings():
        # singular products (fewer samples than dimensions) are expected; handled below
        warnings.simplefilter("ignore", scipy.linalg.LinAlgWarning)
        warnings.simplefilter("ignore", RuntimeWarning)
        covmean = scipy.linalg.sqrtm(s1 @ s2)
        if not np.all(np.isfinite(covmean)):
            off = np.eye(s1.shape[0]) * eps
            covmean = scipy.linalg.sqrtm((s1 + off) @ (s2 + off))
    if not np.all(np.isfinite(covmean)):
        raise FIDError("sqrtm(Σ1·Σ2) is not finite even with ε on the diagonal")
    if np.iscomplexobj(covmean):
        imag = np.max(np.abs(covmean.imag)) if covmean.size else 0.0
        if imag > MAX_IMAG:
            raise FIDError(f"sqrtm(Σ1·Σ2) has an imaginary part of {imag:.3g} (> {MAX_IMAG})")
        covmean = covmean.real
    return float(diff @ diff + np.trace(s1) + np.trace(s2) - 2.0 * np.trace(covmean))


def fid(generated: np.ndarray, real: np.ndarray) -> float:
    """FID between two feature sets (N₁, D) and (N₂, D), each N ≥ 2."""
    g = _features(generated, "generated", 2)
    r = _features(real, "real", 2)
    if g.shape[1] != r.shape[1]:
        raise FIDError(f"feature sizes differ: {g.shape[1]} vs {r.shape[1]}")
    return frechet_distance(*gaussian_stats(g), *gaussian_stats(r))


def intra_fid(
    generated: np.ndarray,
    generated_labels: Sequence[Hashable],
    real: np.ndarray,
    real_labels: Sequence[Hashable],
    min_samples: int = 2,
) -> float:
    """Mean over categories of the FID within each category (NaN if none qualifies).

    Args:
        generated: (N₁, D) features; generated_labels: their categories (N₁,).
        real: (N₂, D) features; real_labels: their categories (N₂,).
        min_samples: fewest generated and real samples a category needs.
    """
    g, r = np.asarray(generated, float), np.asarray(real, float)
    gl, rl = np.asarray(list(generated_labels), object), np.asarray(list(real_labels), object)
    if len(gl) != len(g) or len(rl) != len(r):
        raise FIDError("labels and features differ in length")
    vals = []
    for c in sorted(set(gl) & set(rl), key=str):
        gi, ri = g[gl == c], r[rl == c]
        if len(gi) >= min_samples and len(ri) >= min_samples:
            vals.append(fid(gi, ri))
    return float(np.mean(vals)) if vals else math.nan


def downstream_fid(
    generated: np.ndarray,
    source_labels: Sequence[Hashable],
    target_labels: Sequence[Hashable],
    real: np.ndarray,
    real_labels: Sequence[Hashable],
    min_real: int = DOWNSTREAM_MIN_REAL,
    min_generated: int = 2,
) -> float:
    """Cross-category transfer FID averaged over (source, target) pairs (NaN if none).

    Args:
        generated: (N, D) features of transferred motions.
        source_labels, target_labels: (N,) source and target category of each.
        real: (M, D) real features; real_labels: (M,) their categories.
        min_real: fewest real samples of a target category (docs/metrics.md: 5).
        min_generated: fewest transferred samples of a (source, target) pair.
    """
    g, r = np.asarray(generated, float), np.asarray(real, float)
    sl = np.asarray(list(source_labels), object)
    tl = np.asarray(list(target_labels), object)
    rl = np.asarray(list(real_labels), object)
    if not (len(sl) == len(tl) == len(g)) or len(rl) != len(r):
        raise FIDError("labels and features differ in length")
    vals = []
    for t in sorted(set(tl), key=str):
        rt = r[rl == t]
        if len(rt) < min_real:
            continue
        for s in sorted(set(sl[tl == t]), key=str):
            if s == t:
                continue
            gi = g[(sl == s) & (tl == t)]
            if len(gi) >= min_generated:
                vals.append(fid(gi, rt))
    return float(np.mean(vals)) if vals else math.nan


def diversity(features: np.ndarray, n_pairs: int | None = None, seed: int = 0) -> float:
    """Mean Euclidean distance between the features of random pairs.

    Args:
        features: (N, D), N ≥ 2.
        n_pairs: pairs to draw (default 300, or 100 when N ≤ 300).
        seed: seed of the pair draw.
    """
    f = _features(features, "features", 2)
    n = f.shape[0]
    if n_pairs is None:
        n_pairs = DIVERSITY_PAIRS if n > DIVERSITY_PAIRS else DIVERSITY_PAIRS_SMALL
    rng = np.random.default_rng(seed)
    a = rng.integers(0, n, n_pairs)
    b = (a + rng.integers(1, n, n_pairs)) % n  # b ≠ a
    return float(np.linalg.norm(f[a] - f[b], axis=1).mean())


def one_nna(
    real: np.ndarray, generated: np.ndarray, *, balance: bool = False, seed: int = 0
) -> float:
    """1-nearest-neighbour two-sample accuracy (real = 1, generated = 0; 0.5 is ideal).

    Ties of the nearest distance are broken by the lowest index of the stacked set
    [real; generated]. Exact duplicates across the sets read as misclassified (a copied
    training sample drives 1-NNA toward 0: memorisation).

    Args:
        real: (N₁, D) real features.
        generated: (N₂, D) generated features.
        balance: subsample the larger set (without replacement, seeded) to the size of
            the smaller, so that chance level is 0.5 whatever the set sizes.
        seed: seed of the subsampling.
    """
    r = _features(real, "real", 1)
    g = _features(generated, "generated", 1)
    if r.shape[1] != g.shape[1]:
        raise FIDError(f"feature sizes differ: {r.shape[1]} vs {g.shape[1]}")
    if balance and len(r) != len(g):
        rng = np.random.default_rng(seed)
        n = min(len(r), len(g))
        if len(r) > n:
            r = r[np.sort(rng.choice(len(r), n, replace=False))]
        else:
            g = g[np.sort(rng.choice(len(g), n, replace=False))]
    x = np.concatenate([r, g], 0)
    y = np.concatenate([np.ones(len(r)), np.zeros(len(g))])
    sq = (x * x).sum(1)
    d = sq[:, None] + sq[None, :] - 2.0 * x @ x.T
    np.fill_diagonal(d, np.inf)
    nn = d.argmin(1)
    return float((y[nn] == y).mean())


def mpjpe_mm(a: Motion | np.ndarray, b: Motion | np.ndarray) -> float:
    """Mean per-joint position error [mm] between two motions on the same skeleton.

    Args:
        a, b: motions (same species) or (T, J, 3) global joint positions [m]. Only the
            first min(T_a, T_b) frames are compared.

    Raises:
        InvalidMotionError: motions of different species or arrays of different shapes.
    """
    if isinstance(a, Motion) and isinstance(b, Motion) and a.species != b.species:
        raise InvalidMotionError(
            f"mpjpe_mm compares motions on the same skeleton, got {a.species!r} and {b.species!r}"
        )
    pa = a.global_positions() if isinstance(a, Motion) else np.asarray(a, float)
    pb = b.global_positions() if isinstance(b, Motion) else np.asarray(b, float)
    if pa.ndim != 3 or pa.shape[1:] != pb.shape[1:] or pb.ndim != 3:
        raise InvalidMotionError(f"joint position arrays differ: {pa.shape} vs {pb.shape}")
    t = min(len(pa), len(pb))
    return float(np.linalg.norm(pa[:t] - pb[:t], axis=-1).mean() * 1000.0)


def transfer_mpjpe_mm(transferred: Motion, source: Motion) -> float:
    """``mpjpe_mm`` of a transfer against its source scaled to the target's size [mm].

    Source joint positions are multiplied by h_target / h_source (hip heights) so both
    are on the target's scale; no other alignment.
    """
    k = transferred.species_info.hip_height / source.species_info.hip_height
    return mpjpe_mm(transferred.global_positions(), source.global_positions() * k)
