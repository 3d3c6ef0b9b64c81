"""Several tracking runs side by side in one video (``habitsim track A --beside B
--video V``): each run drawn as :func:`habitsim.render.render_tracking` draws it, in its
own panel with its own camera, the panels put next to each other frame by frame."""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .render import (
    RenderError,
    RenderOptions,
    check_video_writer,
    iter_frames,
    save_video,
    write_mp4,  # the streaming MP4 writer
)

__all__ = ["render_side_by_side", "side_by_side_frames"]


def _tracking_frames(
    result, width: int, height: int, step: int, opts: RenderOptions
) -> Iterator[np.ndarray]:
    """The frames of :func:`habitsim.render.render_tracking` (every ``step``-th), for
    one panel."""
    q = np.atleast_2d(np.asarray(result.qpos, dtype=np.float64))
    if len(q) == 0:
        raise RenderError("a tracking run holds no frame; a video needs at least one")
    arrays = [result.reference_qpos, result.contacts, result.reference_contacts]
    ref, con, ref_con = (None if a is None else np.asarray(a)[::step] for a in arrays)
    return iter_frames(
        result.model,
        q[::step],
        width=width,
        height=height,
        reference=ref,
        contacts=con,
        reference_contacts=ref_con,
        species=result.species,
        options=opts,
    )


def side_by_side_frames(
    results: Sequence[Any],
    *,
    width: int = 640,
    height: int = 480,
    options: RenderOptions | None = None,
) -> tuple[Iterator[np.ndarray], float]:
    """The frames of :func:`render_side_by_side` (each a new ``(height, width × runs, 3)``
    array) and their rate [Hz]. Raises :class:`RenderError` as it does."""
    opts = options or RenderOptions()
    if len(results) < 2:
        raise RenderError(f"a side-by-side video needs two runs or more, got {len(results)}")
    steps = [opts.frame_step(float(r.fps)) for r in results]
    rates = {round(float(r.fps) / k, 6) for r, k in zip(results, steps, strict=True)}
    if len(rates) > 1:
        raise RenderError(
            "the runs side by side must play at one video rate; got "
            + ", ".join(f"{float(r.fps):g} Hz" for r in results)
            + ": resample the clips to one frame rate first"
        )
    counts = [len(np.atleast_2d(r.qpos)[::k]) for r, k in zip(results, steps, strict=True)]
    its = [_tracking_frames(r, width, height, k, opts) for r, k in zip(results, steps, strict=True)]

    def frames() -> Iterator[np.ndarray]:
        last: list[np.ndarray] = [np.array(next(it)) for it in its]  # each run has a frame
        yield np.concatenate(last, axis=1)
        for t in range(1, max(counts)):
            for i, it in enumerate(its):
                if t < counts[i]:
                    last[i] = np.array(next(it))  # a copy: the renderer reuses its buffer
            yield np.concatenate(last, axis=1)

    return frames(), float(results[0].fps) / steps[0]


def render_side_by_side(
    results: Sequence[Any],
    path: str | Path,
    *,
    width: int = 640,
    height: int = 480,
    options: RenderOptions | None = None,
) -> Path:
    """One video of several tracking runs (:class:`habitsim.sim.TrackResult`) side by
    side, left to right: each panel (``width`` × ``height`` px) is the run's
    :func:`habitsim.render.render_tracking` video (the body, its reference ghost, stance
    marks), with its own camera; a run that ends sooner (shorter, or fallen) holds its
    last frame.

    Raises:
        RenderError: fewer than two runs, runs whose videos would have different frame
            rates, or as :func:`habitsim.render.render_video`.
    """
    opts = options or RenderOptions()
    path = Path(path)
    check_video_writer(path)
    frames, fps = side_by_side_frames(results, width=width, height=height, options=opts)
    if path.suffix.lower() == ".mp4":
        return write_mp4(frames, fps, path, opts)
    return save_video(np.stack(list(frames)), fps, path, opts)
