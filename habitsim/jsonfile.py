"""Bounded reading of JSON and TOML files and texts written by habitsim or a user.

Every reader of a JSON or TOML document (motion metadata, data-set manifests, checkpoint
and evaluator configs, evaluation runs, captions, joint maps, glTF documents) goes
through :func:`load_json` / :func:`loads_json` / :func:`loads_toml`. They bound what the
standard parsers do not:

* size: the file's size is checked before it is read (:attr:`DocumentLimits.max_bytes`);
* nesting depth: counted on the text before it is parsed (JSON) or on the parsed value
  (TOML), so a document of ten thousand nested lists never reaches the parser's or a
  reader's recursion (:attr:`DocumentLimits.max_depth`);
* integers: at most :attr:`DocumentLimits.max_int_digits` digits, refused while
  parsing, before Python's own int-conversion limit turns them into a bare
  ``ValueError``.

Every failure is the caller's typed error (``error=``, default :class:`JSONFileError`)
whose message names the file and the reason, never the document's content.
"""

from __future__ import annotations

import json
import re
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .errors import HabitsimError, JSONFileError, brief_path

__all__ = [
    "DocumentLimits",
    "load_json",
    "loads_json",
    "loads_toml",
    "load_toml",
    "depth",
    "read_bounded",
]


@dataclass(frozen=True)
class DocumentLimits:
    """Limits of a JSON or TOML document.

    Attributes:
        max_bytes: largest file or text [bytes] (16 MiB: the largest habitsim writes, a
            big data set's manifest, is a few MB; parsing costs up to ~20 bytes of
            memory per byte).
        max_depth: deepest nesting of lists and objects (a habitsim document nests at
            most ~6 levels).
        max_int_digits: most decimal digits of an integer (an unsigned 64-bit seed has
            20).
    """

    max_bytes: int = 16 << 20
    max_depth: int = 64
    max_int_digits: int = 40


#: A JSON string (with its escapes), to blank out before brackets are counted.
_JSON_STRING = re.compile(rb'"(?:[^"\\]|\\.)*"', re.S)
_OPEN = np.zeros(256, np.int8)
_OPEN[[ord("["), ord("{")]] = 1
_OPEN[[ord("]"), ord("}")]] = -1


class _TooBig(Exception):
    """Raised from the parser's integer hook (an integer with too many digits)."""


def _json_depth(raw: bytes) -> int:
    """Deepest bracket nesting of a JSON text outside its strings (0 for a scalar)."""
    skeleton = _JSON_STRING.sub(b'""', raw)
    if not skeleton:
        return 0
    steps = _OPEN[np.frombuffer(skeleton, np.uint8)]
    return int(np.cumsum(steps, dtype=np.int32).max(initial=0))


def depth(value: Any, limit: int) -> int:
    """Nesting depth of a parsed value (iterative, stops counting past ``limit``).

    Args:
        value: a parsed JSON/TOML value (dicts and lists nest).
        limit: depth past which counting stops (the result is then ``limit + 1``).

    Returns:
        0 for a scalar, 1 for a flat list or dict, …
    """
    deepest, stack = 0, [(value, 1)]
    while stack:
        v, d = stack.pop()
        if isinstance(v, dict):
            items: Any = v.values()
        elif isinstance(v, list):
            items = v
        else:
            continue
        deepest = max(deepest, d)
        if d > limit:
            return limit + 1
        stack.extend((x, d + 1) for x in items)
    return deepest


def _int_hook(max_digits: int):
    def parse(s: str) -> int:
        if len(s) - s.startswith("-") > max_digits:
            raise _TooBig(len(s))
        return int(s)

    return parse


def loads_json(
    raw: bytes | str,
    source: str,
    *,
    error: type[HabitsimError] = JSONFileError,
    options: DocumentLimits | None = None,
) -> Any:
    """Parse a JSON text within the limits of ``options``.

    Args:
        raw: the UTF-8 text (bytes or str).
        source: the document's name in messages (a path, ``"metadata_json of x.npz"``).
        error: the typed error raised on any failure.
        options: the limits (None: :class:`DocumentLimits` defaults).

    Returns:
        The parsed value (NaN and Infinity are accepted as floats).

    Raises:
        error: too large, nested too deep, an integer with too many digits, not UTF-8,
            not JSON; the message names ``source`` and the reason, no content.
    """
    lim = options or DocumentLimits()
    data = raw.encode("utf-8", errors="surrogatepass") if isinstance(raw, str) else raw
    if len(data) > lim.max_bytes:
        raise error(f"{source}: {len(data)} bytes of JSON; valid: at most {lim.max_bytes} bytes")
    d = _json_depth(data)
    if d > lim.max_depth:
        raise error(f"{source}: JSON nested {d} levels deep; valid: at most {lim.max_depth} levels")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise error(f"{source}: not UTF-8 text (byte {e.start})") from None
    try:
        return json.loads(text, parse_int=_int_hook(lim.max_int_digits))
    except _TooBig as e:
        raise error(
            f"{source}: an integer of {e.args[0]} characters; valid: at most "
            f"{lim.max_int_digits} digits"
        ) from None
    except json.JSONDecodeError as e:
        raise error(
            f"{source}: not valid JSON ({e.msg} at line {e.lineno} column {e.colno})"
        ) from None
    except (RecursionError, ValueError, MemoryError) as e:  # defensive: bounded above
        raise error(f"{source}: not a readable JSON document ({type(e).__name__})") from None


