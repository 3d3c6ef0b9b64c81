"""Conforming a decoded motion: bounded by its source, labelled, levelled and planted.

:func:`conform` is the transfer's last step after the network (habitsim.models.transfer):
torch-free, it takes the decoded motion and its source and returns the motion a later
stage can use.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..motion import Motion, resample_motion
from .bounds import bound_heading, bound_height, bound_speed
from .ladder import plant_decoded
from .level import LEVEL_TRUNK, level_trunk
from .schedule import transfer_contacts, walking_stance

__all__ = ["conform"]


def conform(out: Motion, source: Motion, info: dict[str, Any], plant: bool = False) -> Motion:
    """The decoded motion at the source's frame rate with its stance labels
    (:func:`transfer_contacts`; without aerial phases at a speed the target walks,
    :func:`walking_stance`) and, with ``plant``, its feet planted on them by leg IK
    (:func:`habitsim.stance.planting.plant_motion`: each stance run held at one foothold on the
    ground, swing blended in between; footholds by the rules of :data:`FOOTHOLD_RULES`;
    a trunk whose fore and hind stance feet stand at different heights pitched level
    first, :func:`level_trunk`, recorded as ``metadata["transfer"]["levelled"]``),
    kept when the legs reach (:data:`PLANT_MAX_REACH_PER_LEG`,
    :data:`PLANT_MAX_DROP_PER_LEG`); where they do not, the body is moved as far as its
    stance legs carry it and planted again (:data:`PLANT_MIN_SPEED_RATIO`).
    ``metadata["transfer"]["planted"]`` says what the planting did: ``False`` when it was
    off or no foot is in stance, else its report with ``kept``, ``root`` (``decoded`` or
    ``carried``), ``footholds`` (``median`` or ``centred``), ``solved`` (``False`` when
    the footholds were out of reach without IK), ``trimmed`` where stance runs were
    shortened to the legs' reach (the labels returned are then the trimmed ones,
    :func:`trim_to_reach`) and ``reason`` where the first try missed."""
    # frame for frame with the source (a round trip through the model's rate can add or
    # drop a frame at the end)
    out = resample_motion(out, source.fps, source.num_frames)
    out, bounded = bound_speed(out, source)
    if bounded is not None:
        info = {**info, "speed_bounded": bounded}
    out, lowered = bound_height(out, source)
    if lowered is not None:
        info = {**info, "height_bounded": lowered}
    out, turned = bound_heading(out, source)
    if turned is not None:
        info = {**info, "heading_bounded": turned}
    meta = {k: v for k, v in source.metadata.items() if k in ("action", "gait", "pair_key", "seed")}
    contacts, how = transfer_contacts(out, source, out.contacts)
    contacts, walking = walking_stance(out, contacts, source)
    if walking is not None:
        how = {**how, "walking_stance": walking}
    planted: Any = False
    if plant and contacts.any():
        glob: np.ndarray | None = out.global_positions()
        if LEVEL_TRUNK:
            out, levelled = level_trunk(out, contacts, glob)
            if levelled is not None:
                info = {**info, "levelled": levelled}
                glob = None  # the body turned
        out, planted = plant_decoded(out, contacts, glob)
        if ("restep" in planted or "trimmed" in planted) and planted["kept"]:
            assert out.contacts is not None  # plant_motion labels its output
            contacts = out.contacts  # the labels the legs now step on
    meta["transfer"] = {**info, "contacts": how, "planted": planted}
    return Motion(out.species, out.fps, out.root_positions, out.rotations, contacts, meta)
