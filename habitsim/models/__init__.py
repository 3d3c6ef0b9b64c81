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
:mod:`~habitsim.models.model` (the network), :mod:`~habitsim.models.train`,
:mod:`~habitsim.models.checkpoint`, :mod:`~habitsim.models.transfer`,
:mod:`~habitsim.models.evaluate`.
"""

from __future__ import annotations

from .checkpoint import LoadedCheckpoint, load_checkpoint, save_checkpoint
from .config import (
    PRESETS,
    VARIANTS,
    Config,
    HabitConfig,
    ModelConfig,
    NetConfig,
    QuantizerConfig,
    TextConfig,
    TrainConfig,
    preset,
)
from .errors import (
    CheckpointError,
    ConfigError,
    MethodNotAvailableError,
    ModelError,
    TextEncoderError,
    TrainingDataError,
    UnknownMethodError,
)
from .evaluate import REFERENCE_CLIPS, reconstruction_error
from .model import HabitVQVAE
from .text import Retrieval, retrieve_neighbour, species_embeddings
from .train import TrainResult, train
from .transfer import (
    METHODS,
    TransferMethod,
    available_methods,
    direct_transfer,
    load_model,
    reconstruct,
    register_method,
    shipped_checkpoint,
    transfer,
)

__all__ = [
    "transfer",
    "reconstruct",
    "direct_transfer",
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
]
