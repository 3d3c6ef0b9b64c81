"""Gain rules for joint PD control on any MuJoCo model.

Three ways to choose the stiffness ``kp`` [N·m/rad] of each joint
(:func:`stiffness_rule`):

* ``"gravity"``: the joint must carry its static load with at most ``deflection`` rad of
  error, ``kp = τ_load / deflection``. The load is the weight of the joint's own subtree
  at its lever arm, plus, for joints on the chain to a support foot, the share
  ``M·g / n_support`` of the floating body's weight at the joint-to-foot distance
  ("mass · g · leg length").
* ``"inertia"``: a wanted natural frequency ``ω_n``, ``kp = M_ii · ω_n²`` with ``M_ii`` the
  joint-space inertia diagonal.
* ``"torque"``: the actuator reaches its torque limit at ``deflection`` rad of error,
  ``kp = τ_max / deflection``. Needs no knowledge of the feet; with
  ``deflection = 0.15`` in-engine position servos held the home pose of every habitsim
  species (and of the hand-written test quadruped).

Damping follows from :func:`critical_damping`, ``kd = 2 · ratio · sqrt(kp · M_ii)``.
:func:`max_stable_gains` / :func:`max_stable_kd` give the limits beyond which an
*explicit* PD law (torques computed once per step, :class:`~habitsim.controllers.PDController`)
goes unstable; in-engine servos (:mod:`habitsim.controllers.servo`) are integrated
implicitly by MuJoCo's ``implicitfast`` integrator and have no such limit on ``kv``.

Where ``M_ii`` comes from (``method``):

* ``"fullM"`` (default): the diagonal of the joint-space inertia matrix from
  ``mj_fullM`` at the home keyframe (or ``qpos0``), armature included. It is the inertia
  the joint feels when every other joint is held still, an upper bound of the
  effective inertia, so a ratio of 1 gives at least critical damping.
* ``"invweight0"``: ``1 / dof_invweight0``, MuJoCo's own effective inertia at ``qpos0``
  computed with the other joints free (the quantity MuJoCo's ``dampratio`` attribute
  uses). It is smaller than ``M_ii``, giving lighter damping.
"""

from __future__ import annotations

from collections.abc import Sequence

import mujoco
import numpy as np

from habitsim.mjutils import (
    ModelLookupError,
    find_feet,
    free_body,
    home_qpos,
    resolve_feet,
)
from habitsim.mjutils import (
    point_body as _point_body,
)
from habitsim.mjutils import (
    point_pos as _point_pos,
)

from .base import ControllerError, actuated_joints

__all__ = [
    "home_qpos",
    "joint_space_inertia",
    "effective_inertia",
    "free_body",
    "find_feet",
    "stiffness_rule",
    "critical_damping",
    "max_stable_gains",
    "max_stable_kd",
]

_METHODS = ("fullM", "invweight0")
_MODES = ("gravity", "inertia", "torque")


def joint_space_inertia(model: mujoco.MjModel, qpos: np.ndarray | None = None) -> np.ndarray:
    """(nv, nv) dense joint-space inertia ``M(q)`` (armature included) at ``qpos``.

    Args:
        qpos: (nq,) configuration; default :func:`home_qpos`.
    """
    data = mujoco.MjData(model)
    data.qpos[:] = home_qpos(model) if qpos is None else qpos
    mujoco.mj_forward(model, data)
    mass = np.zeros((model.nv, model.nv))
    if hasattr(data, "qM"):  # mujoco < 3.5: mj_fullM(model, dst, qM)
        mujoco.mj_fullM(model, mass, data.qM)
    else:  # mujoco >= 3.5: mj_fullM(model, data, dst)
        mujoco.mj_fullM(model, data, mass)
    return mass


