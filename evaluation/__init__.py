"""Evaluation of habitsim motions: the benchmark (installed as ``habitsim.evaluation``).

The per-clip metrics it reports (kinematic, dynamic, simulated, biomechanical) live one
layer down, in :mod:`habitsim.metrics`. Modules:

* :mod:`habitsim.evaluation.distribution` — the paper's distribution metrics (``fid``,
  ``intra_fid``, ``downstream_fid``, ``diversity``, ``one_nna``) and ``mpjpe_mm``.
* :mod:`habitsim.evaluation.evaluator` — the frozen evaluator network (features and
  species / action heads): :func:`load_evaluator`, :func:`train_evaluator`.
* :mod:`habitsim.evaluation.runner` — the benchmark runner (``habitsim eval``):
  :class:`EvalConfig`, :func:`run_benchmark`; its pieces :mod:`~.config`,
  :mod:`~.planning`, :mod:`~.pairs`, :mod:`~.tables`, :mod:`~.summary`.
* :mod:`habitsim.evaluation.executors` — local process pool and Dask executors.
* :mod:`habitsim.evaluation.report` — HTML / Markdown report: :func:`write_report`.
* :mod:`habitsim.evaluation.rows` — the one row builder: a pipeline run flattened into
  the columns ``eval`` and ``bench real`` pick (:func:`~habitsim.evaluation.rows.run_row`).
* :mod:`habitsim.evaluation.bench` — the ``habitsim bench`` benchmarks, one module each.

The transfer methods it compares come from the one registry,
:mod:`habitsim.transfer_methods` (``direct``, ``ground_truth``, the learned methods of
:mod:`habitsim.models`); ``register_method``, ``get_method``, ``method_names`` and
``MethodUnavailable`` are re-exported here from it. The names below are imported
lazily (the evaluator pulls in torch, the report matplotlib), so
``import habitsim.evaluation.distribution`` stays light.
"""

from __future__ import annotations

import importlib
from typing import Any

#: public name → defining submodule (or a module's full name)
_EXPORTS = {
    "fid": "distribution",
    "intra_fid": "distribution",
    "downstream_fid": "distribution",
    "diversity": "distribution",
    "one_nna": "distribution",
    "frechet_distance": "distribution",
    "mpjpe_mm": "distribution",
    "transfer_mpjpe_mm": "distribution",
    "FIDError": "distribution",
    "Evaluator": "evaluator",
    "EvaluatorConfig": "evaluator",
    "EvaluatorError": "evaluator",
    "load_evaluator": "evaluator",
    "train_evaluator": "evaluator",
    "register_method": "habitsim.transfer_methods",
    "get_method": "habitsim.transfer_methods",
    "method_names": "habitsim.transfer_methods",
    "MethodUnavailable": "habitsim.transfer_methods",
    "EvalConfig": "runner",
    "EvalError": "runner",
    "run_benchmark": "runner",
    "summarize": "runner",
    "make_executor": "executors",
    "write_report": "report",
}

__all__ = sorted(_EXPORTS)


def _module(where: str) -> str:
    return where if where.startswith("habitsim.") else f"{__name__}.{where}"


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:
        value = getattr(importlib.import_module(_module(_EXPORTS[name])), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
