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

__all__ = ["SourceStanceRecord", "ImportReport"]


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
    """

    contacts: SourceStanceRecord
    contact_f1: tuple[float, ...]
    confidence: tuple[tuple[str, float], ...]
    warnings: tuple[str, ...]
    planted: tuple[tuple[str, Any], ...] | None = None

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
        return d
