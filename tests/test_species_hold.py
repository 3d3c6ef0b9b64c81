"""Contract test over every species model with the in-engine servos the runner uses.

For every shipped species (menagerie style, one parametrised test per species):

* the servo variant (``habitsim.sim.servo_model`` = ``configure_servos``, kp = τmax/0.15
  rad, critical kv) compiles and steps 1 s under bounded random targets without any MuJoCo
  warning;
* it holds the ``home`` keyframe for 5 s with NO assistance: trunk height within 5 % of
  home, trunk tilt (angle between the trunk's up axis now and at home) below 5°, and
  horizontal trunk drift below 15 % of leg length (the feet creep a little on soft
  contacts: dog 7 %, wolf 10 % of leg length in 5 s with MuJoCo 4.0.0).

Tilt is measured from the home orientation because several species stand with a sloping
back (giraffe −15.7°, moose −11.7°): their world tilt is large by design.
"""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

import habitsim
from habitsim.sim import servo_model, servo_targets

SPECIES = habitsim.species_names()
HOLD_S = 5.0


def _up(quat: np.ndarray) -> np.ndarray:
    mat = np.zeros(9)
    mujoco.mju_quat2Mat(mat, quat)
    return mat.reshape(3, 3)[:, 2]


@pytest.fixture(scope="module", params=SPECIES)
def servo(request):
    from habitsim.qpos import load_species_model

    return request.param, servo_model(load_species_model(request.param))


def test_random_targets_no_warnings(servo) -> None:
    name, m = servo
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, m.key("home").id)
    home = servo_targets(m, d.qpos)[0]
    lo, hi = m.actuator_ctrlrange[:, 0], m.actuator_ctrlrange[:, 1]
    rng = np.random.default_rng(0)
    for i in range(int(1.0 / m.opt.timestep)):
        if i % 25 == 0:  # new target every 50 ms: 30 % of the way to a random angle
            target = np.clip(home + 0.3 * (rng.uniform(lo, hi) - home), lo, hi)
        d.ctrl[:] = target
        mujoco.mj_step(m, d)
    assert all(w.number == 0 for w in d.warning), [w.number for w in d.warning]
    assert np.all(np.isfinite(d.qpos))


def test_home_held_without_assistance(servo) -> None:
    name, m = servo
    sp = habitsim.load_species(name)
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, m.key("home").id)
    q0 = d.qpos.copy()
    d.ctrl[:] = servo_targets(m, q0)[0]
    for _ in range(int(round(HOLD_S / m.opt.timestep))):
        mujoco.mj_step(m, d)
    assert all(w.number == 0 for w in d.warning), [w.number for w in d.warning]
    height_ratio = d.qpos[2] / q0[2]
    tilt = np.degrees(np.arccos(np.clip(_up(d.qpos[3:7]) @ _up(q0[3:7]), -1.0, 1.0)))
    drift = np.linalg.norm(d.qpos[:2] - q0[:2])
    assert abs(height_ratio - 1.0) < 0.05, f"{name}: trunk height ratio {height_ratio:.3f}"
    assert tilt < 5.0, f"{name}: trunk tilt {tilt:.1f} deg"
    assert drift < 0.15 * sp.leg_length, f"{name}: trunk drift {drift * 1000:.0f} mm"
