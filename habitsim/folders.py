"""Output and input folders: what habitsim wrote, one run at a time, no links out.

A command that writes into an output *folder* claims it with
:func:`claim_output_folder`: a lock file (:data:`LOCK_NAME`) keeps a second run out (in
well under a second; a lock left by a killed run is taken over with a note), and a record
(:data:`WRITTEN_NAME`) lists every file habitsim wrote there, so ``--overwrite`` removes
only those, never someone else's file. Every write of :mod:`habitsim.fileio` into a
folder holding a record is listed in it before the file appears (from any process: the
record is found by walking up from the path), refused when it would replace a file
habitsim did not write, and refused when the path leads out of the folder through a link.

Input folders are listed with :func:`input_files` (and single paths in them checked with
:func:`check_inside`), which refuse links leading out of the folder unless asked to
follow them; their messages name paths, never what a file holds.
"""

from __future__ import annotations

import contextlib
import datetime
import errno
import fcntl
import json
import os
import re
import socket
import tempfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .errors import (
    InputPathError,
    OutputBusyError,
    OutputFolderError,
    OutputPathError,
    OutputWriteError,
    brief,
    brief_path,
)

__all__ = [
    "LOCK_NAME",
    "WRITTEN_NAME",
    "OutputClaim",
    "claim_output_folder",
    "is_written",
    "remove_written",
    "input_files",
    "check_inside",
]


#: What ``errno`` of a failed write says to do about it.
_REMEDIES = {
    errno.ENOSPC: "free space on that disk or write elsewhere",
    errno.EDQUOT: "free space within your disk quota or write elsewhere",
    errno.EFBIG: "write to a file system that takes files this large",
    errno.EIO: "check the disk, or write elsewhere",
    errno.EROFS: "the file system is read-only: write to a writable one",
    errno.EACCES: "write into a folder you may write into",
    errno.EPERM: "write into a folder you may write into",
}
#: Errnos that mean the disk could not take the bytes: a failed write wherever it occurs.
_NO_ROOM = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EIO})


def _output_error(
    path: Path, e: OSError, what: str = "output", *, writing: bool = False
) -> OutputPathError:
    """The typed error of an ``OSError`` on an output path: an :class:`OutputWriteError`
    (exit code 1) for a write that failed on its way (``writing``, or a full disk), else
    an :class:`OutputPathError` (exit code 2: a destination that cannot be written)."""
    if isinstance(e, OutputPathError):
        return e
    reason = e.strerror or type(e).__name__
    remedy = _REMEDIES.get(e.errno or 0, "choose a path habitsim can write")
    if writing or e.errno in _NO_ROOM:
        return OutputWriteError(
            f"{what} {brief_path(path)}: writing it failed ({reason}); nothing was left "
            f"under that name; {remedy}"
        )
    anc = path.parent
    while not anc.exists() and anc.parent != anc:
        anc = anc.parent
    if anc.exists() and not anc.is_dir():
        reason = f"{brief_path(anc)} is a file where a folder should be"
        remedy = "remove that file or choose another path"
    return OutputPathError(f"{what} {brief_path(path)}: cannot be written ({reason}); {remedy}")


def write_failure(e: BaseException) -> bool:
    """Whether ``e`` is the ``OSError`` of a write into an open file that failed for want
    of room or of permission (no file name attached: not an ``open`` of another file)."""
    return (
        isinstance(e, OSError)
        and not isinstance(e, OutputPathError)
        and e.filename is None
        and (e.errno in _NO_ROOM or e.errno in _REMEDIES)
    )


