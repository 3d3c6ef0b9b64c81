"""The data set's records: a clip to make (:class:`ClipJob`), a made clip
(:class:`ClipEntry`), the manifest (:class:`DatasetManifest`), a statistics row
(:class:`StatsRow`), a finished build (:class:`DatasetBuild`); the layout constants.
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from ..errors import DatasetError, brief

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
#: ``kind`` of a data set imported from motion-capture files (:mod:`habitsim.dataset_import`).
IMPORTED_KIND = "habitsim.imported_clips"
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
#: ``action`` of a chained clip (:func:`habitsim.gaits.generate_chain`) in a manifest.
CHAIN_ACTION = "chain"
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
        """Equal for clips of different species that are the same motion (a chained clip
        is its species' own: ``chain:<species>:<seed>``)."""
        if self.action == CHAIN_ACTION:
            return f"{self.action}:{self.species}:{self.seed}"
        return f"{self.action}:{self.seed}"


@dataclass(frozen=True)
class ClipEntry:
    """One clip of a built data set, as listed in ``manifest.json``.

    The generator fields (``gait`` … ``frames``) are the clip's planned values from its
    metadata; ``measured`` holds what :func:`~habitsim.gait_stats.gait_statistics` and
    :func:`~habitsim.metrics.kinematic.kinematic_metrics` measure on the written file
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
        chains_per_species: chained clips generated per species (after the others).
    """

    root: Path
    seed: int
    fps: float
    clips_per_species: int
    generator_version: int
    species: tuple[dict[str, Any], ...]
    clips: tuple[ClipEntry, ...]
    chains_per_species: int = 0

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
        out: dict[str, Any] = {
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
        if self.chains_per_species:
            out["chains_per_species"] = self.chains_per_species
        return out


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
