"""Physics regression: tracking a fixed synthetic walk per species against golden figures.

The golden files (``tests/goldens/test_physics_regression/``) record the figures with the
MuJoCo version they were made with; re-record them deliberately with
``pytest tests/test_physics_regression.py --habitsim-update-goldens`` after a change
that is meant to move them, and say why in the commit.
"""

from __future__ import annotations

import pytest

from habitsim.gaits import generate
from habitsim.sim import track, track_many
from habitsim.species import species_names

pytestmark = pytest.mark.slow

#: (abs, rel) tolerance per figure: simulation is deterministic for one MuJoCo version and
#: machine; the slack covers floating-point differences between CPUs and BLAS builds.
TOLERANCES = {
    "survival": (0.05, 0.0),
    "sim_mpjpe_mm": (2.0, 0.05),
    "root_drift_mm": (5.0, 0.05),
    "contact_f1": (0.05, 0.0),
    "cost_of_transport": (0.05, 0.10),
}
KEYS = tuple(TOLERANCES)


def _figures(metrics: dict) -> dict[str, float]:
    return {k: float(metrics[k]) for k in KEYS}


@pytest.fixture(scope="module")
def servo_runs() -> dict[str, dict]:
    clips = [generate(s, "walk", seed=0, duration_s=3.0) for s in species_names()]
    results = track_many(clips, controller="servo", threads=2)
    return {c.species: r.metrics for c, r in zip(clips, results, strict=True)}


@pytest.mark.parametrize("species", species_names())
def test_servo_walk_matches_golden(servo_runs, habitsim_golden, species: str) -> None:
    habitsim_golden(
        _figures(servo_runs[species]), name=f"servo_walk_{species}", tolerances=TOLERANCES
    )


@pytest.mark.parametrize("species", ["dog", "horse", "cow"])
def test_balance_walk_matches_golden(habitsim_golden, species: str) -> None:
    result = track(generate(species, "walk", seed=0, duration_s=3.0), controller="balance")
    figures = _figures(result.metrics)
    assert figures["survival"] == 1.0  # the balance controller keeps these walks up
    habitsim_golden(figures, name=f"balance_walk_{species}", tolerances=TOLERANCES)