#: Record in an output folder of every file habitsim wrote there: a header line (a JSON
#: object: ``kind``, ``command``), then one JSON string per file, its path relative to
#: the folder. A path is listed before its file appears, so a killed run leaves none out.
WRITTEN_NAME = ".habitsim-written"
#: Lock file of an output folder while a run writes into it (JSON: ``pid``, ``host``,
#: ``command``, ``started``); removed when the run ends.
LOCK_NAME = ".habitsim-lock"
_RECORD_KIND = "habitsim.output"
#: A temporary of :func:`atomic_path` / :func:`check_writable` / a commit: ``.<name>.<8
#: random characters><suffix>``.
_TEMPORARY = re.compile(r"^\.(?P<name>.+)\.[A-Za-z0-9_]{8}(?P<suffix>\.[A-Za-z0-9]+)$")
#: Output folders this process holds (real path -> depth of nested claims).
_HELD: dict[str, int] = {}
#: Parsed records by path: ((inode, size, mtime), header, listed paths).
_RECORDS: dict[str, tuple[tuple[int, int, int], dict[str, Any], frozenset[str]]] = {}


def _inside(root: str, path: str) -> bool:
    """Whether the real path ``path`` is ``root`` or lies under it."""
    return path == root or path.startswith(root.rstrip(os.sep) + os.sep)


def _record_of(path: Path) -> Path | None:
    """The record of the nearest output folder holding ``path`` (its lexical parents)."""
    for anc in Path(os.path.abspath(path)).parents:
        rec = anc / WRITTEN_NAME
        if os.path.lexists(rec):
            return rec
    return None


def _read_record(rec: Path) -> tuple[dict[str, Any], frozenset[str]]:
    """The header and the listed paths of a record (a torn last line is left out).

    Raises:
        OutputFolderError: a record that is not habitsim's (a link, another header).
    """
    try:
        st = os.lstat(rec)
    except FileNotFoundError:
        return {}, frozenset()
    key = (st.st_ino, st.st_size, st.st_mtime_ns)
    hit = _RECORDS.get(str(rec))
    if hit is not None and hit[0] == key:
        return hit[1], hit[2]
    bad = OutputFolderError(
        f"{brief_path(rec)}: not a record of habitsim's outputs (a JSON header of kind "
        f"{_RECORD_KIND!r}, then one path per line); remove it or use another folder"
    )
    if not os.path.isfile(rec) or os.path.islink(rec):
        raise bad
    with open(rec, "rb") as fh:
        lines = fh.read().decode("utf-8", errors="replace").splitlines()
    try:
        header = json.loads(lines[0]) if lines else None
    except (json.JSONDecodeError, RecursionError):
        header = None
    if not isinstance(header, dict) or header.get("kind") != _RECORD_KIND:
        raise bad
    listed = set()
    for line in lines[1:]:
        try:
            rel = json.loads(line)
        except (json.JSONDecodeError, RecursionError):
            continue
        if isinstance(rel, str):
            listed.add(rel)
    out = frozenset(listed)
    _RECORDS[str(rec)] = (key, header, out)
    return header, out


def _relative(path: Path, rec: Path) -> str:
    return Path(os.path.abspath(path)).relative_to(os.path.abspath(rec.parent)).as_posix()


def _guard(path: Path, what: str, *, folder: bool = False) -> tuple[Path, str, bool] | None:
    """Check a destination inside an output folder: (record, relative path, listed), or
    None outside every output folder. With ``folder``, ``path`` is a folder to create:
    only that it stays inside is checked.

    Raises:
        OutputFolderError: the path leads out of the folder through a link, or names a
            file (or link) habitsim did not write.
    """
    rec = _record_of(path)
    if rec is None:
        return None
    root = rec.parent
    real_root = os.path.realpath(root)
    where = Path(os.path.abspath(path))
    if not _inside(real_root, os.path.realpath(where if folder else where.parent)):
        raise OutputFolderError(
            f"{what} {brief_path(path)}: leads out of the output folder {brief_path(root)} "
            "through a link; habitsim writes only inside its output folder (remove the link "
            "or use another folder)"
        )
    rel = _relative(path, rec)
    if folder:
        return rec, rel, True
    listed = rel in _read_record(rec)[1]
    if os.path.lexists(path) and (not listed or os.path.islink(path)):
        raise OutputFolderError(
            f"{what} {brief_path(path)}: a file habitsim did not write is in the way; "
            "habitsim does not replace it (move it away or use another folder)"
        )
    return rec, rel, listed


