"""Typed exceptions of habitsim, all under one root :class:`HabitsimError`.

Every message names the problem and, where there is a finite set of valid choices,
lists them, so a user can fix the input without reading the source.
"""

from __future__ import annotations

import contextlib
import contextvars
from collections.abc import Iterable, Iterator


class HabitsimError(Exception):
    """Root of every error raised on purpose by habitsim.

    Attributes:
        exit_code: what the command line exits with on it: 2 for bad input (the default),
            1 for work that failed (:class:`OutputWriteError`).
    """

    exit_code: int = 2


class UnknownSpeciesError(HabitsimError, KeyError):
    """A species name that is not in the catalog."""

    def __init__(self, name: str, known: Iterable[str]):
        self.name = name
        self.known = sorted(known)
        super().__init__(f"unknown species {brief(name)}; known: {', '.join(self.known)}")

    def __str__(self) -> str:  # KeyError would quote the whole message
        return self.args[0]


class SpeciesFileError(HabitsimError, ValueError):
    """A species TOML file that is missing fields or holds inconsistent numbers."""


class SpeciesNameError(HabitsimError, ValueError):
    """A name a new species cannot take: not a lower-case identifier, or (the subclass
    :class:`SpeciesNameClashError`) already taken."""


class SpeciesNameClashError(SpeciesNameError):
    """A species name found twice: a user species named like a built-in one, or in two
    user catalog folders. Attributes: ``name`` and ``places`` (where each one is)."""

    def __init__(self, name: str, places: Iterable[str], hint: str = ""):
        self.name = name
        self.places = list(places)
        text = f"species name {name!r} clashes: it is {' and '.join(self.places)}"
        super().__init__(text + (f"; {hint}" if hint else ""))


class ClipMeasureError(HabitsimError, ValueError):
    """A clip a species cannot be measured from (``habitsim species from-clip``). The
    attribute ``code`` says what is missing: ``"legs"`` (four legs not found),
    ``"short"`` (too few frames or seconds to show a stride), ``"body"`` (no spine
    joint ahead of the hips, or a zero-length segment)."""

    def __init__(self, code: str, message: str):
        self.code = code
        super().__init__(message)


class InvalidMotionError(HabitsimError, ValueError):
    """Motion arrays of the wrong shape, non-finite values or inconsistent metadata."""


class HabitReferenceError(HabitsimError, ValueError):
    """Reference clips a habit latent cannot be found from (``habit_from``): a clip of
    another species than the target's, clips of several species, none at all, or too
    short for one window; or habit-fitting options out of range.

    Attributes:
        code: what is wrong: ``"species"`` (a clip of another species; the message names
            both), ``"empty"`` (no clip), ``"method"`` (the transfer method has no habit
            latent) or ``"options"`` (a :class:`~habitsim.models.habit_fit.HabitFitOptions`
            field out of range).
    """

    def __init__(self, code: str, message: str):
        self.code = code
        super().__init__(message)


class MotionFileError(HabitsimError, ValueError):
    """A motion file (.npz) that cannot be read: wrong keys, version or corrupt data."""


class BVHParseError(HabitsimError, ValueError):
    """A BVH file that is truncated, malformed or has inconsistent channel counts."""


class GLTFError(HabitsimError, ValueError):
    """A glTF / GLB file that cannot be read as a skinned animation: missing, corrupt or
    truncated, without a skin or an animation, or an unknown animation name."""


class SkeletonMappingError(HabitsimError, ValueError):
    """A source skeleton that cannot be mapped onto the habitsim quadruped topology."""


class RigExportError(HabitsimError, ValueError):
    """A rig that cannot take a habitsim motion: a leg or the trunk the mapping leaves
    unanimated, a joint without the channels its rotation needs, no joint to carry the
    root's travel."""


class IKError(HabitsimError, ValueError):
    """An inverse-kinematics request with invalid input."""


class GaitError(HabitsimError, ValueError):
    """A gait or action that a species does not have, or bad generator parameters."""


class PromptError(HabitsimError, ValueError):
    """A text-to-motion prompt whose species cannot be settled.

    Attributes:
        code: ``no_species`` (neither the text nor the caller names a catalog species),
            ``several_species`` (the text names more than one), ``species_conflict``
            (the text names another species than the caller).
        known: the catalog's species (what is valid).
    """

    def __init__(self, code: str, message: str, known: Iterable[str] = ()):
        self.code = code
        self.known = sorted(known)
        super().__init__(message)


class CaptionError(HabitsimError, ValueError):
    """A clip a caption cannot be written for, or bad caption settings."""


class DatasetError(HabitsimError, ValueError):
    """A data set folder that is missing files or has an inconsistent manifest."""


