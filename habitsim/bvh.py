"""BVH (Biovision hierarchy) reading, forward kinematics and writing.

Why an own parser and not a library (``bvhio`` was evaluated): the BVH grammar is tiny,
and what matters for habitsim is (a) exact rotation semantics for *every* channel order,
per joint, including joints with position channels and End Sites, and (b) error messages
that name the line and the problem for truncated or malformed files. ``bvhio`` builds its
own object tree on top of PyGLM (single precision), converts the data into its own pose
representation and raises bare exceptions (``ValueError`` / ``IndexError`` / ``KeyError``)
without line numbers on bad input, so it would have had to be wrapped and its results
re-converted anyway; it is also not a dependency of habitsim (it was not installed in the
project environment). The parser below is ~250 lines, depends only on numpy / scipy
(through :mod:`habitsim.rotations`), works in float64 and raises
:class:`~habitsim.errors.BVHParseError` with ``file:line`` on every malformed input.

Conventions of the reader (the usual BVH semantics):

* A joint's rotation channels, read left to right, compose as intrinsic rotations:
  ``CHANNELS 3 Zrotation Xrotation Yrotation`` means R = R_z(a) · R_x(b) · R_y(c), angles in
  degrees. Any order and any subset of axes is accepted, on any joint.
* Position channels (usually only on the root, but any joint may have them) *replace* the
  joint's OFFSET along the axes they name; axes without a position channel keep the OFFSET.
* End Sites become extra channel-less joints named ``<parent>_End`` (so they can be mapped,
  e.g. as toe tips), flagged in :attr:`BVHData.is_end_site`.
* Units and axes are those of the file; see :mod:`habitsim.bvh_mapping` for the conversion
  to habitsim's frame.

Frame convention of the writer (:func:`write_bvh`): habitsim's own frame and names — z up,
x forward, y left, metres, joint names of :data:`habitsim.skeleton.JOINT_NAMES`, OFFSETs
from the species' skeleton. The root (``pelvis``) has OFFSET 0 and six channels
``Xposition Yposition Zposition`` + 3 rotations, every other joint three rotation channels
in ``order``. The end points (``snout``, ``tail3``, ``*_toe``) are written as JOINTs with
rotation channels (so any rotation a motion stores there survives the round trip), each
closed by an End Site with a zero offset. A file written so is recognised by
:func:`habitsim.bvh_mapping.import_bvh` (identical joint names) and imported as an identity
mapping without retargeting.
"""

from __future__ import annotations

import math
import re
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import BVHParseError, InvalidMotionError, brief, brief_path
from .fileio import atomic_write
from .rotations import quat_identity, quat_mul, quat_to_euler, quat_to_matrix

__all__ = [
    "BVHData",
    "ROTATION_CHANNELS",
    "POSITION_CHANNELS",
    "END_SITE_SUFFIX",
    "read_bvh",
    "parse_bvh",
    "bvh_text",
    "write_bvh",
]

ROTATION_CHANNELS = ("Xrotation", "Yrotation", "Zrotation")
POSITION_CHANNELS = ("Xposition", "Yposition", "Zposition")
_CHANNEL_CANON = {c.lower(): c for c in ROTATION_CHANNELS + POSITION_CHANNELS}
#: Name suffix of the joints the reader creates for End Sites (``LeftHand_End``).
END_SITE_SUFFIX = "_End"


