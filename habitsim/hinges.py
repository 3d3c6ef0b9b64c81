"""Hinge angles of the habitsim skeleton's joint convention, and their joint-limit roles.

The skeleton (see :mod:`habitsim.skeleton`) poses every joint with a fixed product of
single-axis rotations, which is what the MJCF models represent with hinge joints:

* ``*_shoulder``, ``*_hip``: R = R_x(a) · R_y(f) — abduction ``a`` outermost, flexion ``f``;
* ``*_scapula``, ``*_elbow``, ``*_wrist``, ``*_ilium``, ``*_knee``, ``*_hock``: R = R_y(f);
* ``spine1..3``, ``neck``, ``head``, ``tail1``, ``tail2``: R = R_z(yaw) · R_y(pitch).

Hinge names are ``{joint}_{dof}`` with ``dof`` in ``flex``, ``abd``, ``pitch``, ``yaw``
(e.g. ``lf_shoulder_abd``, ``spine2_pitch``), in the order of :data:`HINGE_NAMES`.

Abduction is reported on the species' joint-limit scale, ``abd = R_x angle ·
ABDUCTION_SIGN[side]`` (equivalently R_x angle = ``ABDUCTION_SIGN[side] · abd``, the sign
being ±1; :data:`habitsim.skeleton.ABDUCTION_SIGN`), meant as "outward = positive" for
both sides, which is how the ``*_upper_abd`` limits read (symmetric limits make the
sign harmless for most species). Note R_x(a > 0) swings a downward bone toward +y.

Decomposition (exact for rotations built with the convention, for any angles in
(−π, π]; a rotation outside the convention is projected — the part a hinge chain cannot
represent is reported by :func:`hinge_residual_rad`). With M the rotation matrix:

* R_y(f):          f = atan2(M[0,2], M[0,0]);
* R_x(a)·R_y(f):   f = atan2(M[0,2], M[0,0]),   a = atan2(M[2,1], M[1,1]);
* R_z(y)·R_y(p):   p = atan2(−M[2,0], M[2,2]),  y = atan2(−M[0,1], M[1,1]).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .errors import InvalidMotionError
from .rotations import quat_angle, quat_mul, quat_to_matrix, rot_x, rot_y, rot_z
from .skeleton import ABDUCTION_SIGN, JOINT_NAMES, LEG_PREFIXES, LEG_ROLE_JOINTS
from .species import Species, load_species

if TYPE_CHECKING:  # pragma: no cover
    from .motion import Motion

__all__ = [
    "HINGE_NAMES",
    "HINGE_JOINTS",
    "hinge_roles",
    "hinge_limits",
    "hinge_angles",
    "compose_hinges",
    "hinge_residual_rad",
]

_AXIAL_ROLE = {
    "spine1": "spine",
    "spine2": "spine",
    "spine3": "spine",
    "neck": "neck",
    "head": "head",
    "tail1": "tail",
    "tail2": "tail",
}
_SEG_ROLE = {seg: role for role, segs in LEG_ROLE_JOINTS.items() for seg in segs}


def _build() -> tuple[tuple[str, ...], dict[str, str], dict[str, str]]:
    names: list[str] = []
    roles: dict[str, str] = {}  # hinge name -> joint-limit key (without _deg)
    kinds: dict[str, str] = {}  # joint name -> "y" | "xy" | "zy"
    for j in JOINT_NAMES:
        if j in _AXIAL_ROLE:
            kinds[j] = "zy"
            for dof in ("pitch", "yaw"):
                names.append(f"{j}_{dof}")
                roles[f"{j}_{dof}"] = f"{_AXIAL_ROLE[j]}_{dof}"
            continue
        prefix, _, seg = j.partition("_")
        if prefix not in LEG_PREFIXES or seg not in _SEG_ROLE:
            continue  # pelvis (free root) and end points
        role = _SEG_ROLE[seg]  # e.g. fore_upper
        names.append(f"{j}_flex")
        roles[f"{j}_flex"] = f"{role}_flex"
        if seg in ("shoulder", "hip"):
            kinds[j] = "xy"
            names.append(f"{j}_abd")
            roles[f"{j}_abd"] = f"{role}_abd"
        else:
            kinds[j] = "y"
    return tuple(names), roles, kinds


HINGE_NAMES, _ROLES, _KINDS = _build()
#: Joints that carry hinges, with their convention: ``y``, ``xy`` or ``zy``.
HINGE_JOINTS: dict[str, str] = dict(_KINDS)
_J = {n: i for i, n in enumerate(JOINT_NAMES)}


def hinge_roles() -> dict[str, str]:
    """Hinge name → species joint-limit key (e.g. ``lh_knee_flex`` → ``hind_lower_flex``)."""
    return dict(_ROLES)


def hinge_limits(species: str | Species) -> dict[str, tuple[float, float]]:
    """Hinge name → (lo, hi) [rad] from the species' joint limits."""
    sp = load_species(species)
    return {h: sp.joint_limits[r] for h, r in _ROLES.items()}


