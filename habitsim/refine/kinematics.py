"""Symbolic (CasADi SX) forward kinematics of a compiled MuJoCo model's kinematic tree.

:class:`SymbolicKinematics` reads the tree of a compiled :class:`mujoco.MjModel` — body
position and orientation offsets, joint anchors and axes, site / geom / inertial frames —
and rebuilds MuJoCo's ``mj_kinematics`` in CasADi, so positions are differentiable
expressions of ``qpos``. It follows MuJoCo's algorithm step by step (``engine_core_smooth.c``):

* a body with a free joint takes ``xpos = qpos[a:a+3]`` and the normalised quaternion
  ``qpos[a+3:a+7]``; its ``body_pos`` / ``body_quat`` are not used;
* any other body starts at ``xpos = xpos_parent + xmat_parent · body_pos``,
  ``xmat = xmat_parent · R(body_quat)``, then applies its joints in order: a slide moves
  it by ``(q − qpos0)`` along the world axis; a hinge rotates it by ``q − qpos0`` about
  ``jnt_axis`` through the anchor ``jnt_pos``; a ball by its normalised quaternion;
* sites, geoms and centres of mass sit at ``xpos + xmat · local_pos``.

Rotations are 3×3 matrices of SX scalars built element by element so that the many
exact zeros and ones of the offsets (principal hinge axes, identity body quaternions)
never enter the expression graph; a whole 25-body quadruped is a few thousand nodes per
frame. Agreement with ``mj_kinematics`` is checked to 1e-9 in the tests on random poses.

Why not Pinocchio's CasADi bindings: they would need a URDF/MJCF re-import with its own
conventions and are not installed; the MuJoCo tree is small and the algorithm short.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import casadi as ca
import mujoco
import numpy as np

from ..mjutils import free_joints
from .errors import RefineError

__all__ = ["SymbolicKinematics", "FKResult", "quat_to_matrix_sx", "gibbs_to_matrix"]

_Scalar = ca.SX | float
_Mat = list[list[_Scalar]]  # 3×3, row major
_Vec = list[_Scalar]  # 3


# ----------------------------------------------------------------- sparse-aware algebra
def _is_zero(a: _Scalar) -> bool:
    return isinstance(a, float) and a == 0.0


def _mul(a: _Scalar, b: _Scalar) -> _Scalar:
    if _is_zero(a) or _is_zero(b):
        return 0.0
    if isinstance(a, float) and a == 1.0:
        return b
    if isinstance(b, float) and b == 1.0:
        return a
    return a * b


def _add(a: _Scalar, b: _Scalar) -> _Scalar:
    if _is_zero(a):
        return b
    if _is_zero(b):
        return a
    return a + b


def _dot(a: Sequence[_Scalar], b: Sequence[_Scalar]) -> _Scalar:
    out: _Scalar = 0.0
    for x, y in zip(a, b, strict=True):
        out = _add(out, _mul(x, y))
    return out


def _matmul(a: _Mat, b: _Mat) -> _Mat:
    return [[_dot(a[i], [b[k][j] for k in range(3)]) for j in range(3)] for i in range(3)]


def _matvec(a: _Mat, v: _Vec) -> _Vec:
    return [_dot(a[i], v) for i in range(3)]


def _vadd(a: _Vec, b: _Vec) -> _Vec:
    return [_add(x, y) for x, y in zip(a, b, strict=True)]


def _vsub(a: _Vec, b: _Vec) -> _Vec:
    return [_add(x, _mul(-1.0, y)) for x, y in zip(a, b, strict=True)]


def _const_vec(v: np.ndarray) -> _Vec:
    return [float(x) for x in v]


def _const_mat(m: np.ndarray) -> _Mat:
    return [[float(m[i, j]) for j in range(3)] for i in range(3)]


def _quat_mat_np(q: np.ndarray) -> np.ndarray:
    out = np.zeros(9)
    mujoco.mju_quat2Mat(out, np.asarray(q, dtype=np.float64))
    return out.reshape(3, 3)


def _to_sx(m: _Mat | _Vec) -> ca.SX:
    if isinstance(m[0], list):
        return ca.vertcat(*[ca.horzcat(*[ca.SX(x) for x in row]) for row in m])
    return ca.vertcat(*[ca.SX(x) for x in m])


def quat_to_matrix_sx(q: Sequence[_Scalar], normalize: bool = True) -> _Mat:
    """Rotation matrix (3×3 list) of a quaternion (w, x, y, z), MuJoCo's ``mju_quat2Mat``.

    Args:
        q: 4 symbolic or numeric components.
        normalize: divide by the norm first (MuJoCo normalises free/ball quaternions).
    """
    w, x, y, z = (q[i] for i in range(4))
    if normalize:
        n = ca.sqrt(w * w + x * x + y * y + z * z)
        w, x, y, z = w / n, x / n, y / n, z / n
    return [
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ]


def gibbs_to_matrix(g: Sequence[_Scalar]) -> _Mat:
    """Rotation matrix of a Gibbs (Rodrigues-parameter) vector g = tan(φ/2)·axis.

    ``R = I + 2/(1 + g·g) · (K + K²)`` with ``K`` the cross-product matrix of ``g``. It is
    rational (no trigonometry, no square root), smooth everywhere and exact for any
    rotation angle below π; g = 0 is the identity. Its quaternion is (1, g)/‖(1, g)‖.
    """
    gx, gy, gz = (g[i] for i in range(3))
    k = [[0.0, -gz, gy], [gz, 0.0, -gx], [-gy, gx, 0.0]]
    k2 = _matmul(k, k)
    s = 2.0 / (1.0 + gx * gx + gy * gy + gz * gz)
    return [
        [(1.0 if i == j else 0.0) + s * (k[i][j] + k2[i][j]) for j in range(3)] for i in range(3)
    ]


def _axis_angle_mat(axis: np.ndarray, angle: _Scalar) -> _Mat:
    """Rodrigues rotation about a numeric unit axis by a symbolic (or numeric) angle."""
    a = np.asarray(axis, dtype=np.float64)
    a = a / np.linalg.norm(a)
    c, s = ca.cos(angle), ca.sin(angle)
    k = [[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]]
    k2 = (np.outer(a, a) - np.eye(3)).tolist()  # K² = a aᵀ − I for a unit axis
    out: _Mat = []
    for i in range(3):
        row: list[_Scalar] = []
        for j in range(3):
            v: _Scalar = 1.0 if i == j else 0.0
            if k[i][j] != 0.0:
                v = _add(v, _mul(float(k[i][j]), s))
            if abs(k2[i][j]) > 0.0:
                v = _add(v, _mul(float(k2[i][j]), 1 - c))
            row.append(v)
        out.append(row)
    return out


# ----------------------------------------------------------------- the tree
_FREE, _BALL, _SLIDE, _HINGE = (
    int(mujoco.mjtJoint.mjJNT_FREE),
    int(mujoco.mjtJoint.mjJNT_BALL),
    int(mujoco.mjtJoint.mjJNT_SLIDE),
    int(mujoco.mjtJoint.mjJNT_HINGE),
)
_JOINT_TYPES = (_FREE, _BALL, _SLIDE, _HINGE)


@dataclass(frozen=True)
class FKResult:
    """World frames of every body of one forward-kinematics evaluation.

    Attributes:
        xpos: per body (index = MuJoCo body id, 0 = world) its origin, 3 scalars.
        xmat: per body its rotation matrix (3×3 nested lists of scalars).
    """

    xpos: list[_Vec]
    xmat: list[_Mat]

    def point(self, body: int, local: np.ndarray) -> _Vec:
        """World position of a point fixed in ``body`` at ``local`` (body frame) [m]."""
        return _vadd(self.xpos[body], _matvec(self.xmat[body], _const_vec(local)))


class SymbolicKinematics:
    """CasADi forward kinematics of a compiled MuJoCo model (see the module docstring).

    Args:
        model: the compiled model. Mocap bodies are not supported.

    Raises:
        RefineError: the model has mocap bodies or an unknown joint type.
    """

    def __init__(self, model: mujoco.MjModel) -> None:
        if model.nmocap:
            raise RefineError("symbolic kinematics does not support mocap bodies")
        self.model = model
        self.nq = int(model.nq)
        self.nbody = int(model.nbody)
        free = free_joints(model)
        #: qpos address of the single free joint (None without one).
        self.free_qposadr: int | None = int(model.jnt_qposadr[free[0]]) if len(free) == 1 else None
        self.free_body: int | None = int(model.jnt_bodyid[free[0]]) if len(free) == 1 else None
        for j in range(model.njnt):
            if (
                int(model.jnt_type[j]) not in _JOINT_TYPES
            ):  # pragma: no cover - MuJoCo has no other joint types
                raise RefineError(f"joint {j} has an unsupported type {model.jnt_type[j]}")

    # -------------------------------------------------------------- core recursion
    def forward(
        self,
        qpos: Sequence[_Scalar] | ca.SX,
        free_rotation: _Mat | None = None,
        normalize: bool = True,
    ) -> FKResult:
        """World frames of all bodies for a (symbolic) ``qpos``.

        Args:
            qpos: nq scalars (casadi SX vector, list of SX or floats).
            free_rotation: optional 3×3 rotation replacing the free joint's quaternion
                (``qpos[a+3:a+7]`` is then ignored) — used by the refinement, whose root
                orientation variables are not a quaternion.
            normalize: normalise quaternions (MuJoCo does); switch off only for
                quaternions known to be unit.

        Returns:
            The body frames.
        """
        m = self.model
        q = [qpos[i] for i in range(self.nq)]
        xpos: list[_Vec] = [[0.0, 0.0, 0.0]]
        xmat: list[_Mat] = [_const_mat(np.eye(3))]
        for b in range(1, self.nbody):
            par = int(m.body_parentid[b])
            j0, nj = int(m.body_jntadr[b]), int(m.body_jntnum[b])
            if nj == 1 and int(m.jnt_type[j0]) == _FREE:
                a = int(m.jnt_qposadr[j0])
                pos: _Vec = [q[a], q[a + 1], q[a + 2]]
                if free_rotation is not None:
                    rot = free_rotation
                else:
                    rot = quat_to_matrix_sx(q[a + 3 : a + 7], normalize=normalize)
                xpos.append(pos)
                xmat.append(rot)
                continue
            pos = _vadd(xpos[par], _matvec(xmat[par], _const_vec(m.body_pos[b])))
            rot = _matmul(xmat[par], _const_mat(_quat_mat_np(m.body_quat[b])))
            for j in range(j0, j0 + nj):
                jt = int(m.jnt_type[j])
                a = int(m.jnt_qposadr[j])
                jpos = _const_vec(m.jnt_pos[j])
                anchor = _vadd(_matvec(rot, jpos), pos)
                if jt == _SLIDE:
                    axis = _matvec(rot, _const_vec(m.jnt_axis[j]))
                    d = q[a] - float(m.qpos0[a])
                    pos = _vadd(pos, [_mul(x, d) for x in axis])
                    continue
                if jt == _HINGE:
                    loc = _axis_angle_mat(m.jnt_axis[j], q[a] - float(m.qpos0[a]))
                elif jt == _BALL:
                    loc = quat_to_matrix_sx(q[a : a + 4], normalize=normalize)
                else:
                    raise RefineError(
                        f"body {m.body(b).name!r}: a free joint must be the body's only joint"
                    )
                rot = _matmul(rot, loc)
                pos = _vsub(anchor, _matvec(rot, jpos))
            xpos.append(pos)
            xmat.append(rot)
        return FKResult(xpos, xmat)

    # -------------------------------------------------------------- named points
    def body_point(self, name: str) -> tuple[int, np.ndarray]:
        """(body id, local position) of a body origin, site or geom called ``name``.

        Bodies are looked up first, then sites, then geoms.

        Raises:
            RefineError: no such element (the message lists the model's bodies and sites).
        """
        m = self.model
        b = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, name)
        if b >= 0:
            return b, np.zeros(3)
        s = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, name)
        if s >= 0:
            return int(m.site_bodyid[s]), m.site_pos[s].copy()
        g = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, name)
        if g >= 0:
            return int(m.geom_bodyid[g]), m.geom_pos[g].copy()
        known = [m.body(i).name for i in range(1, m.nbody)] + [
            m.site(i).name for i in range(m.nsite)
        ]
        raise RefineError(
            f"the model has no body, site or geom {name!r}; known: {', '.join(known)}"
        )

    def points(self, fk: FKResult, spec: Sequence[tuple[int, np.ndarray]]) -> ca.SX:
        """(3, n) SX matrix of the world positions of ``(body, local)`` points."""
        cols = [_to_sx(fk.point(b, p)) for b, p in spec]
        return ca.horzcat(*cols) if cols else ca.SX(3, 0)

    def com(self, fk: FKResult) -> ca.SX:
        """(3,) whole-body centre of mass: mass-weighted ``xipos`` of all bodies."""
        m = self.model
        total = float(np.sum(m.body_mass[1:]))
        acc: _Vec = [0.0, 0.0, 0.0]
        for b in range(1, self.nbody):
            mb = float(m.body_mass[b])
            if mb == 0.0:
                continue
            p = fk.point(b, m.body_ipos[b])
            acc = _vadd(acc, [_mul(mb / total, x) for x in p])
        return _to_sx(acc)

    def function(self, names: Sequence[str], name: str = "fk") -> ca.Function:
        """A casadi Function ``qpos (nq) → (3, len(names))`` world positions of named
        bodies / sites / geoms (see :meth:`body_point`); quaternions are normalised."""
        q = ca.SX.sym("qpos", self.nq)
        fk = self.forward(q)
        pts = self.points(fk, [self.body_point(n) for n in names])
        return ca.Function(name, [q], [pts], ["qpos"], ["points"])

    def frames_function(self, name: str = "frames") -> ca.Function:
        """A casadi Function ``qpos → (xpos (3, nbody), xmat (9, nbody))``, MuJoCo's
        ``data.xpos`` / ``data.xmat`` transposed (xmat rows flattened row-major)."""
        q = ca.SX.sym("qpos", self.nq)
        fk = self.forward(q)
        xp = ca.horzcat(*[_to_sx(p) for p in fk.xpos])
        xm = ca.horzcat(
            *[
                ca.vertcat(*[ca.SX(fk.xmat[b][i][j]) for i in range(3) for j in range(3)])
                for b in range(self.nbody)
            ]
        )
        return ca.Function(name, [q], [xp, xm], ["qpos"], ["xpos", "xmat"])
