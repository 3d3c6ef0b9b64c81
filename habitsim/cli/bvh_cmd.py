"""``habitsim data import-bvh``, ``inspect-bvh`` and ``export-bvh``.

Outputs are written only when the whole command succeeds (atomic writes), so a failed
import never leaves a partial ``.npz`` behind.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from ..errors import MotionFileError
from ..fileio import check_writable
from .conventions import UNIT_CHOICES, UP_CHOICES, add_source_options, source_options

if TYPE_CHECKING:  # pragma: no cover
    from ..motion import Motion


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``import-bvh`` and ``export-bvh`` commands to the ``data`` group."""
    p = sub.add_parser(
        "import-bvh",
        help="import a BVH clip onto a species' skeleton",
        description=(
            "Read a BVH file (any hierarchy and channel order, cm or m, y-up or z-up), map its "
            "joints onto the species' habitsim skeleton (automatically from names and "
            "hierarchy, or with --map), retarget and write a motion .npz. The mapping used is "
            "printed as 'habitsim joint <- source joint' lines. With --dir, every .bvh/.glb/.gltf "
            "file under a folder becomes one clip of a data set folder (--out) that "
            "'habitsim train --data' reads; --labels names each file's action and split."
        ),
    )
    p.add_argument("file", type=Path, nargs="?", help="the .bvh, .glb or .gltf file")
    p.add_argument(
        "--dir",
        type=Path,
        default=None,
        dest="src_dir",
        metavar="DIR",
        help="import every motion file under DIR as a data set (instead of one file)",
    )
    p.add_argument(
        "--species", required=True, help="target catalog species (see 'habitsim species list')"
    )
    p.add_argument(
        "--out",
        required=True,
        type=Path,
        help="output motion file (.npz), or with --dir the data set folder",
    )
    p.add_argument(
        "--labels",
        type=Path,
        default=None,
        metavar="CSV",
        help="with --dir: CSV with columns file,action[,split] (default: action 'unlabelled', "
        "splits 8/1/1 by file order)",
    )
    p.add_argument(
        "--resample",
        type=float,
        default=30.0,
        metavar="HZ",
        help="with --dir: frame rate every clip is resampled to (default 30, the models')",
    )
    p.add_argument(
        "--skip-bad",
        action="store_true",
        help="with --dir: skip files that cannot be imported instead of stopping",
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="with --dir: replace a data set already in --out (only files habitsim wrote "
        "there are removed)",
    )
    p.add_argument(
        "--follow-symlinks",
        action="store_true",
        help="with --dir: read through links in DIR that lead out of it (refused by default)",
    )
    add_source_options(p)
    p.add_argument(
        "--no-plant",
        action="store_true",
        help="keep the source's leg bone directions instead of planting the feet on the "
        "source's footholds",
    )
    p.add_argument(
        "--lenient",
        action="store_true",
        help="accept a truncated file (keep its complete frames) instead of failing",
    )
    p.set_defaults(func=_import)

    i = sub.add_parser(
        "inspect-bvh",
        help="print a BVH/glTF hierarchy with the proposed mapping",
        description=(
            "Print the source hierarchy (bone lengths in file units, rig helpers marked) with "
            "the habitsim joint proposed for each source joint, the detected units and axes, "
            "each leg's mapping confidence and warnings, the stance found on the source's "
            "own feet, the clip's activity timeline (lying, sitting, standing, locomotion "
            "with gait and speed, transitions) and a JSON joint map to edit and pass to "
            "import-bvh --map."
        ),
    )
    i.add_argument("file", type=Path, help="the .bvh, .glb or .gltf file")
    i.add_argument(
        "--species", default="dog", help="species to size the detection against (default dog)"
    )
    add_source_options(i, loop=False)
    i.set_defaults(func=_inspect)

    e = sub.add_parser(
        "export-bvh",
        help="export a motion .npz to BVH (habitsim's rig, or your own with --rig)",
        description=(
            "Write a habitsim motion as BVH in habitsim's frame (z up, x forward, metres) with "
            "habitsim joint names; import-bvh reads it back as an identity mapping. With --rig "
            "the motion goes onto your own rig (a .bvh, .glb or .gltf, mapped as import-bvh "
            "maps it): its hierarchy, joint names, channel orders, units and up axis, its rest "
            "offsets, and its unmapped joints (ears, toes, helpers) in their first-frame pose."
        ),
    )
    e.add_argument("motion", type=Path, help="input motion file (.npz)")
    e.add_argument(
        "--out",
        required=True,
        type=Path,
        help="output .bvh file (with a glTF/GLB --rig also .glb / .gltf: a copy of the model "
        "with the motion added as the animation 'habitsim')",
    )
    e.add_argument(
        "--order",
        default="ZXY",
        help="rotation channel order of habitsim's rig (default ZXY; with --rig the rig's own)",
    )
    add_rig_options(e)
    e.set_defaults(func=_export)


