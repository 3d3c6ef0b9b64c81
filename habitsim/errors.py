"""Typed exceptions of habitsim, all under one root :class:`HabitsimError`.

Every message names the problem and, where there is a finite set of valid choices,
lists them, so a user can fix the input without reading the source.
"""

from __future__ import annotations

from collections.abc import Iterable


class HabitsimError(Exception):
    """Root of every error raised on purpose by habitsim."""


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


class InvalidMotionError(HabitsimError, ValueError):
    """Motion arrays of the wrong shape, non-finite values or inconsistent metadata."""


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


class ArgumentRangeError(HabitsimError, ValueError):
    """A command-line or API argument outside its physically sensible range."""


#: Longest message text a value is echoed with (:func:`brief`).
BRIEF_CHARS = 60
#: Longest message the command line prints after ``error:``.
MAX_MESSAGE_CHARS = 2000


def unknown_choice(kind: str, value: object, valid: Iterable[str]) -> str:
    """Format the standard "unknown X 'v'; valid: a, b, c" message."""
    return f"unknown {kind} {value!r}; valid: {', '.join(sorted(valid))}"


def brief(value: object, limit: int = BRIEF_CHARS) -> str:
    """``repr(value)`` cut to ``limit`` characters, so a 5 MB token or a huge array never
    ends up whole in an error message."""
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
