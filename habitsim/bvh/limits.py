"""Bounds of a BVH file that the reader accepts."""

from __future__ import annotations

#: Sensible bounds of a BVH file; anything outside is a :class:`BVHParseError` naming it.
#: Frame rates [Hz] a file may declare (through ``Frame Time``).
FPS_RANGE = (1.0, 1000.0)
#: Largest |OFFSET| or |channel value| (file units or degrees); beyond, a number is garbage.
MAX_ABS_VALUE = 1e7
#: Deepest joint nesting (the habitsim skeleton is 8 deep, real rigs about 20).
MAX_DEPTH = 200
#: Most joints (End Sites included) and frames of one file.
MAX_JOINTS = 2000
MAX_FRAMES = 1_000_000
#: Longest line, and longest HIERARCHY part, read before the file is refused (bytes).
MAX_LINE_BYTES = 1 << 20
MAX_HIERARCHY_BYTES = 1 << 20
