"""The contact labels a refinement plants: resolved from the input, cleaned against
the motion (:func:`clean_contact_labels`) and summarised for the report."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import MetadataError
from ..motion import Motion
from ..stance.labels import EditReason, StanceLabels, StanceSource, runs
from .errors import RefineInputError
from .options import MAX_TRIM_SHARE, MIN_RUN_S, STANCE_SLIP_PER_LEG

__all__ = [
    "clean_contact_labels",
    "cleaning_summary",
    "FootCleaning",
    "CleaningRecord",
    "CLEANED_BY",
    "STANCE_SLIP_PER_LEG",
    "MAX_TRIM_SHARE",
    "MIN_RUN_S",
]


def _resolve_contacts(motion: Motion, contacts: np.ndarray | None) -> StanceLabels:
    """The labels a refinement plants: ``contacts`` when given, else the motion's own,
    else those detected on it.

    Raises:
        RefineInputError: labels of the wrong shape, or not booleans (or 0/1).
    """
    t = motion.num_frames
    if contacts is None:
        if motion.contacts is not None:
            contacts, source = motion.contacts, StanceSource.INPUT
        else:
            return StanceLabels(motion.detect_contacts(), StanceSource.DETECTED)
    else:
        source = StanceSource.GIVEN
    c = np.asarray(contacts)
    if c.shape != (t, 4):
        raise RefineInputError(
            f"contacts must have shape ({t}, 4) (feet LF, RF, LH, RH), got {c.shape}"
        )
    if c.dtype != bool:
        if not np.issubdtype(c.dtype, np.number) or not np.all(np.isin(c, (0, 1))):
            raise RefineInputError("contacts must be booleans (or 0/1)")
    return StanceLabels(c, source)


#: Who :func:`clean_contact_labels` is in the labels' edit records.
CLEANED_BY = "refine.clean_contact_labels"
#: Foot names of the cleaning summary (a fifth foot and beyond go by their index).
_FOOT_NAMES = ("LF", "RF", "LH", "RH")


def clean_contact_labels(
    labels: StanceLabels,
    toes: np.ndarray,
    fps: float,
    leg_length: float,
    slip_per_leg: float = STANCE_SLIP_PER_LEG,
    min_run_s: float = MIN_RUN_S,
    trim: bool = True,
    max_trim_share: float = MAX_TRIM_SHARE,
) -> StanceLabels:
    """Contact labels made consistent with the motion before they are planted.

    For every foot, in this order (one recorded edit per step, by :data:`CLEANED_BY`):

    1. *trim* (:attr:`~habitsim.stance.labels.EditReason.SLIP_TRIM`): the frames at either
       end of a stance run whose toe lies horizontally further than ``slip_per_leg`` × L
       from where the run rests (the median of its toe positions) become swing — the
       input moves that foot, so planting it there would drag the leg — at most
       ``max_trim_share`` of the run at each end (below 1, every labelled footfall keeps
       a stance even where the foot slides through all of it);
    2. *fill* (:attr:`~habitsim.stance.labels.EditReason.GAP_FILL`): a swing gap of at
       most ``min_run_s`` (at least one frame) between two stance runs that rest within
       ``slip_per_leg`` × L of each other becomes stance (the foot did not step);
    3. *drop* (:attr:`~habitsim.stance.labels.EditReason.BLIP_DROP`): a stance run
       shorter than ``min_run_s`` (at least two frames) that does not touch the clip's
       first or last frame becomes swing (a blip, not a step).

    Args:
        labels: (T, 4) stance labels (LF, RF, LH, RH).
        toes: (T, 4, ≥2) toe positions of the motion [m] (x, y used).
        fps: frame rate [Hz].
        leg_length: the species' hind-leg length L [m].
        slip_per_leg: the distance a stance toe may lie from its run's rest, share of L.
        min_run_s: shortest stance run kept and longest swing gap filled [s].
        trim: run step 1 (off: only fill and drop).
        max_trim_share: step 1 trims at most this share of a run at each end
            (1 for no cap).

    Returns:
        The cleaned labels, ``labels`` with the edits of the steps that changed a frame
        (:func:`cleaning_summary` tells what changed).
    """
    c0 = labels.array
    xy = np.asarray(toes, float)[..., :2]
    t, nf = c0.shape
    tol = float(slip_per_leg) * float(leg_length)
    max_gap = max(1, int(round(min_run_s * fps)))
    min_stance = max(2, int(round(min_run_s * fps)))
    trimmed = c0.copy()
    for f in range(nf):
        for a, b in runs(c0[:, f]) if trim else ():
            anchor = np.median(xy[a:b, f], axis=0)
            far = np.linalg.norm(xy[a:b, f] - anchor, axis=1) > tol
            lo, hi = a, b
            cap = int(np.floor(float(max_trim_share) * (b - a)))
            while lo < hi and far[lo - a] and lo - a < cap:
                lo += 1
            while hi > lo and far[hi - 1 - a] and b - hi < cap:
                hi -= 1
            trimmed[a:lo, f] = False
            trimmed[hi:b, f] = False
    filled = trimmed.copy()
    for f in range(nf):
        rs = runs(trimmed[:, f])
        for (a0, b0), (a1, b1) in zip(rs, rs[1:], strict=False):
            if b0 < a1 and a1 - b0 <= max_gap:
                p0 = np.median(xy[a0:b0, f], axis=0)
                p1 = np.median(xy[a1:b1, f], axis=0)
                if np.linalg.norm(p1 - p0) <= tol:
                    filled[b0:a1, f] = True
    dropped = filled.copy()
    for f in range(nf):
        for a, b in runs(filled[:, f]):
            if b - a < min_stance and a > 0 and b < t:
                dropped[a:b, f] = False
    return (
        labels.edited(trimmed, by=CLEANED_BY, reason=EditReason.SLIP_TRIM)
        .edited(filled, by=CLEANED_BY, reason=EditReason.GAP_FILL)
        .edited(dropped, by=CLEANED_BY, reason=EditReason.BLIP_DROP)
    )


def cleaning_summary(cleaned: StanceLabels, since: int = 0) -> dict[str, Any]:
    """What :func:`clean_contact_labels` changed, as the report lists it
    (``contacts.cleaning``).

    Args:
        cleaned: labels returned by :func:`clean_contact_labels`.
        since: the number of edits the labels had before they were cleaned.

    Returns:
        ``frames_changed``: labels that differ from those before the cleaning (a frame
        trimmed and filled again is unchanged); per foot (``LF`` …): the frames
        ``trimmed``, the gaps ``filled`` and the stance runs ``dropped``.
    """
    counts = np.zeros((3, cleaned.n_feet), dtype=int)
    steps = (EditReason.SLIP_TRIM, EditReason.GAP_FILL, EditReason.BLIP_DROP)
    for e in cleaned.edits[since:]:
        if e.by != CLEANED_BY or e.reason not in steps:
            continue
        k = steps.index(e.reason)
        for f, frames in enumerate(e.frames):
            # trimmed: frames; filled gaps and dropped runs: blocks of consecutive frames
            # (the gaps and runs of one foot never touch each other)
            counts[k, f] += len(frames) if k == 0 else len(runs(e.mask(cleaned.n_frames)[:, f]))
    out: dict[str, Any] = {"frames_changed": int(cleaned.changed_since(since).sum())}
    for f in range(cleaned.n_feet):
        out[_FOOT_NAMES[f] if f < len(_FOOT_NAMES) else str(f)] = {
            "trimmed": int(counts[0, f]),
            "filled": int(counts[1, f]),
            "dropped": int(counts[2, f]),
        }
    return out


# ------------------------------------------------ the report's contacts.cleaning, read back
def _count(m: Mapping[str, Any], key: str, path: str) -> int:
    """``m[key]``, checked to be a count (names ``path.key`` when it is not)."""
    if key not in m:
        raise MetadataError(f"report field {path}.{key} is missing")
    v = m[key]
    if not isinstance(v, int) or isinstance(v, bool) or v < 0:
        raise MetadataError(f"report field {path}.{key} is malformed: {type(v).__name__} {v!r}")
    return v


@dataclass(frozen=True)
class FootCleaning:
    """What :func:`clean_contact_labels` changed on one foot (``contacts.cleaning.LF`` …).

    Attributes:
        trimmed: stance frames at a run's ends that became swing.
        filled: swing gaps that became stance.
        dropped: short stance runs that became swing.
    """

    trimmed: int
    filled: int
    dropped: int

    @classmethod
    def from_dict(cls, d: object, path: str) -> FootCleaning:
        """Read back from its JSON form (``path``: where it sits, for errors).

        Raises:
            MetadataError: a missing or malformed count (named).
        """
        if not isinstance(d, Mapping):
            raise MetadataError(f"report field {path} is malformed: {type(d).__name__}")
        return cls(*(_count(d, k, path) for k in ("trimmed", "filled", "dropped")))

    def items(self) -> tuple[tuple[str, int], ...]:
        """(step, count) in the report's order: ``trimmed``, ``filled``, ``dropped``."""
        return (("trimmed", self.trimmed), ("filled", self.filled), ("dropped", self.dropped))

    @property
    def changed(self) -> bool:
        """Whether any step changed this foot's labels."""
        return any(v for _, v in self.items())

    def to_dict(self) -> dict[str, int]:
        """The JSON form (as :func:`cleaning_summary` writes it)."""
        return dict(self.items())


