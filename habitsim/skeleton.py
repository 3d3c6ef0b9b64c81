"""The shared quadruped skeleton: one topology for every species, per-species offsets.

Topology (30 joints; names are also the stems of MJCF joint names):

* axial: ``pelvis`` (root, at the sacrum) → ``spine1`` (lumbar) → ``spine2`` (thoracic)
  → ``spine3`` (withers) → ``neck`` → ``head`` (skull base) → ``snout`` (end point);
  ``pelvis`` → ``tail1`` → ``tail2`` → ``tail3`` (end point);
* fore legs (``lf_`` / ``rf_``): ``scapula`` (girdle root, child of ``spine3``) →
  ``shoulder`` → ``elbow`` → ``wrist`` → ``toe`` (end point);
* hind legs (``lh_`` / ``rh_``): ``ilium`` (girdle root, child of ``pelvis``) → ``hip``
  → ``knee`` → ``hock`` → ``toe`` (end point).

A joint's local rotation turns the bones to its children (BVH convention). In the
canonical pose (all local rotations identity) the legs point straight down (-z), spine,
neck and head point forward (+x) and the tail points backward (-x); world frame z up,
x forward, y left, metres. The species' standing posture is a set of local rotations
about the lateral (+y) axis on top of this canonical pose (see :func:`standing_pose`).

Hinge convention (what the MJCF models of each species can represent exactly, so a
motion made of these rotations maps onto ``qpos`` without residual):

* ``*_shoulder`` and ``*_hip``: R = R_x(abd) · R_y(flex) (abduction outermost);
* other leg joints (``scapula, elbow, wrist, ilium, knee, hock``): R = R_y(flex);
* ``spine1..3``, ``neck``, ``head``, ``tail1..2``: R = R_z(yaw) · R_y(pitch);
* ``pelvis``: free (the root's global orientation); end points (``snout``, ``tail3``,
  ``*_toe``) carry no rotation of consequence (identity by convention).

R_y(a) with a > 0 swings a downward-pointing bone backward; R_x(a) with a > 0 swings it
toward +y (to the animal's left) — outward for the left legs, inward for the right legs;
use :data:`ABDUCTION_SIGN` to get "outward = positive" for either side.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from .errors import InvalidMotionError
from .rotations import quat_to_matrix, rot_y
from .species import Species, load_species, standing_global_pitch, standing_leg_angles

__all__ = [
    "JOINT_NAMES",
    "PARENTS",
    "FOOT_JOINTS",
    "ABDUCTION_SIGN",
    "LEG_ROLE_JOINTS",
    "LEG_PREFIXES",
    "Skeleton",
    "get_skeleton",
    "standing_leg_angles",
    "fk",
]

LEG_PREFIXES = ("lf", "rf", "lh", "rh")  # the order of FEET: LF, RF, LH, RH
_FORE = ("scapula", "shoulder", "elbow", "wrist", "toe")
_HIND = ("ilium", "hip", "knee", "hock", "toe")

_TOPOLOGY: list[tuple[str, str | None]] = [
    ("pelvis", None),
    ("spine1", "pelvis"),
    ("spine2", "spine1"),
    ("spine3", "spine2"),
    ("neck", "spine3"),
    ("head", "neck"),
    ("snout", "head"),
    ("tail1", "pelvis"),
    ("tail2", "tail1"),
    ("tail3", "tail2"),
]
for _side in ("l", "r"):
    _prev = "spine3"
    for _seg in _FORE:
        _TOPOLOGY.append((f"{_side}f_{_seg}", _prev))
        _prev = f"{_side}f_{_seg}"
for _side in ("l", "r"):
    _prev = "pelvis"
    for _seg in _HIND:
        _TOPOLOGY.append((f"{_side}h_{_seg}", _prev))
        _prev = f"{_side}h_{_seg}"
# Order the legs LF, RF, LH, RH (already so: lf, rf fore; lh, rh hind).

JOINT_NAMES: tuple[str, ...] = tuple(n for n, _ in _TOPOLOGY)
_INDEX = {n: i for i, n in enumerate(JOINT_NAMES)}
PARENTS: tuple[int, ...] = tuple(-1 if p is None else _INDEX[p] for _, p in _TOPOLOGY)
FOOT_JOINTS: tuple[str, ...] = ("lf_toe", "rf_toe", "lh_toe", "rh_toe")
#: Multiply an "outward" abduction angle by this to get the R_x angle of a leg's side.
ABDUCTION_SIGN: dict[str, float] = {"l": 1.0, "r": -1.0}

#: Which local joint carries which leg-flexion role of the species' joint limits.
LEG_ROLE_JOINTS: dict[str, tuple[str, ...]] = {
    "fore_girdle": ("scapula",),
    "fore_upper": ("shoulder",),
    "fore_lower": ("elbow",),
    "fore_foot": ("wrist",),
    "hind_girdle": ("ilium",),
    "hind_upper": ("hip",),
    "hind_lower": ("knee",),
    "hind_foot": ("hock",),
}


def _offsets(sp: Species) -> np.ndarray:
    """Canonical-pose bone offsets (J, 3) [m] of a species, each relative to its parent."""
    s = sp.segments
    off = np.zeros((len(JOINT_NAMES), 3))

    def put(name: str, v: tuple[float, float, float]) -> None:
        off[_INDEX[name]] = v

    t = s["trunk"]
    put("spine1", (t / 3, 0, 0))
    put("spine2", (t / 3, 0, 0))
    put("spine3", (t / 3, 0, 0))
    put("neck", (0.1 * s["neck"], 0, 0))  # base of the neck just ahead of the withers
    put("head", (0.9 * s["neck"], 0, 0))
    put("snout", (s["head"], 0, 0))
    put("tail1", (-0.05 * t, 0, 0))
    put("tail2", (-0.5 * s["tail"], 0, 0))
    put("tail3", (-0.5 * s["tail"], 0, 0))
    for side, sign in (("l", 1.0), ("r", -1.0)):
        put(f"{side}f_scapula", (0, sign * 0.5 * s["trunk_width_fore"], 0))
        put(f"{side}f_shoulder", (0, 0, -s["fore_girdle"]))
        put(f"{side}f_elbow", (0, 0, -s["fore_upper"]))
        put(f"{side}f_wrist", (0, 0, -s["fore_lower"]))
        put(f"{side}f_toe", (0, 0, -s["fore_foot"]))
        put(f"{side}h_ilium", (0, sign * 0.5 * s["trunk_width_hind"], 0))
        put(f"{side}h_hip", (0, 0, -s["hind_girdle"]))
        put(f"{side}h_knee", (0, 0, -s["hind_upper"]))
        put(f"{side}h_hock", (0, 0, -s["hind_lower"]))
        put(f"{side}h_toe", (0, 0, -s["hind_foot"]))
    return off


@dataclass(frozen=True, eq=False)
class Skeleton:
    """The habitsim topology with one species' bone offsets.

    Attributes:
        species: species name.
        joint_names: the 30 joint names (same for every species).
        parents: parent index per joint (-1 for the root).
        offsets: (J, 3) canonical-pose offset of each joint from its parent [m].
        species_info: the :class:`Species` it was made of (None: loaded by name).
    """

    species: str
    joint_names: tuple[str, ...]
    parents: tuple[int, ...]
    offsets: np.ndarray
    species_info: Species | None = None

    @property
    def num_joints(self) -> int:
        return len(self.joint_names)

    @property
    def foot_joints(self) -> tuple[str, ...]:
        """Toe end points in the order LF, RF, LH, RH."""
        return FOOT_JOINTS

    @property
    def foot_indices(self) -> np.ndarray:
        return np.array([_INDEX[n] for n in FOOT_JOINTS])

    def index(self, name: str) -> int:
        """Index of a joint by name (KeyError lists the valid names)."""
        try:
            return _INDEX[name]
        except KeyError:
            raise InvalidMotionError(
                f"unknown joint {name!r}; valid: {', '.join(self.joint_names)}"
            ) from None

    @property
    def bone_lengths(self) -> np.ndarray:
        """(J,) length of the bone from each joint's parent to it (0 for the root)."""
        return np.linalg.norm(self.offsets, axis=-1)

    @functools.cached_property
    def _standing(self) -> tuple[np.ndarray, np.ndarray]:
        sp = self.species_info or load_species(self.species)
        g = standing_global_pitch(sp)
        ang = np.zeros(self.num_joints)
        ang[_INDEX["pelvis"]] = g["trunk"]
        loc = standing_leg_angles(sp)
        for side in ("l", "r"):
            for limb, segs in (("f", _FORE), ("h", _HIND)):
                limb_name = "fore" if limb == "f" else "hind"
                for seg, role in zip(segs[:4], ("girdle", "upper", "lower", "foot"), strict=True):
                    ang[_INDEX[f"{side}{limb}_{seg}"]] = loc[f"{limb_name}_{role}_flex"]
        ang[_INDEX["neck"]] = loc["neck_pitch"]
        ang[_INDEX["head"]] = loc["head_pitch"]
        ang[_INDEX["tail1"]] = loc["tail_pitch"]
        quats = rot_y(ang)
        root = np.zeros(3)
        pos = fk(self, root[None], quats[None])[0]
        root[2] = -pos[self.foot_indices[2:], 2].mean()  # hind toes on the ground
        return root, quats

    def standing_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """The species' standing posture: root position (3,) and local quats (J, 4).

        The hind toes touch the ground (z = 0); the trunk is pitched so that the fore toes
        do too.
        """
        root, quats = self._standing
        return root.copy(), quats.copy()

    def fk(self, root_pos: np.ndarray, quats: np.ndarray) -> np.ndarray:
        """Global joint positions (…, J, 3) [m], see :func:`fk`."""
        return fk(self, root_pos, quats)


