"""Per-clip plausibility metrics of docs/metrics.md (one motion or one tracking run at a time).

The metrics layer sits above the core (motion, species, MuJoCo models, controllers) and
below the stages that report them (refinement, tracking, the data set) and the benchmark
(:mod:`habitsim.evaluation`, which adds the set-level distribution metrics):

* :mod:`habitsim.metrics.kinematic` — kinematic physical plausibility (``penetration_mm``,
  ``float_mm``, ``skate_mm``, ``skate_ratio``, ``jerk``, ``bone_length_error_mm``,
  ``joint_limit_violation_rad`` and the ``*_per_leg`` variants):
  :func:`~habitsim.metrics.kinematic.kinematic_metrics`.
* :mod:`habitsim.metrics.dynamic` — dynamic plausibility (inverse dynamics):
  :func:`~habitsim.metrics.dynamic.dynamic_metrics`.
* :mod:`habitsim.metrics.simulated` — simulated-tracking metrics:
  :func:`~habitsim.metrics.simulated.simulated_metrics`.
* :mod:`habitsim.metrics.biomech` — biomechanical consistency with a species' gait
  table: :func:`~habitsim.metrics.biomech.biomech_metrics`.
"""

from __future__ import annotations

from .biomech import BIOMECH_KEYS, BiomechResult, biomech_metrics
from .dynamic import DYNAMIC_KEYS, dynamic_metrics, inverse_dynamics
from .kinematic import KINEMATIC_KEYS, kinematic_metrics
from .simulated import SIMULATED_KEYS, simulated_metrics

__all__ = [
    "BIOMECH_KEYS",
    "BiomechResult",
    "biomech_metrics",
    "DYNAMIC_KEYS",
    "dynamic_metrics",
    "inverse_dynamics",
    "KINEMATIC_KEYS",
    "kinematic_metrics",
    "SIMULATED_KEYS",
    "simulated_metrics",
]
