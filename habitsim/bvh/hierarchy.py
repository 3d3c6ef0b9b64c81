"""The HIERARCHY part of a BVH file: tokens with their line numbers, joints, channels
and End Sites."""

from __future__ import annotations

import math

import numpy as np

from ..errors import BVHParseError, brief
from .data import _CHANNEL_CANON, END_SITE_SUFFIX, POSITION_CHANNELS, ROTATION_CHANNELS
from .limits import MAX_ABS_VALUE, MAX_DEPTH, MAX_JOINTS


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
