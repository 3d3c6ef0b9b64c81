"""The built refinement problems of a process, cached: :func:`get_problem`."""

from __future__ import annotations

import functools
from collections import OrderedDict

import mujoco

from ..errors import InvalidMotionError
from ..qpos import species_model
from .errors import RefineError
from .options import RefineOptions
from .problem import RefinementProblem, SolverSettings, build_refinement_problem

__all__ = ["ProblemCache", "get_problem", "clear_cache", "builds", "MAX_CACHED_PROBLEMS"]

#: Most built problems the process's cache keeps (least recently used dropped first): a
#: built 100-frame window holds 0.3 (stage A) to 0.8 GB (stage B, exact Hessian) of
#: CasADi graphs.
MAX_CACHED_PROBLEMS = 6


@functools.lru_cache(maxsize=32)
def _species_model(species: str) -> mujoco.MjModel:
    try:
        return species_model(species)
    except InvalidMotionError as e:
        raise RefineError(str(e)) from e


class ProblemCache:
    """Built problems by (species or model, window length, stage, settings), at most
    ``max_size`` of them, the least recently used dropped first.

    Attributes:
        max_size: most problems kept.
        builds: problems built so far by this cache.
    """

    def __init__(self, max_size: int = MAX_CACHED_PROBLEMS) -> None:
        if int(max_size) < 1:
            raise ValueError(f"max_size must be ≥ 1, got {max_size}")
        self.max_size = int(max_size)
        self.builds = 0
        self._problems: OrderedDict[tuple, RefinementProblem] = OrderedDict()

    def __len__(self) -> int:
        return len(self._problems)

    def get(
        self,
        species: str,
        n_frames: int,
        dynamics: bool = False,
        settings: SolverSettings | None = None,
        model: mujoco.MjModel | None = None,
    ) -> RefinementProblem:
        """The problem of a species (or model) and window length: built on the first
        call, the same object later while it is among the ``max_size`` most recently
        used. Default settings: those :func:`refine` uses first."""
        settings = settings or RefineOptions().settings
        key = (
            species if model is None else ("model", id(model)),
            int(n_frames),
            bool(dynamics),
            settings,
        )
        pr = self._problems.get(key)
        if pr is None:
            m = _species_model(species) if model is None else model
            pr = build_refinement_problem(m, int(n_frames), bool(dynamics), settings)
            pr._model_ref = m  # keep id(model) alive
            self._problems[key] = pr
            self.builds += 1
            while len(self._problems) > self.max_size:
                self._problems.popitem(last=False)
        else:
            self._problems.move_to_end(key)
        return pr

    def clear(self) -> None:
        """Forget every built problem."""
        self._problems.clear()


#: The cache of this process (:func:`get_problem`).
_CACHE = ProblemCache()


def get_problem(
    species: str,
    n_frames: int,
    dynamics: bool = False,
    settings: SolverSettings | None = None,
    model: mujoco.MjModel | None = None,
) -> RefinementProblem:
    """The built problem of a species (or model) and window length, cached per process.

    The first call per (species, W, stage, settings) builds it (seconds); later calls
    return the same object while it is among the :data:`MAX_CACHED_PROBLEMS` most
    recently used (so process clips grouped by species). Default settings: those
    :func:`refine` uses first (``RefineOptions().settings``).
    """
    return _CACHE.get(species, n_frames, dynamics, settings, model)


def clear_cache() -> None:
    """Forget every built problem."""
    _CACHE.clear()


def builds() -> int:
    """The number of problems built so far in this process."""
    return _CACHE.builds
