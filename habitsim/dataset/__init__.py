"""The synthetic gait data set: many clips per species with paired ground truth.

:func:`build_dataset` generates ``clips_per_species`` clips of every requested species
with :func:`habitsim.gaits.generate`, writes them as motion files, measures them
(:func:`habitsim.gait_stats.gait_statistics`,
:func:`habitsim.metrics.kinematic.kinematic_metrics`) and writes a manifest;
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

* **Chained clips** (``chains_per_species``, default 0): after a species' other clips,
  clips of action ``chain`` that run 2–4 actions into one another
  (:func:`habitsim.gaits.generate_chain`, steps :func:`habitsim.gaits.draw_chain` of
  (species, seed)); seeds from ``SeedSequence([seed, crc32("chain"), k])``, split as an
  action numbered 13, ``pair_key`` ``"chain:<species>:<seed>"`` (a species' own: the
  steps depend on its gaits). Without them a build is what it was.

Because a clip depends only on (seed, fps, species, action, k), a build with fewer
clips or species is a subset of a bigger one, and resuming a build with another
``clips_per_species`` or species list reuses every clip the two have in common.

The package, one concept per module (every public name is re-exported here):
:mod:`~habitsim.dataset.records` (the dataclasses and layout constants),
:mod:`~habitsim.dataset.planning` (seeds, splits, :func:`plan_clips`),
:mod:`~habitsim.dataset.clips` (one clip), :mod:`~habitsim.dataset.build`
(:func:`build_dataset`), :mod:`~habitsim.dataset.manifest` (:func:`load_manifest`,
:func:`iter_clips`), :mod:`~habitsim.dataset.stats` (statistics tables).
"""

from __future__ import annotations

from .build import build_dataset, check_resumable
from .manifest import iter_clips, load_manifest
from .planning import clip_seed, clip_split, plan_clips
from .records import (
    CHAIN_ACTION,
    DATASET_KIND,
    IMPORTED_KIND,
    MANIFEST_FORMAT_VERSION,
    MANIFEST_NAME,
    MAX_CLIPS_PER_SPECIES,
    MAX_SEED,
    MEASURED_KEYS,
    SPLITS,
    STATS_COLUMNS,
    STATS_CSV_NAME,
    STATS_MD_NAME,
    SYNTH_FPS_RANGE,
    ClipEntry,
    ClipJob,
    DatasetBuild,
    DatasetManifest,
    StatsRow,
)
from .stats import format_stats_table, stats_rows

__all__ = [
    "CHAIN_ACTION",
    "MANIFEST_NAME",
    "MANIFEST_FORMAT_VERSION",
    "SPLITS",
    "DATASET_KIND",
    "IMPORTED_KIND",
    "MAX_CLIPS_PER_SPECIES",
    "MAX_SEED",
    "MEASURED_KEYS",
    "STATS_CSV_NAME",
    "STATS_MD_NAME",
    "SYNTH_FPS_RANGE",
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
