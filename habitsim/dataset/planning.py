"""Which clips a build makes: seeds, splits and the clip list (a pure function of the
build's arguments; see :mod:`habitsim.dataset`).
"""

from __future__ import annotations

import zlib
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from ..errors import DatasetError, brief
from ..gaits import ACTIONS, available_actions
from ..species import all_species, load_species
from .records import _SPLIT_AT, _SPLIT_PERIOD, CHAIN_ACTION, ClipJob


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
    number = ACTIONS.index(action) if action in ACTIONS else len(ACTIONS)
    pos = (pair_index * len(ACTIONS) + number) % _SPLIT_PERIOD
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
    species: Sequence[str],
    clips_per_species: int,
    seed: int,
    fps: float,
    chains_per_species: int = 0,
) -> list[ClipJob]:
    """Every clip a build of these species makes, by species then index.

    After a species' ``clips_per_species`` single-action clips come its
    ``chains_per_species`` chained clips (action ``chain``, indices continuing), the k-th
    seeded ``clip_seed(seed, "chain", k)``; its steps are
    :func:`habitsim.gaits.draw_chain` of (species, that seed).
    """
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
        for k in range(chains_per_species):
            jobs.append(
                ClipJob(
                    sp.name,
                    CHAIN_ACTION,
                    clips_per_species + k,
                    k,
                    clip_seed(seed, CHAIN_ACTION, k),
                    clip_split(CHAIN_ACTION, k, sp.held_out),
                    sp.held_out,
                    float(fps),
                )
            )
    return jobs
