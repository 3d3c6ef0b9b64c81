"""The learning core: habit-preserving motion VQ-VAE, per-species habit flows, text
retrieval, training and the transfer API ("Behave Your Motion", Sec. 3).

Typical use::

    from habitsim import generate
    from habitsim.models import transfer

    horse_trot = generate("horse", "trot", seed=1)
    cat = transfer(horse_trot, to="cat")              # method="habit", shipped checkpoint
    tiger = transfer(horse_trot, to="tiger")          # held out: habit latent of the nearest
    print(tiger.metadata["transfer"]["retrieval"]["explanation"])

Modules: :mod:`~habitsim.models.config` (typed configs and presets),
:mod:`~habitsim.models.features` (the network's motion representation),
:mod:`~habitsim.models.vqvae`, :mod:`~habitsim.models.quantizer`,
:mod:`~habitsim.models.habit`, :mod:`~habitsim.models.text`,
:mod:`~habitsim.models.model` (the network), :mod:`~habitsim.models.train` (with
:mod:`~habitsim.models.losses`, :mod:`~habitsim.models.validation`,
:mod:`~habitsim.models.resume` and :mod:`~habitsim.models.finetune`),
:mod:`~habitsim.models.recipe` (staged presets: the shipped model's stages),
:mod:`~habitsim.models.checkpoint`, :mod:`~habitsim.models.transfer`,
:mod:`~habitsim.models.evaluate`; text to motion: :mod:`~habitsim.models.t2m_data`
(the code set), :mod:`~habitsim.models.t2m_config`, :mod:`~habitsim.models.codegpt` (the
transformer),
:mod:`~habitsim.models.t2m_train`, :mod:`~habitsim.models.t2m`,
:mod:`~habitsim.models.t2m_eval`.
"""

from __future__ import annotations

import importlib
import sys
import types
from typing import Any

#: public name → defining submodule (imported on first use: the network modules pull in
#: torch, and ``habitsim.models.config`` must stay importable without it)
_EXPORTS = {
    "LoadedCheckpoint": "checkpoint",
    "load_checkpoint": "checkpoint",
    "save_checkpoint": "checkpoint",
    "PRESETS": "config",
    "VARIANTS": "config",
    "Config": "config",
    "HabitConfig": "config",
    "ModelConfig": "config",
    "NetConfig": "config",
    "QuantizerConfig": "config",
    "TextConfig": "config",
    "TrainConfig": "config",
    "preset": "config",
    "CheckpointError": "errors",
    "ConfigError": "errors",
    "MethodNotAvailableError": "errors",
    "ModelError": "errors",
    "TextEncoderError": "errors",
    "TrainingDataError": "errors",
    "CodeSetError": "errors",
    "GenerationRequestError": "errors",
    "text_to_motion": "t2m",
    "T2MOptions": "t2m",
    "build_code_set": "t2m_data",
    "load_code_set": "t2m_data",
    "CodeGPT": "codegpt",
    "CodeGPTConfig": "t2m_config",
    "T2MConfig": "t2m_config",
    "t2m_preset": "t2m_config",
    "train_codegpt": "t2m_train",
    "load_codegpt": "t2m_train",
    "prompt_agreement": "t2m_eval",
    "UnknownMethodError": "errors",
    "REFERENCE_CLIPS": "evaluate",
    "reconstruction_error": "evaluate",
    "HabitVQVAE": "model",
    "Retrieval": "text",
    "retrieve_neighbour": "text",
    "species_embeddings": "text",
    "TrainResult": "train",
    "train": "train",
    "RECIPES": "recipe",
    "Stage": "recipe",
    "StagedResult": "recipe",
    "train_staged": "recipe",
    "METHODS": "transfer",
    "TransferMethod": "transfer",
    "available_methods": "transfer",
    "network_method": "transfer",
    "network_transfer": "transfer",
    "load_model": "transfer",
    "reconstruct": "transfer",
    "register_method": "transfer",
    "shipped_checkpoint": "transfer",
    "transfer": "transfer",
    "habit_from_clips": "transfer",
    "HabitFitOptions": "habit_fit",
    "HabitLatent": "habit_fit",
}

__all__ = [
    "transfer",
    "habit_from_clips",
    "HabitFitOptions",
    "HabitLatent",
    "reconstruct",
    "network_method",
    "network_transfer",
    "METHODS",
    "TransferMethod",
    "available_methods",
    "register_method",
    "load_model",
    "shipped_checkpoint",
    "load_checkpoint",
    "save_checkpoint",
    "LoadedCheckpoint",
    "HabitVQVAE",
    "Config",
    "ModelConfig",
    "TrainConfig",
    "NetConfig",
    "QuantizerConfig",
    "HabitConfig",
    "TextConfig",
    "PRESETS",
    "VARIANTS",
    "preset",
    "train",
    "TrainResult",
    "RECIPES",
    "Stage",
    "StagedResult",
    "train_staged",
    "reconstruction_error",
    "REFERENCE_CLIPS",
    "Retrieval",
    "retrieve_neighbour",
    "species_embeddings",
    "ModelError",
    "ConfigError",
    "CheckpointError",
    "UnknownMethodError",
    "MethodNotAvailableError",
    "TextEncoderError",
    "TrainingDataError",
    "CodeSetError",
    "GenerationRequestError",
    "text_to_motion",
    "T2MOptions",
    "build_code_set",
    "load_code_set",
    "CodeGPT",
    "CodeGPTConfig",
    "T2MConfig",
    "t2m_preset",
    "train_codegpt",
    "load_codegpt",
    "prompt_agreement",
]


#: Functions named like the submodule defining them (``habitsim.models.transfer`` is the
#: function, ``habitsim.models.transfer.transfer`` too).
_SHADOWED = ("transfer", "train")


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:
        value = getattr(importlib.import_module(f"{__name__}.{_EXPORTS[name]}"), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


class _Package(types.ModuleType):
    """The import system sets a loaded submodule as an attribute of its package; keep
    ``transfer`` and ``train`` the functions whenever their submodules load."""

    def __setattr__(self, name: str, value: Any) -> None:
        if name in _SHADOWED and isinstance(value, types.ModuleType):
            value = getattr(value, name)
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package
