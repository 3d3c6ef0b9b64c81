"""Stance labels: which feet are on the ground when, where the labels came from, and
every edit made to them; and the one run algebra over such labels.

A clip's stance labels are a ``(T, F)`` bool array, ``True`` where foot ``f`` is in stance
at frame ``t`` (habitsim's four feet in the order LF, RF, LH, RH). :class:`StanceLabels`
holds a read-only copy of the array with its :class:`StanceSource` and the record of the
edits made to it (:class:`StanceEdit`: which stage changed which frames of which foot,
and why, as an :class:`EditReason` code). An edit returns new labels
(:meth:`StanceLabels.edited`); nothing changes labels in place.

The run algebra works on plain arrays, so it serves labels and any other per-frame flags
(a swing mask, a hysteresis band), and :class:`StanceLabels` offers it as methods:

* :func:`runs`: the ``[start, stop)`` runs of ``True`` in a 1-D array;
* :func:`stance_runs` / :func:`swing_gaps`: those runs per foot of stance / of swing;
* :func:`runs_holding`: the runs of one mask that hold a frame of another;
* :func:`swing_bounds`: per swing frame, the lift-off and touch-down frames of its swing;
* :func:`duty_factors`: each foot's stance share;
* :func:`stance_f1` (per foot) and :func:`pooled_stance_f1` (all feet and frames): the
  F1 score of labels against reference labels.

Run convention: a run is ``(start, stop)`` with ``stop`` exclusive (Python's slice
convention), so ``flags[start:stop]`` is the run and ``stop - start`` its length in
frames; a run touching the clip's first frame has ``start = 0``, one touching its last
has ``stop = T``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum

import numpy as np

from ..errors import InvalidMotionError

__all__ = [
    "StanceSource",
    "EditReason",
    "StanceEdit",
    "StanceLabels",
    "as_labels",
    "runs",
    "stance_runs",
    "swing_gaps",
    "runs_holding",
    "swing_bounds",
    "duty_factors",
    "stance_f1",
    "pooled_stance_f1",
]

Run = tuple[int, int]


class StanceSource(StrEnum):
    """Where a clip's stance labels came from (the value is the code written to reports)."""

    #: Passed explicitly by the caller of a stage.
    GIVEN = "given"
    #: The motion's own labels (``Motion.contacts``) as the stage received them.
    INPUT = "input"
    #: Detected from the toes' height and speed (:func:`habitsim.contacts.contacts_from_feet`).
    DETECTED = "detected"
    #: The slowest and lowest share of frames of each foot, its gait's duty factor
    #: (:func:`habitsim.contacts.contacts_by_duty`).
    DUTY = "duty"
    #: The contact outputs of a transfer network.
    DECODED = "decoded"
    #: The source clip's footfall schedule carried over to a transfer's output.
    SOURCE = "source"
    #: Found on the source skeleton's foot paths when a motion-capture file was imported
    #: (:func:`habitsim.stance.planting.label_source_stance`).
    IMPORTED = "imported"
    #: The walking schedule of a transfer to a species that walks at the clip's speed.
    WALKING = "walking"
    #: The planned stance of a synthetic gait (:mod:`habitsim.gaits`).
    PLANNED = "planned"
    #: The foot contacts of a physics simulation.
    SIMULATED = "simulated"
    #: Returned by a transfer method that does not say how it found them.
    METHOD = "method"


