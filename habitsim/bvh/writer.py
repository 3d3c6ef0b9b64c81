"""Writing a habitsim motion as BVH in habitsim's own frame and joint names
(:func:`bvh_text`, :func:`write_bvh`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InvalidMotionError
from ..fileio import atomic_write
from ..rotations import quat_to_euler
from .data import _fmt


def _check_order(order: str) -> str:
    o = str(order).upper()
    if len(o) != 3 or sorted(o) != ["X", "Y", "Z"]:
        raise InvalidMotionError(
            f"rotation order {order!r}: use a permutation of XYZ (XYZ, XZY, YXZ, YZX, ZXY, ZYX)"
        )
    return o


def bvh_text(motion, order: str = "ZXY") -> str:
    """The BVH text of a habitsim motion (see :mod:`habitsim.bvh` for the convention).

    Args:
        motion: a :class:`habitsim.motion.Motion`.
        order: rotation channel order of every joint, a permutation of ``"XYZ"``; channel
            values are intrinsic Euler angles in degrees in that order.

    Returns:
        The file contents (``\\n`` line endings).
    """
    order = _check_order(order)
    skel = motion.skeleton
    rot_ch = " ".join(f"{a}rotation" for a in order)
    children: dict[int, list[int]] = {j: [] for j in range(skel.num_joints)}
    for j, p in enumerate(skel.parents):
        if p >= 0:
            children[p].append(j)
    out = ["HIERARCHY"]

    def emit(j: int, depth: int) -> None:
        ind = "  " * depth
        kw = "ROOT" if skel.parents[j] < 0 else "JOINT"
        out.append(f"{ind}{kw} {skel.joint_names[j]}")
        out.append(f"{ind}{{")
        off = np.zeros(3) if skel.parents[j] < 0 else skel.offsets[j]
        out.append(f"{ind}  OFFSET {' '.join(_fmt(v) for v in off)}")
        if skel.parents[j] < 0:
            out.append(f"{ind}  CHANNELS 6 Xposition Yposition Zposition {rot_ch}")
        else:
            out.append(f"{ind}  CHANNELS 3 {rot_ch}")
        if children[j]:
            for c in children[j]:
                emit(c, depth + 1)
        else:
            out.append(f"{ind}  End Site")
            out.append(f"{ind}  {{")
            out.append(f"{ind}    OFFSET 0 0 0")
            out.append(f"{ind}  }}")
        out.append(f"{ind}}}")

    emit(0, 0)
    # Channel order of the data = depth-first order of emission.
    dfs: list[int] = []

    def walk(j: int) -> None:
        dfs.append(j)
        for c in children[j]:
            walk(c)

    walk(0)
    euler = np.degrees(quat_to_euler(motion.rotations, order))  # (T, J, 3)
    t = motion.num_frames
    cols = [motion.root_positions] + [euler[:, j] for j in dfs]
    data = np.concatenate(cols, axis=1)
    out.append("MOTION")
    out.append(f"Frames: {t}")
    out.append(f"Frame Time: {1.0 / motion.fps!r}")
    for row in data:
        out.append(" ".join(_fmt(v) for v in row))
    return "\n".join(out) + "\n"


def write_bvh(motion, path: str | Path, order: str = "ZXY") -> Path:
    """Export a habitsim motion to a BVH file, atomically.

    The file uses habitsim's frame (z up, x forward, y left, metres) and joint names; the
    root carries 6 channels, every other joint 3 rotation channels in ``order``. Reading it
    back with :func:`habitsim.bvh_mapping.import_bvh` on the same species reproduces the
    motion (joint positions within 1e-5 m).

    Args:
        motion: the :class:`habitsim.motion.Motion` to export.
        path: output ``.bvh`` path (written only if the whole export succeeds).
        order: rotation channel order, a permutation of ``"XYZ"``.

    Returns:
        The written path.
    """
    text = bvh_text(motion, order)
    p = Path(path)
    with atomic_write(p, "w") as fh:
        fh.write(text)
    return p
