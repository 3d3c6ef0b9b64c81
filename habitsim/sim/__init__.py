"""Tracking runner: play a reference qpos trajectory through a controller in MuJoCo.

One clip goes ``Motion → motion_to_qpos → reference at the control rate → controller →
mj_step … → TrackResult`` (simulated qpos at the reference frames, foot contacts, falls,
metrics). The pieces, each usable alone:

* :func:`finite_differences` — (qvel, qacc) of a qpos trajectory at its frame rate
  (``mj_differentiatePos``, so the free joint's quaternion is handled correctly).
* :func:`build_reference` — the reference resampled at the simulation step: cubic Hermite
  for scalar coordinates and the root position, slerp for quaternions; velocities and
  accelerations are the frame-rate finite differences, interpolated linearly.
* :class:`FallDetector` — docs/metrics.md's fall rule, checked at every reference frame.
* :func:`track` — one clip, Python loop (any :class:`~habitsim.controllers.Controller`,
  optional root assistance) or, for in-engine servos without assistance, one
  ``mujoco.rollout`` call (no Python in the loop).
* :func:`track_many` — many clips: ``mujoco.rollout`` over threads when the PD lives in
  the actuators, else a thread pool over :func:`track`.

Failures are results, not exceptions: a fall or a numerically unstable run (NaN, any
MuJoCo warning) ends the clip and is reported (``fell``, ``unstable``, ``survival``).
Bad *inputs* (unknown species or controller, a model without the joints, NaN in the
reference) raise :class:`SimulationError` (or the motion's own typed errors).

Units: SI (m, s, rad, N, N·m); times in [s] from the clip's first frame.

One concept per module: :mod:`~habitsim.sim.reference` (finite differences, resampling),
:mod:`~habitsim.sim.model` (trunk, feet, touch, leg length), :mod:`~habitsim.sim.servo`
(in-engine servos), :mod:`~habitsim.sim.control` (controller construction, control rate),
:mod:`~habitsim.sim.assist` (root assistance gains), :mod:`~habitsim.sim.options` (the
runner's knobs), :mod:`~habitsim.sim.falls`,
:mod:`~habitsim.sim.clip` (one input clip resolved), :mod:`~habitsim.sim.result`,
:mod:`~habitsim.sim.loop` (the Python loop), :mod:`~habitsim.sim.rollout`
(``mujoco.rollout``) and :mod:`~habitsim.sim.tracking` (:func:`track`,
:func:`track_many`). Import the public names from ``habitsim.sim``.
"""

from __future__ import annotations

from ..controllers import CONTROLLERS
from ..errors import SimulationError
from ..qpos import species_model as species_model  # the shipped-model cache
from .assist import root_assist
from .falls import Fall, FallCause, FallDetector, FallOptions, ReferenceResting
from .model import FOOT_GEOMS, foot_geoms
from .model import TOUCH_THRESHOLD_MG as TOUCH_THRESHOLD_MG
from .model import _species_model as _species_model
from .options import TrackOptions
from .reference import ReferenceTrajectory, build_reference, finite_differences
from .result import TrackResult
from .servo import servo_model, servo_targets
from .tracking import track, track_many

__all__ = [
    "SimulationError",
    "CONTROLLERS",
    "ReferenceTrajectory",
    "TrackResult",
    "FallDetector",
    "FallOptions",
    "Fall",
    "FallCause",
    "ReferenceResting",
    "finite_differences",
    "build_reference",
    "foot_geoms",
    "FOOT_GEOMS",
    "TrackOptions",
    "servo_model",
    "root_assist",
    "servo_targets",
    "track",
    "track_many",
]
