"""Building a data set: plan, make every clip over a process pool, write the statistics
and, last, the manifest; resuming and overwriting.
"""

from __future__ import annotations

import concurrent.futures as cf
import json
import math
import os
import time
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from ..errors import DatasetError, brief
from ..fileio import atomic_write_text, check_writable, make_dirs
from ..folders import claim_output_folder, is_written, remove_written
from ..gaits import GENERATOR_VERSION, available_actions
from ..jsonfile import load_json
from ..species import load_species
from .clips import _make_clip
from .manifest import _read_manifest_json
from .planning import _check_int, _resolve_species, plan_clips
from .records import (
    _CLIP_NAME,
    DATASET_KIND,
    MANIFEST_NAME,
    MAX_CLIPS_PER_SPECIES,
    MAX_SEED,
    SPLITS,
    STATS_CSV_NAME,
    STATS_MD_NAME,
    SYNTH_FPS_RANGE,
    ClipEntry,
    DatasetBuild,
    DatasetManifest,
)
from .stats import _stats_csv, _stats_markdown, stats_rows


def check_resumable(out_dir: str | Path, *, seed: int = 0, fps: float = 30.0) -> None:
    """Raise unless a build with this seed and fps may resume in ``out_dir``.

    A folder without a manifest (new, empty, or an interrupted build) is resumable:
    each clip is validated on its own. A manifest must be readable and have the same
    seed, fps and generator version (species and clip counts may differ).

    Raises:
        DatasetError: ``out_dir`` is not a directory, or holds an unreadable or
            different manifest (the message says what differs).
    """
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise DatasetError(f"{out}: exists and is not a directory")
    mpath = out / MANIFEST_NAME
    if not mpath.exists():
        return
    data = _read_manifest_json(mpath)
    diffs = []
    if data.get("seed") != seed:
        diffs.append(f"seed {data.get('seed')!r} != {seed}")
    if not isinstance(data.get("fps"), int | float) or float(data["fps"]) != float(fps):
        diffs.append(f"fps {data.get('fps')!r} != {fps}")
    if data.get("generator_version") != GENERATOR_VERSION:
        diffs.append(f"generator_version {data.get('generator_version')!r} != {GENERATOR_VERSION}")
    if diffs:
        raise DatasetError(
            f"{out} holds a data set built with another configuration ({'; '.join(diffs)}); "
            "use another folder or overwrite it (overwrite=True, CLI --overwrite)"
        )


def _check_overwritable(out: Path) -> None:
    """Refuse to overwrite a folder whose ``manifest.json`` is not a habitsim data set's."""
    mpath = out / MANIFEST_NAME
    if not mpath.exists():
        return
    try:
        data = load_json(mpath, "manifest", error=DatasetError)
    except DatasetError:
        data = None
    if not isinstance(data, dict) or data.get("kind") != DATASET_KIND:
        raise DatasetError(
            f"{mpath}: not a habitsim data set manifest; not overwriting "
            "(remove it or use another folder)"
        )


def _dataset_files(out: Path) -> list[Path]:
    """Clip files and leftover temporaries in the data set layout under ``out``."""
    found = []
    for split in SPLITS:
        base = out / split
        if not base.is_dir():
            continue
        for sub in sorted(p for p in base.iterdir() if p.is_dir()):
            for f in sorted(sub.iterdir()):
                temp = f.name.startswith(".") and f.name.endswith(".tmp")
                if f.is_file() and (_CLIP_NAME.match(f.name) or temp):
                    found.append(f)
    return found


def _remove_empty_dirs(out: Path) -> None:
    for split in SPLITS:
        base = out / split
        if base.is_symlink() or not base.is_dir():
            continue
        for sub in base.iterdir():
            if sub.is_dir() and not sub.is_symlink() and not any(sub.iterdir()):
                sub.rmdir()
        if not any(base.iterdir()):
            base.rmdir()