class EditReason(StrEnum):
    """Why an edit changed stance labels (the value is the code written to reports)."""

    #: Stance frames at an end of a run where the toe lies too far from where the run
    #: rests became swing (refinement's label cleaning, step 1).
    SLIP_TRIM = "slip_trim"
    #: A short swing gap between two stance runs resting at one place became stance (the
    #: foot did not step; refinement's label cleaning, step 2).
    GAP_FILL = "gap_fill"
    #: A stance run too short to be a step became swing (refinement's label cleaning,
    #: step 3).
    BLIP_DROP = "blip_drop"
    #: Stance and swing runs shorter than two frames dropped from decoded or warped
    #: labels (:func:`habitsim.contacts.drop_short_runs`, the footfall schedule).
    SHORT_RUN_DROP = "short_run_drop"
    #: A decoded foot that disagrees with the source's footfalls took the source's
    #: schedule (the footfall schedule).
    SOURCE_FOOT = "source_foot"
    #: A foot whose detected stance share is under half its gait's duty factor took the
    #: duty-factor labels (:func:`habitsim.contacts.contacts_by_duty`, the footfall
    #: schedule).
    DUTY_FOOT = "duty_foot"
    #: Stance runs lengthened at both ends to the walking duty factor
    #: (:func:`habitsim.contacts.lengthen_stance`, the walking stance).
    WALK_LENGTHEN = "walk_lengthen"
    #: Frames with too few feet down given the nearest stance run
    #: (:func:`habitsim.contacts.fill_support`, the walking stance).
    WALK_SUPPORT = "walk_support"
    #: The labels played faster so the legs sweep what the body travels (the planting
    #: ladder's restep).
    RESTEP = "restep"
    #: Out-of-reach stance runs shortened at both ends to the legs' reach (the planting
    #: ladder's trim).
    TRIM = "trim"
    #: An in-place clip's foot whose stance share on its recovered path is well under
    #: its share of backward sweeps took its sweeps as stance (a keyframed foot that
    #: rolls and lifts within its stance; :mod:`habitsim.bvh_mapping.inplace`).
    IN_PLACE_SWEEP = "in_place_sweep"
    #: Stance frames at an end of such a swept foot's run where the target's planted toe
    #: stays above its foothold (the sweep is longer than the leg reaches planted) became
    #: swing (:func:`habitsim.bvh_mapping.inplace.trim_unreached`).
    IN_PLACE_REACH = "in_place_reach"


@dataclass(frozen=True)
class StanceEdit:
    """One recorded edit of stance labels.

    Attributes:
        by: the stage or function that made the edit (e.g. ``"refine.clean_contact_labels"``).
        reason: why.
        frames: per foot (F entries), the ascending frames whose label the edit flipped.
    """

    by: str
    reason: EditReason
    frames: tuple[tuple[int, ...], ...]

    def mask(self, n_frames: int) -> np.ndarray:
        """(T, F) bool: ``True`` at the frames this edit flipped.

        Args:
            n_frames: T, the number of frames of the labels edited.
        """
        out = np.zeros((n_frames, len(self.frames)), dtype=bool)
        for f, frames in enumerate(self.frames):
            out[list(frames), f] = True
        return out

    @property
    def n_changed(self) -> int:
        """Number of (frame, foot) labels the edit flipped."""
        return sum(len(frames) for frames in self.frames)


def _checked(contacts: object, what: str = "contacts") -> np.ndarray:
    """``contacts`` as a (T, F) bool array (a view when it already is one).

    Raises:
        InvalidMotionError: not two-dimensional, or values other than booleans and 0/1.
    """
    c = np.asarray(contacts)
    if c.ndim != 2:
        raise InvalidMotionError(f"{what} must have shape (T, F), got {c.shape}")
    if c.dtype != bool:
        if not np.issubdtype(c.dtype, np.number) or not np.all(np.isin(c, (0, 1))):
            raise InvalidMotionError(f"{what} must be booleans (or 0/1)")
        c = c.astype(bool)
    return c


