"""The contact-aware jitter pre-filter of a qpos trajectory."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..rotations import quat_normalize
from .problem import (
    FEET,
    LEG_PREFIXES,
)


def _lowpass(x: np.ndarray, lam: float, weights: np.ndarray | None = None) -> np.ndarray:
    """Zero-phase smoothing along axis 0: argmin |y − x|² + λ Σ_k w_k (Δ²y)_k².

    Args:
        x: (T, n) signals.
        lam: the penalty λ (cutoff: λ = 1 / (2 − 2 cos ω_c)²).
        weights: optional (T-2,) per-second-difference weights in [0, 1] (0 lets the
            signal bend there).
    """
    from scipy.linalg import solveh_banded

    t = x.shape[0]
    if t < 3 or lam <= 0:
        return x.copy()
    wk = lam * (np.ones(t - 2) if weights is None else np.asarray(weights, float))
    c = (1.0, -2.0, 1.0)  # row k of D² has c at columns k, k+1, k+2
    ab = np.zeros((3, t))  # I + λ D²ᵀ W D² in upper banded form: row 2 − j = diagonal j
    ab[2] = 1.0
    for i in range(3):
        ab[2, i : i + t - 2] += wk * c[i] * c[i]
        if i < 2:
            ab[1, i + 1 : i + t - 1] += wk * c[i] * c[i + 1]
    ab[0, 2:] += wk * c[0] * c[2]
    return solveh_banded(ab, x)


def _lam(fps: float, f_c: float) -> float:
    """The penalty λ of a cutoff ``f_c`` [Hz] at ``fps`` [Hz]."""
    return float(1.0 / (2.0 - 2.0 * np.cos(2 * np.pi * min(f_c / fps, 0.5))) ** 2)


def jitter_autocorr(q: np.ndarray, info: Any, fps: float, f_c: float) -> float:
    """How much a qpos trajectory jitters: the median over its hinges of the lag-1
    autocorrelation of what the second-difference filter of cutoff ``f_c`` [Hz] removes.

    White frame-to-frame noise leaves a high-passed remainder whose neighbouring frames
    are anti-correlated (about −0.5); smooth motion attenuated above the cutoff leaves a
    smooth remainder (0 to 0.3). A hinge the filter leaves untouched counts as 0.
    """
    x = np.asarray(q)[:, info.hinge_qposadr]
    if x.shape[0] < 4 or x.shape[1] == 0:
        return 0.0
    r = x - _lowpass(x, _lam(fps, f_c))
    r = r - r.mean(axis=0)
    energy = (r * r).sum(axis=0)
    lag1 = (r[1:] * r[:-1]).sum(axis=0)
    ac = np.where(energy > 1e-20, lag1 / np.maximum(energy, 1e-300), 0.0)
    return float(np.median(ac))


def _lowpass_qpos(
    q: np.ndarray, info: Any, fps: float, f_c: float, contacts: np.ndarray
) -> np.ndarray:
    """Contact-aware jitter filter of a qpos trajectory (see :class:`RefineOptions`).

    Root position, root quaternion (then renormalised) and every hinge are smoothed
    with the second-difference filter of cutoff ``f_c`` [Hz]; a leg's hinges are not
    smoothed at the corners of its touchdowns and lift-offs (the two second differences
    around a label change), where a foot's velocity legitimately jumps.
    """
    lam = _lam(fps, f_c)
    out = q.copy()
    fa = info.free_qposadr
    out[:, fa : fa + 3] = _lowpass(q[:, fa : fa + 3], lam)
    out[:, fa + 3 : fa + 7] = quat_normalize(_lowpass(q[:, fa + 3 : fa + 7], lam))
    names = info.hinge_names
    axial = [
        a for a, n in zip(info.hinge_qposadr, names, strict=True) if not n.startswith(LEG_PREFIXES)
    ]
    out[:, axial] = _lowpass(q[:, axial], lam)
    t = len(q)
    for f, leg in enumerate(FEET):
        cols = [
            a for a, n in zip(info.hinge_qposadr, names, strict=True) if n.startswith(f"{leg}_")
        ]
        if not cols or t < 3:
            continue
        change = np.flatnonzero(contacts[1:, f] != contacts[:-1, f])  # between t and t+1
        wk = np.ones(t - 2)
        for c in change:  # second differences centred on c and c+1 (index k ↔ frame k+1)
            wk[max(c - 1, 0) : min(c + 1, t - 2)] = 0.0
        out[:, cols] = _lowpass(q[:, cols], lam, wk)
    return out
