"""A benchmark target and its verdict: ``met``, ``MISSED``, or ``n/a`` when the run does
not measure it."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any, Literal

__all__ = ["TargetCheck", "Verdict", "verdict", "exit_code"]

Verdict = Literal["met", "MISSED", "n/a"]


def verdict(ok: bool | None) -> Verdict:
    """``met`` / ``MISSED``; ``n/a`` for None (not measured)."""
    return "n/a" if ok is None else ("met" if ok else "MISSED")


@dataclass(frozen=True)
class TargetCheck:
    """One target of a benchmark against what a run measured.

    Attributes:
        name: what is measured (one line).
        value: the measured figure (None: not measured).
        shown: the figure as printed.
        target: the target as printed.
        verdict: ``met``, ``MISSED`` or ``n/a``.
    """

    name: str
    value: float | None
    shown: str
    target: str
    verdict: Verdict

    def to_dict(self) -> dict[str, Any]:
        """The check as a JSON object (``name``, ``value``, ``shown``, ``target``,
        ``verdict``)."""
        return asdict(self)


def exit_code(checks: Sequence[TargetCheck]) -> int:
    """1 when a target is MISSED, else 0."""
    return 1 if any(t.verdict == "MISSED" for t in checks) else 0