def read_bounded(path: str | Path, what: str, error: type[HabitsimError], max_bytes: int) -> bytes:
    """The bytes of the file ``path`` when it holds at most ``max_bytes`` (read without
    asking for more than the file's size + 1).

    Raises:
        error: a missing or unreadable file, not a file, or one over ``max_bytes``.
    """
    p = Path(path)
    try:
        size = p.stat().st_size
        if not p.is_file():
            raise error(f"{brief_path(p)}: cannot read {what} (not a file)")
        if size > max_bytes:
            raise error(
                f"{brief_path(p)}: cannot read {what} ({size} bytes; valid: at most "
                f"{max_bytes} bytes)"
            )
        with p.open("rb") as fh:
            raw = fh.read(size + 1)  # (not the limit: read() allocates what it is asked)
    except FileNotFoundError:
        raise error(f"{brief_path(p)}: cannot read {what} (no such file)") from None
    except OSError as e:
        reason = e.strerror or type(e).__name__
        raise error(f"{brief_path(p)}: cannot read {what} ({reason})") from None
    if len(raw) > max_bytes:  # grew while being read
        raise error(f"{brief_path(p)}: cannot read {what} (over {max_bytes} bytes)")
    return raw


def load_json(
    path: str | Path,
    what: str = "JSON file",
    *,
    error: type[HabitsimError] = JSONFileError,
    options: DocumentLimits | None = None,
) -> Any:
    """Read and parse a JSON file within the limits of ``options``.

    Args:
        path: the file.
        what: its name in messages (``"manifest"``, ``"checkpoint config"``).
        error: the typed error raised on any failure.
        options: the limits (None: :class:`DocumentLimits` defaults).

    Returns:
        The parsed value.

    Raises:
        error: missing or unreadable file, or any failure of :func:`loads_json`.
    """
    lim = options or DocumentLimits()
    raw = read_bounded(path, what, error, lim.max_bytes)
    return loads_json(raw, f"{brief_path(path)}: cannot read {what}", error=error, options=lim)


def loads_toml(
    raw: bytes | str,
    source: str,
    *,
    error: type[HabitsimError] = JSONFileError,
    options: DocumentLimits | None = None,
) -> dict[str, Any]:
    """Parse a TOML text within the limits of ``options`` (depth and integer size are
    checked on the parsed value: tomllib parses nested arrays by recursion, which ends in
    a ``RecursionError`` turned into ``error`` here).

    Raises:
        error: too large, nested too deep, an integer with too many digits, not UTF-8,
            not TOML; the message names ``source`` and the reason, no content.
    """
    lim = options or DocumentLimits()
    data = raw.encode("utf-8", errors="surrogatepass") if isinstance(raw, str) else raw
    if len(data) > lim.max_bytes:
        raise error(f"{source}: {len(data)} bytes of TOML; valid: at most {lim.max_bytes} bytes")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise error(f"{source}: not UTF-8 text (byte {e.start})") from None
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise error(f"{source}: not valid TOML ({str(e).splitlines()[0][:120]})") from None
    except RecursionError:
        raise error(
            f"{source}: TOML nested too deep; valid: at most {lim.max_depth} levels"
        ) from None
    except ValueError:  # Python's int-conversion limit
        raise error(
            f"{source}: an integer too long; valid: at most {lim.max_int_digits} digits"
        ) from None
    d = depth(doc, lim.max_depth)
    if d > lim.max_depth:
        raise error(f"{source}: TOML nested too deep; valid: at most {lim.max_depth} levels")
    big = 10**lim.max_int_digits
    stack: list[Any] = [doc]
    while stack:
        v = stack.pop()
        if isinstance(v, dict):
            stack.extend(v.values())
        elif isinstance(v, list):
            stack.extend(v)
        elif isinstance(v, int) and not isinstance(v, bool) and abs(v) >= big:
            raise error(
                f"{source}: an integer too long; valid: at most {lim.max_int_digits} digits"
            )
    return doc


def load_toml(
    path: str | Path,
    what: str = "TOML file",
    *,
    error: type[HabitsimError] = JSONFileError,
    options: DocumentLimits | None = None,
) -> dict[str, Any]:
    """Read and parse a TOML file within the limits of ``options`` (as :func:`load_json`).

    Raises:
        error: missing or unreadable file, or any failure of :func:`loads_toml`.
    """
    lim = options or DocumentLimits()
    raw = read_bounded(path, what, error, lim.max_bytes)
    return loads_toml(raw, f"{brief_path(path)}: cannot read {what}", error=error, options=lim)
