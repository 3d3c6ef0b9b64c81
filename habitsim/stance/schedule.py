"""The footfall schedule of a transferred motion: its stance labels and where they came from.

:func:`transfer_contacts` picks the labels of a transfer (the decoder's own, checked
against the source's footfalls; the source's; detected; by duty factor);
:func:`walking_stance` takes the aerial phases and single-foot supports out of a transfer
to a species that walks at its speed.
"""

from __future__ import annotations

from enum import StrEnum
from typing import Any

import numpy as np

from ..errors import HabitsimError
from ..motion import Motion
from ..species import FEET, load_species
from .labels import EditReason, StanceLabels, StanceSource, as_labels
from .policy import ConformPolicy, resolve_policy

__all__ = ["transfer_contacts", "walking_stance", "ScheduleReason"]


class ScheduleReason(StrEnum):
    """Why :func:`transfer_contacts` labelled a transfer the way it did, as a typed code:
    its ``info["reason"]`` is :attr:`text` (read back by
    :attr:`habitsim.stance.report.ScheduleRecord.reason_code`)."""

    #: the source has no stance labels: the labels are the decoder's unchecked, detected
    #: or by duty factor
    NO_SOURCE_LABELS = "no_source_labels"

    @property
    def text(self) -> str:
        """The reason in words, as written to ``metadata["transfer"]["contacts"]``."""
        return _REASON_TEXT[self]


_REASON_TEXT = {ScheduleReason.NO_SOURCE_LABELS: "the source has no stance labels"}


def _gait_duty(target: str, source: Motion) -> tuple[str, float] | None:
    """(gait, duty factor) the target species uses for the source's action: the middle of
    the target's duty-factor range for that gait (the source species' range when the
    target lacks the gait, e.g. a trot sent to a camel); None for non-cyclic actions or
    a source without a known action."""
    from ..gaits import action_gait
    from ..gaits.actions import ACTIONS

    action = source.metadata.get("action")
    if action not in ACTIONS:
        return None
    for sp in (target, source.species):
        try:
            gait = action_gait(sp, str(action))
        except HabitsimError:
            continue
        habit = load_species(sp).gaits.get(gait)
        if habit is not None:
            return gait, float(np.mean(habit.duty_factor))
    return None


def transfer_contacts(
    out: Motion,
    source: Motion,
    decoded: StanceLabels | np.ndarray | None = None,
    policy: ConformPolicy | None = None,
) -> tuple[StanceLabels, dict[str, Any]]:
    """Foot-contact labels of a transferred motion, and how they were found.

    In this order:

    1. ``decoded``: the network's own contact outputs (feature version 3), cleaned of
       runs shorter than 2 frames (:func:`habitsim.contacts.drop_short_runs`). When the
       source carries stance labels they are checked against its footfall schedule
       (carried over in normalised time, :func:`habitsim.contacts.warp_contacts`): the
       per-foot F1 and stance shares go into the report, and a foot that agrees less
       than ``policy.min_source_agreement`` or whose stance share is more
       than ``policy.max_duty_gap`` from the source's takes the source's
       schedule (``policy``: the default :class:`ConformPolicy` when None).
    2. ``source``: no decoded contacts (``direct``), and the source carries stance labels
       (a synthetic clip's planned stance, an import's labels found on the source
       skeleton): the transferred motion keeps the source's footfall schedule.
    3. ``detected``: neither: contacts detected on the output's resting feet
       (:func:`habitsim.contacts.detect_contacts`).
    4. ``duty``: a gait whose stance feet still slide may hold no resting frame at all,
       and a refinement given no stance plants no foot; so a foot whose detected stance
       share is under half its gait's duty factor is labelled by
       :func:`habitsim.contacts.contacts_by_duty` instead (the target's duty factor for
       the source's gait) — the last resort, reported.

    Args:
        out: the transferred motion (T frames).
        source: the source motion (its ``contacts``: the source's labels, any length).
        decoded: (T, 4) the network's contact outputs (an array is taken as
            :attr:`StanceSource.DECODED` labels); None for a method without them.
        policy: the knobs (None: the defaults).

    Returns:
        ``(labels, info)``: ``out``'s (T, 4) :class:`StanceLabels`, their source
        ``decoded``, ``source`` (the source's schedule warped to T frames) or
        ``detected`` and each change recorded (:attr:`EditReason.SHORT_RUN_DROP`,
        :attr:`EditReason.SOURCE_FOOT`, :attr:`EditReason.DUTY_FOOT`); and ``info``, the
        JSON-ready ``metadata["transfer"]["contacts"]`` record (read back by
        :class:`habitsim.stance.report.ScheduleRecord`): ``info["method"]`` (one of
        ``decoded``, ``source``, ``detected``, ``duty``) with the details of that method.
    """
    from ..contacts import contacts_by_duty, contacts_from_feet, drop_short_runs, warp_contacts
    from .labels import stance_f1

    by = "stance.schedule.transfer_contacts"
    policy = resolve_policy(policy)
    src: StanceLabels | None = None
    if source.contacts is not None:
        warped = warp_contacts(np.asarray(source.contacts, bool), out.num_frames)
        src = StanceLabels(warped, StanceSource.SOURCE)
        src = src.edited(drop_short_runs(warped, 2), by=by, reason=EditReason.SHORT_RUN_DROP)
    if decoded is not None:
        raw = as_labels(decoded, StanceSource.DECODED)
        labels = raw.edited(
            drop_short_runs(np.array(raw.array, dtype=bool), 2),
            by=by,
            reason=EditReason.SHORT_RUN_DROP,
        )
        info: dict[str, Any] = {"method": "decoded"}
        if src is not None:
            f1 = stance_f1(labels.array, src.array)
            duty, duty_src = labels.array.mean(axis=0), src.array.mean(axis=0)
            info["source_f1"] = [round(float(v), 3) for v in f1]
            info["duty"] = [round(float(v), 3) for v in duty]
            info["source_duty"] = [round(float(v), 3) for v in duty_src]
            low = (f1 < policy.min_source_agreement) | (
                np.abs(duty - duty_src) > policy.max_duty_gap
            )
            if low.any():
                mixed = np.where(low[None, :], src.array, labels.array)
                labels = labels.edited(mixed, by=by, reason=EditReason.SOURCE_FOOT)
                info["feet_from_source"] = [n for n, lo in zip(FEET, low, strict=True) if lo]
            return labels, info
    elif src is not None:
        info = {
            "method": "source",
            "source_frames": int(np.asarray(source.contacts).shape[0]),
            "time_warped": bool(np.asarray(source.contacts).shape[0] != out.num_frames),
        }
        return src, info
    feet = out.foot_positions()  # one forward-kinematics pass for both labellings
    leg = out.species_info.leg_length
    detected = (
        labels
        if decoded is not None
        else StanceLabels(contacts_from_feet(feet, out.fps, leg), StanceSource.DETECTED)
    )
    why = ScheduleReason.NO_SOURCE_LABELS.text
    info = {"method": "decoded" if decoded is not None else "detected", "reason": why}
    gd = _gait_duty(out.species, source)
    if gd is None or out.num_frames < 5:
        return detected, info
    gait, duty = gd
    low = detected.array.mean(axis=0) < 0.5 * duty
    if not low.any():
        return detected, info
    by_duty = contacts_by_duty(feet, out.fps, leg, duty)
    labels = detected.edited(
        np.where(low[None, :], by_duty, detected.array), by=by, reason=EditReason.DUTY_FOOT
    )
    info = {
        "method": "duty",
        "reason": why,
        "gait": gait,
        "duty_factor": round(duty, 3),
        "feet_by_duty": [n for n, lo in zip(FEET, low, strict=True) if lo],
    }
    return labels, info