def build_dataset(
    out_dir: str | Path,
    *,
    clips_per_species: int = 40,
    chains_per_species: int = 0,
    seed: int = 0,
    species: str | Iterable[str] | None = None,
    workers: int | None = None,
    fps: float = 30.0,
    progress: bool = True,
    resume: bool = True,
    overwrite: bool = False,
) -> DatasetBuild:
    """Build (or finish) the synthetic gait data set in ``out_dir``.

    Args:
        out_dir: data set folder (created if missing).
        clips_per_species: clips per species (≥ 1), actions spread evenly.
        chains_per_species: chained clips per species (≥ 0; 2–4 seeded random steps
            each, :func:`habitsim.gaits.draw_chain`), after the others.
        seed: build seed (≥ 0); every clip seed derives from it.
        species: species names (default: every catalog species).
        workers: worker processes (default ``os.cpu_count()``); the result does not
            depend on it.
        fps: frame rate of the clips [Hz].
        progress: show a tqdm progress bar on stderr.
        resume: keep clips already on disk that load and match their plan (an
            interrupted build continues); False regenerates every clip.
        overwrite: delete an earlier build in ``out_dir`` first, whatever its
            configuration: only the files habitsim wrote there
            (:func:`habitsim.folders.claim_output_folder`).

    Returns:
        A :class:`DatasetBuild` with the manifest, the statistics and counts.

    Raises:
        DatasetError: bad arguments, ``out_dir`` not a directory, ``out_dir`` holding a
            data set of another seed / fps / generator version (without ``overwrite``),
            or a clip that fails to generate (the message names it).
        OutputFolderError: ``out_dir`` holds files habitsim did not write, or the output
            of another command (without ``overwrite``).
        OutputBusyError: another run is writing into ``out_dir``.
        UnknownSpeciesError: an unknown species name.
    """
    t0 = time.perf_counter()
    clips_per_species = _check_int("clips_per_species", clips_per_species, 1, MAX_CLIPS_PER_SPECIES)
    chains_per_species = _check_int(
        "chains_per_species", chains_per_species, 0, MAX_CLIPS_PER_SPECIES
    )
    seed = _check_int("seed", seed, 0, MAX_SEED)
    number = isinstance(fps, int | float) and not isinstance(fps, bool)
    if not (number and math.isfinite(fps) and fps > 0):
        raise DatasetError(f"fps must be a positive number, got {brief(fps)}")
    lo, hi = SYNTH_FPS_RANGE
    if not lo <= fps <= hi:
        raise DatasetError(f"fps {fps:g} Hz; valid: {lo:g} to {hi:g} Hz for synthetic clips")
    fps = float(fps)
    n_workers = (
        (os.cpu_count() or 1) if workers is None else _check_int("workers", workers, 1, 1024)
    )
    names = _resolve_species(species)
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise DatasetError(f"{out}: exists and is not a directory")
    if overwrite:
        _check_overwritable(out)
    else:
        check_resumable(out, seed=seed, fps=fps)

    jobs = plan_clips(names, clips_per_species, seed, fps, chains_per_species)
    with claim_output_folder(
        out,
        command="data synth",
        what="data set folder",
        overwrite=overwrite,
        resume=True,
        resume_flag=None,
        continues=("demo", "bench data"),
        defer_removal=True,
    ) as claim:
        make_dirs(out, "data set folder")
        check_writable(out / MANIFEST_NAME, "data set folder")  # an existing read-only folder
        # From here on the folder is "being built": no manifest until the end. Only files
        # habitsim wrote are removed (habitsim.folders), never a file of someone else's;
        # with overwrite, every file of the earlier run.
        remove_written([out / n for n in (MANIFEST_NAME, STATS_CSV_NAME, STATS_MD_NAME)])
        planned = {out / j.path for j in jobs}
        stale = {out / r for r in claim.stale}
        stale.update(f for f in _dataset_files(out) if f not in planned and is_written(f))
        remove_written(sorted(stale))
        removed = sum(f.name.endswith(".npz") for f in stale)
        entries: list[dict[str, Any] | None] = [None] * len(jobs)
        generated = 0
        n_workers = max(1, min(n_workers, len(jobs)))

        from tqdm import tqdm

        with tqdm(
            total=len(jobs), desc="synthetic clips", unit="clip", disable=not progress
        ) as bar:
            if n_workers == 1:
                for i, job in enumerate(jobs):
                    entries[i], made = _make_clip(str(out), job, resume)
                    generated += made
                    bar.update(1)
            else:
                from ..workers import init_worker, stop_pool

                # workers die with this process, however it ends (see habitsim.workers)
                with cf.ProcessPoolExecutor(
                    max_workers=n_workers, initializer=init_worker, initargs=(os.getpid(),)
                ) as pool:
                    futures: dict[cf.Future, int] = {}
                    try:
                        # submitting hundreds of clips takes a while: an interrupt that lands
                        # here must stop the pool too, not leave `with` waiting for the queue
                        for i, job in enumerate(jobs):
                            futures[pool.submit(_make_clip, str(out), job, resume)] = i
                        for fut in cf.as_completed(futures):
                            entries[futures[fut]], made = fut.result()
                            generated += made
                            bar.update(1)
                    except BaseException:
                        stop_pool(pool)
                        raise
        _remove_empty_dirs(out)

        clips = tuple(
            ClipEntry.from_dict(e, job.path) for e, job in zip(entries, jobs, strict=True)
        )
        manifest = DatasetManifest(
            root=out,
            seed=seed,
            fps=fps,
            clips_per_species=clips_per_species,
            generator_version=GENERATOR_VERSION,
            species=tuple(
                {
                    "name": n,
                    "held_out": load_species(n).held_out,
                    "cousin": load_species(n).cousin,
                    "actions": available_actions(n),
                }
                for n in names
            ),
            clips=clips,
            chains_per_species=chains_per_species,
        )
        rows = stats_rows(manifest)
        atomic_write_text(out / STATS_CSV_NAME, _stats_csv(rows))
        atomic_write_text(out / STATS_MD_NAME, _stats_markdown(rows, manifest))
        text = json.dumps(manifest.to_dict(), indent=1, allow_nan=False) + "\n"
        atomic_write_text(out / MANIFEST_NAME, text)  # last: its presence marks a complete build
        return DatasetBuild(
            manifest=manifest,
            stats=rows,
            generated=generated,
            reused=len(jobs) - generated,
            removed=removed,
            wall_time_s=time.perf_counter() - t0,
            workers=n_workers,
        )
