"""Overlapping windows for long clips: cost linear in length, continuous seams.

A clip of T frames is cut into windows of W frames that overlap by ``overlap`` frames.
Windows are solved in order. Window k+1 starts inside window k; its first ``n_fixed``
frames (half the overlap, at least 2) are *taken over* from window k's solution — fixed
through their variable bounds — and it re-solves everything after them, warm-started by
window k's solution where they overlap. The committed trajectory is therefore exactly
continuous across a seam, a second difference across it is of committed frames, and a
stance phase that spans a seam keeps its pinned toe position (the pin rows link the
fixed frames to the free ones).

Why not blend the two solutions in the overlap (a cross-fade): a blend of two feasible
poses is not feasible — a stance foot pinned at slightly different places in the two
windows would slide during the fade. Fixing the seam frames gives the continuity a blend
is meant to give, with every constraint intact.

All windows have the same length W (the last one is moved back to end at the clip's
end, overlapping its predecessor more), so one built problem serves every window of
every clip longer than W. A clip of at most W frames is one window of its own length.
"""

from __future__ import annotations

from dataclasses import dataclass

from .errors import RefineInputError

__all__ = ["Window", "plan_windows"]


@dataclass(frozen=True)
class Window:
    """One window of a clip.

    Attributes:
        start, stop: frames ``start:stop`` of the clip (stop exclusive).
        n_fixed: frames at the window's start taken over from the previous window.
        commit_stop: the window's solution is committed up to this frame (exclusive);
            the next window takes over from here.
    """

    start: int
    stop: int
    n_fixed: int
    commit_stop: int

    @property
    def length(self) -> int:
        return self.stop - self.start


def plan_windows(n_frames: int, window: int = 100, overlap: int = 20) -> list[Window]:
    """Windows covering ``n_frames`` frames (see the module docstring).

    Args:
        n_frames: clip length T ≥ 1.
        window: window length W ≥ 8.
        overlap: frames shared by consecutive windows, 4 ≤ overlap ≤ W / 2.

    Raises:
        RefineInputError: impossible sizes.
    """
    t, w, ov = int(n_frames), int(window), int(overlap)
    if t < 1:
        raise RefineInputError(f"a clip needs at least one frame, got {t}")
    if w < 8:
        raise RefineInputError(f"window must be at least 8 frames, got {w}")
    if not 4 <= ov <= w // 2:
        raise RefineInputError(f"overlap must be in [4, window/2 = {w // 2}], got {ov}")
    if t <= w:
        return [Window(0, t, 0, t)]
    n_fixed = max(2, ov // 2)
    starts = [0]
    while starts[-1] + w < t:
        starts.append(min(starts[-1] + w - ov, t - w))
    out = []
    for k, a in enumerate(starts):
        fixed = 0 if k == 0 else n_fixed
        commit = starts[k + 1] + n_fixed if k + 1 < len(starts) else t
        out.append(Window(a, a + w, fixed, commit))
    return out
