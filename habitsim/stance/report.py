"""Typed reports of conforming a decoded motion: each planting, the ladder's outcome, the whole.

The planting ladder (:mod:`habitsim.stance.ladder`) judges each planting by these typed
values; ``to_dict`` methods write the JSON-ready, rounded form that goes into a
transfer's ``metadata["transfer"]`` (the ``.npz`` format is unchanged).
:class:`TransferRecord` (with :class:`ScheduleRecord`, :class:`WalkingRecord`,
:class:`PlantedRecord`, :class:`RetrievalRecord`, :class:`LevelledRecord`) is the one
typed reader of that entry, and writes it back as read.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass
from enum import StrEnum
from typing import Any

import numpy as np

from ..errors import MetadataError
from .labels import StanceLabels, as_labels
from .planting import PlantReport
from .policy import ConformPolicy
from .schedule import ScheduleReason

__all__ = [
    "Restep",
    "Trim",
    "Planting",
    "PlantOutcome",
    "PlantReason",
    "ConformReport",
    "WalkingRecord",
    "ScheduleRecord",
    "PlantedRecord",
    "RetrievalRecord",
    "LevelledRecord",
    "TransferRecord",
]


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
        labels: the (T, 4) stance labels this planting stepped on, with their edits
            (a restep's or a trim's recorded); None when the legs were not solved.
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
    labels: StanceLabels | None = None

    @classmethod
    def judged(
        cls,
        report: PlantReport,
        contacts: StanceLabels | np.ndarray,
        leg: float,
        footholds: str,
        free: np.ndarray | None = None,
    ) -> Planting:
        """A solved planting, its largest reach errors taken over the held stance frames
        (not the ``free`` runs), over the swings between two stance runs, and apart over
        each foot's swing before its first or after its last stance run (with no foothold
        to head for at the clip's end, the IK may leave a toe behind there).

        Args:
            report: the planting's report; contacts: the (T, 4) labels it planted (an
            array is taken as given labels); leg: leg length [m]; footholds: the rule;
            free: (T, 4) bool runs left free.
        """
        labels = as_labels(contacts)
        c = labels.array
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
            labels=labels,
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
        labels: the conformed motion's (T, 4) stance labels, where they came from and
            every edit of the schedule, the walking stance and the planting ladder
            (None: not given).
    """

    contacts: dict[str, Any]
    speed_bounded: dict[str, Any] | None = None
    height_bounded: dict[str, Any] | None = None
    heading_bounded: dict[str, Any] | None = None
    levelled: dict[str, Any] | None = None
    planted: PlantOutcome | None = None
    labels: StanceLabels | None = None

    @property
    def schedule(self) -> ScheduleRecord:
        """:attr:`contacts`, typed.

        Raises:
            MetadataError: a missing or malformed field (named).
        """
        return ScheduleRecord.from_dict(self.contacts)

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


# ------------------------------------------------------- metadata["transfer"], read back
def _where(path: str, key: str) -> str:
    return f"{path}.{key}" if path else key


def _entry(d: Mapping[str, Any], key: str, kind: type | tuple[type, ...], path: str) -> Any:
    """``d[key]``, checked to be of ``kind``.

    Raises:
        MetadataError: the field is missing or of another type (names ``path.key``).
    """
    if key not in d:
        raise MetadataError(f"metadata field {_where(path, key)} is missing")
    value = d[key]
    if not isinstance(value, kind) or (isinstance(value, bool) and bool not in _kinds(kind)):
        raise MetadataError(
            f"metadata field {_where(path, key)} is malformed: {type(value).__name__} {value!r}"
        )
    return value


def _kinds(kind: type | tuple[type, ...]) -> tuple[type, ...]:
    return kind if isinstance(kind, tuple) else (kind,)


def _mapping(value: object, path: str) -> Mapping[str, Any]:
    """``value`` checked to be a mapping (names ``path`` when it is not)."""
    if not isinstance(value, Mapping):
        raise MetadataError(f"metadata field {path} is malformed: {type(value).__name__}")
    return value


def _floats(value: object, path: str) -> tuple[float, ...]:
    """``value`` checked to be a list of numbers."""
    if not isinstance(value, list | tuple) or not all(
        isinstance(v, int | float) and not isinstance(v, bool) for v in value
    ):
        raise MetadataError(f"metadata field {path} is malformed: {value!r}")
    return tuple(float(v) for v in value)


