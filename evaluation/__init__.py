"""Evaluation of habitsim motions (installed as ``habitsim.evaluation``).

Modules:

* :mod:`habitsim.evaluation.kinematic` — kinematic physical-plausibility metrics of
  METRICS.md (``penetration_mm``, ``float_mm``, ``skate_mm``, ``skate_ratio``, ``jerk``,
  ``bone_length_error_mm``, ``joint_limit_violation_rad`` and the ``*_per_leg`` variants);
  entry point :func:`habitsim.evaluation.kinematic.kinematic_metrics`.
"""
