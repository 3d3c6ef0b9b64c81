"""The synthetic gait data set: many clips per species with paired ground truth.

:func:`build_dataset` generates ``clips_per_species`` clips of every requested species
with :func:`habitsim.gaits.generate`, writes them as motion files, measures them
(:func:`habitsim.gait_stats.gait_statistics`,
:func:`habitsim.evaluation.kinematic.kinematic_metrics`) and writes a manifest;
:func:`load_manifest` reads and validates a built data set and :func:`iter_clips` walks
its clips.

Layout of a data set folder::

    manifest.json                                  written LAST: no manifest = incomplete
    stats.csv, stats.md                            measured statistics per species × action
    {train,val,test}/<species>/<species>_<action>_<idx:04d>.npz

Which clips a build makes (all deterministic, independent of the worker count and of
which other species are in the build):

* **Actions.** Clip ``idx`` of a species performs ``A[idx % len(A)]``, A = the species'
  :func:`~habitsim.gaits.available_actions`; ``k = idx // len(A)`` is the clip's
  *pair index* (the k-th clip of that action in that species).
* **Seeds and pairing.** The generator seed of a clip is drawn from
  ``np.random.SeedSequence([seed, crc32(action), k])`` — it does not depend on the
  species. :func:`habitsim.gaits.generate` draws every random number as a
  species-independent, dimensionless parameter from its seed, so two species' clips with
  the same action and seed share the same draws: the same relative position of the
  Froude number inside each species' own Froude band for that gait, the same duty-factor
  noise, the same dimensionless turn rate ω·sqrt(h/g), the same start phase, heading and
  clip duration in seconds (jumps and sits may be lengthened per species). Such clips
  carry the same ``pair_key`` (``"<action>:<seed>"``) and are the paired ground truth:
  "the same motion" performed by each species in its own habits. (The alternative,
  ``generate(sp, like=ref)``, would copy a reference species' absolute Froude number,
  which can fall outside another species' band, and would make every clip depend on the
  reference species being in the build; we do not use it.)
* **Splits.** Held-out species (``held_out = true``) go to ``test`` only. A training
  species' clip goes to ``val`` if ``(k·13 + action number) mod 10 == 4``, to ``test`` if
  it is 9, else to ``train`` (13 = ``len(ACTIONS)``, action number = its index in
  :data:`~habitsim.gaits.ACTIONS`): per action, exactly 8/1/1 of every 10 consecutive
  clips, about 80/10/10 per species, and clips with the same ``pair_key`` are in the
  same split in every training species (no pair straddles train and test).

Because a clip depends only on (seed, fps, species, action, k), a build with fewer
clips or species is a subset of a bigger one, and resuming a build with another
``clips_per_species`` or species list reuses every clip the two have in common.
"""

from __future__ import annotations

import concurrent.futures as cf
import csv
import io
import json
import math
import os
import re
import time
import zlib
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path, PurePosixPath
from typing import Any

import numpy as np

from .errors import DatasetError, HabitsimError, brief
from .fileio import atomic_write_text, check_writable, make_dirs
from .gaits import ACTIONS, GENERATOR_VERSION, available_actions, generate
from .motion import Motion, load_motion
from .species import FEET, all_species, load_species

__all__ = [
    "MANIFEST_NAME",
    "MANIFEST_FORMAT_VERSION",
    "SPLITS",
    "STATS_COLUMNS",
    "ClipEntry",
    "ClipJob",
    "DatasetBuild",
    "DatasetManifest",
    "StatsRow",
    "build_dataset",
    "check_resumable",
    "clip_seed",
    "clip_split",
    "format_stats_table",
    "iter_clips",
    "load_manifest",
    "plan_clips",
    "stats_rows",
]

