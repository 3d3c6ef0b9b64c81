"""A lying pose and a clip that starts lying: the animal lies flat, gets up, then does
what the clip does.

Not an action of the generator (no footfall plan, no IK): a pose and a blend, made to
give the pipeline clips whose start it must recognise and leave out
(:mod:`habitsim.activity`). The pose is a sploot: trunk level on the ground, fore legs
stretched forward, hind legs stretched backward, so the toes and the trunk all rest on
the ground.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from ..errors import GaitError
from ..rotations import heading_yaw, quat_mul, quat_slerp, rot_y, rot_z
from ..skeleton import _FORE, _HIND, _INDEX, JOINT_NAMES, get_skeleton
from ..species import Species, load_species

if TYPE_CHECKING:  # pragma: no cover
    from ..motion import Motion

__all__ = ["lying_pose", "with_lying_start"]


def lying_pose(species: str | Species) -> tuple[np.ndarray, np.ndarray]:
    """The species lying flat, heading +x: root position (3,) [m] and local quats (J, 4).

    The standing pose (:meth:`habitsim.skeleton.Skeleton.standing_pose`) with the trunk
    level, the fore legs stretched forward and the hind legs backward (straight from the
    girdles, tilted down just enough that the toes reach the ground with the trunk's
    joints a tenth of a leg length above it), the lowest toe on the ground (z = 0).
    """
    sp = load_species(species)
    skel = get_skeleton(sp)
    _, quats = skel.standing_pose()
    quats[_INDEX["pelvis"]] = rot_y(0.0)
    for name in ("spine1", "spine2", "spine3"):
        quats[_INDEX[name]] = rot_y(0.0)
    # girdle and leg straight along the trunk, tilted down so that the toes touch the
    # ground with the trunk's joints a tenth of a leg length above it
    lift = 0.1 * sp.leg_length
    for side in ("l", "r"):
        for limb, sign, segs in (("f", -1.0, _FORE), ("h", 1.0, _HIND)):
            reach = float(skel.bone_lengths[[_INDEX[f"{side}{limb}_{g}"] for g in segs[1:]]].sum())
            tilt = math.asin(min(1.0, lift / max(reach, 1e-9)))
            quats[_INDEX[f"{side}{limb}_{segs[0]}"]] = rot_y(sign * (0.5 * math.pi - tilt))
            for seg in segs[1:-1]:
                quats[_INDEX[f"{side}{limb}_{seg}"]] = rot_y(0.0)
    root = np.zeros(3)
    pos = skel.fk(root[None], quats[None])[0]
    root[2] = -pos[skel.foot_indices, 2].min()
    return root, quats


def with_lying_start(motion: Motion, lying_s: float = 2.0, rise_s: float = 1.0) -> Motion:
    """``motion`` with a lying start put before it: ``lying_s`` lying flat where and
    heading as the clip starts, then ``rise_s`` blending (slerp of every joint, the root
    linearly) into the clip's first frame, then the clip. Stance labels, when the clip has
    them, are all four feet down before it; metadata is kept.

    Args:
        motion: a :class:`~habitsim.motion.Motion`.
        lying_s, rise_s: durations [s] (>= 0; the rise at least one frame).

    Raises:
        GaitError: a negative or non-finite duration.
    """
    from ..motion import Motion

    if not (math.isfinite(lying_s) and lying_s >= 0 and math.isfinite(rise_s) and rise_s >= 0):
        raise GaitError(f"lying_s and rise_s must be finite and >= 0, got {lying_s}, {rise_s}")
    fps = motion.fps
    n_lie = int(round(lying_s * fps))
    n_rise = max(1, int(round(rise_s * fps)))
    root0, q0 = lying_pose(motion.species)
    first_q = motion.rotations[0]
    yaw = float(heading_yaw(first_q[0]))
    q_lie = q0.copy()
    q_lie[0] = quat_mul(rot_z(yaw), q0[0])
    p_lie = np.array([*motion.root_positions[0, :2], root0[2]])
    t = (np.arange(1, n_rise + 1) / (n_rise + 1))[:, None]
    q_rise = quat_slerp(
        np.broadcast_to(q_lie, (n_rise, *q_lie.shape)),
        np.broadcast_to(first_q, (n_rise, *first_q.shape)),
        np.broadcast_to(t, (n_rise, len(JOINT_NAMES))),
    )
    p_rise = p_lie + t * (motion.root_positions[0] - p_lie)
    rot = np.concatenate([np.broadcast_to(q_lie, (n_lie, *q_lie.shape)), q_rise, motion.rotations])
    pos = np.concatenate([np.broadcast_to(p_lie, (n_lie, 3)), p_rise, motion.root_positions])
    contacts = None
    if motion.contacts is not None:
        contacts = np.concatenate([np.ones((n_lie + n_rise, 4), bool), motion.contacts])
    return Motion(motion.species, fps, pos, rot, contacts, dict(motion.metadata))