def _record_write(path: Path) -> None:
    """List ``path`` in its output folder's record before it is written (see
    :func:`_guard` for the refusals)."""
    found = _guard(path, "output")
    if found is None or found[2]:
        return
    rec, rel, _ = found
    try:
        fd = os.open(rec, os.O_RDWR | os.O_APPEND | os.O_NOFOLLOW)
    except OSError as e:
        raise _output_error(rec, e) from None
    line = (json.dumps(rel) + "\n").encode("utf-8")
    try:
        end = os.fstat(fd).st_size
        if end and os.pread(fd, 1, end - 1) != b"\n":
            line = b"\n" + line  # a line torn by a failed write stays on its own
        os.write(fd, line)
    except OSError as e:
        raise _output_error(rec, e, writing=True) from None
    finally:
        os.close(fd)


def _new_record(root: Path, command: str, keep: list[str] | None = None) -> None:
    """Start a record listing ``keep`` (replacing the old one)."""
    rec = root / WRITTEN_NAME
    header = {"kind": _RECORD_KIND, "format_version": 1, "command": command}
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{WRITTEN_NAME}.", suffix=".tmp", dir=root)
    except OSError as e:
        raise _output_error(rec, e) from None
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(json.dumps(header) + "\n")
            fh.writelines(json.dumps(r) + "\n" for r in sorted(keep or []))
        os.replace(tmp, rec)
    except OSError as e:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise _output_error(rec, e, writing=True) from None
    _RECORDS.pop(str(rec), None)


def _leftovers(root: Path, listed: frozenset[str]) -> list[str]:
    """Temporaries a killed run left next to the files it listed."""
    by_dir: dict[str, set[str]] = {}
    for rel in listed:
        d, _, name = rel.rpartition("/")
        by_dir.setdefault(d, set()).add(name[:64])
    out = []
    for d, names in by_dir.items():
        folder = root / d if d else root
        if os.path.islink(folder) or not folder.is_dir():
            continue
        for entry in os.scandir(folder):
            m = _TEMPORARY.match(entry.name)
            if m and entry.is_file(follow_symlinks=False) and m["name"] in names:
                out.append(f"{d}/{entry.name}" if d else entry.name)
    return out


def _foreign(root: Path, owned: set[str], limit: int) -> list[str]:
    """Up to ``limit`` entries under ``root`` habitsim did not write (links count as
    entries, empty folders do not; a nested output folder with its own record is its
    own run's)."""
    found: list[str] = []
    for dirpath, dirnames, filenames in os.walk(root):
        d = Path(dirpath)
        if d != root and os.path.lexists(d / WRITTEN_NAME):
            dirnames[:] = []
            continue
        links = [n for n in dirnames if os.path.islink(d / n)]
        dirnames[:] = sorted(n for n in dirnames if n not in links)
        for name in sorted(filenames + links):
            if d == root and name in (WRITTEN_NAME, LOCK_NAME):
                continue
            rel = (d / name).relative_to(root).as_posix()
            if rel not in owned or os.path.islink(d / name):
                found.append(rel)
                if len(found) >= limit:
                    return found
    return found


def _remove(root: Path, rels: list[str], what: str) -> int:
    """Remove the regular files ``rels`` (never a link, never through a link leading out
    of ``root``) and the folders they leave empty; the number removed."""
    real_root = os.path.realpath(root)
    removed = 0
    parents: set[Path] = set()
    for rel in sorted(rels):
        p = root / rel
        if os.path.islink(p) or not p.is_file():
            continue
        if not _inside(real_root, os.path.realpath(p.parent)):
            continue
        try:
            p.unlink()
        except FileNotFoundError:
            continue
        except OSError as e:
            raise OutputPathError(
                f"{what} {brief_path(p)}: cannot be removed ({e.strerror or type(e).__name__})"
            ) from None
        removed += 1
        parents.update(a for a in p.parents if a != root and root in a.parents)
    for d in sorted(parents, key=lambda a: len(a.parts), reverse=True):
        with contextlib.suppress(OSError):
            if not os.path.islink(d):
                d.rmdir()  # only when empty
    return removed


