"""The feet of a model and the joints that move them (:class:`LegSet`).

Every actuated joint on the chain trunk → foot (the Jacobian ``Jᵢ`` of the foot point is
non-zero only there, so ``τ = −Jᵢᵀ fᵢ`` loads exactly that chain, spine joints included),
and the joints that belong to one leg alone (:attr:`LegSet.own`, used for swing and
posture). Feet default to the usual names (:func:`default_feet`); the leg length of a
model without a species is :func:`model_leg_length` (:func:`habitsim.mjutils.leg_length`).

Units: SI (m, s, kg, N, N·m, rad); world frame z up.
"""

from __future__ import annotations

from collections.abc import Sequence

import mujoco
import numpy as np

from habitsim.mjutils import (
    HABITSIM_FEET,
    ROBOT_FEET,
    ModelLookupError,
    free_body,
    known_feet,
    leg_length,
    point_pos,
    standing_feet,
)

from .base import ControllerError, JointActuatorMap, actuated_joints
from .gains import _point_body, _resolve_points

__all__ = ["HABITSIM_FEET", "default_feet", "model_leg_length", "LegSet"]


def default_feet(model: mujoco.MjModel) -> tuple[str, ...]:
    """The model's feet in the order LF, RF, LH, RH, found by the usual names
    (:func:`habitsim.mjutils.known_feet`), else as the four legs standing on the ground
    at the home pose (:func:`habitsim.mjutils.standing_feet`).

    Raises:
        ControllerError: no known naming matches (pass ``feet=`` explicitly).
    """
    names = known_feet(model)
    if names is not None:
        return names
    try:
        return standing_feet(model)
    except ModelLookupError as e:
        raise ControllerError(
            "cannot find the feet of the model by name (tried "
            + "; ".join(", ".join(n) for n in (HABITSIM_FEET, *ROBOT_FEET))
            + f") nor as the legs standing at home ({e}); pass feet=[...] (site, geom or "
            "body names in the order LF, RF, LH, RH)"
        ) from e


def model_leg_length(model: mujoco.MjModel, feet: Sequence[str] | None = None) -> float:
    """A model's leg length [m] when no species says it (:func:`habitsim.mjutils.leg_length`:
    the height of the trunk above the mean of the feet at the home pose)."""
    if free_body(model) < 0:
        raise ControllerError("the model has no free joint")
    try:
        return leg_length(model, feet or default_feet(model))
    except ModelLookupError as e:
        raise ControllerError(str(e)) from e


