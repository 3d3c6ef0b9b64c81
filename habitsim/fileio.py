"""Atomic file writing: outputs appear complete or not at all.

A single file is written with :func:`atomic_write` (a temporary file next to it, renamed
over it once complete). A command that writes several files wraps its writes in
:func:`output_transaction`: every destination is checked for writability before any work
starts, the atomic writes inside the block are staged, and the files are renamed into
place together when the block ends without an error, so the command leaves all of its
outputs or none. Any path that cannot be written is an
:class:`~habitsim.errors.OutputPathError`, never a raw ``OSError``.

Inside an output folder claimed with :func:`habitsim.folders.claim_output_folder`, every
path written here is listed in the folder's record first, and a path leading out of the
folder through a link or naming a file habitsim did not write is refused.
"""

from __future__ import annotations

import contextlib
import contextvars
import math
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any, cast

import numpy as np

from .errors import OutputPathError, brief_path
from .folders import _guard, _output_error, _record_write, write_failure

#: Staged (temporary, destination) pairs of the innermost :func:`output_transaction`.
_STAGED: contextvars.ContextVar[list[tuple[str, Path]] | None] = contextvars.ContextVar(
    "habitsim_staged_outputs", default=None
)


def check_writable(path: str | Path, what: str = "output") -> Path:
    """Check, without leaving anything on disk, that ``path`` can be written.

    The nearest existing ancestor must be a folder (not a file where a folder should be)
    that this process can create files in, and ``path`` itself must not be a folder.
    When the parent folder exists, a probe file is created in it and removed at once (so
    read-only file systems are caught even for the super-user).

    Args:
        path: the output file.
        what: its name in messages (``"--report"``).

    Returns:
        ``path`` as a :class:`~pathlib.Path`.

    Inside a claimed output folder (:func:`claim_output_folder`) the path must also stay
    in the folder (no link leading out) and must not replace a file habitsim did not write.

    Raises:
        OutputPathError: naming the path and the reason.
        OutputFolderError: a path through a link leading out of its output folder, or
            one naming a file habitsim did not write.
    """
    p = Path(path)
    if p.is_dir():
        raise OutputPathError(f"{what} {brief_path(p)}: is a folder, expected a file path")
    _guard(p, what)
    anc = p.parent
    while not anc.exists():
        if anc.is_symlink():  # a dangling link where a folder should be
            raise OutputPathError(f"{what} {brief_path(p)}: {brief_path(anc)} is a broken link")
        if anc.parent == anc:
            break
        anc = anc.parent
    if not anc.is_dir():
        raise OutputPathError(
            f"{what} {brief_path(p)}: {brief_path(anc)} is a file where a folder should be"
        )
    if anc != p.parent:
        if not os.access(anc, os.W_OK | os.X_OK):
            raise OutputPathError(f"{what} {brief_path(p)}: folder {brief_path(anc)} is read-only")
        return p
    try:
        fd, probe = tempfile.mkstemp(prefix=f".{p.name[:64]}.", suffix=".probe", dir=anc)
    except OSError as e:
        raise _output_error(p, e, what) from None
    os.close(fd)
    with contextlib.suppress(OSError):
        os.unlink(probe)
    return p


def make_dirs(path: str | Path, what: str = "output folder") -> Path:
    """``mkdir -p path``, with a typed error instead of a raw ``OSError``.

    Raises:
        OutputPathError: a file where a folder should be, a read-only parent, …
        OutputFolderError: a folder reached through a link leading out of its output
            folder.
    """
    p = Path(path)
    _guard(p, what, folder=True)
    try:
        p.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        if p.exists() and not p.is_dir():
            raise OutputPathError(f"{what} {brief_path(p)}: is a file, expected a folder") from None
        raise _output_error(p / "x", e, what) from None
    return p


@contextlib.contextmanager
def output_transaction(paths: dict[str, str | Path | None] | None = None) -> Iterator[None]:
    """Write the files of one command all together or not at all.

    Every ``{what: path}`` given (None values are skipped) is checked with
    :func:`check_writable` on entry, and two outputs may not share a path. Inside the
    block, :func:`atomic_write` (and everything built on it: :meth:`Motion.save
    <habitsim.motion.Motion.save>`, :func:`~habitsim.bvh.write_bvh`, the video writers)
    writes to temporary files next to the destinations; when the block ends normally they
    are renamed into place, and on any exception they are all removed. If a rename fails
    half-way, the files already moved are put back as they were.

    Raises:
        OutputPathError: an unwritable destination (before the block runs) or a failed
            commit.
    """
    seen: dict[Path, str] = {}
    for what, path in (paths or {}).items():
        if path is None:
            continue
        p = check_writable(path, what)
        key = Path(os.path.abspath(p))
        if key in seen:
            raise OutputPathError(f"{seen[key]} and {what} name the same file {brief_path(p)}")
        seen[key] = what
    staged: list[tuple[str, Path]] = []
    token = _STAGED.set(staged)
    try:
        yield
    except BaseException:
        _STAGED.reset(token)
        for tmp, _ in staged:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
        raise
    _STAGED.reset(token)
    _commit(staged)