@dataclass(frozen=True, eq=False)
class BVHData:
    """A parsed BVH file, in the file's own units and axes.

    Attributes:
        names: (J,) joint names, depth-first file order; End Sites included as
            ``<parent>_End`` joints.
        parents: (J,) parent index per joint, -1 for the root.
        offsets: (J, 3) OFFSET of each joint relative to its parent [file units].
        channels: per joint, the canonical channel names in file order (empty for End
            Sites), e.g. ``("Xposition", "Yposition", "Zposition", "Zrotation", ...)``.
        is_end_site: (J,) True for End Site joints.
        frame_time: seconds per frame (> 0).
        frames: (F, C) channel values per frame, C = total channel count, angles in degrees.
        source: file name (or ``"<string>"``) for messages.
    """

    names: tuple[str, ...]
    parents: tuple[int, ...]
    offsets: np.ndarray
    channels: tuple[tuple[str, ...], ...]
    is_end_site: tuple[bool, ...]
    frame_time: float
    frames: np.ndarray
    source: str = "<string>"

    # ------------------------------------------------------------------ basics
    @property
    def num_joints(self) -> int:
        return len(self.names)

    @property
    def num_frames(self) -> int:
        return int(self.frames.shape[0])

    @property
    def num_channels(self) -> int:
        return int(self.frames.shape[1])

    @property
    def fps(self) -> float:
        """Frame rate [Hz] = 1 / frame_time, snapped to an integer within 1e-6 relative."""
        fps = 1.0 / self.frame_time
        r = round(fps)
        return float(r) if r > 0 and abs(fps - r) <= 1e-6 * fps else fps

    @property
    def channel_start(self) -> tuple[int, ...]:
        """(J,) column of each joint's first channel in :attr:`frames`."""
        out, c = [], 0
        for ch in self.channels:
            out.append(c)
            c += len(ch)
        return tuple(out)

    def index(self, name: str) -> int:
        """Index of a joint by name.

        Raises:
            KeyError: with the list of joint names.
        """
        try:
            return self.names.index(name)
        except ValueError:
            raise KeyError(
                f"no joint {name!r} in {self.source}; joints: {', '.join(self.names)}"
            ) from None

    def children(self, j: int) -> list[int]:
        """Indices of the children of joint ``j``."""
        return [i for i, p in enumerate(self.parents) if p == j]

    def channel_values(self, j: int, channel: str) -> np.ndarray | None:
        """(F,) values of one channel of joint ``j`` or None if the joint lacks it."""
        if channel not in self.channels[j]:
            return None
        return self.frames[:, self.channel_start[j] + self.channels[j].index(channel)]

    # ------------------------------------------------------------------ pose
    def local_rotations(self) -> np.ndarray:
        """(F, J, 4) local joint rotations, unit quaternions wxyz.

        The rotation channels of each joint are composed in file order as intrinsic
        rotations (R = R_1 · R_2 · R_3); joints without rotation channels get identity.
        """
        f = self.num_frames
        q = quat_identity((f, self.num_joints))
        starts = self.channel_start
        for j, chans in enumerate(self.channels):
            acc = None
            for k, c in enumerate(chans):
                if c not in ROTATION_CHANNELS:
                    continue
                half = np.radians(self.frames[:, starts[j] + k]) * 0.5
                axis_q = np.zeros((f, 4))
                axis_q[:, 0] = np.cos(half)
                axis_q[:, 1 + ROTATION_CHANNELS.index(c)] = np.sin(half)
                acc = axis_q if acc is None else quat_mul(acc, axis_q)
            if acc is not None:
                q[:, j] = acc
        return q

    def local_translations(self) -> np.ndarray:
        """(F, J, 3) translation of each joint relative to its parent [file units].

        The OFFSET, with the axes that have a position channel replaced by its values.
        """
        t = np.broadcast_to(self.offsets, (self.num_frames, self.num_joints, 3)).copy()
        starts = self.channel_start
        for j, chans in enumerate(self.channels):
            for k, c in enumerate(chans):
                if c in POSITION_CHANNELS:
                    t[:, j, POSITION_CHANNELS.index(c)] = self.frames[:, starts[j] + k]
        return t

    def root_translation(self) -> np.ndarray:
        """(F, 3) root joint position per frame [file units]."""
        return self.local_translations()[:, 0]

    def fk(self, return_rotations: bool = False, rest: bool = False):
        """Forward kinematics of the BVH skeleton in the file's frame and units.

        Args:
            return_rotations: also return the global rotation matrices (F, J, 3, 3).
            rest: evaluate the rest pose (OFFSETs only, identity rotations, root at its
                OFFSET) instead of the frames; then F = 1.

        Returns:
            (F, J, 3) global joint positions [file units] (and the global rotations).
        """
        if rest:
            f = 1
            trans = self.offsets[None].copy()
            local = np.broadcast_to(np.eye(3), (1, self.num_joints, 3, 3))
        else:
            f = self.num_frames
            trans = self.local_translations()
            local = quat_to_matrix(self.local_rotations())
        glob = np.empty((f, self.num_joints, 3, 3))
        pos = np.empty((f, self.num_joints, 3))
        for j, p in enumerate(self.parents):
            if p < 0:
                glob[:, j] = local[:, j]
                pos[:, j] = trans[:, j]
            else:
                glob[:, j] = glob[:, p] @ local[:, j]
                pos[:, j] = pos[:, p] + np.einsum("fab,fb->fa", glob[:, p], trans[:, j])
        return (pos, glob) if return_rotations else pos

    def to_text(self) -> str:
        """Serialise back to BVH text (same hierarchy, channels and values).

        End Site joints are written as ``End Site`` blocks, so ``parse_bvh(d.to_text())``
        reproduces ``d`` (values printed with 10 significant digits).
        """
        kids: list[list[int]] = [[] for _ in range(self.num_joints)]
        for j, p in enumerate(self.parents):
            if p >= 0:
                kids[p].append(j)
        out = ["HIERARCHY"]

        def emit(j: int, depth: int) -> None:
            ind = "\t" * depth
            off = " ".join(_fmt(v) for v in self.offsets[j])
            if self.is_end_site[j]:
                out.extend([f"{ind}End Site", f"{ind}{{", f"{ind}\tOFFSET {off}", f"{ind}}}"])
                return
            out.append(f"{ind}{'ROOT' if self.parents[j] < 0 else 'JOINT'} {self.names[j]}")
            out.append(f"{ind}{{")
            out.append(f"{ind}\tOFFSET {off}")
            out.append(
                f"{ind}\tCHANNELS {len(self.channels[j])} {' '.join(self.channels[j])}".rstrip()
            )
            for c in kids[j]:
                emit(c, depth + 1)
            out.append(f"{ind}}}")

        emit(0, 0)
        out += ["MOTION", f"Frames: {self.num_frames}", f"Frame Time: {self.frame_time!r}"]
        out += [" ".join(_fmt(v) for v in row) for row in self.frames]
        return "\n".join(out) + "\n"