def walking_stance(
    out: Motion,
    contacts: StanceLabels | np.ndarray,
    source: Motion,
    policy: ConformPolicy | None = None,
) -> tuple[StanceLabels, dict[str, Any] | None]:
    """The stance labels of a transfer to a species that walks at the transfer's speed.

    When the transferred motion moves at a Froude number within the target's walking
    band (at most the top of ``gaits.walk.froude`` in its species file), every foot
    standing less than ``policy.walk_min_duty`` of the clip has its stance runs lengthened
    at both ends (:func:`habitsim.contacts.lengthen_stance`), then every frame with
    fewer than ``policy.walk_min_feet`` feet down takes the stance run nearest in time
    (:func:`habitsim.contacts.fill_support`): the source's footfall phases stay, the
    aerial phases and single-foot supports of a faster source go. Kept
    as they are: labels of a gait that is not cyclic (a foot with fewer than two
    touchdowns: a jump, a stand), of a source whose action the target performs in
    another gait than its walk, and of a target species without a walk.

    Args:
        out: the transferred motion (T frames).
        contacts: its (T, 4) stance labels (an array is taken as
            :attr:`StanceSource.GIVEN` labels).
        source: the source motion (its ``action`` metadata).
        policy: the knobs (None: the defaults).

    Returns:
        ``(labels, info)``: the labels (the input when nothing changed) and None, or the
        lengthened labels, the frames added recorded as :attr:`EditReason.WALK_LENGTHEN`
        and :attr:`EditReason.WALK_SUPPORT` edits, with what was done (``froude``,
        ``walk_froude_max``, ``duty_before``, ``duty_after``).
    """
    from ..contacts import fill_support, lengthen_stance, touchdown_frames
    from ..gait_stats import gait_statistics
    from ..gaits import action_gait
    from ..gaits.actions import ACTIONS

    by = "stance.schedule.walking_stance"
    policy = resolve_policy(policy)
    labels = as_labels(contacts)
    walk = load_species(out.species).gaits.get("walk")
    c = labels.array
    if walk is None:
        return labels, None
    duty = c.mean(axis=0)
    if duty.min() >= policy.walk_min_duty:
        return labels, None
    action = source.metadata.get("action")
    if action in ACTIONS:
        try:
            if action_gait(out.species, str(action)) != "walk":
                return labels, None
        except HabitsimError:  # an action the target lacks
            return labels, None
    if any(td.size < 2 for td in touchdown_frames(c)):
        return labels, None
    froude = gait_statistics(out, c).froude
    if not froude <= walk.froude[1]:
        return labels, None
    longer = lengthen_stance(c, policy.walk_min_duty)
    labels = labels.edited(longer, by=by, reason=EditReason.WALK_LENGTHEN)
    if policy.walk_min_feet:
        longer = fill_support(longer, policy.walk_min_feet)
        labels = labels.edited(longer, by=by, reason=EditReason.WALK_SUPPORT)
    return labels, {
        "froude": round(float(froude), 3),
        "walk_froude_max": float(walk.froude[1]),
        "duty_before": [round(float(v), 3) for v in duty],
        "duty_after": [round(float(v), 3) for v in longer.mean(axis=0)],
    }