def _side_sign(joint: str) -> float:
    return ABDUCTION_SIGN[joint[0]]


def hinge_angles(motion: Motion | np.ndarray) -> dict[str, np.ndarray]:
    """Hinge angles of every posable joint.

    Args:
        motion: a :class:`~habitsim.motion.Motion` or local rotations (T, J, 4) wxyz.

    Returns:
        Hinge name (see :data:`HINGE_NAMES`) → (T,) angle [rad] in (−π, π]; abduction is
        the R_x angle times ``ABDUCTION_SIGN[side]`` (see the module docstring).
    """
    q = motion if isinstance(motion, np.ndarray) else motion.rotations
    q = np.asarray(q, dtype=np.float64)
    if q.ndim != 3 or q.shape[1:] != (len(JOINT_NAMES), 4):
        raise InvalidMotionError(
            f"rotations must have shape (T, {len(JOINT_NAMES)}, 4), got {q.shape}"
        )
    joints = list(_KINDS)
    m = quat_to_matrix(q[:, [_J[j] for j in joints]])  # (T, H, 3, 3)
    out: dict[str, np.ndarray] = {}
    for k, j in enumerate(joints):
        mk = m[:, k]
        kind = _KINDS[j]
        if kind == "zy":
            out[f"{j}_pitch"] = np.arctan2(-mk[:, 2, 0], mk[:, 2, 2])
            out[f"{j}_yaw"] = np.arctan2(-mk[:, 0, 1], mk[:, 1, 1])
        else:
            out[f"{j}_flex"] = np.arctan2(mk[:, 0, 2], mk[:, 0, 0])
            if kind == "xy":
                out[f"{j}_abd"] = _side_sign(j) * np.arctan2(mk[:, 2, 1], mk[:, 1, 1])
    return {h: out[h] for h in HINGE_NAMES}


def compose_hinges(angles: dict[str, np.ndarray], base: np.ndarray | None = None) -> np.ndarray:
    """Local rotations from hinge angles (the inverse of :func:`hinge_angles`).

    Args:
        angles: hinge name → (T,) or scalar angle [rad]; missing hinges are 0 (or taken
            from ``base``: a joint with no given hinge keeps its ``base`` rotation).
        base: optional (T, J, 4) rotations providing the pelvis (root orientation), the
            end points and the joints without given hinges; default identity.

    Returns:
        (T, J, 4) local rotations wxyz (T = 1 when every angle is a scalar and no base).
    """
    unknown = set(angles) - set(HINGE_NAMES)
    if unknown:
        raise InvalidMotionError(
            f"unknown hinges {sorted(unknown)}; valid: {', '.join(HINGE_NAMES)}"
        )
    arrs = {k: np.atleast_1d(np.asarray(v, dtype=np.float64)) for k, v in angles.items()}
    t = max([a.shape[0] for a in arrs.values()] + ([base.shape[0]] if base is not None else [1]))
    if base is None:
        q = np.zeros((t, len(JOINT_NAMES), 4))
        q[..., 0] = 1.0
    else:
        q = np.array(base, dtype=np.float64, copy=True)
        if q.shape != (t, len(JOINT_NAMES), 4):
            raise InvalidMotionError(
                f"base must have shape ({t}, {len(JOINT_NAMES)}, 4), got {q.shape}"
            )

    def get(name: str) -> np.ndarray:
        return np.broadcast_to(arrs.get(name, np.zeros(1)), (t,))

    for j, kind in _KINDS.items():
        names = [f"{j}_{d}" for d in (("pitch", "yaw") if kind == "zy" else ("flex", "abd"))]
        if not any(n in arrs for n in names):
            continue
        if kind == "zy":
            r = quat_mul(rot_z(get(f"{j}_yaw")), rot_y(get(f"{j}_pitch")))
        elif kind == "xy":
            r = quat_mul(rot_x(_side_sign(j) * get(f"{j}_abd")), rot_y(get(f"{j}_flex")))
        else:
            r = rot_y(get(f"{j}_flex"))
        q[:, _J[j]] = r
    return q


def hinge_residual_rad(motion: Motion | np.ndarray) -> np.ndarray:
    """(T, H_joints) angle [rad] between each hinged joint's rotation and its projection
    onto the hinge convention (0 for motions built with the convention).

    Columns follow the joints of :data:`HINGE_JOINTS` in order.
    """
    q = motion if isinstance(motion, np.ndarray) else motion.rotations
    q = np.asarray(q, dtype=np.float64)
    rebuilt = compose_hinges(hinge_angles(q), base=q)
    idx = [_J[j] for j in _KINDS]
    return quat_angle(q[:, idx], rebuilt[:, idx])
