"""Reading a built data set: its manifest, validated, and its clips."""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from pathlib import Path, PurePosixPath
from typing import Any

from ..errors import DatasetError, brief
from ..folders import check_inside
from ..jsonfile import load_json
from ..motion import Motion, load_motion
from .records import (
    DATASET_KIND,
    IMPORTED_KIND,
    MANIFEST_FORMAT_VERSION,
    MANIFEST_NAME,
    SPLITS,
    ClipEntry,
    DatasetManifest,
)


def _read_manifest_json(path: Path, kinds: tuple[str, ...] = (DATASET_KIND,)) -> dict[str, Any]:
    data = load_json(path, "manifest", error=DatasetError)
    if not isinstance(data, dict) or data.get("kind") not in kinds:
        raise DatasetError(
            f"{path}: not a habitsim data set manifest of kind {' or '.join(map(repr, kinds))}"
        )
    version = data.get("format_version")
    if version != MANIFEST_FORMAT_VERSION:
        raise DatasetError(
            f"{path}: manifest format_version {brief(version)}; "
            f"this habitsim reads {MANIFEST_FORMAT_VERSION}"
        )
    return data


def _safe_relpath(p: str, where: str) -> str:
    pp = PurePosixPath(p)
    if (
        pp.is_absolute()
        or ".." in pp.parts
        or "\\" in p
        or "\x00" in p
        or not p.endswith(".npz")
        or len(p) > 1024
        or any(len(part) > 255 for part in pp.parts)
    ):
        raise DatasetError(
            f"{where}: clip path {brief(p)} must be a relative .npz path inside the data set"
        )
    return p


def load_manifest(
    dataset_dir: str | Path, *, check_files: bool = True, follow_symlinks: bool = True
) -> DatasetManifest:
    """Read and validate ``manifest.json`` of a built data set.

    Args:
        dataset_dir: the data set folder.
        check_files: also require every listed clip file to exist.
        follow_symlinks: False refuses a clip path that leads out of the folder through
            a link (:func:`habitsim.folders.check_inside`).

    Raises:
        DatasetError: no folder, no manifest (an incomplete build), unreadable or
            inconsistent manifest (bad keys or types, unknown split, duplicate paths,
            a held-out species outside ``test``, a clip of an unlisted species) or a
            missing clip file.
        InputPathError: a clip path leading out of the folder (without
            ``follow_symlinks``).
    """
    root = Path(dataset_dir)
    if not root.is_dir():
        raise DatasetError(f"{root}: no such data set folder")
    mpath = root / MANIFEST_NAME
    if not mpath.is_file():
        raise DatasetError(
            f"{root}: no {MANIFEST_NAME} (not a data set, or an interrupted build; "
            "run the build again to finish it)"
        )
    data = _read_manifest_json(mpath, (DATASET_KIND, IMPORTED_KIND))
    for key, types in (
        ("seed", (int,)),
        ("fps", (int, float)),
        ("clips_per_species", (int,)),
        ("generator_version", (int,)),
        ("species", (list,)),
        ("clips", (list,)),
    ):
        if key not in data or not isinstance(data[key], types) or isinstance(data[key], bool):
            raise DatasetError(f"{mpath}: missing or invalid {key!r}")
    species: list[dict[str, Any]] = []
    for s in data["species"]:
        ok = isinstance(s, dict) and isinstance(s.get("name"), str)
        if not ok or not isinstance(s.get("held_out"), bool):
            raise DatasetError(
                f"{mpath}: species entries need 'name' and 'held_out', got {brief(s)}"
            )
        species.append(dict(s))
    held = {s["name"]: s["held_out"] for s in species}
    clips: list[ClipEntry] = []
    seen: set[str] = set()
    for i, d in enumerate(data["clips"]):
        where = f"{mpath} clip {i}"
        c = ClipEntry.from_dict(d, where)
        _safe_relpath(c.path, where)
        if c.split not in SPLITS:
            raise DatasetError(f"{where}: unknown split {c.split!r}; valid: {', '.join(SPLITS)}")
        if c.species not in held:
            raise DatasetError(
                f"{where}: species {c.species!r} is not in the manifest's species list"
            )
        if c.held_out != held[c.species]:
            raise DatasetError(f"{where}: held_out disagrees with the species list")
        if c.held_out and c.split != "test":
            raise DatasetError(
                f"{where}: held-out species {c.species!r} may only be in 'test', "
                f"found in {c.split!r}"
            )
        if c.path in seen:
            raise DatasetError(f"{where}: duplicate clip path {c.path!r}")
        seen.add(c.path)
        if not follow_symlinks:
            check_inside(root, root / c.path, what="--data")
        if check_files and not (root / c.path).is_file():
            raise DatasetError(f"{root}: clip file {c.path} listed in the manifest is missing")
        clips.append(c)
    return DatasetManifest(
        root=root,
        seed=int(data["seed"]),
        fps=float(data["fps"]),
        clips_per_species=int(data["clips_per_species"]),
        generator_version=int(data["generator_version"]),
        species=tuple(species),
        clips=tuple(clips),
        chains_per_species=_chains(data, mpath),
    )


def _chains(data: dict[str, Any], mpath: Path) -> int:
    """The manifest's ``chains_per_species`` (0 when absent: a build without chains)."""
    n = data.get("chains_per_species", 0)
    if isinstance(n, bool) or not isinstance(n, int) or n < 0:
        raise DatasetError(f"{mpath}: 'chains_per_species' must be an integer ≥ 0, got {brief(n)}")
    return n


def iter_clips(
    dataset: str | Path | DatasetManifest,
    split: str | None = None,
    species: str | Iterable[str] | None = None,
) -> Iterator[tuple[ClipEntry, Motion]]:
    """Yield ``(entry, motion)`` for the clips of a data set, in manifest order.

    Args:
        dataset: data set folder or an already loaded manifest.
        split: only this split (``train``, ``val``, ``test``).
        species: only this species (or these).

    Raises:
        DatasetError: see :func:`load_manifest` and :meth:`DatasetManifest.select`, or a
            clip file whose species differs from its entry.
        MotionFileError: a clip file that cannot be read.
    """
    if isinstance(dataset, DatasetManifest):
        man = dataset
    else:
        man = load_manifest(dataset, check_files=False)
    for entry in man.select(split=split, species=species):
        m = load_motion(man.root / entry.path)
        if m.species != entry.species:
            raise DatasetError(
                f"{man.root / entry.path}: holds species {m.species!r}, "
                f"manifest says {entry.species!r}"
            )
        yield entry, m