def effective_inertia(
    model: mujoco.MjModel,
    joints: Sequence[str] | None = None,
    *,
    method: str = "fullM",
    qpos: np.ndarray | None = None,
) -> np.ndarray:
    """(n,) effective inertia [kg·m²] (hinges) or mass [kg] (slides) of each joint.

    Args:
        joints: joint names (default: every actuated hinge/slide joint).
        method: ``"fullM"`` (``M_ii`` at ``qpos``) or ``"invweight0"``
            (``1/dof_invweight0`` at ``qpos0``); see the module docstring.
        qpos: configuration for ``"fullM"``; default the home keyframe.
    """
    jmap = actuated_joints(model, joints)
    if method == "fullM":
        return np.diag(joint_space_inertia(model, qpos))[jmap.dof_adr].copy()
    if method == "invweight0":
        return 1.0 / np.maximum(model.dof_invweight0[jmap.dof_adr], 1e-12)
    raise ControllerError(f"unknown inertia method {method!r}; valid: {', '.join(_METHODS)}")


def _resolve_points(model: mujoco.MjModel, names: Sequence[str]) -> list[tuple[str, int]]:
    """Feet by name (:func:`habitsim.mjutils.resolve_feet`: a body name is its foot
    sphere), an unknown name as a ControllerError."""
    try:
        return resolve_feet(model, names)
    except ModelLookupError as e:
        raise ControllerError(str(e)) from e


def _is_ancestor(model: mujoco.MjModel, anc: int, body: int) -> bool:
    while body > 0:
        if body == anc:
            return True
        body = int(model.body_parentid[body])
    return anc == 0


def stiffness_rule(
    model: mujoco.MjModel,
    joints: Sequence[str] | None = None,
    *,
    mode: str = "gravity",
    deflection: float | None = None,
    feet: Sequence[str] | None = None,
    n_support: float = 2.0,
    frequency_hz: float = 8.0,
    method: str = "fullM",
    qpos: np.ndarray | None = None,
) -> np.ndarray:
    """(n,) joint stiffness kp [N·m/rad] from a physical rule (see the module docstring).

    Args:
        joints: joint names (default: every actuated hinge/slide joint).
        mode: ``"gravity"``, ``"inertia"`` or ``"torque"``.
        deflection: allowed static error [rad]: default 0.1 (gravity) / 0.15 (torque).
        feet: gravity mode, support points (site, geom or body names); default: the bodies
            touching the ground at the home pose (:func:`find_feet`).
        n_support: gravity mode, number of feet sharing the weight in the worst phase
            (2 for a trot, 3 for a walk).
        frequency_hz: inertia mode, natural frequency ``ω_n / 2π`` [Hz].
        method: inertia mode, how ``M_ii`` is computed (``"fullM"`` / ``"invweight0"``).
        qpos: pose the rule is evaluated at (default: home keyframe or ``qpos0``).

    Raises:
        ControllerError: unknown joints, mode or feet; non-positive deflection, frequency
            or ``n_support``; torque mode on an actuator without a control range.
    """
    jmap = actuated_joints(model, joints)
    if mode not in _MODES:
        raise ControllerError(f"unknown stiffness mode {mode!r}; valid: {', '.join(_MODES)}")
    if mode == "inertia":
        if not frequency_hz > 0:
            raise ControllerError(f"frequency_hz must be > 0, got {frequency_hz}")
        inertia = effective_inertia(model, jmap.names, method=method, qpos=qpos)
        return inertia * (2.0 * np.pi * frequency_hz) ** 2
    defl = (0.1 if mode == "gravity" else 0.15) if deflection is None else float(deflection)
    if not defl > 0:
        raise ControllerError(f"deflection must be > 0 rad, got {deflection}")
    if mode == "torque":
        tmax = jmap.torque_limit
        if not np.all(np.isfinite(tmax)):
            bad = [n for n, t in zip(jmap.names, tmax, strict=True) if not np.isfinite(t)]
            raise ControllerError(
                f"torque rule needs limited actuators; unlimited: {', '.join(bad)}"
            )
        return tmax / defl
    if not n_support > 0:
        raise ControllerError(f"n_support must be > 0, got {n_support}")
    data = mujoco.MjData(model)
    data.qpos[:] = home_qpos(model) if qpos is None else qpos
    mujoco.mj_forward(model, data)
    g = float(np.linalg.norm(model.opt.gravity))
    points = _resolve_points(model, find_feet(model, data.qpos) if feet is None else feet)
    root = free_body(model)
    carried = float(model.body_subtreemass[root]) if root >= 0 else 0.0
    load = np.zeros(len(jmap.names))
    for k, jid in enumerate(jmap.joint_ids):
        body = int(model.jnt_bodyid[jid])
        anchor = data.xanchor[jid]
        lever = np.linalg.norm(data.subtree_com[body] - anchor)
        load[k] = model.body_subtreemass[body] * g * lever
        for kind, i in points:
            if _is_ancestor(model, body, _point_body(model, kind, i)):
                reach = np.linalg.norm(_point_pos(data, kind, i) - anchor)
                load[k] += carried * g / n_support * reach
                break
    return load / defl


