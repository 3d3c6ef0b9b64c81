"""The knobs of the automatic mapping (:class:`MappingOptions`)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class MappingOptions:
    """The tuning knobs of the automatic joint mapping (:func:`~habitsim.bvh_mapping.auto_map`,
    :func:`~habitsim.bvh_mapping.import_bvh`).

    Attributes:
        mirror_bone_tolerance: two unnamed chains hanging from one joint are a left/right
            pair when each bone along them matches its mirror's length within this share
            of the chain's length [unitless]: mirrored legs do, a tail and a sided tail
            helper do not.
    """

    mirror_bone_tolerance: float = 0.05
