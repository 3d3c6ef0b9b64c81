"""The knobs of the automatic mapping (:class:`MappingOptions`)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class MappingOptions:
    """The tuning knobs of the automatic joint mapping (:func:`~habitsim.bvh_mapping.auto_map`,
    :func:`~habitsim.bvh_mapping.import_bvh`). Why each default: ``docs/import.md``.

    Attributes:
        mirror_bone_tolerance: two unnamed chains hanging from one joint are a left/right
            pair when each bone along them matches its mirror's length within this share
            of the chain's length [unitless]: mirrored legs do, a tail and a sided tail
            helper do not.
        animated_share: a chain animates when its tip, seen from the joint the chain
            hangs from, moves by more than this share of the chain's length over the clip
            [unitless]; a static copy of a leg (a deforming chain left in its rest pose
            beside an animated IK chain) does not.
        duplicate_share: two chains of one side are one leg drawn twice (a deforming and
            an IK or control copy) when their first joints lie closer than this share of
            the chain's length, on average over the clip [unitless].
        ground_share: a leg chain's tip reaches the ground when its low height over the
            clip (the ``low_percentile``) is within this share of the leg's length of the
            feet's ground [unitless].
        low_percentile: the percentile of a point's heights over the clip taken as its
            low height [%]: a foot's resting height, not a one-frame glitch.
        up_margin: the up axis is sure when its score (the body's height above the feet
            less the spread of the feet's low heights, in leg lengths) beats every other
            axis's by this much [leg lengths]; below it the mapping notes that the up
            axis is unsure.
        standing_score: the rest pose checks the up axis only when it is a standing
            pose: its best axis scores at least this [leg lengths] (the body that high
            above feet on one plane); a bind pose with the legs spread or a glTF rest
            without its node rotations is no evidence.
        travel_speed: the body's motion along its trunk (the stance feet's sweep, which
            an in-place loop shows as well as a travelling clip) tells which end leads
            when it is at least this fast [leg lengths / s].
        down_share: for that sweep, a foot is down while it is within this share of the
            leg's length of its resting height [unitless]: a foot in stance, not one
            skimming the ground in swing.
    """

    mirror_bone_tolerance: float = 0.05
    animated_share: float = 0.005
    duplicate_share: float = 0.25
    ground_share: float = 0.15
    low_percentile: float = 5.0
    up_margin: float = 0.25
    standing_score: float = 0.5
    travel_speed: float = 0.25
    down_share: float = 0.05
