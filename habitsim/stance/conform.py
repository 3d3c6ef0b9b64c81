"""Conforming a decoded motion: bounded by its source, labelled, levelled and planted.

:func:`conform` is the transfer's last step after the network
(:mod:`habitsim.models.transfer`): torch-free, it takes the decoded motion and its source
and returns the motion a later stage can use, with a typed :class:`ConformReport` of what
it did. Its knobs and switches are those of :class:`~habitsim.stance.policy.ConformPolicy`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..motion import Motion, resample_motion
from .bounds import bound_heading, bound_height, bound_speed
from .ladder import plant_decoded
from .level import level_trunk
from .policy import ConformPolicy, resolve_policy
from .report import ConformReport, PlantOutcome
from .schedule import transfer_contacts, walking_stance

__all__ = ["conform", "ConformReport"]


def conform(
    out: Motion,
    source: Motion,
    info: dict[str, Any] | None = None,
    plant: bool = False,
    policy: ConformPolicy | None = None,
) -> tuple[Motion, ConformReport]:
    """A decoded motion conformed to its source, and what was done.

    In order: the decoded motion is resampled frame for frame onto the source's rate;
    its speed, root height and heading are bounded by the source's
    (:mod:`habitsim.stance.bounds`); it gets its stance labels
    (:func:`~habitsim.stance.schedule.transfer_contacts`; without aerial phases at a
    speed the target walks, :func:`~habitsim.stance.schedule.walking_stance`); and, with
    ``plant``, its feet are planted on them by leg IK
    (:func:`~habitsim.stance.ladder.plant_decoded`: each stance run held at one foothold
    on the ground, swing lifted in between; a trunk whose fore and hind stance feet
    stand at different heights pitched level first,
    :func:`~habitsim.stance.level.level_trunk`), kept when the legs reach, with the
    ladder's fallbacks where they do not. When the kept planting steps on faster or
    trimmed stance runs, the labels returned are those.

    Args:
        out: the decoded motion (any frame rate; its ``contacts`` are the decoder's).
        source: the source motion it was decoded from.
        info: the transfer method's own ``metadata["transfer"]`` entries (method,
            species, seed, …), written first.
        plant: plant the feet on the labels.
        policy: the knobs and switches (None: the defaults).

    Returns:
        ``(motion, report)``: the conformed motion on ``out``'s species at the source's
        frame rate and frame count, with its stance labels, the source's ``action``,
        ``gait``, ``pair_key`` and ``seed`` metadata and ``metadata["transfer"]`` written
        from the report (:meth:`ConformReport.to_metadata`); and the typed
        :class:`ConformReport`.
    """
    policy = resolve_policy(policy)
    # frame for frame with the source (a round trip through the model's rate can add or
    # drop a frame at the end)
    out = resample_motion(out, source.fps, source.num_frames)
    out, speed = bound_speed(out, source, policy)
    out, height = bound_height(out, source, policy)
    out, heading = bound_heading(out, source, policy)
    labels, how = transfer_contacts(out, source, out.contacts, policy)
    labels, walking = walking_stance(out, labels, source, policy)
    if walking is not None:
        how = {**how, "walking_stance": walking}
    levelled = None
    planted: PlantOutcome | None = None
    if plant and labels.array.any():
        glob: np.ndarray | None = out.global_positions()
        if policy.level_trunk:
            out, levelled = level_trunk(out, labels.array, glob, policy)
            if levelled is not None:
                glob = None  # the body turned
        out, planted = plant_decoded(out, labels, glob, policy)
        if planted.relabelled:
            assert planted.planting.labels is not None  # a kept planting is solved
            labels = planted.planting.labels  # the labels the legs now step on
    report = ConformReport(how, speed, height, heading, levelled, planted, labels)
    meta = {k: v for k, v in source.metadata.items() if k in ("action", "gait", "pair_key", "seed")}
    meta["transfer"] = report.to_metadata(info or {})
    contacts = np.array(labels.array)
    return Motion(out.species, out.fps, out.root_positions, out.rotations, contacts, meta), report
