"""A data set from a folder of motion-capture files (``habitsim data import-bvh --dir``).

Every ``.bvh`` / ``.glb`` / ``.gltf`` file under a folder is imported onto one catalog
species (:func:`habitsim.bvh_mapping.import_bvh`: automatic or given joint mapping,
planted retargeting, stance labels found on the source's own feet), resampled to one
frame rate, and written as a data set folder that :func:`habitsim.dataset.load_manifest`
reads and ``habitsim train --data DIR`` trains on::

    manifest.json                       written last (kind "habitsim.imported_clips")
    {train,val,test}/<species>/<file stem>.npz

An optional CSV names each file's action (and, optionally, its split)::

    file,action,split
    walk_001.bvh,walk,train
    trot_003.bvh,trot,val

Without a split column (or an empty cell), the i-th file in sorted order goes to ``val``
when ``i mod 10 = 4``, to ``test`` when it is 9, else to ``train`` (the synthetic data
set's 8/1/1 rule); a held-out species' clips all go to ``test``. The whole folder is
written as one transaction: all clips and the manifest, or nothing. The output folder is
claimed with :func:`habitsim.folders.claim_output_folder`: one import at a time, a
folder holding files habitsim did not write or an earlier data set refused without
``overwrite``, and ``overwrite`` removes only the files habitsim wrote there. Links in the
source folder that lead out of it are refused unless ``follow_symlinks``.
"""

from __future__ import annotations

import csv
import json
import math
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .dataset import (
    IMPORTED_KIND,
    MANIFEST_FORMAT_VERSION,
    MANIFEST_NAME,
    SPLITS,
    ClipEntry,
    DatasetManifest,
)
from .dataset.clips import _measure
from .errors import DatasetError, HabitsimError, OutputPathError, brief, brief_path, unquoted
from .fileio import atomic_write_text, make_dirs, output_transaction
from .folders import claim_output_folder, input_files
from .motion import Motion, resample_motion
from .physics_constants import GRAVITY
from .species import load_species

__all__ = ["IMPORT_KIND", "SOURCE_SUFFIXES", "ImportBuild", "import_folder", "read_labels"]

#: Value of the manifest's ``kind`` key for an imported data set.
IMPORT_KIND = IMPORTED_KIND
#: File types imported from a folder.
SOURCE_SUFFIXES = (".bvh", ".glb", ".gltf")
#: Most files one import takes (a guard against pointing it at a whole disk).
MAX_FILES = 10_000
_STEM = re.compile(r"[^a-z0-9_]+")


@dataclass
class ImportBuild:
    """Outcome of :func:`import_folder`.

    Attributes:
        manifest: the written data set.
        warnings: ``(file, warning)`` of the joint mappings (low-confidence limbs, …).
        skipped: ``(file, reason)`` of files that could not be imported (only with
            ``skip_bad``).
    """

    manifest: DatasetManifest
    warnings: list[tuple[str, str]] = field(default_factory=list)
    skipped: list[tuple[str, str]] = field(default_factory=list)


def read_labels(path: str | Path) -> dict[str, dict[str, str]]:
    """Per-file labels of a CSV with columns ``file``, ``action`` and optional ``split``.

    Files are matched by name (``walk_001.bvh``) or by path relative to the imported
    folder. Returns ``{file: {"action": …, "split": …}}`` (split may be "").

    Raises:
        DatasetError: unreadable file, missing columns, an empty action, an unknown split
            or a file named twice.
    """
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as e:
        raise DatasetError(
            f"labels {brief_path(p)}: cannot read ({e.__class__.__name__})"
        ) from None
    rows = list(csv.DictReader(text.splitlines()))
    cols = set(rows[0]) if rows else set()
    if not {"file", "action"} <= cols:
        raise DatasetError(
            f"labels {brief_path(p)}: needs a header with the columns file,action[,split]; "
            f"got {brief(sorted(c for c in cols if c))}"
        )
    out: dict[str, dict[str, str]] = {}
    for i, r in enumerate(rows, start=2):
        name = (r.get("file") or "").strip()
        action = (r.get("action") or "").strip()
        split = (r.get("split") or "").strip()
        if not name or not action:
            raise DatasetError(f"labels {brief_path(p)} line {i}: empty file or action")
        if split and split not in SPLITS:
            raise DatasetError(
                f"labels {brief_path(p)} line {i}: unknown split {brief(split)}; "
                f"valid: {', '.join(SPLITS)} or empty"
            )
        if name in out:
            raise DatasetError(f"labels {brief_path(p)} line {i}: {brief(name)} named twice")
        out[name] = {"action": action, "split": split}
    return out


