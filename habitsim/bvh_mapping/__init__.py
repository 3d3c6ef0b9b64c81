"""Map a BVH skeleton onto a species' habitsim skeleton and retarget its motion.

Pipeline of :func:`import_bvh`:

1. Read the file (:func:`habitsim.bvh.read_bvh`).
2. A file written by :func:`habitsim.bvh.write_bvh` (joint names and hierarchy identical to
   the habitsim skeleton) is imported as an *identity* mapping: rotations and root
   translation are copied, no retargeting.
3. Otherwise find the joint mapping, either from an explicit joint-map TOML
   (:func:`load_joint_map`) or automatically from names and hierarchy
   (:func:`auto_map`): the four legs (left/right name cues; of the chains of one leg,
   the one that animates and reaches the ground, a deforming chain before an IK or
   control copy; fore/hind from the end of the trunk that carries the head, then name
   cues, then the way the body travels, then where they hang; unnamed symmetric chains
   are accepted too and sided by geometry), the hips (where the hind legs hang), the
   spine chain from the hips to the chest (where the fore legs hang), neck and head
   beyond the chest, and the tail behind the hips.
4. Detect the file's frame (:func:`detect_frame`): units (cm / m / mm, from the hind-leg
   length against the species'), up axis (from where the feet are over the clip,
   checked against the rest pose: :func:`find_up`) and forward axis (from the hips toward
   the chest in the first frame, snapped to a coordinate axis), giving a proper rotation
   to habitsim's frame (z up, x forward, y left).
5. Retarget (:func:`retarget`): the source's global joint positions are converted to
   habitsim's frame; the pelvis takes the source hips' frame (heading along hips → chest,
   up from the world up); then, root to leaf, every habitsim joint that drives a bone of
   its chain gets the shortest-arc rotation that points that bone along the world
   direction between the corresponding mapped source joints. Joints whose bone has no
   mapped counterpart keep the species' standing pose; end points get identity. The root
   translation is scaled by species hip height / source hip height (heights above the
   source's ground, estimated as the median lowest foot height).

The retargeted rotations are general quaternions (no hinge projection; that is done
downstream).

Submodules, one concept each: :mod:`.names` (name cues, rig helpers), :mod:`.chains` (the
habitsim chains filled), :mod:`.tree` (the source rig as a tree), :mod:`.limbs` (leg
chains, mirrored pairs, leg roles), :mod:`.automap` (the automatic mapping),
:mod:`.map_files` (explicit joint maps), :mod:`.options` (the mapping's knobs),
:mod:`.clip_cues` (what the clip's motion says: animated chains, up, travel, skulls),
:mod:`.frame` (units and axes),
:mod:`.result` (:class:`JointMapping`), :mod:`.identity` (habitsim's own files),
:mod:`.retargeting` (retargeting, source stance, leg confidence), :mod:`.inplace` (in-place
clips, their travel recovered from the stance feet), :mod:`.loops` (loops and their
repeats), :mod:`.importing` (the entry points) and :mod:`.export` (a habitsim motion back
onto a user's rig, the import's inverse).
"""

from __future__ import annotations

from .automap import auto_map
from .export import RigExport, RoundTrip, check_rig, export_to_rig, round_trip
from .frame import DETECTED_UNITS as DETECTED_UNITS
from .frame import UNIT_SCALES, FrameConversion, UpEvidence, detect_frame, find_up
from .identity import is_habitsim_bvh
from .importing import SOURCE_SUFFIXES, describe_hierarchy, import_bvh, map_joints, read_source
from .inplace import InPlaceFit, InPlaceOptions, InPlaceOptionsError, recover_in_place
from .limbs import LEG_PROPORTIONS as LEG_PROPORTIONS
from .loops import LoopError, LoopFit, LoopOptions, detect_loop, repeat_loop
from .map_files import load_joint_map, validate_joint_map
from .names import is_control_name, is_helper_name, is_never_limb_name, name_cues
from .options import MappingOptions
from .report import ImportReport, InPlaceRecord, SourceStanceRecord, in_place_note
from .result import CONFIDENCE_CHECKS, CONFIDENCE_WARN, JointMapping, MappingNote
from .retargeting import retarget

__all__ = [
    "ImportReport",
    "InPlaceRecord",
    "in_place_note",
    "InPlaceFit",
    "InPlaceOptions",
    "InPlaceOptionsError",
    "recover_in_place",
    "LoopError",
    "LoopFit",
    "LoopOptions",
    "detect_loop",
    "repeat_loop",
    "SourceStanceRecord",
    "UNIT_SCALES",
    "FrameConversion",
    "JointMapping",
    "MappingNote",
    "MappingOptions",
    "name_cues",
    "auto_map",
    "load_joint_map",
    "validate_joint_map",
    "detect_frame",
    "find_up",
    "UpEvidence",
    "is_habitsim_bvh",
    "retarget",
    "import_bvh",
    "map_joints",
    "export_to_rig",
    "check_rig",
    "round_trip",
    "RigExport",
    "RoundTrip",
    "read_source",
    "SOURCE_SUFFIXES",
    "CONFIDENCE_CHECKS",
    "CONFIDENCE_WARN",
    "is_helper_name",
    "is_control_name",
    "is_never_limb_name",
    "describe_hierarchy",
]