#: File name of the manifest inside a data set folder.
MANIFEST_NAME = "manifest.json"
STATS_CSV_NAME = "stats.csv"
STATS_MD_NAME = "stats.md"
#: Version of the manifest layout (bumped when keys change meaning).
MANIFEST_FORMAT_VERSION = 1
#: Frame rates [Hz] the synthetic generator is built for (higher only costs time).
SYNTH_FPS_RANGE = (1.0, 240.0)
#: Most clips per species of one build, and the largest build seed.
MAX_CLIPS_PER_SPECIES = 10_000
MAX_SEED = 2**32 - 1
#: Value of the manifest's ``kind`` key.
DATASET_KIND = "habitsim.synthetic_gaits"
SPLITS: tuple[str, ...] = ("train", "val", "test")
#: Split rule position (k·len(ACTIONS) + action number) mod 10 → split (others: train).
_SPLIT_PERIOD = 10
_SPLIT_AT = {4: "val", 9: "test"}
#: Measured per-clip statistics stored in the manifest (``ClipEntry.measured``).
MEASURED_KEYS: tuple[str, ...] = (
    "speed_mps",
    "froude",
    "duty_factor",
    "stride_frequency_hz",
    "relative_stride_length",
    "phase_error",
    "stability_margin_min_m",
    "statically_stable_fraction",
    "skate_mm",
    "penetration_mm",
    "float_mm",
)
_CLIP_NAME = re.compile(r"^[a-z][a-z0-9_]*_\d{4}\.npz$")


# ---------------------------------------------------------------------------- records


@dataclass(frozen=True)
class ClipJob:
    """One clip a build must produce (a pure function of these fields).

    Attributes:
        species: catalog species name.
        action: generator action.
        index: clip index within the species (``idx`` in the file name).
        pair_index: k, the clip's rank among the species' clips of this action.
        seed: generator seed (species-independent, see the module docstring).
        split: ``train``, ``val`` or ``test``.
        held_out: the species is held out.
        fps: frame rate [Hz].
    """

    species: str
    action: str
    index: int
    pair_index: int
    seed: int
    split: str
    held_out: bool
    fps: float

    @property
    def path(self) -> str:
        """Path relative to the data set folder (POSIX separators)."""
        return f"{self.split}/{self.species}/{self.species}_{self.action}_{self.index:04d}.npz"

    @property
    def pair_key(self) -> str:
        """Equal for clips of different species that are the same motion."""
        return f"{self.action}:{self.seed}"


