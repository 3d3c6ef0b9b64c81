"""Typed reports of conforming a decoded motion: each planting, the ladder's outcome, the whole.

The planting ladder (:mod:`habitsim.stance.ladder`) judges each planting by these typed
values; ``to_dict`` methods write the JSON-ready, rounded form that goes into a
transfer's ``metadata["transfer"]`` (the ``.npz`` format is unchanged).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from typing import Any

import numpy as np

from .planting import PlantReport
from .policy import ConformPolicy

__all__ = ["Restep", "Trim", "Planting", "PlantOutcome", "PlantReason", "ConformReport"]


@dataclass(frozen=True)
class Restep:
    """How the stance labels were played faster (:func:`habitsim.stance.ladder.restep`).

    Attributes:
        period_s: (before, after) stride period [s].
        rate: how many times faster the labels are played.
        sweep_limit_per_leg: the longest stance sweep of the legs [leg lengths].
    """

    period_s: tuple[float, float]
    rate: float
    sweep_limit_per_leg: float

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready, rounded to 3 digits."""
        return {
            "period_s": [round(self.period_s[0], 3), round(self.period_s[1], 3)],
            "rate": round(self.rate, 3),
            "sweep_limit_per_leg": round(self.sweep_limit_per_leg, 3),
        }


@dataclass(frozen=True)
class Trim:
    """Stance runs shortened to the legs' reach (:func:`habitsim.stance.ladder.trim_to_reach`).

    Attributes:
        runs: how many runs were shortened.
        frames: how many stance frames became swing.
        duty_before, duty_after: (4,) stance share of each foot before and after [0–1].
    """

    runs: int
    frames: int
    duty_before: np.ndarray
    duty_after: np.ndarray

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready, duty factors rounded to 3 digits."""
        return {
            "runs": self.runs,
            "frames": self.frames,
            "duty_before": [round(float(v), 3) for v in self.duty_before],
            "duty_after": [round(float(v), 3) for v in self.duty_after],
        }


@dataclass(frozen=True)
class Planting:
    """One planting of the ladder and how far its legs miss (lengths per leg length).

    Attributes:
        footholds: the foothold rule, ``median`` or ``centred``.
        leg_length: the target's leg length [m].
        report: what :func:`habitsim.stance.planting.plant_motion` did; None when the
            footholds lie beyond the stretched legs and no IK was solved.
        max_reach_error_per_leg: largest miss of a held stance toe (not solved: how far
            the farthest foothold lies beyond the stretched leg).
        max_pelvis_drop_per_leg: how far the pelvis came down (not solved: the limit it
            was tested with).
        max_swing_reach_error_per_leg: largest miss of a swing toe between two stance
            runs (None: not solved).
        max_edge_reach_error_per_leg: largest miss of a swing toe before a foot's first
            or after its last stance run; it does not decide whether a planting is kept
            (None: not solved).
        free_frames, stance_frames: a partial planting's stance frames left free, of all
            stance frames (None: every run held).
        free_runs: a partial planting's (free, all) stance runs (None: every run held).
        trimmed: the stance runs shortened first (None: none).
        restep: how the labels were played faster (None: they were not).
    """

    footholds: str
    leg_length: float
    report: PlantReport | None
    max_reach_error_per_leg: float
    max_pelvis_drop_per_leg: float
    max_swing_reach_error_per_leg: float | None = None
    max_edge_reach_error_per_leg: float | None = None
    free_frames: int | None = None
    stance_frames: int | None = None
    free_runs: tuple[int, int] | None = None
    trimmed: Trim | None = None
    restep: Restep | None = None

    @classmethod
    def judged(
        cls,
        report: PlantReport,
        contacts: np.ndarray,
        leg: float,
        footholds: str,
        free: np.ndarray | None = None,
    ) -> Planting:
        """A solved planting, its largest reach errors taken over the held stance frames
        (not the ``free`` runs), over the swings between two stance runs, and apart over
        each foot's swing before its first or after its last stance run (with no foothold
        to head for at the clip's end, the IK may leave a toe behind there).

        Args:
            report: the planting's report; contacts: (T, 4) bool labels it planted;
            leg: leg length [m]; footholds: the rule; free: (T, 4) bool runs left free.
        """
        c = np.asarray(contacts, dtype=bool)
        idx = np.arange(c.shape[0])[:, None]
        first = np.where(c.any(axis=0), c.argmax(axis=0), c.shape[0])
        last = np.where(c.any(axis=0), c.shape[0] - 1 - c[::-1].argmax(axis=0), -1)
        edge = ~c & ((idx < first[None, :]) | (idx > last[None, :]))
        held = c if free is None else c & ~np.asarray(free, dtype=bool)
        err = report.reach_error

        def worst(mask: np.ndarray) -> float:
            return float(np.where(mask, err, 0.0).max()) / leg

        return cls(
            footholds=footholds,
            leg_length=leg,
            report=report,
            max_reach_error_per_leg=worst(held),
            max_pelvis_drop_per_leg=float(report.pelvis_drop.max()) / leg,
            max_swing_reach_error_per_leg=worst(~c & ~edge),
            max_edge_reach_error_per_leg=worst(edge),
        )

    @property
    def solved(self) -> bool:
        """Whether the legs were solved by IK."""
        return self.report is not None

    @property
    def free_share(self) -> float | None:
        """Share of the stance frames a partial planting leaves free (None: none)."""
        if self.free_frames is None or not self.stance_frames:
            return None
        return self.free_frames / self.stance_frames

    def reaches(self, policy: ConformPolicy) -> bool:
        """Whether the legs reach within the policy's limits (``plant_max_*``)."""
        return (
            self.max_reach_error_per_leg <= policy.plant_max_reach_per_leg
            and (self.max_swing_reach_error_per_leg or 0.0) <= policy.plant_max_swing_reach_per_leg
            and self.max_pelvis_drop_per_leg <= policy.plant_max_drop_per_leg
        )

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary, lengths per leg length rounded to 5 digits."""
        if self.report is None:
            return {
                "max_reach_error_per_leg": round(self.max_reach_error_per_leg, 5),
                "max_pelvis_drop_per_leg": self.max_pelvis_drop_per_leg,
                "footholds": self.footholds,
                "solved": False,
            }
        d: dict[str, Any] = dict(self.report.to_dict(self.leg_length))
        d["max_reach_error_per_leg"] = round(self.max_reach_error_per_leg, 5)
        d["max_swing_reach_error_per_leg"] = round(self.max_swing_reach_error_per_leg or 0.0, 5)
        d["max_edge_reach_error_per_leg"] = round(self.max_edge_reach_error_per_leg or 0.0, 5)
        d["footholds"] = self.footholds
        d["solved"] = True
        if self.restep is not None:
            d["restep"] = self.restep.to_dict()
        if self.free_runs is not None:
            d["free_runs"] = list(self.free_runs)
            d["free_share"] = round(self.free_share or 0.0, 3)
        if self.trimmed is not None:
            d["trimmed"] = self.trimmed.to_dict()
        return d


class PlantReason(StrEnum):
    """One clause of a :class:`PlantOutcome`'s ``reason``, as a typed code (the text says
    the same in words, with the figures)."""

    #: the legs do not reach the footholds with the decoded root path
    OUT_OF_REACH = "out_of_reach"
    #: kept: the body moved as far as its stance legs carry it
    CARRIED = "carried"
    #: the carried body was tried and its legs missed too
    CARRY_MISSED = "carry_missed"
    #: the stance legs carry the body too slowly to try it
    CARRY_TOO_SLOW = "carry_too_slow"
    #: kept: the legs step faster
    RESTEPPED = "restepped"
    #: stepping faster was tried and missed
    RESTEP_MISSED = "restep_missed"
    #: the partial planting holds the faster steps' labels
    PARTLY_ON_RESTEP = "partly_on_restep"
    #: stance runs were shortened to the legs' reach
    TRIMMED = "trimmed"
    #: kept: the stance runs out of reach keep the decoded feet
    PARTLY = "partly"
    #: nothing kept: the decoded feet are
    DECODED_FEET_KEPT = "decoded_feet_kept"


@dataclass(frozen=True)
class PlantOutcome:
    """What the planting ladder (:func:`habitsim.stance.ladder.plant_decoded`) did.

    Attributes:
        kept: whether a planting was kept (False: the decoded feet are).
        planting: the planting kept; when none was, the first rule's on the decoded
            root path.
        root: ``decoded`` or ``carried`` (moved as far as the stance legs carry it);
            None when nothing was kept.
        speed_ratio: the carried body's speed over its decoded speed, where it was
            computed for the outcome (None otherwise).
        reason: why the first planting was not kept (None: it was).
        restep_tried: the planting on faster steps that missed, when a later fallback
            (or nothing) was kept (None: not tried, or it was kept).
        reason_codes: the clauses of ``reason`` as typed codes, in its order (empty: the
            first planting was kept); not written to the metadata.
    """

    kept: bool
    planting: Planting
    root: str | None = None
    speed_ratio: float | None = None
    reason: str | None = None
    restep_tried: Planting | None = None
    reason_codes: tuple[PlantReason, ...] = ()

    @property
    def relabelled(self) -> bool:
        """Whether the kept planting steps on other labels than it was given (faster or
        trimmed stance runs)."""
        p = self.planting
        return self.kept and (
            p.restep is not None or p.trimmed is not None or self.restep_tried is not None
        )

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: the planting's summary with ``kept``, ``root``, ``speed_ratio``,
        ``reason`` and a missed ``restep``."""
        d = self.planting.to_dict()
        tried = self.restep_tried
        if tried is not None and tried.restep is not None:
            d["restep"] = {
                **tried.restep.to_dict(),
                "max_reach_error_per_leg": round(tried.max_reach_error_per_leg, 5),
                "max_pelvis_drop_per_leg": round(tried.max_pelvis_drop_per_leg, 5),
            }
        d["kept"] = self.kept
        if self.root is not None:
            d["root"] = self.root
        if self.speed_ratio is not None:
            d["speed_ratio"] = round(self.speed_ratio, 3)
        if self.reason is not None:
            d["reason"] = self.reason
        return d