# ---------------------------------------------------------------------- parsing


class _PartEnded(Exception):
    """The tokens of the start of an over-long file ran out (not an error of the file)."""


class _Tokens:
    """Whitespace tokens of the HIERARCHY part with their 1-based line numbers.

    With ``complete=False`` the lines are only the start of the file, and running out of
    tokens raises :class:`_PartEnded` instead of a "truncated file" error.
    """

    def __init__(self, lines: list[str], source: str, complete: bool = True):
        self.source = source
        self.complete = complete
        self.items: list[tuple[str, int, int]] = []  # (token, line, index within line)
        for n, line in enumerate(lines, start=1):
            for k, tok in enumerate(line.split()):
                self.items.append((tok, n, k))
        self.pos = 0
        self.last_line = len(lines)

    def error(self, msg: str, line: int | None = None) -> BVHParseError:
        if line is None:
            line = self.items[self.pos][1] if self.pos < len(self.items) else self.last_line
        return BVHParseError(f"{self.source}:{line}: {msg}")

    def peek(self) -> str | None:
        return self.items[self.pos][0] if self.pos < len(self.items) else None

    def next(self, what: str) -> tuple[str, int]:
        if self.pos >= len(self.items):
            if not self.complete:
                raise _PartEnded
            raise self.error(
                f"unexpected end of the HIERARCHY section, expected {what} "
                "(truncated file or unbalanced braces?)"
            )
        tok, line, _ = self.items[self.pos]
        self.pos += 1
        return tok, line

    def expect(self, word: str) -> int:
        tok, line = self.next(repr(word))
        if tok.upper() != word.upper():
            raise self.error(f"expected {word!r}, found {brief(tok)}", line)
        return line

    def rest_of_line(self, line: int) -> list[str]:
        out = []
        while self.pos < len(self.items) and self.items[self.pos][1] == line:
            out.append(self.items[self.pos][0])
            self.pos += 1
        return out

    def number(self, what: str) -> float:
        tok, line = self.next(what)
        try:
            v = float(tok)
        except ValueError:
            raise self.error(f"{what}: {brief(tok)} is not a number", line) from None
        if not math.isfinite(v):
            raise self.error(f"{what}: non-finite value {brief(tok)}", line)
        if abs(v) > MAX_ABS_VALUE:
            raise self.error(f"{what}: {brief(tok)}; valid: |value| <= {MAX_ABS_VALUE:g}", line)
        return v


