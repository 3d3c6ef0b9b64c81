"""``habitsim models build|path``: generate the per-species MJCF models."""

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


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``models build`` and ``models path``."""
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