class LegSet:
    """The feet of a model and the joints that move them.

    Args:
        model: the MuJoCo model (one free joint: the trunk).
        feet: foot names (site, geom or body), default :func:`default_feet`; the order is
            the order of contact labels (LF, RF, LH, RH for habitsim motions).

    Attributes:
        feet: the names; points: ``(kind, id)`` per foot; bodies: (nf,) foot bodies.
        trunk: free-joint body; qadr, dadr: its qpos / dof addresses.
        jmap: every actuated hinge/slide joint (the controller's joint order).
        own: (nf, n) bool, joint k belongs to foot i's leg alone (on its chain, on no
            other foot's chain).
        body: (n,) bool, joints on no foot's chain or on several (spine, neck, tail).
        radius: (nf,) foot sphere radius [m] (0 for sites/bodies without a sphere geom).
        mass: total mass [kg]; leg_mass: (nf,) mass of each leg's own bodies [kg].
    """

    def __init__(self, model: mujoco.MjModel, feet: Sequence[str] | None = None) -> None:
        self.feet = tuple(feet) if feet is not None else default_feet(model)
        if not self.feet:
            raise ControllerError("at least one foot is needed")
        self.points = _resolve_points(model, list(self.feet))
        self.trunk = free_body(model)
        if self.trunk < 0:
            raise ControllerError("balance control needs a model with a free joint (the trunk)")
        jnt = int(model.body_jntadr[self.trunk])
        self.qadr, self.dadr = int(model.jnt_qposadr[jnt]), int(model.jnt_dofadr[jnt])
        self.bodies = np.array([_point_body(model, k, i) for k, i in self.points], dtype=int)
        self.jmap: JointActuatorMap = actuated_joints(model)
        nf, n = len(self.feet), len(self.jmap.names)
        on_chain = np.zeros((nf, n), dtype=bool)
        for i, fb in enumerate(self.bodies):
            chain = set()
            b = int(fb)
            while b > 0 and b != self.trunk:
                chain.add(b)
                b = int(model.body_parentid[b])
            if b != self.trunk:
                raise ControllerError(f"foot {self.feet[i]!r} is not below the trunk body")
            for k, j in enumerate(self.jmap.joint_ids):
                on_chain[i, k] = int(model.jnt_bodyid[j]) in chain
        shared = on_chain.sum(axis=0) > 1
        self.own = on_chain & ~shared[None, :]
        self.on_chain = on_chain
        self.body = ~self.own.any(axis=0)
        for i in range(nf):
            if not self.own[i].any():
                raise ControllerError(f"foot {self.feet[i]!r} has no actuated joint of its own")
        self.mass = float(model.body_subtreemass[self.trunk])
        # each leg's own bodies: subtree of the highest body carrying one of its own joints
        self.leg_mass = np.zeros(nf)
        for i in range(nf):
            tops = [int(model.jnt_bodyid[j]) for j in self.jmap.joint_ids[self.own[i]]]
            depth = [self._depth(model, b) for b in tops]
            self.leg_mass[i] = float(model.body_subtreemass[tops[int(np.argmin(depth))]])
        self.radius = np.zeros(nf)
        self.geom_lut = np.full(model.ngeom, -1, dtype=int)
        for i, (kind, oid) in enumerate(self.points):
            if kind == "geom" and int(model.geom_type[oid]) == int(mujoco.mjtGeom.mjGEOM_SPHERE):
                self.radius[i] = float(model.geom_size[oid, 0])
            # every colliding geom of the foot's body is "the foot" (a paw's toe capsule
            # or a plantigrade sole touches the ground as well as the foot sphere)
            geoms = [
                g
                for g in range(model.ngeom)
                if model.geom_bodyid[g] == self.bodies[i]
                and (model.geom_contype[g] or model.geom_conaffinity[g])
            ]
            if kind == "geom":
                geoms.append(oid)
            self.geom_lut[geoms] = i
        # padded index of each leg's own joints (for batched null-space projection)
        width = int(self.own.sum(axis=1).max())
        self.own_idx = np.full((nf, width), n, dtype=int)  # n = a zero column
        for i in range(nf):
            cols = np.flatnonzero(self.own[i])
            self.own_idx[i, : cols.size] = cols
        kinds = {k for k, _ in self.points}
        self._kind = kinds.pop() if len(kinds) == 1 else "mixed"
        self._ids = np.array([i for _, i in self.points], dtype=int)
        self._foot_range = np.arange(nf)
        self._body_list = [int(b) for b in self.bodies]

    @staticmethod
    def _depth(model: mujoco.MjModel, b: int) -> int:
        d = 0
        while b > 0:
            b = int(model.body_parentid[b])
            d += 1
        return d

    @property
    def n_feet(self) -> int:
        return len(self.feet)

    def positions(self, data: mujoco.MjData) -> np.ndarray:
        """(nf, 3) foot points [m], world frame (from ``data``'s kinematics)."""
        if self._kind == "geom":
            return data.geom_xpos[self._ids]
        if self._kind == "site":
            return data.site_xpos[self._ids]
        return np.array([point_pos(data, k, i) for k, i in self.points])

    def jacobians(
        self,
        model: mujoco.MjModel,
        data: mujoco.MjData,
        points: np.ndarray,
        out: np.ndarray | None = None,
    ) -> np.ndarray:
        """(nf, 3, nv) translational Jacobians of the foot points (into ``out``)."""
        if out is None:
            out = np.empty((self.n_feet, 3, model.nv))
        for i, b in enumerate(self._body_list):
            mujoco.mj_jac(model, data, out[i], None, points[i], b)
        return out

    def touching(self, data: mujoco.MjData) -> np.ndarray:
        """(nf,) bool: the foot has an active contact (any colliding geom of its body)."""
        return self.contact_points(data)[0]

    def contact_points(self, data: mujoco.MjData) -> tuple[np.ndarray, np.ndarray]:
        """(touching (nf,) bool, points (nf, 3)): per foot whether any geom of its body
        has a contact, and the mean position of those contacts (NaN without contact) —
        where the ground really pushes, which for a paw lying on its toe capsule or a
        plantigrade sole is not the foot sphere's centre."""
        nf = self.n_feet
        if not data.ncon:
            return np.zeros(nf, dtype=bool), np.full((nf, 3), np.nan)
        con = data.contact
        geoms = con.geom
        foot = np.maximum(self.geom_lut[geoms[:, 0]], self.geom_lut[geoms[:, 1]])
        onehot = (foot[:, None] == self._foot_range).astype(float)  # (ncon, nf); -1: none
        count = onehot.sum(axis=0)
        touch = count > 0
        pts = (onehot.T @ con.pos) / np.maximum(count, 1.0)[:, None]
        pts[~touch] = np.nan
        return touch, pts