class _Builder:
    def __init__(self) -> None:
        self.names: list[str] = []
        self.parents: list[int] = []
        self.offsets: list[tuple[float, float, float]] = []
        self.channels: list[tuple[str, ...]] = []
        self.end: list[bool] = []


def _parse_offset(tk: _Tokens, owner: str) -> tuple[float, float, float]:
    return (
        tk.number(f"OFFSET x of {owner}"),
        tk.number(f"OFFSET y of {owner}"),
        tk.number(f"OFFSET z of {owner}"),
    )


def _parse_channels(tk: _Tokens, owner: str, line: int) -> tuple[str, ...]:
    tok, n_line = tk.next(f"channel count of {owner}")
    try:
        n = int(tok)
    except ValueError:
        raise tk.error(
            f"CHANNELS of {owner}: channel count {brief(tok)} is not an integer", n_line
        ) from None
    if not 0 <= n <= 6:
        raise tk.error(f"CHANNELS of {owner}: {n} channels; a joint has 0 to 6", n_line)
    names = tk.rest_of_line(n_line)
    if len(names) != n:
        raise tk.error(
            f"CHANNELS of {owner} declares {n} channels but lists {len(names)}: "
            + brief(" ".join(names)),
            n_line,
        )
    out = []
    for c in names:
        canon = _CHANNEL_CANON.get(c.lower())
        if canon is None:
            raise tk.error(
                f"unknown channel {brief(c)} of {owner}; valid: "
                + ", ".join(POSITION_CHANNELS + ROTATION_CHANNELS),
                n_line,
            )
        if canon in out:
            raise tk.error(f"channel {canon} listed twice for {owner}", n_line)
        out.append(canon)
    return tuple(out)


def _parse_joint(tk: _Tokens, b: _Builder, parent: int, kw_line: int, depth: int) -> None:
    if depth >= MAX_DEPTH:
        raise tk.error(f"joints nested {depth + 1} deep; valid: at most {MAX_DEPTH}", kw_line)
    if len(b.names) >= MAX_JOINTS:
        raise tk.error(f"more than {MAX_JOINTS} joints; valid: at most {MAX_JOINTS}", kw_line)
    name_toks = tk.rest_of_line(kw_line)
    opened = bool(name_toks) and name_toks[-1] == "{"
    if opened:
        name_toks = name_toks[:-1]
    if not name_toks:
        raise tk.error("joint without a name", kw_line)
    name = " ".join(name_toks)
    if len(name) > 200:
        raise tk.error(f"joint name {brief(name)} longer than 200 characters", kw_line)
    if name in b.names:
        raise tk.error(f"duplicate joint name {name!r}", kw_line)
    if not opened:
        tk.expect("{")
    idx = len(b.names)
    b.names.append(name)
    b.parents.append(parent)
    b.offsets.append((0.0, 0.0, 0.0))
    b.channels.append(())
    b.end.append(False)
    seen_offset = seen_channels = False
    n_children = 0
    while True:
        tok, line = tk.next(f"'}}' closing joint {name!r}")
        kw = tok.upper()
        if kw == "OFFSET":
            if seen_offset:
                raise tk.error(f"second OFFSET in joint {name!r}", line)
            b.offsets[idx] = _parse_offset(tk, name)
            seen_offset = True
        elif kw == "CHANNELS":
            if seen_channels:
                raise tk.error(f"second CHANNELS in joint {name!r}", line)
            b.channels[idx] = _parse_channels(tk, name, line)
            seen_channels = True
        elif kw == "JOINT":
            _parse_joint(tk, b, idx, line, depth + 1)
            n_children += 1
        elif kw == "END":
            tk.expect("Site")
            _parse_end_site(tk, b, idx, name)
            n_children += 1
        elif kw == "}":
            break
        elif kw in ("MOTION", "ROOT", "HIERARCHY"):
            raise tk.error(f"found {tok} before joint {name!r} was closed with '}}'", line)
        else:
            raise tk.error(f"unexpected {brief(tok)} in joint {name!r}", line)
    if not seen_offset:
        raise tk.error(f"joint {name!r} has no OFFSET", kw_line)


