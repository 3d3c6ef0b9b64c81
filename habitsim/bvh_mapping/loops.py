"""Loops: a clip whose last pose runs on into its first (:func:`detect_loop`), repeated
seamlessly to a requested length with its travel accumulated (:func:`repeat_loop`).

A game loop comes in one of two forms: *closed*, its last frame a copy of its first
(the period is one frame shorter than the clip), or *open*, its last frame one step
before its first (the period is the whole clip). Poses are compared relative to the
trunk, in leg lengths (the root mean square over the joints), against the clip's own
frame-to-frame step: a seam no bigger than a step or two is not seen.

A clip that is not a loop is refused with :class:`LoopError`, which names the mismatch
and, where the clip holds one, the pair of frames that would make a loop if the clip
were cut there.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from scipy.spatial.distance import cdist

from ..errors import HabitsimError
from ..motion import Motion
from .report import ImportReport

__all__ = ["LoopError", "LoopOptions", "LoopFit", "detect_loop", "repeat_loop"]

LoopKind = Literal["closed", "open"]


class LoopError(HabitsimError, ValueError):
    """A clip that cannot be repeated seamlessly (not a loop), or a bad repeat request."""


@dataclass(frozen=True)
class LoopOptions:
    """The knobs of telling a loop.

    Attributes:
        closed_steps: the last pose is a copy of the first (a closed loop) when they are
            closer than this share of the clip's median frame-to-frame step [steps].
        seam_steps: the last pose runs on into the first (an open loop) when they are at
            most this many median steps apart [steps].
        tolerance_per_leg: ... or closer than this, whatever the step [leg lengths, root
            mean square over the joints].
        min_cycle_s: the shortest cycle looked for when a clip that is not a loop is
            searched for a pair of matching frames [s].
    """

    closed_steps: float = 0.5
    seam_steps: float = 1.5
    tolerance_per_leg: float = 0.02
    min_cycle_s: float = 0.3

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if not (math.isfinite(v) and v > 0.0):
                raise LoopError(f"LoopOptions.{f.name} must be > 0, got {v!r}")


@dataclass(frozen=True)
class LoopFit:
    """Whether a clip is a loop.

    Attributes:
        kind: ``"closed"`` (last frame = first), ``"open"`` (last frame runs on into the
            first) or None (not a loop).
        mismatch: distance of the last pose from the first [leg lengths, RMS over joints].
        step: the clip's median frame-to-frame step [leg lengths, RMS over joints].
        limit: the largest mismatch a loop may have [leg lengths].
    """

    kind: LoopKind | None
    mismatch: float
    step: float
    limit: float

    def period(self, n_frames: int) -> int:
        """Frames in one cycle of a clip of ``n_frames``."""
        return n_frames - 1 if self.kind == "closed" else n_frames


def _pose_distance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """RMS over joints of the distance between poses a and b (..., J, 3)."""
    return np.sqrt(np.mean(np.sum((a - b) ** 2, axis=-1), axis=-1))


def detect_loop(rel: np.ndarray, leg_length: float, options: LoopOptions | None = None) -> LoopFit:
    """Whether the poses ``rel`` (T, J, 3) [m], relative to the trunk, make a loop.

    Args:
        rel: joint positions relative to the trunk per frame [m].
        leg_length: the normalising length [m].
        options: the knobs (defaults when None).
    """
    opts = options or LoopOptions()
    rel = np.asarray(rel, dtype=np.float64) / leg_length
    if rel.shape[0] < 4:
        return LoopFit(None, math.inf, 0.0, 0.0)
    step = float(np.median(_pose_distance(rel[1:], rel[:-1])))
    end = float(_pose_distance(rel[-1], rel[0]))
    limit = max(opts.tolerance_per_leg, opts.seam_steps * step)
    if end <= opts.closed_steps * step:
        kind: LoopKind | None = "closed"
    elif end <= limit:
        kind = "open"
    else:
        kind = None
    return LoopFit(kind, end, step, limit)


def _relative(motion: Motion) -> np.ndarray:
    return motion.global_positions() - motion.root_positions[:, None, :]


def _best_cut(
    rel: np.ndarray, fps: float, leg: float, limit: float, opts: LoopOptions
) -> tuple[int, int, float]:
    """The pair of frames (i, j), at least a cycle apart, that make the longest loop (poses
    within ``limit``), else the pair whose poses match best."""
    t = rel.shape[0]
    stride = max(1, math.ceil(t / 600))
    idx = np.arange(0, t, stride)
    flat = rel[idx].reshape(len(idx), -1) / leg
    d = cdist(flat, flat) / math.sqrt(rel.shape[1])
    gap = idx[None, :] - idx[:, None]
    d[gap < max(2, opts.min_cycle_s * fps)] = np.inf
    if not np.isfinite(d).any():
        return 0, t - 1, math.inf
    ok = d <= limit
    if ok.any():
        score = np.where(ok, gap - d, -np.inf)  # the longest span; the closer match on a tie
        i, j = np.unravel_index(int(np.argmax(score)), d.shape)
    else:
        i, j = np.unravel_index(int(np.argmin(d)), d.shape)
    return int(idx[i]), int(idx[j]), float(d[i, j])


def repeat_loop(
    motion: Motion,
    cycles: int | None = None,
    seconds: float | None = None,
    options: LoopOptions | None = None,
) -> Motion:
    """A loop repeated seamlessly: ``cycles`` times, or to ``seconds`` long.

    Each cycle starts where the previous one's travel ended (the root's horizontal
    displacement over a cycle is carried on); rotations, heights and stance labels repeat
    as they are. A closed loop's duplicate last frame is played once, at the very end.
    An imported motion's report (``metadata["import"]``) records the cycles and the loop
    as found on the motion.

    Args:
        motion: the clip.
        cycles: how many times to play it (>= 1).
        seconds: or the length to reach [s] (the last cycle is cut there).
        options: the knobs of telling a loop (defaults when None).

    Returns:
        The repeated :class:`~habitsim.motion.Motion`.

    Raises:
        LoopError: neither or both of ``cycles`` and ``seconds``, a value out of range, or
            a clip that is not a loop (saying how far its ends are apart and, where the
            clip holds one, which frames to cut it at to make one).
    """
    opts = options or LoopOptions()
    if (cycles is None) == (seconds is None):
        raise LoopError("give the loop's length as cycles or as seconds (one of the two)")
    if cycles is not None and (isinstance(cycles, bool) or int(cycles) != cycles or cycles < 1):
        raise LoopError(f"cycles must be a whole number >= 1, got {cycles!r}")
    if seconds is not None and not (math.isfinite(seconds) and seconds > 0):
        raise LoopError(f"seconds must be > 0, got {seconds!r}")
    leg = motion.species_info.leg_length
    rel = _relative(motion)
    fit = detect_loop(rel, leg, opts)
    t = motion.num_frames
    name = motion.metadata.get("bvh_file", "the clip")
    if fit.kind is None:
        why = (
            f"{name} is not a loop: its last pose is {fit.mismatch:.3f} leg lengths from its "
            f"first (a loop's ends are within {fit.limit:.3f}, {opts.seam_steps:g} of its "
            f"frame steps)"
        )
        i, j, d = _best_cut(rel, motion.fps, leg, opts.tolerance_per_leg, opts)
        if d <= opts.tolerance_per_leg:
            why += (
                f"; frames {i} and {j} match within {d:.3f}: keep frames {i}–{j} to make a "
                f"loop (--start {i / motion.fps:.4f} --end {(j + 1) / motion.fps:.4f})"
            )
        else:
            why += (
                "; no two of its frames a cycle apart match either: give a clip whose first "
                "and last poses match (a game loop)"
            )
        raise LoopError(why)
    period = fit.period(t)
    if period < 2:
        raise LoopError(f"{name} has {t} frames: too short to repeat")
    if cycles is not None:
        need = int(cycles) * period
    else:
        assert seconds is not None
        need = max(1, int(round(float(seconds) * motion.fps)))
    n_cycles = max(1, math.ceil(need / period))
    root = motion.root_positions
    shift = np.zeros(3)
    shift[:2] = root[period if fit.kind == "closed" else t - 1, :2] - root[0, :2]
    if fit.kind == "open":
        shift[:2] += 0.5 * (root[1, :2] - root[0, :2] + root[t - 1, :2] - root[t - 2, :2])
    frames = np.arange(need + (1 if fit.kind == "closed" and cycles is not None else 0))
    k, f = np.divmod(frames, period)
    if fit.kind == "closed" and len(frames) and frames[-1] == n_cycles * period:
        k[-1], f[-1] = n_cycles - 1, period  # the duplicate last frame, played once
    new_root = root[f] + k[:, None] * shift
    contacts = None if motion.contacts is None else motion.contacts[f].copy()
    meta = dict(motion.metadata)
    report = ImportReport.from_metadata(meta)
    if report is not None and report.in_place is not None:
        done = dataclasses.replace(
            report.in_place, loop=fit.kind, loop_mismatch=round(fit.mismatch, 4), cycles=n_cycles
        )
        meta["import"] = dataclasses.replace(report, in_place=done).to_metadata()
    return Motion(motion.species, motion.fps, new_root, motion.rotations[f].copy(), contacts, meta)