@dataclass(frozen=True)
class ClipEntry:
    """One clip of a built data set, as listed in ``manifest.json``.

    The generator fields (``gait`` … ``frames``) are the clip's planned values from its
    metadata; ``measured`` holds what :func:`~habitsim.gait_stats.gait_statistics` and
    :func:`~habitsim.evaluation.kinematic.kinematic_metrics` measure on the written file
    (keys :data:`MEASURED_KEYS`; ``None`` where undefined, e.g. the phase error of a
    clip without steps). ``phase_error`` is the mean circular distance [stride] between
    measured and planned footfall phases of LF, RF and RH.
    """

    path: str
    split: str
    species: str
    held_out: bool
    action: str
    gait: str
    index: int
    pair_index: int
    pair_key: str
    seed: int
    speed_mps: float
    froude: float
    duty_factor: float
    turn_rate: float
    turn_rate_nd: float
    duration_s: float
    frames: int
    fps: float
    measured: dict[str, float | None] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (the manifest entry)."""
        return asdict(self)

    @classmethod
    def from_dict(cls, d: Any, where: str) -> ClipEntry:
        """Parse and type-check a manifest entry.

        Raises:
            DatasetError: missing keys or values of the wrong type.
        """
        if not isinstance(d, dict):
            raise DatasetError(f"{where}: a clip entry must be a JSON object")
        kinds: dict[str, tuple[type, ...]] = {
            "path": (str,),
            "split": (str,),
            "species": (str,),
            "held_out": (bool,),
            "action": (str,),
            "gait": (str,),
            "index": (int,),
            "pair_index": (int,),
            "pair_key": (str,),
            "seed": (int,),
            "speed_mps": (int, float),
            "froude": (int, float),
            "duty_factor": (int, float),
            "turn_rate": (int, float),
            "turn_rate_nd": (int, float),
            "duration_s": (int, float),
            "frames": (int,),
            "fps": (int, float),
            "measured": (dict,),
        }
        missing = [k for k in kinds if k not in d]
        if missing:
            raise DatasetError(f"{where}: clip entry lacks {', '.join(missing)}")
        for k, types in kinds.items():
            v = d[k]
            if not isinstance(v, types) or (bool not in types and isinstance(v, bool)):
                kind = "/".join(t.__name__ for t in types)
                raise DatasetError(f"{where}: {k!r} must be {kind}, got {brief(v)}")
        measured: dict[str, float | None] = {}
        for k, v in d["measured"].items():
            if v is not None and (isinstance(v, bool) or not isinstance(v, int | float)):
                raise DatasetError(
                    f"{where}: measured {brief(k)} must be a number or null, got {brief(v)}"
                )
            measured[str(k)] = None if v is None else float(v)
        vals = {k: d[k] for k in kinds if k != "measured"}
        for k, types in kinds.items():
            if types == (int, float):
                vals[k] = float(vals[k])
        return cls(**vals, measured=measured)


@dataclass(frozen=True)
class DatasetManifest:
    """A built data set: its configuration and every clip.

    Attributes:
        root: the data set folder (clip paths are relative to it).
        seed: build seed.
        fps: frame rate of every clip [Hz].
        clips_per_species: clips generated per species.
        generator_version: :data:`habitsim.gaits.GENERATOR_VERSION` of the clips.
        species: per species ``{"name", "held_out", "cousin", "actions"}``, sorted by name.
        clips: the clip entries, by species then index.
    """

    root: Path
    seed: int
    fps: float
    clips_per_species: int
    generator_version: int
    species: tuple[dict[str, Any], ...]
    clips: tuple[ClipEntry, ...]

    @property
    def species_names(self) -> list[str]:
        """Names of the data set's species."""
        return [s["name"] for s in self.species]

    def select(
        self, split: str | None = None, species: str | Iterable[str] | None = None
    ) -> list[ClipEntry]:
        """Entries of one split and/or some species (None = all).

        Raises:
            DatasetError: an unknown split or a species that is not in the data set.
        """
        if split is not None and split not in SPLITS:
            raise DatasetError(f"unknown split {split!r}; valid: {', '.join(SPLITS)}")
        wanted: set[str] | None = None
        if species is not None:
            wanted = {species} if isinstance(species, str) else set(species)
            unknown = sorted(wanted - set(self.species_names))
            if unknown:
                raise DatasetError(
                    f"species {', '.join(unknown)} not in the data set at {self.root}; "
                    f"it has: {', '.join(self.species_names)}"
                )
        return [
            c
            for c in self.clips
            if (split is None or c.split == split) and (wanted is None or c.species in wanted)
        ]

    def split_counts(self) -> dict[str, int]:
        """Number of clips per split."""
        return {s: sum(c.split == s for c in self.clips) for s in SPLITS}

    def pairs(self, source: str, target: str) -> list[tuple[ClipEntry, ClipEntry]]:
        """Paired clips (equal ``pair_key``) of two species, in the source's clip order."""
        tgt = {c.pair_key: c for c in self.select(species=target)}
        return [(c, tgt[c.pair_key]) for c in self.select(species=source) if c.pair_key in tgt]

    def to_dict(self) -> dict[str, Any]:
        """The JSON object written to ``manifest.json``."""
        return {
            "kind": DATASET_KIND,
            "format_version": MANIFEST_FORMAT_VERSION,
            "generator_version": self.generator_version,
            "seed": self.seed,
            "fps": self.fps,
            "clips_per_species": self.clips_per_species,
            "splits": list(SPLITS),
            "pairing": (
                "clips with equal pair_key share action and generator seed "
                "(same dimensionless draws)"
            ),
            "species": [dict(s) for s in self.species],
            "num_clips": len(self.clips),
            "clips": [c.to_dict() for c in self.clips],
        }


@dataclass(frozen=True)
class StatsRow:
    """Mean measured statistics of one species × action (NaN where undefined)."""

    species: str
    action: str
    gait: str
    held_out: bool
    clips: int
    froude_target: float
    froude: float
    duty_factor_target: float
    duty_factor: float
    relative_stride_length: float
    phase_error: float
    skate_mm: float
    penetration_mm: float
    statically_stable_fraction: float


#: Column order of ``stats.csv`` (the fields of :class:`StatsRow`).
STATS_COLUMNS: tuple[str, ...] = tuple(StatsRow.__dataclass_fields__)