def _parse_end_site(tk: _Tokens, b: _Builder, parent: int, parent_name: str) -> None:
    tk.expect("{")
    tok, line = tk.next(f"OFFSET of the End Site of {parent_name!r}")
    if tok.upper() != "OFFSET":
        raise tk.error(f"End Site of {parent_name!r}: expected OFFSET, found {brief(tok)}", line)
    off = _parse_offset(tk, f"End Site of {parent_name}")
    tk.expect("}")
    name = parent_name + END_SITE_SUFFIX
    k = 2
    while name in b.names:
        name = f"{parent_name}{END_SITE_SUFFIX}{k}"
        k += 1
    b.names.append(name)
    b.parents.append(parent)
    b.offsets.append(off)
    b.channels.append(())
    b.end.append(True)


_FRAMES_RE = re.compile(r"^\s*frames\s*:\s*(\S*)\s*$", re.IGNORECASE)
_FTIME_RE = re.compile(r"^\s*frame\s+time\s*:\s*(\S*)\s*$", re.IGNORECASE)

#: Sensible bounds of a BVH file; anything outside is a :class:`BVHParseError` naming it.
#: Frame rates [Hz] a file may declare (through ``Frame Time``).
FPS_RANGE = (1.0, 1000.0)
#: Largest |OFFSET| or |channel value| (file units or degrees); beyond, a number is garbage.
MAX_ABS_VALUE = 1e7
#: Deepest joint nesting (the habitsim skeleton is 8 deep, real rigs about 20).
MAX_DEPTH = 200
#: Most joints (End Sites included) and frames of one file.
MAX_JOINTS = 2000
MAX_FRAMES = 1_000_000
#: Longest line, and longest HIERARCHY part, read before the file is refused (bytes).
MAX_LINE_BYTES = 1 << 20
MAX_HIERARCHY_BYTES = 1 << 20


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


def _parse_hierarchy(head: list[str], source: str, complete: bool) -> _Builder:
    """Parse the HIERARCHY lines; with ``complete=False`` (the start of an over-long
    file) only a malformation inside that part is reported, running out of it is not."""
    tk = _Tokens(head, source, complete)
    try:
        if tk.peek() is None:
            raise BVHParseError(f"{source}:1: empty file, expected HIERARCHY")
        tk.expect("HIERARCHY")
        tok, ln_no = tk.next("ROOT")
        if tok.upper() != "ROOT":
            raise tk.error(f"expected ROOT, found {brief(tok)}", ln_no)
        b = _Builder()
        _parse_joint(tk, b, -1, ln_no, depth=0)
        if tk.peek() is not None:
            tok, ln_no = tk.next("MOTION")
            if tok.upper() == "ROOT":
                raise tk.error(
                    "more than one ROOT: only single-skeleton BVH files are supported", ln_no
                )
            raise tk.error(f"unexpected {brief(tok)} after the hierarchy, expected MOTION", ln_no)
    except _PartEnded:
        return _Builder()
    offsets = np.asarray(b.offsets, dtype=np.float64).reshape(-1, 3)
    if len(b.names) > 1 and not np.any(offsets[1:]):
        raise BVHParseError(
            f"{source}: every joint OFFSET is zero, so the skeleton has no size; "
            "valid: at least one non-zero OFFSET below the root"
        )
    return b


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


