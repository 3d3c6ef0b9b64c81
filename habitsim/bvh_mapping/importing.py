"""The entry points: read a source clip (:func:`read_source`), import it onto a species
(:func:`import_bvh`), and describe its hierarchy (:func:`describe_hierarchy`)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

from ..bvh import BVHData, read_bvh
from ..errors import SkeletonMappingError
from ..motion import Motion
from ..skeleton import JOINT_NAMES
from ..species import Species, load_species
from .automap import _analyse, _Analysis, _resolve_sides
from .chains import _LEG_CHAINS
from .frame import _parse_up, detect_frame
from .identity import _identity_import, is_habitsim_bvh
from .inplace import InPlaceOptions, recover_in_place
from .loops import LoopOptions
from .map_files import load_joint_map, validate_joint_map
from .options import MappingOptions
from .result import JointMapping, MappingNote
from .retargeting import retarget
from .tree import _Tree

_JOINT = {n: i for i, n in enumerate(JOINT_NAMES)}


def describe_hierarchy(bvh: BVHData, mapping: JointMapping | None = None) -> str:
    """The source hierarchy as an indented tree, each joint with its proposed habitsim joint.

    Each line: the joint, its bone length in file units, ``[helper]`` for rig helpers that
    are never limbs, ``[control]`` for control bones (IK, pole, target, twist, roll,
    MCH/ORG: limbs only where they are the chain that animates), ``[end]`` for End Sites,
    and ``-> habitsim_joint`` where mapped.
    """
    inv = {v: k for k, v in mapping.mapped().items()} if mapping is not None else {}
    t = _Tree(bvh)
    lines = []
    for j, name in enumerate(bvh.names):
        tags = []
        if bvh.is_end_site[j]:
            tags.append("[end]")
        elif t.never[j]:
            tags.append("[helper]")
        elif t.control[j]:
            tags.append("[control]")
        text = f"{'  ' * t.depth[j]}{name}  ({t.blen[j]:.4g})"
        if tags:
            text += " " + " ".join(tags)
        if name in inv:
            text += f"  -> {inv[name]}"
        lines.append(text)
    return "\n".join(lines)


#: File types :func:`read_source` reads (BVH motion capture, glTF skinned animations).
SOURCE_SUFFIXES: tuple[str, ...] = (".bvh", ".glb", ".gltf")


def read_source(
    path: str | Path,
    animation: str | int | None = None,
    fps: float | None = None,
    strict: bool = True,
) -> BVHData:
    """Read a source clip: a BVH file, or one animation of a glTF/GLB skinned model.

    Args:
        path: a ``.bvh``, ``.glb`` or ``.gltf`` file.
        animation: glTF only: the animation's name or index (None: the first).
        fps: glTF only: sampling rate [Hz] (default 30).
        strict: BVH only: see :func:`habitsim.bvh.parse_bvh`.

    Returns:
        The clip as :class:`~habitsim.bvh.BVHData`.

    Raises:
        SkeletonMappingError: an unknown file type (lists the valid ones), or glTF
            options given for a BVH file.
        BVHParseError, GLTFError: an unreadable file.
    """
    p = Path(path)
    kind = p.suffix.lower()
    if kind == ".bvh":
        if animation is not None or fps is not None:
            raise SkeletonMappingError(
                f"{p.name}: animation and fps apply to glTF files only (.glb, .gltf)"
            )
        return read_bvh(p, strict=strict)
    if kind in (".glb", ".gltf"):
        from ..gltf import read_gltf

        return read_gltf(p, animation=animation, fps=30.0 if fps is None else fps)
    raise SkeletonMappingError(
        f"{p.name}: unknown source file type {p.suffix!r}; valid: {', '.join(SOURCE_SUFFIXES)}"
    )


def _in_place(motion: Motion, options: InPlaceOptions | None) -> bool:
    """Whether a copied (identity-imported) motion is an in-place clip, which is then
    imported through the retargeting that recovers its travel."""
    pos = motion.global_positions()
    feet = []
    for prefix, top in zip(
        ("lf", "rf", "lh", "rh"), ("wrist", "wrist", "hock", "hock"), strict=True
    ):
        feet.append(pos[:, [_JOINT[f"{prefix}_{top}"], _JOINT[f"{prefix}_toe"]]])
    forward = pos[:, _JOINT["spine3"]] - pos[:, 0]
    leg = motion.species_info.hind_leg_length
    fit = recover_in_place(feet, pos[:, 0], forward, motion.fps, leg, options=options)
    return fit.detected


def map_joints(
    bvh: BVHData,
    species: str | Species | None,
    joint_map: str | Path | Mapping[str, str] | None = None,
    units: str | float | None = None,
    up: str | None = None,
    options: MappingOptions | None = None,
) -> JointMapping:
    """The joint mapping and frame conversion :func:`import_bvh` uses for a source
    skeleton, without retargeting its motion (arguments as :func:`import_bvh`'s; a
    ``species`` of None detects the units against a 0.5 m leg, as for a rig that makes a
    new species).

    Raises:
        SkeletonMappingError: unmappable skeleton or invalid joint map.
    """
    sp = load_species(species) if species is not None else None
    options = options or MappingOptions()
    notes: list[str] = []
    codes: list[MappingNote] = []
    geometric: list[tuple[str, str]] = []
    if joint_map is None:
        if is_habitsim_bvh(bvh):
            joints = validate_joint_map({n: n for n in JOINT_NAMES}, bvh)
            method = "habitsim names, converted"
        else:
            an = _analyse(bvh, options)
            joints, geometric, notes, codes = an.joints, an.geometric_sides, an.notes, an.note_codes
            method = "auto"
    elif isinstance(joint_map, Mapping):
        joints = validate_joint_map(joint_map, bvh)
        method = "explicit"
    else:
        spec = load_joint_map(joint_map)
        if spec["extends"] == "auto":
            an = _analyse(bvh, options)
            base = dict(an.joints)
            base.update(spec["map"])
            joints = validate_joint_map(base, bvh, where=str(joint_map))
            codes = [*an.note_codes, MappingNote.SET_BY_HAND]
            notes = an.notes + [f"joints set by hand: {', '.join(sorted(spec['map']))}"]
            geometric = [
                (lp, rp)
                for lp, rp in an.geometric_sides
                if not any(n in spec["map"] for n in _LEG_CHAINS[lp] + _LEG_CHAINS[rp])
            ]
            method = f"auto, overridden by map file {joint_map}"
        else:
            joints = validate_joint_map(spec["map"], bvh, where=str(joint_map))
            method = f"map file {joint_map}"
        units = units if units is not None else spec["units"]
        up = up if up is not None else spec["up"]

    frame = detect_frame(bvh, joints, units=units, up=up, species=sp, options=options)
    if geometric:
        an2 = _Analysis(joints, geometric, notes, codes)
        _resolve_sides(bvh, an2, frame)
    mapping = JointMapping(joints, method, frame, 1.0, list(notes), note_codes=list(codes))
    ev = frame.up_evidence
    if ev is not None and ev.source != "given":
        code = MappingNote.UP_UNSURE if ev.unsure else MappingNote.UP_FROM_FEET
        mapping.note(code, ev.describe())
    return mapping


def import_bvh(
    path: str | Path | BVHData,
    species: str | Species,
    joint_map: str | Path | Mapping[str, str] | None = None,
    units: str | float | None = None,
    up: str | None = None,
    strict: bool = True,
    plant: bool = True,
    animation: str | int | None = None,
    fps: float | None = None,
    options: MappingOptions | None = None,
    inplace: InPlaceOptions | None = None,
    loops: LoopOptions | None = None,
) -> tuple[Motion, JointMapping]:
    """Read a BVH file (or a glTF/GLB animation) and retarget it onto a species' skeleton.

    Args:
        path: the ``.bvh`` file (or an already parsed :class:`~habitsim.bvh.BVHData`).
        species: target catalog species.
        joint_map: None for the automatic mapping, a joint-map TOML path
            (:func:`load_joint_map`) or a dict habitsim joint → source joint.
        units: source length unit (``"m"``, ``"cm"``, ``"mm"`` or metres per unit);
            None = detect (a TOML's ``units`` applies when this is None).
        up: source up axis (``"y"``, ``"z"``, ``"-y"``…); None = detect.
        strict: see :func:`habitsim.bvh.parse_bvh`.
        plant: plant the legs on the source's footholds (see :func:`retarget`).
        animation, fps: for a glTF/GLB file, the animation and the sampling rate
            (:func:`read_source`).
        options: the automatic mapping's tuning knobs (default :class:`MappingOptions`).
        inplace: the knobs of detecting an in-place clip and recovering its root travel
            from its stance feet (default :class:`~habitsim.bvh_mapping.inplace.
            InPlaceOptions`); ``metadata["import"]["in_place"]`` says what was found.
        loops: the knobs of telling a loop (default :class:`~habitsim.bvh_mapping.loops.
            LoopOptions`).

    Returns:
        ``(motion, mapping)``; print ``mapping`` for the habitsim ← source lines.

    Raises:
        UnknownSpeciesError: unknown species (lists the known ones).
        BVHParseError: unreadable / malformed file.
        SkeletonMappingError: unmappable skeleton or invalid joint map.
    """
    sp = load_species(species)
    options = options or MappingOptions()
    bvh = (
        path
        if isinstance(path, BVHData)
        else read_source(path, animation=animation, fps=fps, strict=strict)
    )
    offsets = np.asarray(bvh.offsets, dtype=np.float64)
    if len(bvh.names) > 1 and not (np.all(np.isfinite(offsets)) and np.any(offsets[1:])):
        raise SkeletonMappingError(
            f"{bvh.source}: every joint offset below the root is zero (or not finite), so the "
            "skeleton has no size; valid: a rig with at least one non-zero bone"
        )
    plain = (units is None or (isinstance(units, str) and units.lower() == "m")) and (
        up is None or _parse_up(up) == "+z"
    )
    if joint_map is None and is_habitsim_bvh(bvh) and plain:
        copied = _identity_import(bvh, sp)
        if not _in_place(copied[0], inplace):
            return copied

    mapping = map_joints(bvh, sp, joint_map=joint_map, units=units, up=up, options=options)
    motion = retarget(bvh, mapping, sp, plant=plant, inplace=inplace, loops=loops)
    motion.metadata["mapping"] = mapping.to_dict()
    return motion, mapping