def add_rig_options(p: argparse.ArgumentParser, prefix: str = "") -> None:
    """``--rig`` and how to map it (``--map``, ``--units``, ``--up``, ``--animation``; with
    ``prefix="rig-"`` as ``--rig-map`` … for commands whose ``--map`` is the source's)."""
    p.add_argument(
        "--rig",
        type=Path,
        default=None,
        metavar="RIG",
        help="write the motion onto this rig (.bvh, .glb or .gltf) instead of habitsim's",
    )
    p.add_argument(
        f"--{prefix}map",
        type=Path,
        default=None,
        dest="rig_map",
        metavar="MAP",
        help="joint-map JSON or TOML of the rig (as import-bvh --map; default: automatic)",
    )
    p.add_argument(
        f"--{prefix}units",
        choices=UNIT_CHOICES,
        default=None,
        dest="rig_units",
        help="length unit of the rig (default: detect)",
    )
    p.add_argument(
        f"--{prefix}up",
        choices=UP_CHOICES,
        default=None,
        dest="rig_up",
        help="up axis of the rig (default: detect)",
    )
    p.add_argument(
        f"--{prefix}travel",
        choices=("round-trip", "feet"),
        default="round-trip",
        dest="rig_travel",
        help="how the rig's root travels: round-trip (default: importing the file gives the "
        "motion back) or feet (the rig's stance feet stay put where its proportions differ)",
    )
    p.add_argument(
        f"--{prefix}animation",
        default=None,
        dest="rig_animation",
        metavar="NAME|INDEX",
        help="glTF/GLB rig: the animation whose first frame is the rig's pose (default: first)",
    )


def _animation(value: str | None) -> str | int | None:
    """A glTF animation given on the command line: its index when a number, else its name."""
    if value is None:
        return None
    try:
        return int(value)
    except ValueError:
        return value


def write_on_rig(motion: Motion, out: Path, ns: argparse.Namespace) -> str:
    """Write ``motion`` onto ``ns.rig`` as BVH at ``out``; the line to print."""
    from ..bvh_mapping.export import RigExportOptions, export_to_rig

    ex = export_to_rig(
        motion,
        ns.rig,
        joint_map=ns.rig_map,
        units=ns.rig_units,
        up=ns.rig_up,
        animation=_animation(ns.rig_animation),
        export=RigExportOptions(travel=ns.rig_travel),
    )
    ex.write(out)
    fr = ex.mapping.frame
    assert fr is not None
    mapped = len(ex.mapping.mapped())
    return (
        f"{ns.rig.name}: {mapped} joints mapped ({ex.mapping.method}), {ex.bvh.num_joints} "
        f"written; units {fr.units}, up {fr.up}; root travel / {ex.root_scale:.4g}"
    )


def _print_in_place(motion: Motion) -> None:
    """The import report's lines on in-place clips and loops."""
    from ..bvh_mapping import ImportReport

    report = ImportReport.from_metadata(motion.metadata)
    if report is not None and report.in_place is not None:
        for line in report.in_place.lines():
            print(line)


def _inspect(ns: argparse.Namespace) -> int:
    import json

    from ..bvh_mapping import describe_hierarchy, import_bvh, read_source
    from ..source import cut_source
    from ..species import load_species

    sp = load_species(ns.species)
    o = source_options(ns, sp.name)
    whole = read_source(ns.file, animation=o.animation, fps=o.fps)
    src, first = cut_source(whole, o.span)
    line = f"{ns.file.name}: {src.num_joints} joints, {whole.num_frames} frames at {src.fps:g} fps"
    if src is not whole:
        t0 = first / src.fps
        line += f"; inspecting {t0:.2f}–{t0 + src.num_frames / src.fps:.2f} s"
    print(line)
    try:
        motion, mapping = import_bvh(src, sp, joint_map=o.joint_map, units=o.units, up=o.up)
    except Exception:
        print(describe_hierarchy(src))
        raise
    print(describe_hierarchy(src, mapping))
    print()
    print(mapping)
    imp = motion.metadata.get("import", {})
    if imp:
        c = imp["contacts"]
        print(
            "stance on the source's own feet (LF RF LH RH): duty "
            + " ".join(f"{d:.2f}" for d in c["duty"])
            + "; foot joints "
            + ", ".join(c["foot_joints"])
        )
    _print_in_place(motion)
    print()
    _print_timeline(motion)
    template = {"extends": "auto", "map": mapping.mapped()}
    print()
    print("joint map to edit (save as map.json, pass --map map.json; null unmaps a joint):")
    print(json.dumps(template, indent=1))
    return 0


def _print_timeline(motion: Motion) -> None:
    """The clip's activity timeline (:func:`habitsim.activity.timeline`) and the part a
    command runs by default."""
    from ..activity import ActivityError, default_span, timeline

    tl = timeline(motion)
    print(
        f"activity on the {motion.species}'s skeleton (start–end, activity, speed, trunk height):"
    )
    print(tl.describe())
    try:
        start, _ = default_span(tl)
    except ActivityError as e:
        print(f"default span: none ({e})")
        return
    if start > 0:
        first = tl.segments[0]
        print(
            f"default span: from {start / tl.fps:.2f} s (the {first.activity.value} start "
            "is left out by retarget and bench real)"
        )