@dataclass(frozen=True, eq=False)
class StanceLabels:
    """A clip's stance labels, where they came from and the edits made to them.

    Two labels are equal when their arrays, sources and edit records are equal; labels
    are not hashable (they hold an array).

    Attributes:
        array: (T, F) bool stance flags, a read-only copy of the array given.
        source: where the labels came from (a :class:`StanceSource` or its code).
        edits: the edits made since, oldest first.

    Raises:
        InvalidMotionError: ``array`` is not (T, F) booleans (or 0/1), an edit names
            another number of feet, or ``source`` is not a known code.
    """

    array: np.ndarray
    source: StanceSource
    edits: tuple[StanceEdit, ...] = field(default=())

    def __post_init__(self) -> None:
        c = np.array(_checked(self.array), dtype=bool)  # always a copy
        c.setflags(write=False)
        try:
            source = StanceSource(self.source)
        except ValueError:
            known = ", ".join(s.value for s in StanceSource)
            raise InvalidMotionError(
                f"unknown stance source {self.source!r}; known: {known}"
            ) from None
        edits = tuple(self.edits)
        for e in edits:
            if len(e.frames) != c.shape[1]:
                raise InvalidMotionError(
                    f"an edit by {e.by} names {len(e.frames)} feet, the labels have {c.shape[1]}"
                )
        object.__setattr__(self, "array", c)
        object.__setattr__(self, "source", source)
        object.__setattr__(self, "edits", edits)

    def __array__(self, dtype: object = None, copy: object = None) -> np.ndarray:
        """The (T, F) labels as a numpy array (``np.asarray(labels)``; read-only unless a
        dtype conversion copies it)."""
        return self.array if dtype is None else self.array.astype(dtype)  # type: ignore[call-overload]

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, StanceLabels):
            return NotImplemented
        return (
            self.source == other.source
            and self.edits == other.edits
            and self.array.shape == other.array.shape
            and bool(np.array_equal(self.array, other.array))
        )

    __hash__ = None  # type: ignore[assignment]

    @property
    def n_frames(self) -> int:
        """T, the number of frames."""
        return int(self.array.shape[0])

    @property
    def n_feet(self) -> int:
        """F, the number of feet."""
        return int(self.array.shape[1])

    def edited(self, new: np.ndarray, *, by: str, reason: EditReason) -> StanceLabels:
        """These labels changed to ``new``, with the edit recorded.

        Args:
            new: (T, F) bool, the labels after the edit.
            by: the stage or function making the edit.
            reason: why.

        Returns:
            New labels holding ``new`` and one more edit record naming the frames that
            changed; these labels themselves when nothing changed (no record is made).

        Raises:
            InvalidMotionError: ``new`` has another shape or is not booleans (or 0/1), or
                ``reason`` is not a known code.
        """
        try:
            code = EditReason(reason)
        except ValueError:
            known = ", ".join(r.value for r in EditReason)
            raise InvalidMotionError(f"unknown edit reason {reason!r}; known: {known}") from None
        c = _checked(new, "edited labels")
        if c.shape != self.array.shape:
            raise InvalidMotionError(
                f"edited labels must keep the shape {self.array.shape}, got {c.shape}"
            )
        flipped = c != self.array
        if not flipped.any():
            return self
        frames = tuple(tuple(np.flatnonzero(flipped[:, f]).tolist()) for f in range(c.shape[1]))
        edit = StanceEdit(by=str(by), reason=code, frames=frames)
        return StanceLabels(c, self.source, (*self.edits, edit))

    def changed_since(self, n_edits: int = 0) -> np.ndarray:
        """(T, F) bool: the labels that differ from what they were before edit ``n_edits``.

        A frame flipped by one edit and flipped back by a later one is unchanged.

        Args:
            n_edits: the number of edits that had been made at the point of comparison
                (0: the labels as they came from their source).
        """
        out = np.zeros(self.array.shape, dtype=bool)
        for e in self.edits[int(n_edits) :]:
            out ^= e.mask(self.n_frames)
        return out

    def runs(self) -> list[list[Run]]:
        """The stance runs of each foot (:func:`stance_runs`)."""
        return stance_runs(self.array)

    def gaps(self) -> list[list[Run]]:
        """The swing gaps of each foot (:func:`swing_gaps`)."""
        return swing_gaps(self.array)

    def duty_factors(self) -> np.ndarray:
        """(F,) each foot's stance share (:func:`duty_factors`)."""
        return duty_factors(self.array)

    def f1(self, reference: StanceLabels | np.ndarray) -> np.ndarray:
        """(F,) per-foot F1 of these labels against ``reference`` (:func:`stance_f1`)."""
        ref = reference.array if isinstance(reference, StanceLabels) else reference
        return stance_f1(self.array, ref)


