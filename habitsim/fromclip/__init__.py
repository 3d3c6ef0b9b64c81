"""A new species from one clip: measure the rig a motion-capture clip shows
(:mod:`.measure`), draft its species file by the catalog's rules (:mod:`.draft`), then
build its MuJoCo models into a user catalog folder and check that it stands
(:mod:`habitsim.fromclip.make`, physics layer: import it by its full name).

``habitsim species from-clip`` is the command; docs/species.md the user's page.
"""

from __future__ import annotations

from .draft import Draft, choose_cousin, classify_posture, draft_species, mass_rule, size_length
from .measure import LEG_SEGMENTS, RigMeasure, Span, measure_rig
from .options import FromClipOptions

__all__ = [
    "Draft",
    "FromClipOptions",
    "LEG_SEGMENTS",
    "RigMeasure",
    "Span",
    "choose_cousin",
    "classify_posture",
    "draft_species",
    "mass_rule",
    "measure_rig",
    "size_length",
]
