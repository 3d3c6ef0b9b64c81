"""The typed import report: what the importer found on a source clip's own feet.

:class:`ImportReport` is what :func:`habitsim.bvh_mapping.retargeting.retarget` writes
into a motion's ``metadata["import"]`` (:meth:`ImportReport.to_metadata`) and the one
reader of it (:meth:`ImportReport.from_metadata`); the ``.npz`` format is unchanged.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from ..errors import MetadataError
from ..stance.labels import StanceSource

__all__ = ["SourceStanceRecord", "InPlaceRecord", "ImportReport", "in_place_note"]


def _get(d: Mapping[str, Any], key: str, path: str) -> Any:
    if key not in d:
        raise MetadataError(f"metadata field {path}.{key} is missing")
    return d[key]


def _mapping(value: object, path: str) -> Mapping[str, Any]:
    if not isinstance(value, Mapping):
        raise MetadataError(f"metadata field {path} is malformed: {type(value).__name__}")
    return value


def _list(value: object, path: str, kind: type | tuple[type, ...]) -> tuple[Any, ...]:
    if not isinstance(value, list | tuple) or not all(
        isinstance(v, kind) and not isinstance(v, bool) for v in value
    ):
        raise MetadataError(f"metadata field {path} is malformed: {value!r}")
    return tuple(value)


def _checked_number(value: object, path: str) -> Any:
    """``value`` as it is, checked to be a number."""
    if not isinstance(value, int | float) or isinstance(value, bool):
        raise MetadataError(f"metadata field {path} is malformed: {value!r}")
    return value


def _number(value: object, path: str) -> float:
    return float(_checked_number(value, path))


@dataclass(frozen=True)
class SourceStanceRecord:
    """How the source's stance labels were found (``metadata["import"]["contacts"]``).

    Attributes:
        method: the labelling's name (``source foot path``).
        foot_joints: the source joint of each foot (LF, RF, LH, RH).
        foot_points: per foot, the source joints whose lowest one is its sole.
        floors_m: (4,) each foot's floor above the ground [m].
        source_leg_length_m: the source's normalising (hind-leg) length [m].
        duty: (4,) each foot's stance share [0–1].
    """

    method: str
    foot_joints: tuple[str, ...]
    foot_points: tuple[tuple[str, ...], ...]
    floors_m: tuple[float, ...]
    source_leg_length_m: float
    duty: tuple[float, ...]

    @property
    def source(self) -> StanceSource:
        """Where the labels came from: :attr:`StanceSource.IMPORTED`."""
        return StanceSource.IMPORTED

    @classmethod
    def from_dict(cls, d: object, path: str = "import.contacts") -> SourceStanceRecord:
        """Read back from its JSON form.

        Raises:
            MetadataError: a missing or malformed field (named).
        """
        m = _mapping(d, path)
        method = _get(m, "method", path)
        if not isinstance(method, str):
            raise MetadataError(f"metadata field {path}.method is malformed: {method!r}")
        points = _get(m, "foot_points", path)
        if not isinstance(points, list | tuple):
            raise MetadataError(f"metadata field {path}.foot_points is malformed: {points!r}")
        return cls(
            method,
            _list(_get(m, "foot_joints", path), f"{path}.foot_joints", str),
            tuple(_list(p, f"{path}.foot_points", str) for p in points),
            _list(_get(m, "floors_m", path), f"{path}.floors_m", (int, float)),
            _number(_get(m, "source_leg_length_m", path), f"{path}.source_leg_length_m"),
            _list(_get(m, "duty", path), f"{path}.duty", (int, float)),
        )

    def to_dict(self) -> dict[str, Any]:
        """The JSON form, in its written order."""
        return {
            "method": self.method,
            "foot_joints": list(self.foot_joints),
            "foot_points": [list(p) for p in self.foot_points],
            "floors_m": list(self.floors_m),
            "source_leg_length_m": self.source_leg_length_m,
            "duty": list(self.duty),
        }


@dataclass(frozen=True)
class InPlaceRecord:
    """Whether the source was an in-place clip or a loop, and what was done
    (``metadata["import"]["in_place"]``; :mod:`habitsim.bvh_mapping.inplace`,
    :mod:`habitsim.bvh_mapping.loops`).

    Attributes:
        detected: the clip was in place and its root travel was recovered from its
            stance feet.
        recovered_m: path length of the recovered travel, in the source's size [m] (0
            when not detected).
        heading_deg: direction of the recovered travel in the habitsim frame (0 = +x,
            90 = +y) [deg]; None when not detected.
        root_travel_m: the evidence: the trunk's horizontal path in the clip as given [m],
        foot_sweep_m: ... the feet's backward sweep relative to the trunk while low [m],
        backward_share: ... how straight back the low feet move (1 = straight back).
        reason: one line saying why the clip is or is not in place.
        loop: ``"closed"`` (last frame = first), ``"open"`` (last frame runs on into the
            first) or ``"no"``.
        loop_mismatch: distance of the last pose from the first [leg lengths].
        swept_feet: the feet (``lf``, ``rf``, ``lh``, ``rh``) whose stance labels are
            their backward sweeps (a keyframed foot that rolls within its stance).
        cycles: how many times the clip was played (1: as it came).
        unreached_frames: stance frames of the swept feet taken off at the ends of their
            runs, where the target's leg does not reach the foothold planted
            (:func:`habitsim.bvh_mapping.inplace.trim_unreached`).
    """

    detected: bool
    recovered_m: float
    heading_deg: float | None
    root_travel_m: float
    foot_sweep_m: float
    backward_share: float
    reason: str
    loop: str
    loop_mismatch: float
    swept_feet: tuple[str, ...] = ()
    cycles: int = 1
    unreached_frames: int = 0

    @classmethod
    def from_dict(cls, d: object, path: str = "import.in_place") -> InPlaceRecord:
        """Read back from its JSON form.

        Raises:
            MetadataError: a missing or malformed field (named).
        """
        m = _mapping(d, path)
        detected = _get(m, "detected", path)
        reason = _get(m, "reason", path)
        loop = _get(m, "loop", path)
        heading = _get(m, "heading_deg", path)
        cycles = _get(m, "cycles", path)
        unreached = _get(m, "unreached_frames", path)
        if not isinstance(detected, bool):
            raise MetadataError(f"metadata field {path}.detected is malformed: {detected!r}")
        if not isinstance(reason, str):
            raise MetadataError(f"metadata field {path}.reason is malformed: {reason!r}")
        if loop not in ("closed", "open", "no"):
            raise MetadataError(f"metadata field {path}.loop is malformed: {loop!r}")
        if not isinstance(cycles, int) or isinstance(cycles, bool) or cycles < 1:
            raise MetadataError(f"metadata field {path}.cycles is malformed: {cycles!r}")
        if not isinstance(unreached, int) or isinstance(unreached, bool) or unreached < 0:
            raise MetadataError(
                f"metadata field {path}.unreached_frames is malformed: {unreached!r}"
            )
        return cls(
            detected,
            _number(_get(m, "recovered_m", path), f"{path}.recovered_m"),
            None if heading is None else _number(heading, f"{path}.heading_deg"),
            _number(_get(m, "root_travel_m", path), f"{path}.root_travel_m"),
            _number(_get(m, "foot_sweep_m", path), f"{path}.foot_sweep_m"),
            _number(_get(m, "backward_share", path), f"{path}.backward_share"),
            reason,
            loop,
            _number(_get(m, "loop_mismatch", path), f"{path}.loop_mismatch"),
            _list(_get(m, "swept_feet", path), f"{path}.swept_feet", str),
            cycles,
            unreached,
        )

    def to_dict(self) -> dict[str, Any]:
        """The JSON form, in its written order."""
        return {
            "detected": self.detected,
            "recovered_m": self.recovered_m,
            "heading_deg": self.heading_deg,
            "root_travel_m": self.root_travel_m,
            "foot_sweep_m": self.foot_sweep_m,
            "backward_share": self.backward_share,
            "reason": self.reason,
            "loop": self.loop,
            "loop_mismatch": self.loop_mismatch,
            "swept_feet": list(self.swept_feet),
            "cycles": self.cycles,
            "unreached_frames": self.unreached_frames,
        }

    def lines(self) -> list[str]:
        """What was done, as printed by the command line (one item a line)."""
        out = []
        if self.detected:
            out.append(
                f"in place: yes; root travel recovered from the stance feet: "
                f"{self.recovered_m:.2f} m, heading {self.heading_deg:.0f} deg "
                f"(trunk moved {self.root_travel_m:.3f} m while the feet swept "
                f"{self.foot_sweep_m:.2f} m back, backward share {self.backward_share:.2f})"
            )
            if self.swept_feet:
                out.append(
                    f"in place: stance of {', '.join(self.swept_feet)} taken from the "
                    "feet's backward sweeps (they roll or lift within their stance)"
                )
            if self.unreached_frames:
                out.append(
                    f"in place: {self.unreached_frames} stance frame"
                    f"{'s' if self.unreached_frames != 1 else ''} at the ends of those sweeps "
                    "taken off (the legs do not reach them planted)"
                )
        else:
            out.append(f"in place: no ({self.reason})")
        if self.loop == "no":
            out.append(f"loop: no (last pose {self.loop_mismatch:.3f} leg lengths from the first)")
        else:
            out.append(
                f"loop: yes, {self.loop} (last pose {self.loop_mismatch:.3f} leg lengths from "
                f"the first); played {self.cycles} time{'s' if self.cycles != 1 else ''}"
            )
        return out


@dataclass(frozen=True)
class ImportReport:
    """What the importer found (``metadata["import"]``).

    Attributes:
        contacts: how the source's stance labels were found on its own feet.
        planted: the legs' planting onto the source's footholds
            (:meth:`habitsim.stance.planting.PlantReport.to_dict`, lengths per leg
            length; None: the legs were not planted).
        contact_f1: (4,) per foot, the F1 of the stance detected on the imported feet
            against the source's labels.
        confidence: per leg (``lf``, ``rf``, ``lh``, ``rh``) the mapping's confidence
            [0–1].
        warnings: the mapping's warnings.
        in_place: whether the clip was in place (its travel recovered) or a loop, and
            how often it was played (None: not looked for, e.g. a file written before).
    """

    contacts: SourceStanceRecord
    contact_f1: tuple[float, ...]
    confidence: tuple[tuple[str, float], ...]
    warnings: tuple[str, ...]
    planted: tuple[tuple[str, Any], ...] | None = None
    in_place: InPlaceRecord | None = None

    @classmethod
    def from_metadata(cls, metadata: Mapping[str, Any] | None) -> ImportReport | None:
        """The report of a motion's metadata; None when it has no ``import`` entry.

        Raises:
            MetadataError: a missing or malformed field (named, e.g.
                ``import.contact_f1``).
        """
        if not metadata or "import" not in metadata:
            return None
        path = "import"
        m = _mapping(metadata["import"], path)
        planted = m.get("planted")
        conf = _mapping(_get(m, "confidence", path), f"{path}.confidence")
        return cls(
            SourceStanceRecord.from_dict(_get(m, "contacts", path)),
            _list(_get(m, "contact_f1", path), f"{path}.contact_f1", (int, float)),
            tuple((str(k), _checked_number(v, f"{path}.confidence.{k}")) for k, v in conf.items()),
            _list(_get(m, "warnings", path), f"{path}.warnings", str),
            None if planted is None else tuple(_mapping(planted, f"{path}.planted").items()),
            None if m.get("in_place") is None else InPlaceRecord.from_dict(m["in_place"]),
        )

    @property
    def mean_contact_f1(self) -> float | None:
        """The feet's mean :attr:`contact_f1` (None without feet)."""
        return sum(self.contact_f1) / len(self.contact_f1) if self.contact_f1 else None

    def to_metadata(self) -> dict[str, Any]:
        """``metadata["import"]``, in its written order."""
        d: dict[str, Any] = {"contacts": self.contacts.to_dict()}
        if self.planted is not None:
            d["planted"] = dict(self.planted)
        d["contact_f1"] = list(self.contact_f1)
        d["confidence"] = dict(self.confidence)
        d["warnings"] = list(self.warnings)
        if self.in_place is not None:
            d["in_place"] = self.in_place.to_dict()
        return d


def in_place_note(metadata: Mapping[str, Any] | None) -> str | None:
    """A one-line note for a motion imported from an in-place clip (None otherwise):
    what the commands that read a clip print.

    Raises:
        MetadataError: a malformed ``metadata["import"]``.
    """
    report = ImportReport.from_metadata(metadata)
    ip = None if report is None else report.in_place
    if ip is None or not ip.detected:
        return None
    return (
        f"note: the input clip was in place (its root stays put while the feet sweep); its "
        f"travel, {ip.recovered_m:.2f} m at heading {ip.heading_deg:.0f} deg, was recovered "
        "from its stance feet"
    )
