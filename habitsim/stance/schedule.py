"""The footfall schedule of a transferred motion: its stance labels and where they came from.

:func:`transfer_contacts` picks the labels of a transfer (the decoder's own, checked
against the source's footfalls; the source's; detected; by duty factor);
:func:`walking_stance` takes the aerial phases and single-foot supports out of a transfer
to a species that walks at its speed.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import HabitsimError
from ..motion import Motion
from ..species import FEET, load_species

__all__ = [
    "MIN_SOURCE_AGREEMENT",
    "MAX_DUTY_GAP",
    "WALK_MIN_DUTY",
    "WALK_MIN_FEET",
    "transfer_contacts",
    "walking_stance",
]


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


#: A decoded foot whose stance labels match the source's footfall schedule with an F1
#: below this takes the source's schedule instead (the action's footfalls survive).
#: The F1 alone lets a foot that is labelled in stance almost all the time through
#: (stance share 0.9 against the source's 0.4 still scores 0.6), hence also
#: :data:`MAX_DUTY_GAP`. Measured with the feature version 3 model: median decoded F1
#: 0.83 on synthetic test transfers, 0.70 on transfers of real dog clips.
MIN_SOURCE_AGREEMENT = 0.8

#: ... and a decoded foot whose stance share differs from the source's by more than this
#: takes the source's schedule too. On a real trot sent to the tiger the decoded feet
#: stood 82–91 % of the time against the source's 38–42 %; planted, that clip fell after
#: 0.3 s, with the source's schedule it was tracked to the end.
MAX_DUTY_GAP = 0.1


def transfer_contacts(
    out: Motion, source: Motion, decoded: np.ndarray | None = None
) -> tuple[np.ndarray, dict[str, Any]]:
    """Foot-contact labels of a transferred motion, and how they were found.

    In this order:

    1. ``decoded``: the network's own contact outputs (feature version 3), cleaned of
       runs shorter than 2 frames (:func:`habitsim.contacts.drop_short_runs`). When the
       source carries stance labels they are checked against its footfall schedule
       (carried over in normalised time, :func:`habitsim.contacts.warp_contacts`): the
       per-foot F1 and stance shares go into the report, and a foot that agrees less
       than :data:`MIN_SOURCE_AGREEMENT` or whose stance share is more than
       :data:`MAX_DUTY_GAP` from the source's takes the source's schedule.
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

    Returns:
        ``(labels, info)``: (T, 4) bool labels of ``out`` and ``info["method"]`` (one of
        ``decoded``, ``source``, ``detected``, ``duty``) with the details of that method.
    """
    from ..contacts import contacts_by_duty, contacts_from_feet, drop_short_runs, warp_contacts
    from .planting import contact_f1

    src = None
    if source.contacts is not None:
        src = drop_short_runs(warp_contacts(np.asarray(source.contacts, bool), out.num_frames), 2)
    if decoded is not None:
        labels = drop_short_runs(np.asarray(decoded, dtype=bool), 2)
        info: dict[str, Any] = {"method": "decoded"}
        if src is not None:
            f1 = contact_f1(labels, src)
            duty, duty_src = labels.mean(axis=0), src.mean(axis=0)
            info["source_f1"] = [round(float(v), 3) for v in f1]
            info["duty"] = [round(float(v), 3) for v in duty]
            info["source_duty"] = [round(float(v), 3) for v in duty_src]
            low = (f1 < MIN_SOURCE_AGREEMENT) | (np.abs(duty - duty_src) > MAX_DUTY_GAP)
            if low.any():
                labels[:, low] = src[:, low]
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
    detected = labels if decoded is not None else contacts_from_feet(feet, out.fps, leg)
    why = "the source has no stance labels"
    info = {"method": "decoded" if decoded is not None else "detected", "reason": why}
    gd = _gait_duty(out.species, source)
    if gd is None or out.num_frames < 5:
        return detected, info
    gait, duty = gd
    low = detected.mean(axis=0) < 0.5 * duty
    if not low.any():
        return detected, info
    by_duty = contacts_by_duty(feet, out.fps, leg, duty)
    labels = np.where(low[None, :], by_duty, detected)
    info = {
        "method": "duty",
        "reason": why,
        "gait": gait,
        "duty_factor": round(duty, 3),
        "feet_by_duty": [n for n, lo in zip(FEET, low, strict=True) if lo],
    }
    return labels, info


#: A gait whose duty factor is below one half has an aerial phase (BIOMECH.md, footfall
#: table); a target species that walks at the transfer's speed has none, so a transfer
#: below the top of the target's walking Froude band has every foot in stance at least
#: this share of the clip (:func:`walking_stance`). Measured with ``habitsim bench real``:
#: a real Labrador's fast lateral-sequence walk (duty factor 0.31–0.50, Froude 0.28–0.54)
#: sent to the cat kept its single-foot frames, which need a residual root force of
#: 0.28 m·g against 0.09 with two feet down (README, "Real motion").
WALK_MIN_DUTY = 0.5
#: ... and at least this many feet down on every frame (:func:`habitsim.contacts.
#: fill_support`; 0 switches it off): a duty factor of one half with the uneven footfall
#: spacing of a real walk, or a clip that speeds up at its end, still left single-foot
#: supports (a cat transfer of a Labrador walk that speeds up stood on one foot for the
#: last 0.3 s and fell there). With it the habit references of ``habitsim bench real``
#: need a median residual root force of 0.078 m·g instead of 0.108 (the cat's three
#: walking windows 0.07–0.08 instead of 0.10–0.12).
WALK_MIN_FEET = 2


def walking_stance(
    out: Motion, contacts: np.ndarray, source: Motion
) -> tuple[np.ndarray, dict[str, Any] | None]:
    """The stance labels of a transfer to a species that walks at the transfer's speed.

    When the transferred motion moves at a Froude number within the target's walking
    band (at most the top of ``gaits.walk.froude`` in its species file), every foot
    standing less than :data:`WALK_MIN_DUTY` of the clip has its stance runs lengthened
    at both ends (:func:`habitsim.contacts.lengthen_stance`), then every frame with
    fewer than :data:`WALK_MIN_FEET` feet down takes the stance run nearest in time
    (:func:`habitsim.contacts.fill_support`): the source's footfall phases stay, the
    aerial phases and single-foot supports of a faster source go. Kept
    as they are: labels of a gait that is not cyclic (a foot with fewer than two
    touchdowns: a jump, a stand), of a source whose action the target performs in
    another gait than its walk, and of a target species without a walk.

    Returns:
        ``(labels, info)``: the labels (the input when nothing changed) and None, or the
        lengthened labels with what was done (``froude``, ``walk_froude_max``,
        ``duty_before``, ``duty_after``).
    """
    from ..contacts import fill_support, lengthen_stance, touchdown_frames
    from ..gait_stats import gait_statistics
    from ..gaits import action_gait
    from ..gaits.actions import ACTIONS

    walk = load_species(out.species).gaits.get("walk")
    c = np.asarray(contacts, dtype=bool)
    if walk is None or c.ndim != 2:
        return c, None
    duty = c.mean(axis=0)
    if duty.min() >= WALK_MIN_DUTY:
        return c, None
    action = source.metadata.get("action")
    if action in ACTIONS:
        try:
            if action_gait(out.species, str(action)) != "walk":
                return c, None
        except HabitsimError:  # an action the target lacks
            return c, None
    if any(td.size < 2 for td in touchdown_frames(c)):
        return c, None
    froude = gait_statistics(out, c).froude
    if not froude <= walk.froude[1]:
        return c, None
    longer = lengthen_stance(c, WALK_MIN_DUTY)
    if WALK_MIN_FEET:
        longer = fill_support(longer, WALK_MIN_FEET)
    return longer, {
        "froude": round(float(froude), 3),
        "walk_froude_max": float(walk.froude[1]),
        "duty_before": [round(float(v), 3) for v in duty],
        "duty_after": [round(float(v), 3) for v in longer.mean(axis=0)],
    }