def as_labels(
    contacts: StanceLabels | np.ndarray, source: StanceSource = StanceSource.GIVEN
) -> StanceLabels:
    """``contacts`` as :class:`StanceLabels`: labels as they are, a (T, F) array wrapped
    with ``source`` (the boundary where a stage takes a caller's plain array).

    Raises:
        InvalidMotionError: an array that is not (T, F) booleans (or 0/1).
    """
    if isinstance(contacts, StanceLabels):
        return contacts
    return StanceLabels(np.asarray(contacts), source)


# ------------------------------------------------------------------------ run algebra
def runs(flags: np.ndarray) -> list[Run]:
    """The runs of ``True`` in a 1-D array, in time order.

    Args:
        flags: (T,) bool (or 0/1) flags.

    Returns:
        ``(start, stop)`` frame ranges, ``stop`` exclusive.

    Raises:
        InvalidMotionError: ``flags`` is not one-dimensional.
    """
    f = np.asarray(flags, dtype=bool)
    if f.ndim != 1:
        raise InvalidMotionError(f"flags must have shape (T,), got {f.shape}")
    padded = np.concatenate([[False], f, [False]])
    edges = np.flatnonzero(padded[1:] != padded[:-1])
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2], strict=True)]


def stance_runs(contacts: np.ndarray) -> list[list[Run]]:
    """The stance runs of each foot.

    Args:
        contacts: (T, F) bool stance flags.

    Returns:
        For each of the F feet, its ``(start, stop)`` stance runs (``stop`` exclusive) in
        time order; an empty list for a foot that never stands.

    Raises:
        InvalidMotionError: ``contacts`` is not two-dimensional.
    """
    c = np.asarray(contacts, dtype=bool)
    if c.ndim != 2:
        raise InvalidMotionError(f"contacts must have shape (T, F), got {c.shape}")
    return [runs(c[:, f]) for f in range(c.shape[1])]


def swing_gaps(contacts: np.ndarray) -> list[list[Run]]:
    """The swing gaps of each foot: the runs of frames it is not in stance.

    A gap with ``start > 0`` and ``stop < T`` lies between two stance runs; one touching
    the clip's start or end does not (the foot's stance before or after is unknown).

    Args:
        contacts: (T, F) bool stance flags.

    Returns:
        For each of the F feet, its ``(start, stop)`` swing gaps (``stop`` exclusive) in
        time order; ``[(0, T)]`` for a foot that never stands.

    Raises:
        InvalidMotionError: ``contacts`` is not two-dimensional.
    """
    c = np.asarray(contacts, dtype=bool)
    if c.ndim != 2:
        raise InvalidMotionError(f"contacts must have shape (T, F), got {c.shape}")
    return stance_runs(~c)


def runs_holding(flags: np.ndarray, seed: np.ndarray) -> np.ndarray:
    """The runs of ``flags`` (per foot, along axis 0) that hold at least one ``seed`` frame.

    Args:
        flags: (T, F) bool flags.
        seed: (T, F) bool flags; a ``seed`` frame outside ``flags`` seeds nothing.

    Returns:
        (T, F) bool: ``flags`` without its runs that hold no ``seed`` frame.

    Raises:
        InvalidMotionError: the arrays are not (T, F) of one shape.
    """
    loose = np.asarray(flags, dtype=bool)
    strict = np.asarray(seed, dtype=bool)
    if loose.ndim != 2 or strict.shape != loose.shape:
        raise InvalidMotionError(
            f"flags and seed must have one shape (T, F), got {loose.shape}, {strict.shape}"
        )
    t, f = loose.shape
    pad = np.zeros((1, f), dtype=bool)
    lp = np.concatenate([pad, loose, pad], axis=0)
    starts = lp[1:] & ~lp[:-1]  # (T+1, F): True at the first frame of a run
    run_id = np.cumsum(starts, axis=0)[:-1]  # (T, F) id of the run a frame belongs to
    run_id = np.where(loose, run_id, 0)
    # a run is seeded if it holds a seed frame: per foot, mark the seeded ids
    n_ids = int(run_id.max()) + 1 if run_id.size else 1
    seeded = np.zeros((n_ids, f), dtype=bool)
    cols = np.broadcast_to(np.arange(f), (t, f))
    sel = strict & loose
    seeded[run_id[sel], cols[sel]] = True
    seeded[0] = False
    return seeded[run_id, cols]