def _default_split(i: int, held_out: bool) -> str:
    if held_out:
        return "test"
    return {4: "val", 9: "test"}.get(i % 10, "train")


def _stem(path: Path, taken: set[str]) -> str:
    base = _STEM.sub("_", path.stem.lower()).strip("_") or "clip"
    if not base[0].isalpha():
        base = f"clip_{base}"
    name, k = base, 2
    while name in taken:
        name, k = f"{base}_{k}", k + 1
    taken.add(name)
    return name


def _gait(species: str, action: str) -> str:
    from .gaits import action_gait

    try:
        return action_gait(species, action)
    except HabitsimError:
        return ""


def _yaw(m: Motion) -> np.ndarray:
    q = m.rotations[:, 0]
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return np.unwrap(np.arctan2(2.0 * (x * y + w * z), 1.0 - 2.0 * (y * y + z * z)))


def _entry(m: Motion, rel: str, split: str, held_out: bool, action: str, i: int) -> ClipEntry:
    sp = m.species_info
    dur = max((m.num_frames - 1) / m.fps, 1e-9)
    path_len = float(np.linalg.norm(np.diff(m.root_positions[:, :2], axis=0), axis=1).sum())
    speed = path_len / dur
    yaw = _yaw(m)
    turn = float((yaw[-1] - yaw[0]) / dur)
    try:
        measured = _measure(m)
    except HabitsimError:
        measured = {}
    duty = float(np.mean(m.contacts)) if m.contacts is not None else 0.0
    return ClipEntry(
        path=rel,
        split=split,
        species=m.species,
        held_out=held_out,
        action=action,
        gait=_gait(m.species, action),
        index=i,
        pair_index=i,
        pair_key=f"import:{Path(rel).stem}",
        seed=0,
        speed_mps=speed,
        froude=speed * speed / (GRAVITY * sp.hip_height),
        duty_factor=duty,
        turn_rate=turn,
        turn_rate_nd=turn * math.sqrt(sp.hip_height / GRAVITY),
        duration_s=float(dur),
        frames=int(m.num_frames),
        fps=float(m.fps),
        measured=measured,
    )