def _import(ns: argparse.Namespace) -> int:
    from ..bvh_mapping import SOURCE_SUFFIXES
    from ..source import load_clip
    from ..species import load_species

    sp = load_species(ns.species)  # fail fast with the list of known species
    if (ns.file is None) == (ns.src_dir is None):
        raise MotionFileError("give one motion FILE or --dir DIR (not both, not neither)")
    if ns.src_dir is not None:
        return _import_dir(ns)
    for flag, value in (("--labels", ns.labels), ("--skip-bad", ns.skip_bad)):
        if value:
            raise MotionFileError(f"{flag} only applies with --dir")
    if ns.out.suffix != ".npz":
        raise MotionFileError(f"--out must end in .npz, got {ns.out.name!r}")
    check_writable(ns.out, "--out")  # before the import, not after it
    if ns.file.suffix.lower() not in SOURCE_SUFFIXES:
        raise MotionFileError(
            f"{ns.file.name}: import-bvh reads motion capture ({', '.join(SOURCE_SUFFIXES)}), "
            f"got {ns.file.suffix!r}"
        )
    clip = load_clip(
        ns.file, source_options(ns, sp.name, strict=not ns.lenient, plant=not ns.no_plant)
    )
    mapping = clip.mapping
    assert mapping is not None  # a motion-capture source always has one
    print(mapping)
    motion = clip.motion
    _print_in_place(motion)
    for w in mapping.warnings:
        print(f"warning: {w}", file=sys.stderr)
    motion.save(ns.out)
    kept = f"; kept {clip.kept()}" if clip.cut else ""
    print(
        f"imported {ns.file.name}: {motion.num_frames} frames at {motion.fps:g} fps "
        f"({motion.duration:.2f} s{kept}) onto {motion.species} -> {ns.out}"
    )
    return 0


def _import_dir(ns: argparse.Namespace) -> int:
    from ..dataset_import import import_folder

    one_file = (
        ("--animation", ns.animation),
        ("--fps", ns.fps),
        ("--lenient", ns.lenient),
        ("--start", ns.start),
        ("--end", ns.end),
        ("--loop", ns.loop),
        ("--seconds", ns.loop_seconds),
    )
    given = [flag for flag, v in one_file if v not in (None, False)]
    if given:
        raise MotionFileError(f"{', '.join(given)} apply to one file, not --dir")
    build = import_folder(
        ns.src_dir,
        ns.out,
        ns.species,
        labels=ns.labels,
        fps=ns.resample,
        overwrite=ns.overwrite,
        skip_bad=ns.skip_bad,
        joint_map=ns.joint_map,
        units=ns.units,
        up=ns.up,
        plant=not ns.no_plant,
        follow_symlinks=ns.follow_symlinks,
        log=print,
    )
    for f, w in build.warnings:
        print(f"warning: {f}: {w}", file=sys.stderr)
    for f, why in build.skipped:
        print(f"skipped: {f}: {why}", file=sys.stderr)
    man = build.manifest
    counts = ", ".join(f"{k} {v}" for k, v in man.split_counts().items())
    frames = sum(c.frames for c in man.clips)
    print(
        f"data set {ns.out}: {len(man.clips)} clips of {man.species_names[0]} "
        f"({frames} frames at {man.fps:g} fps; {counts})"
        + (f"; {len(build.skipped)} file(s) skipped" if build.skipped else "")
    )
    return 0


def _export(ns: argparse.Namespace) -> int:
    from ..bvh import write_bvh
    from ..motion import load_motion

    kinds = (".bvh", ".glb", ".gltf") if ns.rig is not None else (".bvh",)
    if ns.out.suffix.lower() not in kinds:
        raise MotionFileError(f"--out must end in {' or '.join(kinds)}, got {ns.out.name!r}")
    check_writable(ns.out, "--out")
    motion = load_motion(ns.motion)
    if ns.rig is not None:
        line = write_on_rig(motion, ns.out, ns)
        print(f"exported {motion.num_frames} frames of {motion.species} to {ns.out} on {line}")
        return 0
    given = [f for f, v in (("--map", ns.rig_map), ("--units", ns.rig_units)) if v is not None]
    given += [f for f, v in (("--up", ns.rig_up), ("--animation", ns.rig_animation)) if v]
    given += ["--travel"] if ns.rig_travel != "round-trip" else []
    if given:
        raise MotionFileError(f"{', '.join(given)} describe a rig: give it with --rig RIG")
    write_bvh(motion, ns.out, order=ns.order)
    print(f"exported {motion.num_frames} frames of {motion.species} to {ns.out} (z up, metres)")
    return 0
