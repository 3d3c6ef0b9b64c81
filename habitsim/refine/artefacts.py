"""Inject the artefacts the refinement removes into a clean clip (tests, benchmarks).

Each artefact acts on the clip's qpos (its root path and hinge angles on the species'
model) and is sized relative to the species' hind-leg length L, so the same call is as
hard for a cat as for an elephant:

=============  =============================================================================
``slide``      feet skate: a smooth horizontal root oscillation (amplitude 2 % L, 1.5 Hz)
               that the legs do not compensate, so stance feet move with the body
``sink``       the body (and with it every foot) sinks 2 % L into the ground over the
               middle half of the clip (smooth ramp in and out)
``float``      the body hovers 2 % L above the ground over the middle half of the clip
``jitter``     Gaussian noise on every hinge angle (σ = 0.5°), i.e. joint jitter
``limits``     the leg hinges that come closest to an end of their range (within 0.15 rad,
               else the two closest) pushed 0.1 rad past it where they approach it
``momentum``   an implausible vertical bounce of the root (amplitude 1.5 % L at 4 Hz:
               peak accelerations beyond what the feet can produce)
=============  =============================================================================

Contact labels of the clean clip are kept (they are the ground truth the refinement is
told), and the artefact names are added to ``metadata["artefacts"]``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..errors import unknown_choice
from ..motion import Motion
from ..qpos import load_species_model, motion_to_qpos, qpos_to_motion
from .errors import RefineInputError

__all__ = ["ARTEFACTS", "inject_artefacts"]

ARTEFACTS = ("slide", "sink", "float", "jitter", "limits", "momentum")
_LEGS = ("lf_", "rf_", "lh_", "rh_")


def _bump(t: int, lo: float = 0.25, hi: float = 0.75, ramp: float = 0.1) -> np.ndarray:
    """(T,) smooth 0 → 1 → 0 window over [lo, hi] of the clip (cosine ramps)."""
    u = np.linspace(0.0, 1.0, t)

    def step(x: np.ndarray) -> np.ndarray:
        return 0.5 - 0.5 * np.cos(np.pi * np.clip(x, 0.0, 1.0))

    return step((u - lo + ramp) / ramp) * step((hi + ramp - u) / ramp)


def inject_artefacts(
    motion: Motion,
    kinds: Sequence[str] = ARTEFACTS,
    seed: int = 0,
    scale: float = 1.0,
) -> Motion:
    """A copy of ``motion`` with artefacts (see the module docstring).

    Args:
        motion: a clean clip with contact labels.
        kinds: artefact names from :data:`ARTEFACTS`.
        seed: seed of the jitter noise (``np.random.default_rng``).
        scale: multiplies every artefact's size.

    Raises:
        RefineInputError: an unknown artefact name.
    """
    bad = [k for k in kinds if k not in ARTEFACTS]
    if bad:
        raise RefineInputError(unknown_choice("artefact", bad[0], ARTEFACTS))
    model = load_species_model(motion.species)
    q = motion_to_qpos(motion, model).qpos.copy()
    t = q.shape[0]
    leg = motion.species_info.leg_length
    time = np.arange(t) / motion.fps
    rng = np.random.default_rng(seed)
    hinge = np.arange(7, model.nq)
    if "slide" in kinds:
        amp = 0.02 * leg * scale
        heading = q[:, :2][-1] - q[:, :2][0]
        n = np.linalg.norm(heading)
        d = heading / n if n > 1e-6 else np.array([1.0, 0.0])
        osc = amp * np.sin(2 * np.pi * 1.5 * time)
        q[:, 0] += osc * d[0]
        q[:, 1] += osc * d[1]
    if "sink" in kinds:
        q[:, 2] -= 0.02 * leg * scale * _bump(t)
    if "float" in kinds:
        q[:, 2] += 0.02 * leg * scale * _bump(t)
    if "momentum" in kinds:
        q[:, 2] += 0.015 * leg * scale * np.sin(2 * np.pi * 4.0 * time) * _bump(t, 0.1, 0.9)
    if "jitter" in kinds:
        q[:, hinge] += rng.normal(scale=np.deg2rad(0.5) * scale, size=(t, len(hinge)))
    if "limits" in kinds:
        # the hinges that come closest to an end of their range get pushed past it
        lo_hi = [
            (int(model.jnt_qposadr[j]), *model.jnt_range[j])
            for j in range(model.njnt)
            if model.jnt_limited[j] and model.joint(j).name.startswith(_LEGS)
        ]
        dist = [(min(np.min(q[:, a] - lo), np.min(hi - q[:, a])), a, lo, hi) for a, lo, hi in lo_hi]
        dist.sort(key=lambda d: d[0])
        chosen = [d for d in dist if d[0] < 0.15] or dist[:2]
        for d_min, a, lo, hi in chosen:
            to_hi = np.min(hi - q[:, a]) <= np.min(q[:, a] - lo)
            near = (hi - q[:, a]) if to_hi else (q[:, a] - lo)
            push = (max(d_min, 0.0) + 0.1 * scale) * np.clip(1.0 - (near - d_min) / 0.3, 0.0, 1.0)
            q[:, a] += push if to_hi else -push
    out = qpos_to_motion(model, q, motion.species, motion.fps)
    out.contacts = None if motion.contacts is None else motion.contacts.copy()
    out.metadata = dict(motion.metadata, artefacts=list(kinds))
    return out
