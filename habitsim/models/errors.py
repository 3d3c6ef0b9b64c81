"""Typed errors of the learning core, all under :class:`habitsim.errors.HabitsimError`."""

from __future__ import annotations

from ..errors import HabitsimError, MethodUnavailable, UnknownMethodError

__all__ = [
    "ModelError",
    "CheckpointError",
    "UnknownMethodError",
    "MethodNotAvailableError",
    "TextEncoderError",
    "TrainingDataError",
    "ConfigError",
    "CodeSetError",
    "GenerationRequestError",
]


class ModelError(HabitsimError, ValueError):
    """Root of the learning core's errors (bad model input or state)."""


class ConfigError(ModelError):
    """A model / training configuration with unknown keys, bad values or an unknown preset."""


class CheckpointError(ModelError):
    """A checkpoint folder that is missing files, corrupt, or does not match its config."""


class MethodNotAvailableError(ModelError, MethodUnavailable):
    """A registered transfer method whose trained checkpoint is not shipped / not given
    (a :class:`~habitsim.errors.MethodUnavailable`: the benchmarks record it in the row)."""


class TextEncoderError(ModelError):
    """The sentence-embedding model cannot be loaded or a description cannot be embedded."""


class TrainingDataError(ModelError):
    """A training data set that is empty or lacks the species / splits training needs."""


class CodeSetError(ModelError):
    """A text-to-motion code set that is missing, unreadable or cannot be built (no
    captions, no captioned clip, embeddings of the wrong shape)."""


class GenerationRequestError(ModelError):
    """A text-to-motion request the model cannot serve.

    Attributes:
        code: what is wrong: ``empty_text``, ``text_too_long``, ``bad_text`` (a character
            that is no text, e.g. a lone surrogate), ``length_out_of_range``,
            ``bad_sampling`` (temperature, top-k or guidance outside their ranges).
    """

    def __init__(self, code: str, message: str):
        self.code = code
        super().__init__(message)
