"""pytest plugin of habitsim (registered through the ``pytest11`` entry point).

Installing habitsim makes these available in any pytest suite, with no import:

Fixtures:
    ``habitsim_species_model``: callable ``(species) -> mujoco.MjModel`` of the shipped
        scene of a catalog species (cached for the session).
    ``habitsim_clip``: callable ``(species, action, seed=0, **kw) -> Motion`` — a
        synthetic clip from :func:`habitsim.gaits.generate` (cached).
    ``habitsim_track``: callable ``(motion, **kw)`` running :func:`habitsim.sim.track`
        on a motion and returning its result.
    ``habitsim_golden``: callable ``(figures, name=None, tolerances=None)`` comparing a
        ``{metric: number}`` dict with the golden file
        ``<test file dir>/goldens/<test module>/<name or test name>.json`` (see
        :func:`habitsim.testing.assert_matches_golden`).
    ``habitsim_assert_plausible``: :func:`habitsim.testing.assert_plausible`.

Option:
    ``--habitsim-update-goldens``: (re)record golden files instead of failing.

Each fixture's docstring says the same (``pytest --fixtures`` prints them); the user guide
is docs/testing.md.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest


def pytest_addoption(parser: pytest.Parser) -> None:
    """Add ``--habitsim-update-goldens`` to pytest's command line (group "habitsim")."""
    group = parser.getgroup("habitsim")
    group.addoption(
        "--habitsim-update-goldens",
        action="store_true",
        default=False,
        help="record habitsim golden figure files instead of comparing against them",
    )


@pytest.fixture(scope="session")
def habitsim_species_model() -> Callable[[str], Any]:
    """habitsim: ``(species) -> mujoco.MjModel``, the shipped scene of a catalog species
    (loaded once per session)."""
    from .qpos import species_model

    return species_model


@pytest.fixture(scope="session")
def habitsim_clip() -> Callable[..., Any]:
    """habitsim: ``(species, action, seed=0, **kw) -> Motion``, a synthetic clip of
    ``habitsim.gaits.generate`` (keywords as there, e.g. ``duration_s``; cached per
    session, so do not modify the returned motion in place)."""
    from .gaits import generate

    cache: dict[tuple, Any] = {}

    def make(species: str, action: str, seed: int = 0, **kw: Any) -> Any:
        key = (species, action, seed, tuple(sorted(kw.items())))
        if key not in cache:
            cache[key] = generate(species, action, seed=seed, **kw)
        return cache[key]

    return make


@pytest.fixture
def habitsim_track() -> Callable[..., Any]:
    """habitsim: ``(motion, **kw) -> TrackResult``, ``habitsim.sim.track`` on a motion
    (keywords as there, e.g. ``controller="mpc"``, ``assist=True``); the result has
    ``fell``, ``survival`` and ``metrics``."""

    def run(motion: Any, **kw: Any) -> Any:
        from .sim import track

        return track(motion, **kw)

    return run


@pytest.fixture
def habitsim_golden(request: pytest.FixtureRequest) -> Callable[..., Any]:
    """habitsim: ``(figures, name=None, tolerances=None)``, compare a ``{metric: number}``
    dict with ``<test dir>/goldens/<test module>/<name or test name>.json`` (default
    tolerance: 2 % relative); ``pytest --habitsim-update-goldens`` records the file."""
    from .testing import assert_matches_golden

    update = bool(request.config.getoption("--habitsim-update-goldens"))
    test_path = Path(str(request.node.path))
    folder = test_path.parent / "goldens" / test_path.stem

    def check(
        figures: dict[str, Any], name: str | None = None, tolerances: dict[str, Any] | None = None
    ):
        stem = name or re.sub(r"[^A-Za-z0-9_.-]+", "_", request.node.name)
        return assert_matches_golden(figures, folder / f"{stem}.json", tolerances, update=update)

    return check


@pytest.fixture
def habitsim_assert_plausible() -> Callable[..., None]:
    """habitsim: ``(motion, bounds=None, *, use_contacts=False, **bounds)``, fail when a
    kinematic metric exceeds its bound (``habitsim.testing.assert_plausible``); a bound is
    changed by its keyword, e.g. ``skate_per_leg=0.004``, or switched off with ``None``."""
    from .testing import assert_plausible

    return assert_plausible
