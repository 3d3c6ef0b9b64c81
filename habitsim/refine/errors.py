"""Typed errors of the refinement (all under :class:`habitsim.HabitsimError`)."""

from __future__ import annotations

from ..errors import HabitsimError

__all__ = ["RefineError", "RefineInputError", "RefineConvergenceError"]


class RefineError(HabitsimError):
    """Root of the refinement's errors (also raised for models it cannot handle)."""


class RefineInputError(RefineError, ValueError):
    """Bad input to the refinement: unknown species or model mismatch, NaN, wrong shapes,
    bad contact labels, bad options."""


class RefineConvergenceError(RefineError, RuntimeError):
    """IPOPT did not converge on a window (pass ``fallback=True`` to get the input back
    with the status recorded instead).

    Attributes:
        status: IPOPT's return status (e.g. ``Maximum_Iterations_Exceeded``).
        window: (start, stop) frames of the failing window.
        report: the partial report (dict) up to the failure.
    """

    def __init__(
        self, message: str, status: str, window: tuple[int, int], report: dict | None = None
    ):
        super().__init__(message)
        self.status = status
        self.window = window
        self.report = report or {}