def _describe(holder: dict[str, Any] | None) -> str:
    if not holder:
        return "no details recorded"
    return (
        f"PID {brief(holder.get('pid'))} on {brief(holder.get('host'))}, "
        f"habitsim {brief(holder.get('command'))}, started {brief(holder.get('started'))}"
    )


def _read_lock(fd: int) -> dict[str, Any] | None:
    try:
        doc = json.loads(os.pread(fd, 4096, 0).decode("utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, RecursionError):
        return None
    return doc if isinstance(doc, dict) else None


def _lock(root: Path, command: str, what: str) -> tuple[int, str | None]:
    """Take the folder's lock without waiting: (open lock file, note on a lock taken
    over from a run that ended without releasing it)."""
    path = root / LOCK_NAME
    for _ in range(8):  # the holder may remove the file between our open and flock
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o644)
        except OSError as e:
            raise _output_error(path, e, what) from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = _read_lock(fd)
            os.close(fd)
            raise OutputBusyError(
                f"{what} {brief_path(root)}: another habitsim run is writing into it "
                f"({_describe(holder)}); wait for it to end or use another folder"
            ) from None
        except OSError as e:
            os.close(fd)
            raise _output_error(path, e, what) from None
        try:
            same = os.fstat(fd).st_ino == os.lstat(path).st_ino
        except FileNotFoundError:
            same = False
        if same:
            break
        os.close(fd)
    else:
        raise OutputBusyError(f"{what} {brief_path(root)}: its lock keeps changing hands")
    old = _read_lock(fd)
    note = None
    if old is not None:
        note = (
            f"{what} {brief_path(root)}: took over the lock of a run that ended without "
            f"releasing it ({_describe(old)})"
        )
    me = {
        "pid": os.getpid(),
        "host": socket.gethostname(),
        "command": command,
        "started": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
    }
    os.ftruncate(fd, 0)
    os.pwrite(fd, json.dumps(me).encode("utf-8"), 0)
    return fd, note


def _unlock(root: Path, fd: int) -> None:
    with contextlib.suppress(OSError):
        os.unlink(root / LOCK_NAME)
    os.close(fd)


@dataclass(frozen=True)
class OutputClaim:
    """An output folder claimed by one run (:func:`claim_output_folder`).

    Attributes:
        root: the folder.
        earlier: the command of the earlier run continued in it (``resume``), or None.
        removed: files of an earlier run removed (``overwrite``).
        note: a lock taken over from a run that ended without releasing it, or None.
        stale: the earlier run's files left for :meth:`remove_stale` (``overwrite`` with
            ``defer_removal``), relative to ``root``.
    """

    root: Path
    earlier: str | None
    removed: int
    note: str | None
    stale: tuple[str, ...] = ()

    def remove_stale(self, keep: set[Path]) -> int:
        """Remove the earlier run's files that this run did not write again (``keep``:
        this run's files); returns the number removed."""
        kept = {Path(os.path.abspath(p)) for p in keep}
        gone = [r for r in self.stale if Path(os.path.abspath(self.root / r)) not in kept]
        return _remove(self.root, gone, "output")


@contextlib.contextmanager
def claim_output_folder(
    root: str | Path,
    *,
    command: str,
    what: str = "--out",
    overwrite: bool = False,
    resume: bool = False,
    resume_flag: str | None = "--resume",
    overwrite_flag: str | None = "--overwrite",
    continues: tuple[str, ...] = (),
    defer_removal: bool = False,
    log: Callable[[str], None] | None = None,
) -> Iterator[OutputClaim]:
    """Write into the folder ``root`` as the only run, with a record of what is written.

    On entry: the folder is created; its lock is taken without waiting (a lock left by a
    run that died is taken over, with a note to ``log``); then what is in it is checked:

    * files habitsim did not write (not in the folder's record) are refused unless
      ``overwrite``, which writes beside them and never removes or replaces them;
    * an earlier run's files are refused unless ``resume`` (the same ``command`` only)
      or ``overwrite``, which removes exactly the files the record lists (never a link,
      never through a link leading out of the folder) and the folders left empty.

    Inside the block every :func:`atomic_write` into the folder is listed in the record.
    On exit the lock is released (the lock file removed); the record stays. A claim of a
    folder this process already holds (a command that builds its data set in its own
    output folder) checks and removes nothing.

    Args:
        root: the output folder.
        command: the command writing it (``"eval"``, ``"data synth"``), kept in the
            record and the lock, and compared on ``resume``.
        what: the folder's name in messages (``"--out"``).
        overwrite: replace an earlier run (only the files habitsim wrote are removed).
        resume: continue an earlier run of the same command.
        resume_flag: the option that resumes, named in the refusal (None: the command
            cannot resume).
        overwrite_flag: the option that overwrites, named in the refusals (None: the
            command has none).
        continues: other commands whose output ``resume`` continues (``demo`` continues
            a ``data synth`` folder).
        defer_removal: with ``overwrite``, leave the earlier run's files in place (listed
            in :attr:`OutputClaim.stale`) for the caller to remove once its new outputs
            are complete (:meth:`OutputClaim.remove_stale`).
        log: where the note on a taken-over lock goes.

    Raises:
        OutputBusyError: another run holds the folder (in well under a second).
        OutputFolderError: foreign files or an earlier run, as above; a record that is
            not habitsim's.
        OutputPathError: the folder cannot be created, locked or cleared.
    """
    root = Path(root)
    if os.path.lexists(root) and not root.is_dir():
        raise OutputPathError(f"{what} {brief_path(root)}: is a file, expected a folder")
    real = os.path.realpath(root)
    if real in _HELD:
        _HELD[real] += 1
        try:
            yield OutputClaim(root, None, 0, None)
        finally:
            _HELD[real] -= 1
        return
    created = _first_missing(root)
    try:
        root.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise _output_error(root / "x", e, what) from None
    fd, note = _lock(root, command, what)
    _HELD[real] = 1
    failed = True
    try:
        if note and log:
            log(f"note: {note}")
        header, listed = _read_record(root / WRITTEN_NAME)
        present = [r for r in listed if os.path.isfile(root / r) and not os.path.islink(root / r)]
        present += _leftovers(root, listed)
        earlier = header.get("command") if present else None
        same = earlier == command or earlier in continues
        again = f"pass {overwrite_flag} to replace it (only the files habitsim wrote are removed), "
        removed = 0
        stale: tuple[str, ...] = ()
        if overwrite and defer_removal:
            stale = tuple(sorted(present))
            _new_record(root, command, keep=list(present))
        elif overwrite:
            removed = _remove(root, present, what)
            _new_record(root, command)
        else:
            foreign = _foreign(root, set(present), 4)
            if foreign:
                more = "" if len(foreign) < 4 else ", …"
                beside = (
                    f", or pass {overwrite_flag} to write beside them (they are kept)"
                    if overwrite_flag
                    else ""
                )
                raise OutputFolderError(
                    f"{what} {brief_path(root)}: holds files habitsim did not write "
                    f"({', '.join(brief_path(f, 60) for f in foreign[:3])}{more}); use an "
                    f"empty or new folder{beside}"
                )
            if present and not (resume and same):
                hint = f"pass {resume_flag} to continue it, " if resume_flag and same else ""
                raise OutputFolderError(
                    f"{what} {brief_path(root)}: holds an earlier habitsim "
                    f"{brief(earlier)} run ({len(present)} files); {hint}"
                    f"{again if overwrite_flag else ''}or use another folder"
                )
            if not present:
                _new_record(root, command)
        yield OutputClaim(root, earlier if resume else None, removed, note, stale)
        failed = False
    finally:
        _HELD.pop(real, None)
        _unlock(root, fd)
        if failed and created is not None:
            _remove_if_unused(root, created)


def _first_missing(root: Path) -> Path | None:
    """The outermost folder of ``root``'s path that does not exist yet (None: it does)."""
    missing = None
    p = Path(os.path.abspath(root))
    while not os.path.lexists(p):
        missing = p
        if p.parent == p:
            break
        p = p.parent
    return missing


def _remove_if_unused(root: Path, created: Path) -> None:
    """After a failed run: remove the folders this claim created (``created`` and the
    folders below it down to ``root``) when nothing but the record was written into them."""
    with contextlib.suppress(OSError):
        if any(e.name != WRITTEN_NAME for e in os.scandir(root)):
            return
        _, listed = _read_record(root / WRITTEN_NAME)
        if listed:
            return
        os.unlink(root / WRITTEN_NAME)
        p = Path(os.path.abspath(root))
        while True:
            os.rmdir(p)  # fails (and stops) on a folder that is not empty
            if p == created:
                break
            p = p.parent


def is_written(path: str | Path) -> bool:
    """Whether habitsim wrote ``path``: it is listed in its output folder's record."""
    p = Path(path)
    rec = _record_of(p)
    return rec is not None and _relative(p, rec) in _read_record(rec)[1]


def remove_written(paths: list[Path], what: str = "output") -> int:
    """Remove those of ``paths`` that habitsim wrote (listed in their output folder's
    record, regular files, not reached through a link leading out of the folder); the
    others are left alone. Returns the number removed.

    Raises:
        OutputPathError: a listed file that cannot be removed.
    """
    removed = 0
    for p in paths:
        rec = _record_of(p)
        if rec is not None and _relative(p, rec) in _read_record(rec)[1]:
            removed += _remove(rec.parent, [_relative(p, rec)], what)
    return removed


# --- input folders -------------------------------------------------------------------------


def input_files(
    root: str | Path,
    suffixes: tuple[str, ...],
    *,
    follow_symlinks: bool = False,
    what: str = "--dir",
) -> list[Path]:
    """Every file under the folder ``root`` whose suffix (any case) is one of
    ``suffixes``, sorted.

    A link (to a file of those types, or to a folder) that leads out of ``root`` is
    refused unless ``follow_symlinks``; a link to a folder inside ``root`` is not walked
    (its files are found where they are). With ``follow_symlinks`` linked folders are
    walked, each real folder once.

    Raises:
        InputPathError: a link leading out of the folder (the message names the link,
            never what it points to or holds).
    """
    base = Path(root)
    real_root = os.path.realpath(base)
    out: list[Path] = []
    seen: set[str] = set()
    stack = [base]
    while stack:
        d = stack.pop()
        real = os.path.realpath(d)
        if real in seen:
            continue
        seen.add(real)
        try:
            entries = sorted(os.scandir(d), key=lambda x: x.name)
        except OSError as e:
            raise InputPathError(
                f"{what} {brief_path(d)}: cannot be read ({e.strerror or type(e).__name__})"
            ) from None
        for entry in entries:
            p = Path(entry.path)
            link = entry.is_symlink()
            is_dir = entry.is_dir(follow_symlinks=True)
            wanted = is_dir or p.suffix.lower() in suffixes
            if link and wanted and not follow_symlinks:
                if _inside(real_root, os.path.realpath(p)):
                    if not is_dir:
                        out.append(p)
                    continue
                raise InputPathError(
                    f"{what} {brief_path(base)}: {brief_path(p.relative_to(base).as_posix())} "
                    "is a link leading out of the folder; pass --follow-symlinks to read "
                    "through it, or copy what it points to into the folder"
                )
            if is_dir:
                stack.append(p)
            elif wanted and entry.is_file(follow_symlinks=True):
                out.append(p)
    return sorted(out)


def check_inside(
    root: str | Path, path: str | Path, *, follow_symlinks: bool = False, what: str = "--data"
) -> Path:
    """``path`` (under the folder ``root``), refused when it leads out of ``root``
    through a link and ``follow_symlinks`` is False.

    Raises:
        InputPathError: naming the path, never what it holds.
    """
    p = Path(path)
    if not follow_symlinks and not _inside(os.path.realpath(root), os.path.realpath(p)):
        raise InputPathError(
            f"{what} {brief_path(root)}: {brief_path(p)} leads out of the folder through a "
            "link; pass --follow-symlinks to read through it"
        )
    return p
