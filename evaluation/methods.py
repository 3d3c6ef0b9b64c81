"""The transfer methods the benchmark compares: its names for the one registry,
:mod:`habitsim.transfer_methods` (:data:`~habitsim.transfer_methods.METHODS`).

The runner plans with :func:`get_method` (an unknown name raises
:class:`UnknownMethodError` listing the registered ones), a pair runs its method through
:func:`habitsim.pipeline.run_clip` (:func:`run_method`), and a method that cannot serve a
pair raises :class:`MethodUnavailable`, which the row records instead of failing. The
baselines are ``direct`` (:func:`direct_transfer`) and ``ground_truth``
(:func:`ground_truth_transfer`, also the reference of ``paired_mpjpe_mm``); the learned
methods run :func:`habitsim.models.transfer`. A new method registers with
:func:`register_method`.
"""

from __future__ import annotations

from habitsim.transfer_methods import (
    METHODS,
    MethodUnavailable,
    TransferMethod,
    UnknownMethodError,
    direct_transfer,
    get_method,
    ground_truth_transfer,
    method_names,
    register_method,
    run_method,
)

__all__ = [
    "METHODS",
    "MethodUnavailable",
    "TransferMethod",
    "UnknownMethodError",
    "direct_transfer",
    "ground_truth_transfer",
    "register_method",
    "get_method",
    "method_names",
    "run_method",
]