@dataclass(frozen=True)
class DatasetBuild:
    """What :func:`build_dataset` did.

    Attributes:
        manifest: the written manifest.
        stats: per species × action statistics (also in ``stats.csv`` / ``stats.md``).
        generated: clips generated by this run.
        reused: valid clips found on disk and kept (resume).
        removed: stale clip files of an earlier build that were deleted.
        wall_time_s: duration of the build [s].
        workers: worker processes used.
    """

    manifest: DatasetManifest
    stats: list[StatsRow]
    generated: int
    reused: int
    removed: int
    wall_time_s: float
    workers: int


# ---------------------------------------------------------------------------- planning


def clip_seed(seed: int, action: str, pair_index: int) -> int:
    """Generator seed of the ``pair_index``-th clip of ``action`` (any species).

    Derived with ``np.random.SeedSequence([seed, crc32(action), pair_index])`` and kept
    in [0, 2**63) so it is a plain JSON integer.
    """
    ss = np.random.SeedSequence([int(seed), zlib.crc32(action.encode("utf-8")), int(pair_index)])
    return int(ss.generate_state(1, dtype=np.uint64)[0] >> np.uint64(1))


def clip_split(action: str, pair_index: int, held_out: bool) -> str:
    """Split of a clip (see the module docstring for the rule)."""
    if held_out:
        return "test"
    pos = (pair_index * len(ACTIONS) + ACTIONS.index(action)) % _SPLIT_PERIOD
    return _SPLIT_AT.get(pos, "train")


def _check_int(name: str, value: Any, minimum: int, maximum: int | None = None) -> int:
    if (
        isinstance(value, bool)
        or not isinstance(value, int | np.integer)
        or value < minimum
        or (maximum is not None and value > maximum)
    ):
        valid = f"≥ {minimum}" if maximum is None else f"from {minimum} to {maximum}"
        raise DatasetError(f"{name} must be an integer {valid}, got {brief(value)}")
    return int(value)


def _resolve_species(species: str | Iterable[str] | None) -> list[str]:
    if species is None:
        return [s.name for s in all_species()]
    names = [species] if isinstance(species, str) else list(species)
    if not names:
        raise DatasetError("no species given; pass None for every catalog species")
    resolved = [load_species(n).name for n in names]  # UnknownSpeciesError lists the catalog
    dup = sorted({n for n in resolved if resolved.count(n) > 1})
    if dup:
        raise DatasetError(f"species listed more than once: {', '.join(dup)}")
    return sorted(resolved)


def plan_clips(
    species: Sequence[str], clips_per_species: int, seed: int, fps: float
) -> list[ClipJob]:
    """Every clip a build of these species makes, by species then index."""
    jobs: list[ClipJob] = []
    for name in species:
        sp = load_species(name)
        acts = available_actions(sp)
        for idx in range(clips_per_species):
            action, k = acts[idx % len(acts)], idx // len(acts)
            jobs.append(
                ClipJob(
                    sp.name,
                    action,
                    idx,
                    k,
                    clip_seed(seed, action, k),
                    clip_split(action, k, sp.held_out),
                    sp.held_out,
                    float(fps),
                )
            )
    return jobs


# ---------------------------------------------------------------------------- one clip


def _finite(x: Any) -> float | None:
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


def _phase_error(measured: dict[str, Any], planned: dict[str, Any] | None) -> float | None:
    """Mean circular distance [stride] between measured and planned footfall phases."""
    if not planned:
        return None
    errs = []
    for f in FEET:
        if f == "LH" or measured.get(f) is None or f not in planned:
            continue
        d = (float(measured[f]) - float(planned[f])) % 1.0
        errs.append(min(d, 1.0 - d))
    return float(np.mean(errs)) if errs else None


def _measure(m: Motion) -> dict[str, float | None]:
    from .evaluation.kinematic import kinematic_metrics
    from .gait_stats import gait_statistics

    gs = gait_statistics(m).to_dict()
    km = kinematic_metrics(m)
    out: dict[str, float | None] = {}
    for k in MEASURED_KEYS:
        if k == "phase_error":
            out[k] = _phase_error(gs["phase_offsets"], m.metadata.get("footfall"))
        else:
            out[k] = _finite(gs[k] if k in gs else km[k])
    return out