@dataclass(frozen=True)
class CleaningRecord:
    """A refinement report's ``contacts.cleaning``, typed: the one reader of what
    :func:`cleaning_summary` wrote (the writer is unchanged).

    Attributes:
        frames_changed: labels that differ from those before the cleaning.
        feet: (foot name, what changed on it), in the report's order (``LF`` …).
    """

    frames_changed: int
    feet: tuple[tuple[str, FootCleaning], ...]

    @classmethod
    def from_dict(cls, d: object, path: str = "contacts.cleaning") -> CleaningRecord:
        """Read back from its JSON form.

        Raises:
            MetadataError: a missing or malformed field (named, e.g.
                ``contacts.cleaning.LF.trimmed``).
        """
        if not isinstance(d, Mapping):
            raise MetadataError(f"report field {path} is malformed: {type(d).__name__}")
        return cls(
            _count(d, "frames_changed", path),
            tuple(
                (str(k), FootCleaning.from_dict(v, f"{path}.{k}"))
                for k, v in d.items()
                if k != "frames_changed"
            ),
        )

    @classmethod
    def from_report(cls, report: Mapping[str, Any]) -> CleaningRecord | None:
        """The cleaning of a refinement's JSON report (:mod:`habitsim.refine.report`);
        None when the report has no ``contacts`` or the labels were not cleaned.

        Raises:
            MetadataError: ``contacts`` is no mapping, or a missing or malformed field of
                ``contacts.cleaning`` (named).
        """
        contacts = report.get("contacts")
        if contacts is None:
            return None
        if not isinstance(contacts, Mapping):
            raise MetadataError(f"report field contacts is malformed: {type(contacts).__name__}")
        cleaning = contacts.get("cleaning")
        return None if cleaning is None else cls.from_dict(cleaning)

    def to_dict(self) -> dict[str, Any]:
        """The JSON form, keys in their written order (as :func:`cleaning_summary`
        writes it)."""
        return {"frames_changed": self.frames_changed, **{k: f.to_dict() for k, f in self.feet}}