def _commit(staged: list[tuple[str, Path]]) -> None:
    """Rename staged files into place; on a failure put back what was already moved."""
    done: list[tuple[Path, str | None]] = []  # (destination, hard link to its old file)
    try:
        for tmp, dest in staged:
            old = None
            if dest.exists():
                old = tempfile.mktemp(prefix=f".{dest.name[:64]}.", suffix=".old", dir=dest.parent)
                os.link(dest, old)
            try:
                os.replace(tmp, dest)
            except OSError:
                if old is not None:
                    os.unlink(old)
                raise
            done.append((dest, old))
    except OSError as e:
        for d, old in reversed(done):
            with contextlib.suppress(OSError):
                if old is None:
                    os.unlink(d)
                else:
                    os.replace(old, d)
        for tmp, _ in staged:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
        raise _output_error(dest, e, writing=True) from None
    for _, old in done:
        if old is not None:
            with contextlib.suppress(OSError):
                os.unlink(old)


@contextlib.contextmanager
def atomic_path(path: str | Path, suffix: str = ".tmp", *, sync: bool = True) -> Iterator[str]:
    """A temporary file name next to ``path`` for writers that need a name, not a handle
    (ffmpeg). When the block ends normally the file is flushed to the disk (``fsync``;
    not with ``sync=False``, for a writer that did it) and renamed over ``path`` (or
    staged, inside an :func:`output_transaction`); on any exception it is removed.

    Inside a claimed output folder the path is listed in the folder's record before the
    file appears (see :func:`claim_output_folder`).

    Raises:
        OutputPathError: the folder cannot be created or written.
        OutputWriteError: a write into the file inside the block (an ``OSError`` without
            a file name: a full disk, a quota reached), the flush or the rename failed;
            the temporary file is removed.
        OutputFolderError: see :func:`check_writable`.
    """
    path = Path(path)
    _record_write(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name[:64]}.", suffix=suffix, dir=path.parent)
    except OSError as e:
        raise _output_error(path, e) from None
    os.close(fd)
    # mkstemp creates the file private (0600); give it the permissions a plain open()
    # would (0666 minus the umask), so outputs are readable like any other file.
    umask = os.umask(0)
    os.umask(umask)
    try:
        yield tmp
        try:
            if sync:
                _fsync_file(tmp)
            os.chmod(tmp, 0o666 & ~umask)
            staged = _STAGED.get()
            if staged is not None:
                staged.append((tmp, path))
                return
            os.replace(tmp, path)
        except OSError as e:
            raise _output_error(path, e, writing=True) from None
    except BaseException as e:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        if write_failure(e):  # the writer's own write into ``tmp`` (pygltflib, …)
            raise _output_error(path, cast(OSError, e), writing=True) from None
        raise


def _fsync_file(name: str) -> None:
    """Flush a file another program wrote (ffmpeg) to the disk."""
    fd = os.open(name, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


@contextlib.contextmanager
def atomic_write(path: str | Path, mode: str = "wb") -> Iterator[IO]:
    """Open a temporary file next to ``path``; rename it over ``path`` on success.

    The file is flushed to the disk (``fsync``) before the rename. On any exception the
    temporary file is removed and ``path`` is left untouched, so no half-written output
    is ever left on disk. Inside an :func:`output_transaction` the rename waits for the
    end of the transaction.

    Raises:
        OutputPathError: the folder cannot be created or written.
        OutputWriteError: a write into the file, its flush or its rename failed (a full
            disk, a quota reached, a file system gone read-only).
    """
    with atomic_path(path, sync=False) as tmp:
        try:
            text: dict[str, Any] = {} if "b" in mode else {"encoding": "utf-8"}
            fh = open(tmp, mode, **text)
        except OSError as e:
            raise _output_error(Path(path), e, writing=True) from None
        try:
            yield fh
        except BaseException as e:
            with contextlib.suppress(OSError):
                fh.close()  # may try to flush the buffer again
            if write_failure(e):
                raise _output_error(Path(path), cast(OSError, e), writing=True) from None
            raise
        try:
            with fh:
                fh.flush()
                os.fsync(fh.fileno())
        except OSError as e:
            raise _output_error(Path(path), e, writing=True) from None


def atomic_write_text(path: str | Path, text: str) -> None:
    """Write ``text`` to ``path`` atomically (UTF-8)."""
    with atomic_write(path, "w") as fh:
        fh.write(text)


def json_safe(v: Any) -> Any:
    """``v`` with NaN / inf floats as None, numpy scalars as Python ones and dict keys as
    strings, so :func:`json.dumps` writes standard JSON."""
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if isinstance(v, np.generic):
        return json_safe(v.item())
    if isinstance(v, dict):
        return {str(k): json_safe(x) for k, x in v.items()}
    if isinstance(v, list | tuple):
        return [json_safe(x) for x in v]
    return v
