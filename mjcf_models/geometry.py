"""The solid geometry of a species model: capsule meshes along its bones, the foot
spheres, and the gravity moments the actuators are sized by."""

from __future__ import annotations

import math
from typing import cast

import numpy as np
import trimesh

from habitsim.body import bone_girth_keys
from habitsim.physics_constants import GRAVITY
from habitsim.skeleton import JOINT_NAMES, PARENTS, get_skeleton
from habitsim.species import Species


def _capsule(p0: np.ndarray, p1: np.ndarray, radius: float) -> trimesh.Trimesh:
    """A trimesh capsule from p0 to p1 (body frame) with the given radius [m]."""
    d = p1 - p0
    length = float(np.linalg.norm(d))
    cap = trimesh.creation.capsule(height=length, radius=radius, count=[10, 10])
    # trimesh's capsule runs along z, centred; align z with d and move to the midpoint.
    tf = trimesh.geometry.align_vectors([0.0, 0.0, 1.0], d / length)
    tf[:3, 3] = 0.5 * (p0 + p1)
    cap.apply_transform(tf)
    return cap


def _bones_by_body(sp: Species) -> dict[str, list[tuple[str, np.ndarray, float]]]:
    """For each body (rotating skeleton joint), its bones as (child, offset, radius)."""
    skel = get_skeleton(sp)
    keys = bone_girth_keys()
    bones: dict[str, list[tuple[str, np.ndarray, float]]] = {}
    for j, p in enumerate(PARENTS):
        if p < 0:
            continue
        key = keys[JOINT_NAMES[j]]
        if key is None:
            continue
        bones.setdefault(JOINT_NAMES[p], []).append(
            (JOINT_NAMES[j], skel.offsets[j].copy(), sp.girths[key] / (2.0 * math.pi))
        )
    return bones


def _body_meshes(sp: Species) -> dict[str, trimesh.Trimesh]:
    return {
        # concatenating meshes gives a mesh
        body: cast(
            trimesh.Trimesh,
            trimesh.util.concatenate([_capsule(np.zeros(3), off, r) for _, off, r in bl]),
        )
        for body, bl in _bones_by_body(sp).items()
    }


def _gravity_moments(
    sp: Species, solids: dict[str, trimesh.Trimesh], density: float
) -> dict[str, float]:
    """Largest gravity moment [N·m] about each joint from the bodies distal to it.

    Computed in the canonical pose with the distal subtree's centre of mass at its
    distance from the joint (the worst case: that lever horizontal).
    """
    skel = get_skeleton(sp)
    pos = skel.fk(np.zeros(3), np.tile([1.0, 0.0, 0.0, 0.0], (len(JOINT_NAMES), 1)))
    mass = np.zeros(len(JOINT_NAMES))
    com = np.zeros((len(JOINT_NAMES), 3))
    for j, name in enumerate(JOINT_NAMES):
        if name in solids:
            mass[j] = density * solids[name].volume
            com[j] = pos[j] + solids[name].center_mass
    out: dict[str, float] = {}
    for j, name in enumerate(JOINT_NAMES):
        sub = [j]
        for c in range(j + 1, len(JOINT_NAMES)):  # parents precede children
            if PARENTS[c] in sub:
                sub.append(c)
        m_sub = mass[sub].sum()
        if m_sub <= 0:
            out[name] = 0.0
            continue
        c_sub = (mass[sub, None] * com[sub]).sum(0) / m_sub
        out[name] = float(m_sub * GRAVITY * np.linalg.norm(c_sub - pos[j]))
    return out


def _foot_radius(sp: Species, toe: str) -> float:
    """Radius [m] of a foot's contact sphere: the foot segment's girth radius."""
    limb = "fore" if toe[1] == "f" else "hind"
    return sp.girths[f"{limb}_foot"] / (2.0 * math.pi)
