"""BVH (Biovision hierarchy) reading, forward kinematics and writing.

Why an own parser and not a library (``bvhio`` was evaluated): the BVH grammar is tiny,
and what matters for habitsim is (a) exact rotation semantics for *every* channel order,
per joint, including joints with position channels and End Sites, and (b) error messages
that name the line and the problem for truncated or malformed files. ``bvhio`` builds its
own object tree on top of PyGLM (single precision), converts the data into its own pose
representation and raises bare exceptions (``ValueError`` / ``IndexError`` / ``KeyError``)
without line numbers on bad input, so it would have had to be wrapped and its results
re-converted anyway; it is also not a dependency of habitsim (it was not installed in the
project environment). The parser (:mod:`.hierarchy`, :mod:`.reader`) depends only on numpy /
scipy (through :mod:`habitsim.rotations`), works in float64 and raises
:class:`~habitsim.errors.BVHParseError` with ``file:line`` on every malformed input.

Conventions of the reader (the usual BVH semantics):

* A joint's rotation channels, read left to right, compose as intrinsic rotations:
  ``CHANNELS 3 Zrotation Xrotation Yrotation`` means R = R_z(a) · R_x(b) · R_y(c), angles in
  degrees. Any order and any subset of axes is accepted, on any joint.
* Position channels (usually only on the root, but any joint may have them) *replace* the
  joint's OFFSET along the axes they name; axes without a position channel keep the OFFSET.
* End Sites become extra channel-less joints named ``<parent>_End`` (so they can be mapped,
  e.g. as toe tips), flagged in :attr:`BVHData.is_end_site`.
* Units and axes are those of the file; see :mod:`habitsim.bvh_mapping` for the conversion
  to habitsim's frame.

Frame convention of the writer (:func:`write_bvh`): habitsim's own frame and names — z up,
x forward, y left, metres, joint names of :data:`habitsim.skeleton.JOINT_NAMES`, OFFSETs
from the species' skeleton. The root (``pelvis``) has OFFSET 0 and six channels
``Xposition Yposition Zposition`` + 3 rotations, every other joint three rotation channels
in ``order``. The end points (``snout``, ``tail3``, ``*_toe``) are written as JOINTs with
rotation channels (so any rotation a motion stores there survives the round trip), each
closed by an End Site with a zero offset. A file written so is recognised by
:func:`habitsim.bvh_mapping.import_bvh` (identical joint names) and imported as an identity
mapping without retargeting.

Submodules, one concept each: :mod:`.data` (:class:`BVHData`), :mod:`.limits` (the bounds
of a file), :mod:`.hierarchy` (the HIERARCHY part), :mod:`.reader` (:func:`parse_bvh`,
:func:`read_bvh`) and :mod:`.writer` (:func:`bvh_text`, :func:`write_bvh`).
"""

from __future__ import annotations

from .data import END_SITE_SUFFIX, POSITION_CHANNELS, ROTATION_CHANNELS, BVHData
from .limits import FPS_RANGE as FPS_RANGE
from .limits import MAX_ABS_VALUE as MAX_ABS_VALUE
from .limits import MAX_DEPTH as MAX_DEPTH
from .limits import MAX_FRAMES as MAX_FRAMES
from .limits import MAX_HIERARCHY_BYTES as MAX_HIERARCHY_BYTES
from .limits import MAX_JOINTS as MAX_JOINTS
from .limits import MAX_LINE_BYTES as MAX_LINE_BYTES
from .reader import parse_bvh, read_bvh
from .writer import bvh_text, write_bvh

__all__ = [
    "BVHData",
    "ROTATION_CHANNELS",
    "POSITION_CHANNELS",
    "END_SITE_SUFFIX",
    "read_bvh",
    "parse_bvh",
    "bvh_text",
    "write_bvh",
]
