"""habitsim: cross-species animal motion transfer with habits, checked in physics."""

from __future__ import annotations

from .errors import (
    BVHParseError,
    DatasetError,
    GaitError,
    GLTFError,
    HabitsimError,
    IKError,
    InvalidMotionError,
    MotionFileError,
    SkeletonMappingError,
    SpeciesFileError,
    UnknownSpeciesError,
)
from .gaits import available_actions, generate
from .motion import Motion, load_motion
from .skeleton import JOINT_NAMES, Skeleton, get_skeleton
from .species import Species, all_species, load_species, species_names

__version__ = "0.1.0"

__all__ = [
    "__version__",
    "HabitsimError",
    "UnknownSpeciesError",
    "SpeciesFileError",
    "InvalidMotionError",
    "MotionFileError",
    "BVHParseError",
    "GLTFError",
    "SkeletonMappingError",
    "IKError",
    "GaitError",
    "DatasetError",
    "Species",
    "load_species",
    "species_names",
    "all_species",
    "Skeleton",
    "get_skeleton",
    "JOINT_NAMES",
    "Motion",
    "load_motion",
    "generate",
    "available_actions",
    "transfer",
    "refine",
]


def __getattr__(name: str):
    """``habitsim.transfer`` (the function) and ``habitsim.refine`` (the module, its
    function is ``habitsim.refine.refine``) load their stage on first use."""
    if name == "transfer":
        from .models import transfer

        return transfer
    if name == "refine":
        import importlib

        return importlib.import_module(".refine", __name__)
    raise AttributeError(f"module 'habitsim' has no attribute {name!r}")