def critical_damping(
    model: mujoco.MjModel,
    kp: float | np.ndarray,
    joints: Sequence[str] | None = None,
    ratio: float = 1.0,
    *,
    method: str = "fullM",
    qpos: np.ndarray | None = None,
) -> np.ndarray:
    """(n,) damping kd = 2 · ratio · sqrt(kp · M_ii) [N·m·s/rad].

    Args:
        kp: stiffness per joint (array) or one value.
        joints: joint names (default: every actuated hinge/slide joint).
        ratio: damping ratio ζ (1 = critical).
        method, qpos: how ``M_ii`` is computed, see :func:`effective_inertia`.

    Raises:
        ControllerError: negative or non-finite kp or ratio.
    """
    inertia = effective_inertia(model, joints, method=method, qpos=qpos)
    kp_a = np.broadcast_to(np.asarray(kp, dtype=float), inertia.shape)
    if not np.all(np.isfinite(kp_a)) or np.any(kp_a < 0):
        raise ControllerError("kp must be finite and non-negative")
    if not (np.isfinite(ratio) and ratio >= 0):
        raise ControllerError(f"damping ratio must be finite and >= 0, got {ratio}")
    return 2.0 * ratio * np.sqrt(kp_a * inertia)


def max_stable_gains(
    model: mujoco.MjModel,
    dt: float | None = None,
    joints: Sequence[str] | None = None,
    *,
    margin: float = 0.5,
    method: str = "invweight0",
) -> tuple[np.ndarray, np.ndarray]:
    """(kp_max, kd_max) per joint for an EXPLICIT PD law updated every ``dt``.

    A joint of inertia ``m`` under ``τ = −kp·e − kd·ė`` with the torque held over a step
    ``dt`` (semi-implicit Euler) is stable when ``kd·dt/m < 2`` and ``kp·dt²/m < 4``;
    the returned values are ``margin`` times those bounds. The default inertia is MuJoCo's
    ``1/dof_invweight0`` (the lighter, other-joints-free value), the stricter choice.
    Joint damping and armature integrated implicitly by the engine are not counted.

    Args:
        dt: control period [s]; default ``model.opt.timestep``.
        margin: fraction of the theoretical bound (0 < margin ≤ 1).
    """
    step = float(model.opt.timestep if dt is None else dt)
    if not step > 0:
        raise ControllerError(f"dt must be > 0, got {dt}")
    if not 0 < margin <= 1:
        raise ControllerError(f"margin must be in (0, 1], got {margin}")
    inertia = effective_inertia(model, joints, method=method)
    return margin * 4.0 * inertia / step**2, margin * 2.0 * inertia / step


def max_stable_kd(
    model: mujoco.MjModel,
    dt: float | None = None,
    joints: Sequence[str] | None = None,
    *,
    margin: float = 0.5,
) -> np.ndarray:
    """(n,) largest damping [N·m·s/rad] an explicit PD law tolerates (see
    :func:`max_stable_gains`)."""
    return max_stable_gains(model, dt, joints, margin=margin)[1]
