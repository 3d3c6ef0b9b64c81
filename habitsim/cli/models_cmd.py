"""``habitsim models build|path|vendor``: generate the per-species MJCF models; make a
collision-only single-file copy of a robot."""

from __future__ import annotations

import argparse
from pathlib import Path

from .conventions import add_list_option


def _build(ns: argparse.Namespace) -> int:
    from habitsim.mjcf_models.builder import write_model
    from habitsim.species import load_species, species_names

    names = ns.species or species_names()
    for n in names:
        load_species(n)  # fail early, with the list of known species
    for n in names:
        scene = write_model(n, ns.out, preview=not ns.no_preview)
        print(f"{n:10s} -> {scene}")
    return 0


def _path(ns: argparse.Namespace) -> int:
    from habitsim.mjcf_models.builder import (
        model_path,
        scene_path,
        torque_model_path,
        torque_scene_path,
    )

    if ns.torque:
        print(torque_scene_path(ns.species) if ns.scene else torque_model_path(ns.species))
    else:
        print(scene_path(ns.species) if ns.scene else model_path(ns.species))
    return 0


def _vendor(ns: argparse.Namespace) -> int:
    from habitsim.retarget.vendor import VendorOptions, vendor_robot

    opts = VendorOptions(shape=ns.shape, fit_aabb=not ns.inertia_fit, fit_scale=ns.fit_scale)
    rep = vendor_robot(ns.model, ns.out, opts)
    kinds: dict[str, int] = {}
    for _, kind, _ in rep.fitted:
        kinds[kind] = kinds.get(kind, 0) + 1
    fits = ", ".join(
        f"{n} {k}{'es' if k == 'box' and n > 1 else 's' if n > 1 else ''}"
        for k, n in sorted(kinds.items())
    )
    print(
        f"{ns.model} -> {rep.out}: {len(rep.dropped)} visual mesh geoms dropped, "
        f"{len(rep.fitted)} collision meshes replaced ({fits or 'none'}), "
        f"{len(rep.assets_removed)} assets removed"
        + (f"; licence {rep.licence}" if rep.licence else "; no licence file found beside it")
    )
    for geom, mesh in rep.stand_ins:
        print(f"  {geom}: its collision mesh cannot be read; fitted to the visual mesh {mesh}")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``models build``, ``models path`` and ``models vendor``."""
    p = sub.add_parser(
        "build",
        help="write <species>/<species>.xml and scene.xml (the standing model), "
        "<species>_torque.xml and scene_torque.xml (the torque model), README.md, preview.png",
    )
    add_list_option(p, "--species", help="species (default: all)")
    p.add_argument(
        "--out",
        type=Path,
        default=None,
        help="models folder (default: the installed habitsim.mjcf_models)",
    )
    p.add_argument(
        "--no-preview",
        action="store_true",
        help="do not render preview.png (it needs an OpenGL context: EGL or OSMesa headless)",
    )
    p.set_defaults(func=_build)
    q = sub.add_parser("path", help="print the path of a species' model file")
    q.add_argument("species")
    q.add_argument("--scene", action="store_true", help="the scene (floor + light)")
    q.add_argument(
        "--torque",
        action="store_true",
        help="the torque model the controllers drive instead of the standing model "
        "(position actuators holding 'home'; it stands in plain MuJoCo)",
    )
    q.set_defaults(func=_path)
    v = sub.add_parser(
        "vendor",
        help="write a collision-only single-file copy of a robot MJCF (visual meshes "
        "dropped, collision meshes replaced by fitted primitives), to vendor it",
    )
    v.add_argument("model", type=Path, metavar="ROBOT.xml", help="the robot's MJCF or scene")
    v.add_argument(
        "--out", type=Path, required=True, metavar="DIR", help="folder to write the copy into"
    )
    v.add_argument(
        "--shape",
        default="auto",
        choices=("auto", "box", "capsule", "sphere"),
        help="primitive each collision mesh becomes (default auto: the one closest to the "
        "mesh's volume)",
    )
    v.add_argument(
        "--inertia-fit",
        action="store_true",
        help="fit primitives to the mesh's equivalent-inertia box instead of its bounding box",
    )
    v.add_argument(
        "--fit-scale",
        type=float,
        default=1.0,
        metavar="S",
        help="scale of the fitted primitives (default 1)",
    )
    v.set_defaults(func=_vendor)