def swing_bounds(contacts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per swing frame, the frames its swing lifted off and touches down.

    Args:
        contacts: (T, F) bool stance flags.

    Returns:
        ``(liftoff, touchdown)``, each (T, F) int: for a frame in the swing gap
        ``(start, stop)`` of a foot, ``start`` and ``stop`` (the first stance frame after
        it, or T when the foot is still in swing at the clip's end; a swing at the clip's
        start lifted off at 0); -1 in stance frames.

    Raises:
        InvalidMotionError: ``contacts`` is not two-dimensional.
    """
    c = np.asarray(contacts, dtype=bool)
    if c.ndim != 2:
        raise InvalidMotionError(f"contacts must have shape (T, F), got {c.shape}")
    liftoff = np.full(c.shape, -1, dtype=int)
    touchdown = np.full(c.shape, -1, dtype=int)
    for f, gaps in enumerate(swing_gaps(c)):
        for a, b in gaps:
            liftoff[a:b, f] = a
            touchdown[a:b, f] = b
    return liftoff, touchdown


def duty_factors(contacts: np.ndarray) -> np.ndarray:
    """(F,) each foot's stance share over the clip (its duty factor), in [0, 1].

    Args:
        contacts: (T, F) bool stance flags, T ≥ 1.

    Raises:
        InvalidMotionError: ``contacts`` is not two-dimensional with T ≥ 1.
    """
    c = np.asarray(contacts, dtype=bool)
    if c.ndim != 2 or c.shape[0] < 1:
        raise InvalidMotionError(f"contacts must have shape (T, F) with T >= 1, got {c.shape}")
    return c.mean(axis=0)


def stance_f1(pred: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """(F,) F1 score per foot of stance flags against reference flags.

    F1 = 2·TP / (2·TP + FP + FN) over the frames of the foot. A foot with no stance in
    either array scores 1 (they agree); one with stance in only one of them scores 0.

    Args:
        pred: (T, F) bool stance flags.
        ref: (T, F) bool reference stance flags.

    Raises:
        InvalidMotionError: the arrays are not (T, F) of one shape.
    """
    p = np.asarray(pred, dtype=bool)
    r = np.asarray(ref, dtype=bool)
    if p.shape != r.shape or p.ndim != 2:
        raise InvalidMotionError(f"contact arrays must match as (T, F), got {p.shape}, {r.shape}")
    tp = (p & r).sum(axis=0)
    den = p.sum(axis=0) + r.sum(axis=0)  # 2·TP + FP + FN
    return np.where(den > 0, 2.0 * tp / np.maximum(den, 1), 1.0)


def pooled_stance_f1(pred: np.ndarray, ref: np.ndarray) -> float:
    """F1 score of stance flags against reference flags, all feet and frames pooled.

    F1 = 2·TP / (2·TP + FP + FN) with the counts summed over every (frame, foot); 1.0
    when neither array has a stance frame (also for empty arrays).

    Args:
        pred: (T, F) bool stance flags.
        ref: reference stance flags of the same shape.

    Raises:
        InvalidMotionError: the shapes differ.
    """
    p = np.asarray(pred, dtype=bool)
    r = np.asarray(ref, dtype=bool)
    if p.shape != r.shape:
        raise InvalidMotionError(f"contacts shapes differ: {p.shape} vs {r.shape}")
    tp = np.sum(p & r)
    fp = np.sum(p & ~r)
    fn = np.sum(~p & r)
    if tp + fp + fn == 0:
        return 1.0
    return float(2 * tp / (2 * tp + fp + fn))
