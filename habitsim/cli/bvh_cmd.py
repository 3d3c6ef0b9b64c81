"""``habitsim data import-bvh`` and ``habitsim data export-bvh``.

Outputs are written only when the whole command succeeds (atomic writes), so a failed
import never leaves a partial ``.npz`` behind.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ..errors import MotionFileError


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``import-bvh`` and ``export-bvh`` commands to the ``data`` group."""
    p = sub.add_parser(
        "import-bvh",
        help="import a BVH clip onto a species' skeleton",
        description=(
            "Read a BVH file (any hierarchy and channel order, cm or m, y-up or z-up), map its "
            "joints onto the species' habitsim skeleton (automatically from names and "
            "hierarchy, or with --map), retarget and write a motion .npz. The mapping used is "
            "printed as 'habitsim joint <- source joint' lines."
        ),
    )
    p.add_argument("file", type=Path, help="the .bvh file")
    p.add_argument(
        "--species", required=True, help="target catalog species (see 'habitsim species list')"
    )
    p.add_argument("--out", required=True, type=Path, help="output motion file (.npz)")
    p.add_argument(
        "--map",
        type=Path,
        default=None,
        dest="joint_map",
        help='joint-map TOML: [map] habitsim_joint = "SourceJoint"',
    )
    p.add_argument(
        "--units",
        choices=("cm", "m", "mm"),
        default=None,
        help="length unit of the file (default: detect)",
    )
    p.add_argument(
        "--up",
        choices=("y", "z", "-y", "-z", "x", "-x"),
        default=None,
        help="up axis of the file (default: detect)",
    )
    p.add_argument(
        "--lenient",
        action="store_true",
        help="accept a truncated file (keep its complete frames) instead of failing",
    )
    p.set_defaults(func=_import)

    e = sub.add_parser(
        "export-bvh",
        help="export a motion .npz to BVH",
        description=(
            "Write a habitsim motion as BVH in habitsim's frame (z up, x forward, metres) with "
            "habitsim joint names; import-bvh reads it back as an identity mapping."
        ),
    )
    e.add_argument("motion", type=Path, help="input motion file (.npz)")
    e.add_argument("--out", required=True, type=Path, help="output .bvh file")
    e.add_argument("--order", default="ZXY", help="rotation channel order (default ZXY)")
    e.set_defaults(func=_export)


def _import(ns: argparse.Namespace) -> int:
    from ..bvh_mapping import import_bvh
    from ..species import load_species

    sp = load_species(ns.species)  # fail fast with the list of known species
    if ns.out.suffix != ".npz":
        raise MotionFileError(f"--out must end in .npz, got {ns.out.name!r}")
    motion, mapping = import_bvh(
        ns.file, sp, joint_map=ns.joint_map, units=ns.units, up=ns.up, strict=not ns.lenient
    )
    print(mapping)
    motion.save(ns.out)
    print(
        f"imported {ns.file.name}: {motion.num_frames} frames at {motion.fps:g} fps "
        f"({motion.duration:.2f} s) onto {motion.species} -> {ns.out}"
    )
    return 0


def _export(ns: argparse.Namespace) -> int:
    from ..bvh import write_bvh
    from ..motion import load_motion

    if ns.out.suffix.lower() != ".bvh":
        raise MotionFileError(f"--out must end in .bvh, got {ns.out.name!r}")
    motion = load_motion(ns.motion)
    write_bvh(motion, ns.out, order=ns.order)
    print(f"exported {motion.num_frames} frames of {motion.species} to {ns.out} (z up, metres)")
    return 0
