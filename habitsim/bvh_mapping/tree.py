"""The source rig as a tree: children, depths, heights, name cues, bone lengths and
the paths and chains through it."""

from __future__ import annotations

import numpy as np

from ..bvh import BVHData
from .names import is_control_name, is_never_limb_name, is_segment_name, name_cues


class _Tree:
    def __init__(self, bvh: BVHData):
        self.bvh = bvh
        self.n = bvh.num_joints
        self.parents = bvh.parents
        self.kids: list[list[int]] = [[] for _ in range(self.n)]
        for j, p in enumerate(bvh.parents):
            if p >= 0:
                self.kids[p].append(j)
        self.height = [0] * self.n  # longest path (in joints) below j
        for j in reversed(range(self.n)):
            if self.kids[j]:
                self.height[j] = 1 + max(self.height[c] for c in self.kids[j])
        self.depth = [0] * self.n
        for j, p in enumerate(bvh.parents):
            self.depth[j] = 0 if p < 0 else self.depth[p] + 1
        self.cues = [name_cues(n) for n in bvh.names]
        self.blen = np.linalg.norm(bvh.offsets, axis=1)
        #: helpers that are never part of a limb (tails, armour, nubs)
        self.never = [is_never_limb_name(n) for n in bvh.names]
        #: control bones (IK, pole, target, twist, roll, MCH/ORG): limbs only if they animate
        self.control = [is_control_name(n) and not self.never[j] for j, n in enumerate(bvh.names)]
        #: twist and roll bones, which lie along a limb bone
        self.segment = [is_segment_name(n) and not self.never[j] for j, n in enumerate(bvh.names)]
        self._fk: tuple[np.ndarray, np.ndarray] | None = None

    def fk(self) -> tuple[np.ndarray, np.ndarray]:
        """The clip's joint positions (F, J, 3) and rotations (F, J, 3, 3), computed once."""
        if self._fk is None:
            self._fk = self.bvh.fk(return_rotations=True)
        return self._fk

    def _limb_kids(self, j: int) -> list[int]:
        """Children of j a limb may continue through: never helpers, and control bones
        only where j has no other child (a chain of control bones is followed whole)."""
        kids = [c for c in self.kids[j] if not self.never[c]]
        if self.control[j]:
            return kids
        plain = [c for c in kids if not self.control[c]]
        return plain or [c for c in kids if self.segment[c]]

    def ancestors(self, j: int) -> list[int]:
        out = []
        while self.parents[j] >= 0:
            j = self.parents[j]
            out.append(j)
        return out

    def is_ancestor(self, a: int, b: int) -> bool:
        """True if a is a strict ancestor of b."""
        return a in self.ancestors(b)

    def deepest_path(self, j: int) -> list[int]:
        out = [j]
        while self.kids[j]:
            j = max(self.kids[j], key=lambda c: self.height[c])  # first on ties
            out.append(j)
        return out

    def is_pure(self, j: int) -> bool:
        """True if the subtree of j is one chain (rig helpers hanging off it aside)."""
        while True:
            kids = self._limb_kids(j)
            if not kids:
                return True
            if len(kids) > 1:
                return False
            j = kids[0]

    def leg_path(self, j: int) -> list[int]:
        """The limb chain from j down: rig helpers skipped, the deepest real child taken.

        A trailing End Site is kept only when it hangs directly from the last real joint
        (it is then the toe tip); an End Site below a helper (a biped nub) is not.
        """
        out = [j]
        while True:
            kids = self._limb_kids(j)
            real = [c for c in kids if not self.bvh.is_end_site[c]]
            if real:
                j = max(real, key=lambda c: self.height[c])  # first on ties
                out.append(j)
                continue
            if kids and not self.bvh.is_end_site[j]:
                out.append(kids[0])
            return out

    def path(self, a: int, b: int) -> list[int]:
        """Joints from a to b through the tree (both included)."""
        up_a = [a] + self.ancestors(a)
        up_b = [b] + self.ancestors(b)
        common = next(x for x in up_a if x in up_b)
        return up_a[: up_a.index(common) + 1] + list(reversed(up_b[: up_b.index(common)]))

    def path_length(self, a: int, b: int) -> float:
        """Sum of bone lengths along the tree path from a to b [file units]."""
        p = self.path(a, b)
        lca_pos = min(range(len(p)), key=lambda k: self.depth[p[k]])
        return float(sum(self.blen[j] for k, j in enumerate(p) if k != lca_pos))

    def chain_length(self, chain: list[int]) -> float:
        return float(sum(self.blen[j] for j in chain[1:]))

    def lca(self, joints: list[int]) -> int:
        common = [joints[0]] + self.ancestors(joints[0])
        for j in joints[1:]:
            anc = {j, *self.ancestors(j)}
            common = [c for c in common if c in anc]
        return common[0]