def _matches(m: Motion, job: ClipJob) -> bool:
    """True if a motion on disk is exactly the clip ``job`` asks for."""
    meta = m.metadata
    return (
        m.species == job.species
        and m.fps == job.fps
        and meta.get("generator") == "habitsim.gaits"
        and meta.get("generator_version") == GENERATOR_VERSION
        and meta.get("action") == job.action
        and meta.get("seed") == job.seed
        and meta.get("pair_key") == job.pair_key
    )


def _make_clip(root: str, job: ClipJob, resume: bool) -> tuple[dict[str, Any], bool]:
    """Generate (or, resuming, reuse) one clip, measure it and return its manifest entry.

    Runs in worker processes; every failure comes back as a :class:`DatasetError`
    naming the clip (plain exceptions pickle reliably; some typed ones do not).
    """
    path = Path(root) / job.path
    try:
        m: Motion | None = None
        if resume and path.is_file():
            try:
                m = load_motion(path)
            except HabitsimError:  # unreadable or invalid: generate it again
                m = None
            if m is not None and not _matches(m, job):
                m = None
        generated = m is None
        if m is None:
            clip = generate(job.species, job.action, seed=job.seed, fps=job.fps)
            clip.metadata["pair_key"] = job.pair_key
            clip.save(path)
            # Measure the file as written, so a resumed build measures the same numbers.
            m = load_motion(path)
        meta = m.metadata
        entry = ClipEntry(
            path=job.path,
            split=job.split,
            species=job.species,
            held_out=job.held_out,
            action=job.action,
            gait=str(meta["gait"]),
            index=job.index,
            pair_index=job.pair_index,
            pair_key=job.pair_key,
            seed=job.seed,
            speed_mps=float(meta["speed_mps"]),
            froude=float(meta["froude"]),
            duty_factor=float(meta["duty_factor"]),
            turn_rate=float(meta["turn_rate"]),
            turn_rate_nd=float(meta["turn_rate_nd"]),
            duration_s=float(meta["duration_s"]),
            frames=int(meta["frames"]),
            fps=job.fps,
            measured=_measure(m),
        )
    except Exception as e:  # noqa: BLE001 - re-raised typed, with the clip named
        raise DatasetError(
            f"clip {job.path} (species {job.species}, action {job.action}, seed {job.seed}) "
            f"failed: {type(e).__name__}: {e}"
        ) from e
    return entry.to_dict(), generated


# ---------------------------------------------------------------------------- build


