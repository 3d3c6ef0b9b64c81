"""The swing clearance profile of contact labels: :func:`swing_clearance`."""

from __future__ import annotations

import numpy as np

from ..physics_constants import CONTACT_HEIGHT_PER_LEG
from ..stance.labels import runs
from .options import SWING_CLEARANCE_PER_LEG, SWING_RAMP_S

__all__ = ["swing_clearance", "SWING_RAMP_S"]


def swing_clearance(
    contacts: np.ndarray,
    fps: float,
    leg_length: float,
    clearance_per_leg: float = SWING_CLEARANCE_PER_LEG,
    ramp_s: float = SWING_RAMP_S,
    toes: np.ndarray | None = None,
    still: float = 0.0,
    sunk: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """The swing clearance profile of contact labels (:mod:`habitsim.refine.solve`, step 5).

    A swing frame k frames from the nearest stance frame must hold its toe at least
    ``clearance_per_leg`` × L × min(1, k / r) high, r = max(1, round(ramp_s · fps));
    the swing frames whose minimum is below docs/metrics.md's contact height are pinned
    horizontally to the neighbouring foothold (a swing run whose every frame would be
    pinned gets the full clearance in its middle frame(s), so the foot can move there).

    Args:
        contacts: (T, 4) bool labels.
        fps: frame rate [Hz].
        leg_length: L [m].
        clearance_per_leg: the full clearance, share of L (≥ the contact height).
        ramp_s: rise time from the ground to the full clearance [s].
        toes: optional (T, 4, 3) toe positions of the input [m]: the swing frames at
            either end of a swing run whose toe is still below the contact height, not
            more than ``sunk`` [m] under the floor, and within ``still`` [m]
            horizontally of the foothold it leaves or reaches count as on the ground
            (floor 0, pinned): a foot the input lifts a frame later than its label is
            not lifted earlier, only one that moves there (or is sunk) is.
        still, sunk: see ``toes``.

    Returns:
        ``floor`` (T, 4): lowest toe height [m] in swing, NaN in stance; ``pins``
        (T-1, 4) bool: frame pairs (t, t+1) whose horizontal toe displacement must be 0
        (every pair of stance or pinned swing frames).
    """
    c = np.asarray(contacts, bool)
    t, nf = c.shape
    full = float(clearance_per_leg) * float(leg_length)
    h_c = CONTACT_HEIGHT_PER_LEG * float(leg_length)
    r = max(1, int(round(ramp_s * fps)))
    frames = np.arange(t)
    floor = np.full((t, nf), np.nan)
    rest = c.copy()
    ground = c.copy()  # stance, and swing frames where the input's toe is still down
    if toes is not None:
        p = np.asarray(toes, float)
        for f in range(nf):
            for a, b in runs(~c[:, f]):
                if a > 0:  # after a lift-off
                    i = a
                    while i < b and _down(p, i, a - 1, f, (-sunk, h_c), still):
                        ground[i, f] = True
                        i += 1
                if b < t:  # before a touch-down
                    i = b - 1
                    while i >= a and not ground[i, f] and _down(p, i, b, f, (-sunk, h_c), still):
                        ground[i, f] = True
                        i -= 1
    for f in range(nf):
        stance = np.flatnonzero(c[:, f])
        down = np.flatnonzero(ground[:, f])
        for a, b in runs(~c[:, f]):
            k = frames[a:b]
            if len(stance):
                d0 = np.abs(k[:, None] - stance[None, :]).min(axis=1).astype(float)
                d = np.abs(k[:, None] - down[None, :]).min(axis=1).astype(float)
            else:
                d0 = d = np.full(len(k), np.inf)
            h = full * np.minimum(1.0, d / r)
            low = h < h_c
            if low.all():
                h = full * np.minimum(1.0, d0 / r)
                low = h < h_c
            if low.all():
                top = d0 == d0.max()
                h[top], low[top] = full, False
            floor[a:b, f] = h
            rest[a:b, f] = low
    pins = rest[1:] & rest[:-1]
    return floor, pins


def _down(
    p: np.ndarray, k: int, hold: int, f: int, band: tuple[float, float], still: float
) -> bool:
    """Whether toe ``f`` of ``p`` is at frame ``k`` at a height in ``band`` [lo, hi) and
    within ``still`` horizontally of where it is at frame ``hold``."""
    z = p[k, f, 2]
    return bool(band[0] <= z < band[1] and np.linalg.norm(p[k, f, :2] - p[hold, f, :2]) <= still)
