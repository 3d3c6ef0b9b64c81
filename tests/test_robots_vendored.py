"""Every robot vendored under tests/robots stands and trots: Go1, Go2, A1, ANYmal B and C,
Spot (issue 50's target), each loaded by ``load_robot`` as a user would, checked standing,
given a retargeted synthetic dog trot and tracked under ``mpc`` with no assistance."""

from __future__ import annotations

import warnings
from pathlib import Path

import mujoco
import pytest

import habitsim
from habitsim.retarget import (
    StandingPoseWarning,
    find_robot_feet,
    load_robot,
    retarget,
    robot_legs,
    stand_check,
    track_clip,
)

ROBOTS = Path(__file__).parent / "robots"
DOCS = Path(__file__).parent.parent / "docs" / "robots.md"
#: The robots issue 50 names, by their Menagerie folder.
NAMED = (
    "unitree_go1",
    "unitree_go2",
    "unitree_a1",
    "anybotics_anymal_b",
    "anybotics_anymal_c",
    "boston_dynamics_spot",
)
VENDORED = sorted(p.name for p in ROBOTS.iterdir() if (p / "scene.xml").is_file())


def test_every_named_robot_is_vendored_and_listed_in_the_docs():
    assert set(NAMED) <= set(VENDORED)
    text = DOCS.read_text(encoding="utf-8")
    for name in VENDORED:
        assert f"tests/robots/{name}" in text, name


@pytest.mark.parametrize("name", VENDORED)
def test_vendored_robot_is_collision_only_with_its_licence(name):
    folder = ROBOTS / name
    assert (folder / "LICENSE").read_text(encoding="utf-8").strip()
    assert "Menagerie" in (folder / "README.md").read_text(encoding="utf-8")
    model = load_robot(folder / "scene.xml")
    assert model.nmesh == 0 and not any(model.geom_type == mujoco.mjtGeom.mjGEOM_MESH)
    assert model.nu == 12 and model.jnt_type[0] == mujoco.mjtJoint.mjJNT_FREE


@pytest.fixture(scope="module")
def dog_trot() -> habitsim.Motion:
    return habitsim.generate("dog", "trot", seed=7, duration_s=2.0)


@pytest.mark.parametrize("name", VENDORED)
def test_robot_stands_and_trots_a_retargeted_dog_trot_under_mpc(name, dog_trot):
    robot = load_robot(ROBOTS / name / "scene.xml")
    with warnings.catch_warnings():
        warnings.simplefilter("error", StandingPoseWarning)  # a folded standing pose warns
        check = stand_check(robot_legs(robot, find_robot_feet(robot)))
        clip = retarget(dog_trot, robot)
    assert check["problems"] == [], check
    assert check["joints_at_limit_share"] <= 0.25 and check["height_over_leg"] >= 0.4
    assert clip.metadata["ik_residual_max_m"] < 0.02
    res = track_clip(clip, robot, controller="mpc")
    assert res.survival == 1.0, (name, res.metrics)
    assert res.metrics["sim_mpjpe_mm"] < 250.0, (name, res.metrics)
