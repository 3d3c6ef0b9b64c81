"""Refinement: make a (transferred) motion physically plausible before it is tracked.

A trajectory optimisation (CasADi + IPOPT) on the target species' compiled MuJoCo model
that removes foot sliding, ground penetration, hovering, joint-limit excursions and
jitter while staying close to the input motion; stage B adds contact forces and
centroidal dynamics. See :func:`refine` and, for the pieces:

* :mod:`~habitsim.refine.kinematics` — symbolic forward kinematics of an MjModel;
* :mod:`~habitsim.refine.problem` — the NLP of one window, built apart from solving it
  (from :mod:`~habitsim.refine.layout`, :mod:`~habitsim.refine.settings`,
  :mod:`~habitsim.refine.model_facts`, :mod:`~habitsim.refine.expressions` and
  :mod:`~habitsim.refine.nlp`);
* :mod:`~habitsim.refine.windows` — overlapping windows for long clips;
* :mod:`~habitsim.refine.solve` — :func:`refine` itself, from
  :mod:`~habitsim.refine.options` (:class:`RefineOptions`), :mod:`~habitsim.refine.cache`
  (the built problems of a process), :mod:`~habitsim.refine.cleaning` (the labels
  planted), :mod:`~habitsim.refine.clearance` (the swing clearance profile),
  :mod:`~habitsim.refine.filtering` (the jitter pre-filter),
  :mod:`~habitsim.refine.prepare` (targets and initial guess) and
  :mod:`~habitsim.refine.attempt` (the windows solved and checked);
* :mod:`~habitsim.refine.verdict` — is the result worse than the input (solver guard, report);
* :mod:`~habitsim.refine.report` — the JSON report;
* :mod:`~habitsim.refine.artefacts` — artefact injection for tests and benchmarks.
"""

from __future__ import annotations

from .artefacts import ARTEFACTS, inject_artefacts
from .errors import RefineConvergenceError, RefineError, RefineInputError
from .kinematics import SymbolicKinematics
from .problem import RefinementProblem, SolverSettings, build_refinement_problem
from .solve import RefineOptions, RefineResult, get_problem, refine
from .windows import Window, plan_windows

__all__ = [
    "refine",
    "RefineOptions",
    "RefineResult",
    "RefineError",
    "RefineInputError",
    "RefineConvergenceError",
    "SymbolicKinematics",
    "RefinementProblem",
    "SolverSettings",
    "build_refinement_problem",
    "get_problem",
    "Window",
    "plan_windows",
    "ARTEFACTS",
    "inject_artefacts",
]