def get_skeleton(species: str | Species) -> Skeleton:
    """The skeleton of a species (cached per loaded :class:`Species`: a user species
    whose file changed is loaded anew, and gets a skeleton of its new numbers)."""
    return _skeleton(load_species(species))


@functools.lru_cache(maxsize=256)
def _skeleton(sp: Species) -> Skeleton:
    return Skeleton(sp.name, JOINT_NAMES, PARENTS, _offsets(sp), sp)


def _check_fk_shapes(root_shape: tuple[int, ...], q_shape: tuple[int, ...], j: int) -> None:
    if len(q_shape) < 2 or q_shape[-2:] != (j, 4):
        raise InvalidMotionError(f"quaternions must have shape (..., {j}, 4), got {q_shape}")
    if root_shape[-1:] != (3,) or root_shape[:-1] != q_shape[:-2]:
        raise InvalidMotionError(
            f"root positions must have shape {(*q_shape[:-2], 3)}, got {root_shape}"
        )


def fk(skel: Skeleton, root_pos: np.ndarray, quats: np.ndarray, return_rotations: bool = False):
    """Batched forward kinematics in numpy.

    Args:
        skel: the skeleton (offsets and parents).
        root_pos: (…, 3) root (pelvis) positions [m].
        quats: (…, J, 4) local rotations, unit quaternions wxyz.
        return_rotations: also return the global rotation matrices (…, J, 3, 3).

    Returns:
        (…, J, 3) global joint positions [m] (and the global rotations if asked).
    """
    root_pos = np.asarray(root_pos, dtype=np.float64)
    quats = np.asarray(quats, dtype=np.float64)
    _check_fk_shapes(root_pos.shape, quats.shape, skel.num_joints)
    local = quat_to_matrix(quats)  # (…, J, 3, 3)
    glob = np.empty_like(local)
    pos = np.empty((*quats.shape[:-1], 3))
    for j, p in enumerate(skel.parents):
        if p < 0:
            glob[..., j, :, :] = local[..., j, :, :]
            pos[..., j, :] = root_pos
        else:
            glob[..., j, :, :] = glob[..., p, :, :] @ local[..., j, :, :]
            pos[..., j, :] = pos[..., p, :] + glob[..., p, :, :] @ skel.offsets[j]
    return (pos, glob) if return_rotations else pos
