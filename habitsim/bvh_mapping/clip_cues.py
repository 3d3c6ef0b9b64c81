"""What a clip's motion says about its rig: which chains animate, how high a point rests,
which axis is up (the feet below the body on one ground), which way the body goes (the
stance feet's sweep), and which chain carries a skull."""

from __future__ import annotations

import numpy as np

from .tree import _Tree

#: The six signed coordinate axes an up axis is chosen among.
SIGNED_AXES: tuple[str, ...] = ("+x", "-x", "+y", "-y", "+z", "-z")


def axis_vector(axis: str) -> np.ndarray:
    """The unit vector of a signed axis name (``"+y"``, ``"-z"``)."""
    v = np.zeros(3)
    v["xyz".index(axis[-1])] = -1.0 if axis.startswith("-") else 1.0
    return v


def chain_motion(t: _Tree, chain: list[int]) -> float:
    """How far a chain's tip moves over the clip, seen from the joint the chain hangs
    from (in that joint's frame), as a share of the chain's length: 0 for a chain whose
    joints keep their pose (a static copy of a leg), about a third for a walking leg."""
    pos, rot = t.fk()
    tip, base = chain[-1], t.parents[chain[0]]
    length = t.chain_length(chain) + float(t.blen[chain[0]])
    if length <= 0:
        return 0.0
    if base < 0:
        rel = pos[:, tip] - pos[:, chain[0]]
    else:
        rel = np.einsum("fba,fb->fa", rot[:, base], pos[:, tip] - pos[:, base])
    dev = np.linalg.norm(rel - np.median(rel, axis=0), axis=-1)
    return float(np.percentile(dev, 95)) / length


def low_heights(pos: np.ndarray, joints: list[int], up: np.ndarray, pct: float) -> np.ndarray:
    """Each joint's low height along ``up`` over the clip (its ``pct`` percentile)."""
    return np.percentile(pos[:, joints] @ up, pct, axis=0)


def up_scores(
    pos: np.ndarray, feet: list[int], body: list[int], leg: float, pct: float
) -> dict[str, float]:
    """A score per signed axis of how well it fits as up [leg lengths]: the body's
    median height above the feet, less the spread of the feet's low heights (feet on one
    ground rest at one height). Up scores about the hip height; a horizontal axis scores
    about zero less the body's length or width between the feet."""
    out = {}
    for axis in SIGNED_AXES:
        h = pos @ axis_vector(axis)
        low = np.percentile(h[:, feet], pct, axis=0)
        spread = float(low.max() - low.min())
        lift = float(np.median(h[:, body].mean(axis=1) - h[:, feet].mean(axis=1)))
        out[axis] = (lift - spread) / leg
    return out


def body_travel(
    pos: np.ndarray,
    feet: list[int],
    ends: tuple[list[int], list[int]],
    up: np.ndarray,
    leg: float,
    fps: float,
    pct: float,
    down_share: float,
) -> float:
    """The body's speed toward ``ends[1]`` from ``ends[0]`` [leg lengths / s], from the
    stance feet's sweep: a foot at rest on the ground moves backward under the body as
    fast as the body goes forward, in a travelling clip and in an in-place loop alike.

    Args:
        pos: (F, J, 3) joint positions.
        feet: the feet's joints.
        ends: the joints of the trunk's two ends (the two leg pairs' roots).
        up: the up vector.
        leg: the leg length [file units].
        fps: frames per second.
        pct: the percentile taken as a foot's resting height.
        down_share: a foot within this share of ``leg`` of its resting height is down.
    """
    if pos.shape[0] < 3:
        return 0.0
    a, b = pos[:, ends[0]].mean(axis=1), pos[:, ends[1]].mean(axis=1)
    d = b - a
    d = d - (d @ up)[:, None] * up
    n = np.linalg.norm(d, axis=-1, keepdims=True)
    ok = n[:, 0] > 1e-9
    d = np.where(ok[:, None], d / np.where(ok[:, None], n, 1.0), 0.0)
    mid = 0.5 * (a + b)
    sweeps = []
    for f in feet:
        h = pos[:, f] @ up
        down = h <= np.percentile(h, pct) + down_share * leg
        rel = np.sum((pos[:, f] - mid) * d, axis=-1)
        v = np.gradient(rel) * fps
        if down.sum() >= 2:
            sweeps.append(float(v[down].mean()))
    if not sweeps:
        return 0.0
    return -float(np.mean(sweeps)) / leg


def carries_skull(t: _Tree, chain: list[int]) -> bool:
    """True if a chain has a joint with two or more children (a skull carries a jaw,
    ears, eyes or a nub); a tail, a neck alone or a spine is one unbranched line."""
    return any(len(t.kids[c]) >= 2 for c in chain if not t.bvh.is_end_site[c])