@dataclass(frozen=True)
class WalkingRecord:
    """What the walking stance did (``metadata["transfer"]["contacts"]["walking_stance"]``,
    :func:`habitsim.stance.schedule.walking_stance`).

    Attributes:
        froude: the transfer's Froude number.
        walk_froude_max: the top of the target's walking band.
        duty_before, duty_after: (4,) each foot's stance share before / after [0–1].
    """

    froude: float
    walk_froude_max: float
    duty_before: tuple[float, ...]
    duty_after: tuple[float, ...]

    @classmethod
    def from_dict(cls, d: object, path: str) -> WalkingRecord:
        """Read back from its JSON form (``path``: where it sits, for errors).

        Raises:
            MetadataError: a missing or malformed field (named).
        """
        m = _mapping(d, path)
        return cls(
            float(_entry(m, "froude", (int, float), path)),
            float(_entry(m, "walk_froude_max", (int, float), path)),
            _floats(_entry(m, "duty_before", list, path), f"{path}.duty_before"),
            _floats(_entry(m, "duty_after", list, path), f"{path}.duty_after"),
        )

    def to_dict(self) -> dict[str, Any]:
        """The JSON form (as :func:`~habitsim.stance.schedule.walking_stance` writes it)."""
        return {
            "froude": self.froude,
            "walk_froude_max": self.walk_froude_max,
            "duty_before": list(self.duty_before),
            "duty_after": list(self.duty_after),
        }


@dataclass(frozen=True)
class ScheduleRecord:
    """How a transfer's stance labels were found (``metadata["transfer"]["contacts"]``,
    written by :func:`habitsim.stance.schedule.transfer_contacts`).

    Attributes:
        method: ``decoded``, ``source``, ``detected``, ``duty`` (or another method's own
            code).
        details: the method's details, in their written order (``source_f1``, ``duty``,
            ``feet_from_source``, ``gait``, …; JSON values).
        walking_stance: what the walking stance did (None: not applied).
    """

    method: str
    details: tuple[tuple[str, Any], ...] = ()
    walking_stance: WalkingRecord | None = None

    @classmethod
    def from_dict(cls, d: object, path: str = "transfer.contacts") -> ScheduleRecord:
        """Read back from its JSON form.

        Raises:
            MetadataError: a missing or malformed field (named).
        """
        m = _mapping(d, path)
        method = str(_entry(m, "method", str, path))
        walking = m.get("walking_stance")
        return cls(
            method,
            tuple((k, m[k]) for k in m if k not in ("method", "walking_stance")),
            None if walking is None else WalkingRecord.from_dict(walking, f"{path}.walking_stance"),
        )

    def detail(self, key: str, path: str = "transfer.contacts") -> Any:
        """The detail ``key`` (e.g. ``gait``, ``duty_factor``, ``feet_by_duty`` of the
        ``duty`` method).

        Raises:
            MetadataError: the detail was not written (names ``path.key``).
        """
        for k, v in self.details:
            if k == key:
                return v
        raise MetadataError(f"metadata field {_where(path, key)} is missing")

    @property
    def reason_code(self) -> ScheduleReason | None:
        """The ``reason`` detail as its typed code (None: no reason written, or one that is
        not :func:`~habitsim.stance.schedule.transfer_contacts`' own)."""
        reason = dict(self.details).get("reason")
        return next((code for code in ScheduleReason if code.text == reason), None)

    def to_dict(self) -> dict[str, Any]:
        """The JSON form, keys in their written order."""
        d: dict[str, Any] = {"method": self.method, **dict(self.details)}
        if self.walking_stance is not None:
            d["walking_stance"] = self.walking_stance.to_dict()
        return d


@dataclass(frozen=True)
class PlantedRecord:
    """How a transfer planted its feet (``metadata["transfer"]["planted"]``, written by
    :meth:`PlantOutcome.to_dict`).

    Attributes:
        kept: whether a planting was kept.
        root: the root path the kept planting stands under (``decoded`` / ``carried``;
            None when not written).
        summary: the whole JSON record, in its written order.
    """

    kept: bool
    root: str | None
    summary: tuple[tuple[str, Any], ...]

    @classmethod
    def from_dict(cls, d: object, path: str = "transfer.planted") -> PlantedRecord:
        """Read back from its JSON form.

        Raises:
            MetadataError: a missing or malformed field (named).
        """
        m = _mapping(d, path)
        kept = bool(_entry(m, "kept", bool, path))
        root = m.get("root")
        if root is not None and not isinstance(root, str):
            raise MetadataError(f"metadata field {path}.root is malformed: {root!r}")
        return cls(kept, root, tuple(m.items()))

    @property
    def how(self) -> str:
        """``decoded`` / ``carried`` (the root path the feet were planted under) or ``no``
        (out of reach, decoded feet kept)."""
        return (self.root or "decoded") if self.kept else "no"

    def to_dict(self) -> dict[str, Any]:
        """The JSON form, keys in their written order."""
        return dict(self.summary)


