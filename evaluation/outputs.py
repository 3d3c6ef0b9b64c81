"""Another method's outputs, read from a folder: ``habitsim eval --method NAME=DIR``.

The folder's contract: one file per (source clip, target species) pair,

    DIR/<target>/<clip_id>.npz     (or .bvh, .glb, .gltf)

``<target>`` a catalog species name, ``<clip_id>`` the source clip's id in the data set
(the stem of its file as the manifest names it: ``clips/dog/dog_0003.npz`` → ``dog_0003``).
Each file is read as :func:`habitsim.evaluation.score.read_motion` reads it: a ``.npz``
with its stance labels (the method's own), a BVH or glTF clip imported onto the target
without planting its legs and without labels (the pipeline's transfer stage then labels
it as it labels any method's output that has none). A file of another species than its
folder names, a missing file, or two files for one pair are a typed error
(:class:`OutputsError`, :class:`~habitsim.evaluation.score.ScoreError`) in that pair's
row; :func:`stray_outputs` lists the files that follow no pair of the data set.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from habitsim.errors import HabitsimError, brief_path

if TYPE_CHECKING:  # pragma: no cover
    from habitsim.motion import Motion
    from habitsim.transfer_methods import TransferMethod

__all__ = [
    "OutputsError",
    "MethodOutputs",
    "parse_method_outputs",
    "dataset_clip_ids",
    "stray_outputs",
]


class OutputsError(HabitsimError, ValueError):
    """A folder of a method's outputs that breaks its contract (``DIR/<target>/<clip_id>``
    with a motion file's suffix): a bad ``NAME=DIR``, no such folder, a pair's file
    missing or given twice."""


def _suffixes() -> tuple[str, ...]:
    from habitsim.source import CLIP_SUFFIXES

    return CLIP_SUFFIXES


@dataclass(frozen=True)
class MethodOutputs:
    """A method whose transfers are files in a folder (plain data: it travels to the
    executors' workers with the task).

    Attributes:
        name: the method's name in the tables (a lower-case identifier).
        folder: the folder (absolute).
    """

    name: str
    folder: str

    def path(self, target: str, clip_id: str) -> Path:
        """The output file of one pair.

        Raises:
            OutputsError: no file or more than one for the pair (names the contract).
        """
        sub = Path(self.folder) / target
        found = [sub / f"{clip_id}{s}" for s in _suffixes() if (sub / f"{clip_id}{s}").is_file()]
        contract = f"{self.name}'s outputs follow DIR/<target>/<clip_id>" + "|".join(_suffixes())
        if not found:
            raise OutputsError(
                f"no output for clip {clip_id} to {target}: expected "
                f"{brief_path(sub / clip_id)}{'|'.join(_suffixes())} ({contract})"
            )
        if len(found) > 1:
            raise OutputsError(
                f"{len(found)} outputs for clip {clip_id} to {target} "
                f"({', '.join(p.name for p in found)}): keep one"
            )
        return found[0]

    def __call__(
        self, source: Motion, target: str, *, clip_id: str | None = None, **_: Any
    ) -> Motion:
        """The method's output for ``source`` → ``target``: the file of ``clip_id``.

        Raises:
            OutputsError: no clip id given, or the pair's file missing or given twice.
            ScoreError: a file of another species than ``target``.
        """
        from habitsim.species import load_species

        from .score import read_motion

        del source
        if clip_id is None:
            raise OutputsError(f"method {self.name!r} reads its outputs by the source's clip id")
        tgt = load_species(target).name
        out = read_motion(self.path(tgt, clip_id), species=tgt)
        out.metadata = {**out.metadata, "method": self.name}
        return out

    def method(self) -> TransferMethod:
        """The unregistered :class:`~habitsim.transfer_methods.TransferMethod` reading them."""
        from habitsim.transfer_methods import TransferMethod

        return TransferMethod(self.name, f"outputs read from {self.folder}", self, "external")


def parse_method_outputs(text: str) -> MethodOutputs:
    """``NAME=DIR`` as :class:`MethodOutputs`.

    Raises:
        OutputsError: no ``=``, a name that is no lower-case identifier or names a
            registered method, a folder that does not exist.
    """
    from habitsim.transfer_methods import METHODS

    name, sep, folder = str(text).partition("=")
    name = name.strip()
    if not sep or not folder.strip():
        raise OutputsError(f"--method {text!r}: give NAME=DIR (e.g. mine=outputs/)")
    if not name or not name.replace("_", "").isalnum() or name != name.lower():
        raise OutputsError(
            f"--method {text!r}: the name must be a lower-case identifier (e.g. my_method)"
        )
    if name in METHODS:
        raise OutputsError(
            f"--method {text!r}: {name!r} is a registered method; name the outputs otherwise"
        )
    p = Path(folder.strip()).expanduser()
    if not p.is_dir():
        raise OutputsError(
            f"--method {text!r}: {brief_path(p)} is no folder; expected DIR/<target>/<clip_id>"
            + "|".join(_suffixes())
        )
    return MethodOutputs(name, str(p.resolve()))


def dataset_clip_ids(data: str | Path) -> set[str]:
    """The clip ids of a data set: the stems of its manifest's clip files."""
    from habitsim.dataset import load_manifest

    return {Path(c.path).stem for c in load_manifest(data, check_files=False).clips}


def stray_outputs(outputs: MethodOutputs, clip_ids: set[str]) -> list[str]:
    """The files under ``outputs.folder`` that follow no pair of the contract: not in a
    folder named after a species (built-in or user), not named after a clip id of ``clip_ids``, or
    of another type (paths relative to the folder, sorted)."""
    from habitsim.species import species_names

    root = Path(outputs.folder)
    known = set(species_names(include_user=True))
    bad = []
    for f in sorted(root.rglob("*")):
        if not f.is_file() or f.name.startswith("."):
            continue
        rel = f.relative_to(root)
        ok = (
            len(rel.parts) == 2
            and rel.parts[0] in known
            and f.suffix.lower() in _suffixes()
            and f.stem in clip_ids
        )
        if not ok:
            bad.append(rel.as_posix())
    return bad