class SimulationError(HabitsimError, ValueError):
    """Bad input to the tracking runner: unknown controller, a model that does not fit
    the reference (missing joints, wrong nq), NaN in a reference, bad rates."""


class UnknownMethodError(HabitsimError, KeyError, ValueError):
    """A transfer method name that is not registered (the message lists the valid ones);
    raised by the method registry, :data:`habitsim.transfer_methods.METHODS`."""

    def __str__(self) -> str:  # KeyError would quote the whole message
        return str(self.args[0]) if self.args else ""


class MethodUnavailable(HabitsimError):
    """A registered transfer method that cannot serve this (motion, target) pair: no
    paired ground truth, no trained checkpoint of its variant; the reason is the message."""


class OutputPathError(HabitsimError, OSError):
    """An output path that cannot be written: a file where a folder should be, a folder
    where a file should be, a read-only folder, a full disk."""


class OutputWriteError(OutputPathError):
    """An output that failed while it was being written, after the work was done: a full
    disk (``ENOSPC``), a quota reached (``EDQUOT``), a file system gone read-only
    (``EROFS``), permission taken away (``EACCES``). Nothing half-written is left under
    the output's name; the command line exits with code 1 (failed work, not bad input)."""

    exit_code = 1


class OutputFolderError(HabitsimError, ValueError):
    """An output folder habitsim may not write into as asked: it holds files habitsim did
    not write or an earlier run (without ``--overwrite`` / ``--resume``), or a path in it
    leads out of it through a link. The message says what is there and what to do."""


class OutputBusyError(HabitsimError):
    """An output folder another habitsim run is writing into (its lock is held); the
    message names that run's PID, host, command and start time."""


class InputPathError(HabitsimError, ValueError):
    """An input folder holding a link that leads out of it (without
    ``--follow-symlinks``); the message names the link, never a file's content."""


class ArgumentRangeError(HabitsimError, ValueError):
    """A command-line or API argument outside its physically sensible range."""


class TimeLimitError(HabitsimError):
    """A call that ran past its time limit and was stopped (an entry-point method that
    hangs, :func:`habitsim.timelimit.call_with_time_limit`)."""


#: Longest message text a value is echoed with (:func:`brief`).
BRIEF_CHARS = 60
#: Longest message the command line prints after ``error:``.
MAX_MESSAGE_CHARS = 2000


def unknown_choice(kind: str, value: object, valid: Iterable[str]) -> str:
    """Format the standard "unknown X 'v'; valid: a, b, c" message."""
    return f"unknown {kind} {value!r}; valid: {', '.join(sorted(valid))}"


#: False while reading files of an input folder (:func:`unquoted`): :func:`brief` then
#: gives a string's length, never its text.
_QUOTE_TEXT: contextvars.ContextVar[bool] = contextvars.ContextVar("habitsim_quote", default=True)


@contextlib.contextmanager
def unquoted() -> Iterator[None]:
    """Inside the block, messages built with :func:`brief` say how long a piece of text
    is instead of quoting it (files read from an input folder: a message never echoes
    what a file holds)."""
    token = _QUOTE_TEXT.set(False)
    try:
        yield
    finally:
        _QUOTE_TEXT.reset(token)


def brief(value: object, limit: int = BRIEF_CHARS) -> str:
    """``repr(value)`` cut to ``limit`` characters, so a 5 MB token or a huge array never
    ends up whole in an error message (inside :func:`unquoted`, text is not quoted)."""
    if isinstance(value, str | bytes) and not _QUOTE_TEXT.get():
        return f"<text of {len(value)} characters>"
    if isinstance(value, str | bytes) and len(value) > 4 * limit:
        value = value[: 4 * limit]  # repr of a huge string costs its whole length
        text = repr(value)
        return text[:limit] + "…"
    text = repr(value)
    return text if len(text) <= limit else text[:limit] + f"… ({len(text)} characters)"


def bounded(message: str, limit: int = MAX_MESSAGE_CHARS) -> str:
    """``message`` cut to ``limit`` characters (the rest elided with its length)."""
    if len(message) <= limit:
        return message
    return message[:limit] + f"… ({len(message)} characters)"


def brief_path(path: object, limit: int = 160) -> str:
    """A path for a message: only its last ``limit`` characters when longer (the file
    name is the informative end)."""
    text = str(path)
    return text if len(text) <= limit else "…" + text[-limit:]


class MetadataError(HabitsimError, ValueError):
    """A motion's metadata entry (``metadata["import"]``, ``metadata["transfer"]``) with
    a missing or malformed field; the message names the field."""


class JSONFileError(HabitsimError, ValueError):
    """A JSON or TOML document that cannot be read: too large, nested too deep, an
    integer with too many digits, not UTF-8 or not well-formed (:mod:`habitsim.jsonfile`;
    readers raise their own error class with the same message)."""