@dataclass(frozen=True)
class RetrievalRecord:
    """Which species' habits served a held-out target (``metadata["transfer"]["retrieval"]``,
    written by :func:`habitsim.models.transfer` for the habit method).

    Attributes:
        neighbour: the nearest training species by its habit description.
        text_distance, morphology_distance: how far it lies, by text and by body.
        explanation: the retrieval in words.
    """

    neighbour: str
    text_distance: float
    morphology_distance: float
    explanation: str

    @classmethod
    def from_dict(cls, d: object, path: str = "transfer.retrieval") -> RetrievalRecord:
        """Read back from its JSON form.

        Raises:
            MetadataError: a missing or malformed field (named).
        """
        m = _mapping(d, path)
        return cls(
            str(_entry(m, "neighbour", str, path)),
            _entry(m, "text_distance", (int, float), path),
            _entry(m, "morphology_distance", (int, float), path),
            str(_entry(m, "explanation", str, path)),
        )

    def to_dict(self) -> dict[str, Any]:
        """The JSON form, keys in their written order."""
        return asdict(self)


@dataclass(frozen=True)
class LevelledRecord:
    """How the trunk was pitched level before planting (``metadata["transfer"]["levelled"]``,
    written by :func:`habitsim.stance.level.level_trunk`).

    Attributes:
        pitch_deg: the pitch applied [deg].
        fore_minus_hind_per_leg: how far the decoded fore stance toes stood above the hind
            ones (negative: below) [leg lengths].
    """

    pitch_deg: float
    fore_minus_hind_per_leg: float

    @classmethod
    def from_dict(cls, d: object, path: str = "transfer.levelled") -> LevelledRecord:
        """Read back from its JSON form.

        Raises:
            MetadataError: a missing or malformed field (named).
        """
        m = _mapping(d, path)
        return cls(
            _entry(m, "pitch_deg", (int, float), path),
            _entry(m, "fore_minus_hind_per_leg", (int, float), path),
        )

    def to_dict(self) -> dict[str, Any]:
        """The JSON form, keys in their written order."""
        return asdict(self)


#: The entries of ``metadata["transfer"]`` :class:`TransferRecord` reads into typed fields.
_TYPED = ("contacts", "planted", "retrieval", "levelled")


@dataclass(frozen=True)
class TransferRecord:
    """A transferred motion's ``metadata["transfer"]``, typed: the one reader of what a
    transfer method wrote (:meth:`ConformReport.to_metadata`, the direct methods).

    Attributes:
        contacts: how its stance labels were found (None: the method wrote none).
        planted: how its feet were planted (None: ``planted`` False or not written).
        entries: the other entries (the method's own: ``method``, ``species``, ``seed``,
            ``habit_species``; the bounds to the source), JSON values.
        order: the keys in their written order (so the record is written back as read).
        retrieval: which species' habits served a held-out target (None: ``retrieval``
            None or not written).
        levelled: how the trunk was pitched level (None: not written).
    """

    contacts: ScheduleRecord | None
    planted: PlantedRecord | None
    entries: tuple[tuple[str, Any], ...]
    order: tuple[str, ...]
    retrieval: RetrievalRecord | None = None
    levelled: LevelledRecord | None = None

    @classmethod
    def from_metadata(cls, metadata: Mapping[str, Any] | None) -> TransferRecord | None:
        """The record of a motion's metadata; None when it has no ``transfer`` entry.

        Raises:
            MetadataError: ``transfer`` is no mapping, or a missing or malformed field
                (named, e.g. ``transfer.contacts.method``).
        """
        if not metadata or "transfer" not in metadata:
            return None
        m = _mapping(metadata["transfer"], "transfer")
        contacts = m.get("contacts")
        planted = m.get("planted", False)
        retrieval = m.get("retrieval")
        levelled = m.get("levelled")
        habit = m.get("habit_species")
        if habit is not None and not isinstance(habit, str):
            raise MetadataError(f"metadata field transfer.habit_species is malformed: {habit!r}")
        return cls(
            None if contacts is None else ScheduleRecord.from_dict(contacts),
            None if planted is False else PlantedRecord.from_dict(planted),
            tuple((k, v) for k, v in m.items() if k not in _TYPED),
            tuple(m),
            None if retrieval is None else RetrievalRecord.from_dict(retrieval),
            None if levelled is None else LevelledRecord.from_dict(levelled),
        )

    @property
    def habit_species(self) -> str | None:
        """The species whose habits the habit method drew (None: not written, or written
        None)."""
        return dict(self.entries).get("habit_species")

    @property
    def planted_how(self) -> str:
        """``decoded`` / ``carried`` / ``no`` (:attr:`PlantedRecord.how`), or ``-``
        (the method does not plant)."""
        return "-" if self.planted is None else self.planted.how

    def to_metadata(self) -> dict[str, Any]:
        """``metadata["transfer"]`` as it was read (same keys, order and values)."""
        parts = dict(self.entries)
        if self.contacts is not None:
            parts["contacts"] = self.contacts.to_dict()
        parts["planted"] = False if self.planted is None else self.planted.to_dict()
        # written only where read (``order``): None stands for an entry written None
        parts["retrieval"] = None if self.retrieval is None else self.retrieval.to_dict()
        parts["levelled"] = None if self.levelled is None else self.levelled.to_dict()
        return {k: parts[k] for k in self.order}