# ---------------------------------------------------------------------- writing


def _check_order(order: str) -> str:
    o = str(order).upper()
    if len(o) != 3 or sorted(o) != ["X", "Y", "Z"]:
        raise InvalidMotionError(
            f"rotation order {order!r}: use a permutation of XYZ (XYZ, XZY, YXZ, YZX, ZXY, ZYX)"
        )
    return o


def _fmt(v: float) -> str:
    s = f"{v:.10g}"
    return "0" if s in ("-0", "0") else s


def bvh_text(motion, order: str = "ZXY") -> str:
    """The BVH text of a habitsim motion (see the module docstring for the convention).

    Args:
        motion: a :class:`habitsim.motion.Motion`.
        order: rotation channel order of every joint, a permutation of ``"XYZ"``; channel
            values are intrinsic Euler angles in degrees in that order.

    Returns:
        The file contents (``\\n`` line endings).
    """
    order = _check_order(order)
    skel = motion.skeleton
    rot_ch = " ".join(f"{a}rotation" for a in order)
    children: dict[int, list[int]] = {j: [] for j in range(skel.num_joints)}
    for j, p in enumerate(skel.parents):
        if p >= 0:
            children[p].append(j)
    out = ["HIERARCHY"]

    def emit(j: int, depth: int) -> None:
        ind = "  " * depth
        kw = "ROOT" if skel.parents[j] < 0 else "JOINT"
        out.append(f"{ind}{kw} {skel.joint_names[j]}")
        out.append(f"{ind}{{")
        off = np.zeros(3) if skel.parents[j] < 0 else skel.offsets[j]
        out.append(f"{ind}  OFFSET {' '.join(_fmt(v) for v in off)}")
        if skel.parents[j] < 0:
            out.append(f"{ind}  CHANNELS 6 Xposition Yposition Zposition {rot_ch}")
        else:
            out.append(f"{ind}  CHANNELS 3 {rot_ch}")
        if children[j]:
            for c in children[j]:
                emit(c, depth + 1)
        else:
            out.append(f"{ind}  End Site")
            out.append(f"{ind}  {{")
            out.append(f"{ind}    OFFSET 0 0 0")
            out.append(f"{ind}  }}")
        out.append(f"{ind}}}")

    emit(0, 0)
    # Channel order of the data = depth-first order of emission.
    dfs: list[int] = []

    def walk(j: int) -> None:
        dfs.append(j)
        for c in children[j]:
            walk(c)

    walk(0)
    euler = np.degrees(quat_to_euler(motion.rotations, order))  # (T, J, 3)
    t = motion.num_frames
    cols = [motion.root_positions] + [euler[:, j] for j in dfs]
    data = np.concatenate(cols, axis=1)
    out.append("MOTION")
    out.append(f"Frames: {t}")
    out.append(f"Frame Time: {1.0 / motion.fps!r}")
    for row in data:
        out.append(" ".join(_fmt(v) for v in row))
    return "\n".join(out) + "\n"


def write_bvh(motion, path: str | Path, order: str = "ZXY") -> Path:
    """Export a habitsim motion to a BVH file, atomically.

    The file uses habitsim's frame (z up, x forward, y left, metres) and joint names; the
    root carries 6 channels, every other joint 3 rotation channels in ``order``. Reading it
    back with :func:`habitsim.bvh_mapping.import_bvh` on the same species reproduces the
    motion (joint positions within 1e-5 m).

    Args:
        motion: the :class:`habitsim.motion.Motion` to export.
        path: output ``.bvh`` path (written only if the whole export succeeds).
        order: rotation channel order, a permutation of ``"XYZ"``.

    Returns:
        The written path.
    """
    text = bvh_text(motion, order)
    p = Path(path)
    with atomic_write(p, "w") as fh:
        fh.write(text)
    return p