def _read_manifest_json(path: Path) -> dict[str, Any]:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, RecursionError) as e:
        reason = "nested too deep" if isinstance(e, RecursionError) else brief(str(e), 200)
        raise DatasetError(f"{path}: not a readable manifest ({reason})") from None
    if not isinstance(data, dict) or data.get("kind") != DATASET_KIND:
        raise DatasetError(
            f"{path}: not a habitsim synthetic data set manifest (kind != {DATASET_KIND!r})"
        )
    version = data.get("format_version")
    if version != MANIFEST_FORMAT_VERSION:
        raise DatasetError(
            f"{path}: manifest format_version {brief(version)}; "
            f"this habitsim reads {MANIFEST_FORMAT_VERSION}"
        )
    return data


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
        data = json.loads(mpath.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
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
        if not base.is_dir():
            continue
        for sub in base.iterdir():
            if sub.is_dir() and not any(sub.iterdir()):
                sub.rmdir()
        if not any(base.iterdir()):
            base.rmdir()


def build_dataset(
    out_dir: str | Path,
    *,
    clips_per_species: int = 40,
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
        seed: build seed (≥ 0); every clip seed derives from it.
        species: species names (default: every catalog species).
        workers: worker processes (default ``os.cpu_count()``); the result does not
            depend on it.
        fps: frame rate of the clips [Hz].
        progress: show a tqdm progress bar on stderr.
        resume: keep clips already on disk that load and match their plan (an
            interrupted build continues); False regenerates every clip.
        overwrite: delete an existing data set in ``out_dir`` (manifest, statistics and
            clip files of the layout) first, whatever its configuration.

    Returns:
        A :class:`DatasetBuild` with the manifest, the statistics and counts.

    Raises:
        DatasetError: bad arguments, ``out_dir`` not a directory, ``out_dir`` holding a
            data set of another seed / fps / generator version (without ``overwrite``),
            or a clip that fails to generate (the message names it).
        UnknownSpeciesError: an unknown species name.
    """
    t0 = time.perf_counter()
    clips_per_species = _check_int("clips_per_species", clips_per_species, 1, MAX_CLIPS_PER_SPECIES)
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

    jobs = plan_clips(names, clips_per_species, seed, fps)
    make_dirs(out, "data set folder")
    check_writable(out / MANIFEST_NAME, "data set folder")  # an existing read-only folder
    # From here on the folder is "being built": no manifest until the end.
    for name in (MANIFEST_NAME, STATS_CSV_NAME, STATS_MD_NAME):
        (out / name).unlink(missing_ok=True)
    planned = {out / j.path for j in jobs}
    removed = 0
    for f in _dataset_files(out):
        if overwrite or f not in planned:
            f.unlink()
            removed += f.name.endswith(".npz")
    entries: list[dict[str, Any] | None] = [None] * len(jobs)
    generated = 0
    n_workers = max(1, min(n_workers, len(jobs)))

    from tqdm import tqdm

    with tqdm(total=len(jobs), desc="synthetic clips", unit="clip", disable=not progress) as bar:
        if n_workers == 1:
            for i, job in enumerate(jobs):
                entries[i], made = _make_clip(str(out), job, resume)
                generated += made
                bar.update(1)
        else:
            from .workers import init_worker, stop_pool

            # workers die with this process, however it ends (see habitsim.workers)
            with cf.ProcessPoolExecutor(
                max_workers=n_workers, initializer=init_worker, initargs=(os.getpid(),)
            ) as pool:
                futures = {
                    pool.submit(_make_clip, str(out), job, resume): i for i, job in enumerate(jobs)
                }
                try:
                    for fut in cf.as_completed(futures):
                        entries[futures[fut]], made = fut.result()
                        generated += made
                        bar.update(1)
                except BaseException:
                    stop_pool(pool)
                    raise
    _remove_empty_dirs(out)

    clips = tuple(ClipEntry.from_dict(e, job.path) for e, job in zip(entries, jobs, strict=True))
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


# ---------------------------------------------------------------------------- reading


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


def load_manifest(dataset_dir: str | Path, *, check_files: bool = True) -> DatasetManifest:
    """Read and validate ``manifest.json`` of a built data set.

    Args:
        dataset_dir: the data set folder.
        check_files: also require every listed clip file to exist.

    Raises:
        DatasetError: no folder, no manifest (an incomplete build), unreadable or
            inconsistent manifest (bad keys or types, unknown split, duplicate paths,
            a held-out species outside ``test``, a clip of an unlisted species) or a
            missing clip file.
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
    data = _read_manifest_json(mpath)
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
    )


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


# ---------------------------------------------------------------------------- statistics


def _mean(values: Iterable[float | None]) -> float:
    v = [x for x in values if x is not None and math.isfinite(x)]
    return float(np.mean(v)) if v else math.nan


def stats_rows(manifest: DatasetManifest) -> list[StatsRow]:
    """Per species × action means of the clips' measured statistics.

    Rows are ordered by species name, then action in :data:`~habitsim.gaits.ACTIONS`
    order. ``*_target`` columns are the generator's planned values.
    """
    groups: dict[tuple[str, str], list[ClipEntry]] = {}
    for c in manifest.clips:
        groups.setdefault((c.species, c.action), []).append(c)
    rows = []
    for sp, action in sorted(groups, key=lambda key: (key[0], ACTIONS.index(key[1]))):
        cs = groups[(sp, action)]

        def m(key: str, cs: list[ClipEntry] = cs) -> float:
            return _mean(c.measured.get(key) for c in cs)

        rows.append(
            StatsRow(
                species=sp,
                action=action,
                gait=cs[0].gait,
                held_out=cs[0].held_out,
                clips=len(cs),
                froude_target=_mean(c.froude for c in cs),
                froude=m("froude"),
                duty_factor_target=_mean(c.duty_factor for c in cs),
                duty_factor=m("duty_factor"),
                relative_stride_length=m("relative_stride_length"),
                phase_error=m("phase_error"),
                skate_mm=m("skate_mm"),
                penetration_mm=m("penetration_mm"),
                statically_stable_fraction=m("statically_stable_fraction"),
            )
        )
    return rows


def _csv_cell(v: Any) -> str:
    """A CSV cell: booleans as true/false, floats with 6 significant digits, NaN empty."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return f"{v:.6g}" if math.isfinite(v) else ""
    return str(v)


def _stats_csv(rows: list[StatsRow]) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(STATS_COLUMNS)
    for r in rows:
        w.writerow([_csv_cell(getattr(r, k)) for k in STATS_COLUMNS])
    return buf.getvalue()


#: (column header, StatsRow field, number format) of the printed tables.
_TABLE: tuple[tuple[str, str, str], ...] = (
    ("species", "species", ""),
    ("action", "action", ""),
    ("gait", "gait", ""),
    ("n", "clips", ""),
    ("Fr plan", "froude_target", ".3g"),
    ("Fr", "froude", ".3g"),
    ("duty plan", "duty_factor_target", ".3f"),
    ("duty", "duty_factor", ".3f"),
    ("stride/h", "relative_stride_length", ".3g"),
    ("phase err", "phase_error", ".4f"),
    ("skate mm", "skate_mm", ".2f"),
    ("pen mm", "penetration_mm", ".2f"),
    ("stable", "statically_stable_fraction", ".2f"),
)


def _fmt(v: Any, spec: str) -> str:
    if isinstance(v, float):
        return f"{v:{spec}}" if math.isfinite(v) else "-"
    return str(v)


def format_stats_table(rows: Sequence[StatsRow], markdown: bool = False) -> str:
    """The statistics as an aligned plain-text table (or a Markdown table).

    Columns: species, action, gait, clip count, planned and measured Froude number and
    duty factor, relative stride length λ/h, footfall phase error [stride], skating
    [mm], penetration [mm], statically stable fraction. Undefined values print as ``-``.
    """
    header = [h for h, _, _ in _TABLE]
    body = []
    for r in rows:
        name = r.species + (" (held out)" if r.held_out and markdown else "*" if r.held_out else "")
        body.append([name] + [_fmt(getattr(r, f), spec) for _, f, spec in _TABLE[1:]])
    if markdown:
        lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
        lines += ["| " + " | ".join(c) + " |" for c in body]
        return "\n".join(lines)
    widths = [max(len(x) for x in col) for col in zip(header, *body, strict=False)]
    fmt = [f"{{:<{w}}}" if i < 3 else f"{{:>{w}}}" for i, w in enumerate(widths)]
    lines = [
        "  ".join(f.format(c) for f, c in zip(fmt, row, strict=True)) for row in [header, *body]
    ]
    if any(r.held_out for r in rows):
        lines.append("* held-out species (test split only)")
    return "\n".join(lines)


def _stats_markdown(rows: list[StatsRow], man: DatasetManifest) -> str:
    counts = man.split_counts()
    return (
        "# Synthetic gait data set: measured statistics\n\n"
        f"seed {man.seed}, {man.fps:g} fps, {man.clips_per_species} clips per species, "
        f"{len(man.species)} species, {len(man.clips)} clips "
        f"(train {counts['train']}, val {counts['val']}, test {counts['test']}), "
        f"generator version {man.generator_version}.\n\n"
        "Means per species × action of the measured statistics of the written clips "
        "(`habitsim.gait_stats.gait_statistics`, "
        "`habitsim.evaluation.kinematic.kinematic_metrics`); "
        "'plan' columns are the generator's targets, phase err is the mean circular distance "
        "between measured and planned footfall phases [stride], '-' = undefined "
        "(e.g. no steps). For `jump`, 'Fr plan' is the take-off Froude number while 'Fr' "
        "averages the whole clip (stand, jump, land).\n\n"
        + format_stats_table(rows, markdown=True)
        + "\n"
    )