def import_folder(
    src_dir: str | Path,
    out_dir: str | Path,
    species: str,
    *,
    labels: str | Path | Mapping[str, Mapping[str, str]] | None = None,
    fps: float = 30.0,
    overwrite: bool = False,
    skip_bad: bool = False,
    joint_map: str | Path | Mapping[str, str] | None = None,
    units: str | None = None,
    up: str | None = None,
    plant: bool = True,
    follow_symlinks: bool = False,
    log: Callable[[str], None] | None = None,
) -> ImportBuild:
    """Import every motion file under ``src_dir`` onto ``species`` as a data set.

    Args:
        src_dir: folder searched recursively for ``.bvh`` / ``.glb`` / ``.gltf`` files.
        out_dir: the data set folder to write (see the module docstring).
        species: target catalog species.
        labels: a labels CSV (:func:`read_labels`) or its parsed mapping; files without a
            label get the action ``unlabelled``.
        fps: frame rate every clip is resampled to [Hz] (a training set has one rate; the
            shipped model runs at 30).
        overwrite: replace a data set already in ``out_dir``: the files an earlier
            habitsim run wrote there are removed first, nothing else.
        skip_bad: skip files that cannot be imported (listed in the result) instead of
            failing on the first one.
        joint_map, units, up, plant: as :func:`habitsim.bvh_mapping.import_bvh`, for every
            file.
        follow_symlinks: read through links in ``src_dir`` that lead out of it (else
            they are refused).
        log: where per-file lines go (None = nowhere).

    Raises:
        DatasetError: no such folder, no motion file in it, a labels entry naming no file,
            an existing data set without ``overwrite``, or nothing importable.
        InputPathError: a link in ``src_dir`` leading out of it (without
            ``follow_symlinks``).
        OutputFolderError: ``out_dir`` holds files habitsim did not write, or an earlier
            run (without ``overwrite``).
        OutputBusyError: another run is writing into ``out_dir``.
        OutputPathError: ``out_dir`` cannot be written.
        BVHParseError, GLTFError, SkeletonMappingError: a file that cannot be imported
            (without ``skip_bad``; the message names the file).
    """
    from .bvh_mapping import import_bvh

    src = Path(src_dir)
    out = Path(out_dir)
    sp = load_species(species)
    if not (isinstance(fps, int | float) and math.isfinite(fps) and 1.0 <= fps <= 1000.0):
        raise DatasetError(f"fps must be in [1, 1000] Hz, got {brief(fps)}")
    if not src.is_dir():
        raise DatasetError(f"{brief_path(src)}: no such folder")
    files = input_files(src, SOURCE_SUFFIXES, follow_symlinks=follow_symlinks, what="--dir")
    if not files:
        raise DatasetError(
            f"{brief_path(src)}: no motion file ({', '.join(SOURCE_SUFFIXES)}) in the folder"
        )
    if len(files) > MAX_FILES:
        raise DatasetError(f"{brief_path(src)}: {len(files)} files, at most {MAX_FILES} per import")
    table = dict(read_labels(labels) if isinstance(labels, str | Path) else (labels or {}))
    names = {p.name for p in files} | {p.relative_to(src).as_posix() for p in files}
    unknown = sorted(set(table) - names)
    if unknown:
        raise DatasetError(f"labels name files that are not in {brief_path(src)}: {brief(unknown)}")
    if out.exists() and not out.is_dir():
        raise OutputPathError(f"output folder {brief_path(out)}: is a file, expected a folder")
    with claim_output_folder(
        out,
        command="data import-bvh",
        overwrite=overwrite,
        resume_flag=None,
        defer_removal=True,
        log=log,
    ) as claim:
        held = bool(sp.held_out)
        entries: list[ClipEntry] = []
        motions: list[tuple[str, Motion]] = []
        warnings: list[tuple[str, str]] = []
        skipped: list[tuple[str, str]] = []
        taken: set[str] = set()
        for f in files:
            rel_src = f.relative_to(src).as_posix()
            lab = table.get(rel_src) or table.get(f.name) or {}
            try:
                with unquoted():  # a message names the file, never what it holds
                    m, mapping = import_bvh(
                        f, sp, joint_map=joint_map, units=units, up=up, plant=plant
                    )
            except HabitsimError as e:
                if not skip_bad:
                    raise type(e)(f"{rel_src}: {e}") from None
                skipped.append((rel_src, str(e)))
                if log:
                    log(f"skipped {rel_src}: {e}")
                continue
            warnings += [(rel_src, w) for w in mapping.warnings]
            m = resample_motion(m, float(fps))
            action = lab.get("action") or "unlabelled"
            split = lab.get("split") or _default_split(len(entries), held)
            if held and split != "test":
                raise DatasetError(
                    f"{rel_src}: {sp.name} is a held-out species; its clips may only be in 'test'"
                )
            meta = dict(m.metadata)
            meta.update(action=action, source_file=rel_src)
            rel = f"{split}/{sp.name}/{_stem(f, taken)}.npz"
            meta["pair_key"] = f"import:{Path(rel).stem}"
            m = Motion(m.species, m.fps, m.root_positions, m.rotations, m.contacts, meta)
            entries.append(_entry(m, rel, split, held, action, len(entries)))
            motions.append((rel, m))
            if log:
                line = f"{rel_src} -> {rel}: {m.num_frames} frames, {m.duration:.1f} s, {action}"
                if m.contacts is not None:
                    duty = " ".join(f"{d:.2f}" for d in np.mean(m.contacts, axis=0))
                    line += f", stance share LF RF LH RH {duty}"
                log(line)
        if not entries:
            raise DatasetError(f"{brief_path(src)}: no file could be imported ({len(files)} tried)")
        manifest = DatasetManifest(
            root=out,
            seed=0,
            fps=float(fps),
            clips_per_species=len(entries),
            generator_version=0,
            species=({"name": sp.name, "held_out": held, "cousin": None, "actions": []},),
            clips=tuple(entries),
        )
        doc: dict[str, Any] = manifest.to_dict()
        doc["kind"] = IMPORT_KIND
        doc["format_version"] = MANIFEST_FORMAT_VERSION
        doc["source"] = {"folder": str(src.resolve()), "files": len(files)}
        doc["pairing"] = "none: every imported clip is its own pair key"
        with output_transaction():
            for rel, m in motions:
                make_dirs((out / rel).parent)
                m.save(out / rel)
            atomic_write_text(
                out / MANIFEST_NAME, json.dumps(doc, indent=1, allow_nan=False) + "\n"
            )
        # the replaced data set's files that the new one does not write again
        claim.remove_stale({out / rel for rel, _ in motions} | {out / MANIFEST_NAME})
    return ImportBuild(manifest, warnings, skipped)
