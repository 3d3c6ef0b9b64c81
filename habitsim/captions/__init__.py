"""Captions of animal motion clips, written from what is measured on them.

:func:`clip_facts` measures what is true of a clip (species, action, speed and Froude
number, turning, direction, duration, start and end pose, its activity timeline);
:func:`captions` writes varied captions from those facts; :mod:`habitsim.captions.store`
keeps a data set's captions in one file beside its manifest. See docs/captions.md.
"""

from .facts import ChainStep, ClipFacts, FactsOptions, SegmentFacts, clip_facts
from .phrasing import FORMS, LEVELS, Caption, CaptionOptions, captions, speed_class

__all__ = [
    "Caption",
    "ChainStep",
    "CaptionOptions",
    "ClipFacts",
    "FORMS",
    "FactsOptions",
    "LEVELS",
    "SegmentFacts",
    "captions",
    "clip_facts",
    "speed_class",
]
