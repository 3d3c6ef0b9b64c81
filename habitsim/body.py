"""A simple mass model of a species' body for the centre of mass.

Each bone (parent joint → joint) is a cylinder whose radius comes from the species' girth
(circumference) of that body part; its mass sits at the bone's midpoint. Uniform density
is then scaled so the masses add up to the species' body mass. Lateral offsets inside the
trunk (withers → scapula root, pelvis → ilium) and zero-length bones carry no mass.
The MJCF builder uses the same girths for its solids, so the two agree on proportions.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from .skeleton import JOINT_NAMES, get_skeleton
from .species import Species, load_species

__all__ = ["bone_girth_keys", "bone_masses", "center_of_mass"]


def bone_girth_keys() -> dict[str, str | None]:
    """For each joint, the girth key of the bone that ends at it (None = massless)."""
    keys: dict[str, str | None] = {}
    for name in JOINT_NAMES:
        if name == "pelvis":
            keys[name] = None
        elif name.startswith("spine"):
            keys[name] = "trunk"
        elif name in ("neck", "head"):
            keys[name] = "neck"
        elif name == "snout":
            keys[name] = "head"
        elif name.startswith("tail"):
            keys[name] = "tail"
        else:
            limb = "fore" if name[1] == "f" else "hind"
            seg = name[3:]
            keys[name] = {
                "scapula": None,
                "ilium": None,
                "shoulder": f"{limb}_upper",  # girdle bone: shares the upper-limb girth
                "hip": f"{limb}_upper",
                "elbow": f"{limb}_upper",
                "knee": f"{limb}_upper",
                "wrist": f"{limb}_lower",
                "hock": f"{limb}_lower",
                "toe": f"{limb}_foot",
            }[seg]
    return keys


@functools.lru_cache(maxsize=256)
def _bone_masses(sp: Species) -> np.ndarray:
    skel = get_skeleton(sp)
    lengths = skel.bone_lengths
    vol = np.zeros(len(JOINT_NAMES))
    for j, key in enumerate(bone_girth_keys().values()):
        if key is None:
            continue
        r = sp.girths[key] / (2.0 * math.pi)
        vol[j] = math.pi * r * r * lengths[j]
    masses = vol * (sp.mass_kg / vol.sum())
    masses.setflags(write=False)
    return masses


def bone_masses(species: str | Species) -> np.ndarray:
    """(J,) mass [kg] of the bone ending at each joint; sums to the species' mass."""
    return _bone_masses(load_species(species))


def center_of_mass(species: str | Species, positions: np.ndarray) -> np.ndarray:
    """Centre of mass (…, 3) [m] from global joint positions (…, J, 3)."""
    skel = get_skeleton(species)
    m = bone_masses(species)
    pos = np.asarray(positions, dtype=np.float64)
    parents = np.array([max(p, 0) for p in skel.parents])
    mid = 0.5 * (pos + pos[..., parents, :])
    return np.einsum("j,...jk->...k", m, mid) / m.sum()
