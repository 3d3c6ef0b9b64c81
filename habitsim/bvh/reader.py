"""Reading BVH text and files: the MOTION part read line by line, every malformation
a :class:`~habitsim.errors.BVHParseError` naming its line (:func:`parse_bvh`,
:func:`read_bvh`)."""

from __future__ import annotations

import math
import re
import warnings
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from ..errors import BVHParseError, brief, brief_path
from .data import BVHData
from .hierarchy import _Builder, _parse_hierarchy
from .limits import FPS_RANGE, MAX_ABS_VALUE, MAX_FRAMES, MAX_HIERARCHY_BYTES, MAX_LINE_BYTES

_FRAMES_RE = re.compile(r"^\s*frames\s*:\s*(\S*)\s*$", re.IGNORECASE)
_FTIME_RE = re.compile(r"^\s*frame\s+time\s*:\s*(\S*)\s*$", re.IGNORECASE)


def parse_bvh(text: str, source: str = "<string>", strict: bool = True) -> BVHData:
    """Parse BVH text.

    Args:
        text: the file contents (any line endings, tabs or spaces).
        source: name used in error messages.
        strict: if True (default) a file with fewer (or more) frame lines than its
            ``Frames:`` header, or a short last line, is an error; if False the complete
            frames are kept and a warning is issued.

    Returns:
        The parsed :class:`BVHData`.

    Raises:
        BVHParseError: malformed hierarchy, bad channel declarations, missing MOTION
            section / ``Frames:`` / ``Frame Time:``, truncated data, wrong number of values
            on a frame line, non-numeric or non-finite values, a frame time outside
            :data:`FPS_RANGE`, offsets or values beyond :data:`MAX_ABS_VALUE`, a skeleton
            whose offsets are all zero, nesting deeper than :data:`MAX_DEPTH`, more than
            :data:`MAX_JOINTS` joints or :data:`MAX_FRAMES` frames. The message starts
            with ``source:line:`` and quotes at most a short piece of any bad token.
    """
    return _parse_lines(iter(text.lstrip("\ufeff").splitlines()), source, strict)


def _parse_lines(lines: Iterator[str], source: str, strict: bool) -> BVHData:
    """Parse BVH lines read one at a time: the HIERARCHY part (at most
    :data:`MAX_HIERARCHY_BYTES`) is kept until the MOTION line, the frame lines are
    converted as they come, so a malformed file fails before it is read whole."""
    # Split off the MOTION section (line based) from the HIERARCHY part (token based).
    head: list[str] = []
    size = 0
    motion_line = None
    for text_line in lines:
        if text_line.strip().upper() == "MOTION":
            motion_line = len(head)
            break
        head.append(text_line)
        size += len(text_line) + 1
        if size > MAX_HIERARCHY_BYTES:
            # a hierarchy this long is no hierarchy: report what is wrong in it, if anything
            _parse_hierarchy(head, source, complete=False)
            raise BVHParseError(
                f"{source}:{len(head)}: no MOTION section in the first "
                f"{MAX_HIERARCHY_BYTES >> 20} MB (a HIERARCHY is far shorter)"
            )
    b = _parse_hierarchy(head, source, complete=True)
    if motion_line is None:
        raise BVHParseError(f"{source}:{len(head)}: no MOTION section (truncated file?)")

    n_channels = sum(len(c) for c in b.channels)
    n = motion_line + 1  # 1-based number of the MOTION line
    numbered = _numbered_nonempty(lines, n)
    # Header lines of MOTION.
    item = next(numbered, None)
    if item is None:
        raise BVHParseError(f"{source}:{n}: MOTION section without 'Frames:' line")
    ln, line = item
    m = _FRAMES_RE.match(line)
    if not m:
        raise BVHParseError(f"{source}:{ln}: expected 'Frames: N', found {brief(line.strip())}")
    try:
        n_frames = int(m.group(1)) if len(m.group(1)) <= 20 else None
    except ValueError:
        n_frames = None
    if n_frames is None:
        raise BVHParseError(f"{source}:{ln}: frame count {brief(m.group(1))} is not an integer")
    if not 1 <= n_frames <= MAX_FRAMES:
        raise BVHParseError(
            f"{source}:{ln}: the file declares {n_frames} frames; valid: 1 to {MAX_FRAMES}"
        )
    last_ln = ln
    item = next(numbered, None)
    if item is None:
        raise BVHParseError(f"{source}:{last_ln}: missing 'Frame Time:' line (truncated file?)")
    ln, line = item
    m = _FTIME_RE.match(line)
    if not m:
        raise BVHParseError(
            f"{source}:{ln}: expected 'Frame Time: seconds', found {brief(line.strip())}"
        )
    try:
        frame_time = float(m.group(1))
    except ValueError:
        raise BVHParseError(
            f"{source}:{ln}: frame time {brief(m.group(1))} is not a number"
        ) from None
    lo, hi = 1.0 / FPS_RANGE[1], 1.0 / FPS_RANGE[0]
    if not (math.isfinite(frame_time) and lo * (1 - 1e-9) <= frame_time <= hi * (1 + 1e-9)):
        raise BVHParseError(
            f"{source}:{ln}: frame time must be positive and finite, from {lo:g} to {hi:g} s "
            f"(a frame rate of {FPS_RANGE[0]:g} to {FPS_RANGE[1]:g} Hz), got {brief(m.group(1))}"
        )

    # Frame lines.
    rows: list[np.ndarray] = []
    row_lines: list[int] = []
    problem: str | None = None
    item = next(numbered, None)
    while item is not None:
        ln, line = item
        last_ln = ln
        item = next(numbered, None)
        last = item is None
        toks = line.split()
        try:
            vals = np.array(toks, dtype=np.float64)
        except ValueError:
            c = next(c for c, t in enumerate(toks) if not _is_number(t))
            if last and c == len(toks) - 1 and len(toks) <= n_channels:
                vals = np.array(toks[:-1], dtype=np.float64)  # a number cut off at end of file
            else:
                raise BVHParseError(
                    f"{source}:{ln}: value {c + 1} ({_channel_label(b, c)}) {brief(toks[c])} "
                    "is not a number"
                ) from None
        if vals.size != n_channels:
            if last and vals.size < n_channels:
                problem = (
                    f"{source}:{ln}: last frame line holds {vals.size} of {n_channels} values "
                    "(truncated file?)"
                )
                break
            raise BVHParseError(
                f"{source}:{ln}: frame line holds {vals.size} values but the hierarchy declares "
                f"{n_channels} channels"
            )
        bad = ~(np.abs(vals) <= MAX_ABS_VALUE)
        if bad.any():
            c = int(np.flatnonzero(bad)[0])
            kind = "non-finite value" if not np.isfinite(vals[c]) else "value"
            raise BVHParseError(
                f"{source}:{ln}: {kind} {brief(toks[c])} in value {c + 1} "
                f"({_channel_label(b, c)}); valid: |value| <= {MAX_ABS_VALUE:g}"
            )
        rows.append(vals)
        row_lines.append(ln)
        if len(rows) > n_frames:
            break  # more frames than declared: no need to read the rest
    if problem is None and len(rows) < n_frames:
        problem = (
            f"{source}:{last_ln}: the file declares {n_frames} frames but holds "
            f"{len(rows)} (truncated file?)"
        )
    if problem is None and len(rows) > n_frames:
        problem = (
            f"{source}:{row_lines[n_frames]}: the file declares {n_frames} frames but holds more"
        )
    if problem is not None:
        if strict or not rows:
            raise BVHParseError(problem)
        warnings.warn(problem + "; keeping the complete frames", stacklevel=3)
        rows = rows[:n_frames]
    frames = np.stack(rows) if n_channels else np.zeros((len(rows), 0))
    return BVHData(
        names=tuple(b.names),
        parents=tuple(b.parents),
        offsets=np.asarray(b.offsets, dtype=np.float64).reshape(-1, 3),
        channels=tuple(b.channels),
        is_end_site=tuple(b.end),
        frame_time=frame_time,
        frames=frames,
        source=source,
    )


