"""The built refinement problems of a process, cached: :func:`get_problem`."""

from __future__ import annotations

import functools
from collections import OrderedDict

import mujoco

from ..errors import InvalidMotionError
from ..qpos import (
    species_model,
)
from .errors import RefineError
from .options import RefineOptions
from .problem import (
    RefinementProblem,
    SolverSettings,
    build_refinement_problem,
)

__all__ = ["get_problem", "clear_cache", "builds", "MAX_CACHED_PROBLEMS"]

#: Most built problems kept per process (least recently used dropped first). A built
#: 100-frame window holds 0.3 (stage A) to 0.8 GB (stage B, exact Hessian) of CasADi
#: graphs; unbounded, a run over 17 species with both stages grew past 24 GB.
MAX_CACHED_PROBLEMS = 6

_PROBLEMS: OrderedDict[tuple, RefinementProblem] = OrderedDict()
_BUILDS = 0  # problems built so far in this process


@functools.lru_cache(maxsize=32)
def _species_model(species: str) -> mujoco.MjModel:
    try:
        return species_model(species)
    except InvalidMotionError as e:
        raise RefineError(str(e)) from e


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
    global _BUILDS
    settings = settings or RefineOptions().settings
    key = (
        species if model is None else ("model", id(model)),
        int(n_frames),
        bool(dynamics),
        settings,
    )
    pr = _PROBLEMS.get(key)
    if pr is None:
        m = _species_model(species) if model is None else model
        pr = build_refinement_problem(m, int(n_frames), bool(dynamics), settings)
        pr._model_ref = m  # keep id(model) alive
        _PROBLEMS[key] = pr
        _BUILDS += 1
        while len(_PROBLEMS) > MAX_CACHED_PROBLEMS:
            _PROBLEMS.popitem(last=False)
    else:
        _PROBLEMS.move_to_end(key)
    return pr


def clear_cache() -> None:
    """Forget every built problem."""
    _PROBLEMS.clear()


def builds() -> int:
    """The number of problems built so far in this process."""
    return _BUILDS