@dataclass(frozen=True)
class ConformReport:
    """What conforming a decoded motion did (:func:`habitsim.stance.conform.conform`).

    Attributes:
        contacts: how the stance labels were found (:func:`~habitsim.stance.schedule.
            transfer_contacts`' info, with ``walking_stance`` where that changed them).
        speed_bounded, height_bounded, heading_bounded: what each bound to the source
            changed (None: nothing).
        levelled: how the trunk was pitched level (None: it was not).
        planted: the planting ladder's outcome (None: planting off or no foot in stance).
    """

    contacts: dict[str, Any]
    speed_bounded: dict[str, Any] | None = None
    height_bounded: dict[str, Any] | None = None
    heading_bounded: dict[str, Any] | None = None
    levelled: dict[str, Any] | None = None
    planted: PlantOutcome | None = None

    def to_metadata(self, info: dict[str, Any]) -> dict[str, Any]:
        """``metadata["transfer"]`` of the transferred motion: ``info`` (the method's
        own entries) followed by this report's, ``planted`` False when nothing was."""
        meta = dict(info)
        for key in ("speed_bounded", "height_bounded", "heading_bounded", "levelled"):
            value = getattr(self, key)
            if value is not None:
                meta[key] = value
        meta["contacts"] = self.contacts
        meta["planted"] = False if self.planted is None else self.planted.to_dict()
        return meta