def _numbered_nonempty(lines: Iterator[str], after: int) -> Iterator[tuple[int, str]]:
    """(1-based line number, line) of the non-blank lines of ``lines``, numbered from
    ``after + 1``."""
    for k, line in enumerate(lines, start=after + 1):
        if line.strip():
            yield k, line


def _is_number(tok: str) -> bool:
    try:
        float(tok)
    except ValueError:
        return False
    return True


def _channel_label(b: _Builder, column: int) -> str:
    """'Joint.Channel' name of a column of the frame data."""
    c = 0
    for name, chans in zip(b.names, b.channels, strict=True):
        if column < c + len(chans):
            return f"{name}.{chans[column - c]}"
        c += len(chans)
    return "beyond the declared channels"


def read_bvh(path: str | Path, strict: bool = True) -> BVHData:
    """Read a BVH file, line by line (a malformed file fails without being read whole).

    Args:
        path: the ``.bvh`` file.
        strict: see :func:`parse_bvh`.

    Raises:
        BVHParseError: missing / unreadable file, binary data, a line longer than
            :data:`MAX_LINE_BYTES` or any problem listed in :func:`parse_bvh`.
    """
    p = Path(path)
    try:
        fh = p.open("rb")
    except FileNotFoundError:
        raise BVHParseError(f"{brief_path(p)}: no such BVH file") from None
    except OSError as e:
        raise BVHParseError(f"{brief_path(p)}: cannot read BVH file ({e.strerror})") from None
    with fh:
        try:
            if b"\x00" in fh.read(4096):
                raise BVHParseError(f"{brief_path(p)}: binary data, not a BVH text file")
            fh.seek(0)
            return _parse_lines(_file_lines(fh, str(p)), str(p), strict)
        except OSError as e:
            raise BVHParseError(f"{brief_path(p)}: cannot read BVH file ({e.strerror})") from None


def _file_lines(fh, source: str) -> Iterator[str]:
    """Decoded lines of a binary file (UTF-8, Latin-1 where that fails), at most
    :data:`MAX_LINE_BYTES` each; a BOM at the start is dropped."""
    first = True
    for n, raw in enumerate(iter(lambda: fh.readline(MAX_LINE_BYTES + 1), b""), start=1):
        if len(raw) > MAX_LINE_BYTES:
            raise BVHParseError(
                f"{source}:{n}: line longer than {MAX_LINE_BYTES >> 20} MB; not a BVH file"
            )
        try:
            line = raw.decode("utf-8")
        except UnicodeDecodeError:
            line = raw.decode("latin-1")
        if first:
            line = line.lstrip("\ufeff")
            first = False
        # the same line breaks as str.splitlines() on the whole text
        yield from line.splitlines() or [""]
