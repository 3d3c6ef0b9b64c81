"""Shared MuJoCo model lookups, written once (in the style of mink's ``utils`` module).

The lowest layer of the simulation code: numpy and mujoco only (no torch, no habitsim
module above :mod:`habitsim.errors`), used by :mod:`habitsim.sim`, the controllers,
retargeting, refinement and the metrics (:mod:`habitsim.sim` re-exports what it always
offered). Lookups return ``-1`` / an empty result when
the model lacks what is asked for, so each caller keeps its own typed error; the
name-resolving ones raise :class:`ModelLookupError` with a message that lists the
model's valid names.

* the free joint: :func:`free_joints`, :func:`free_joint`, :func:`free_body`,
  :func:`body_free_joint`, :func:`free_dofs`;
* the home pose: :func:`home_qpos` (the keyframe named ``home``, else ``qpos0``);
* named points (site, geom or body): :func:`resolve_points`, :func:`point_body`,
  :func:`point_pos`; feet named by a site, geom or body: :func:`resolve_feet`;
* feet: :data:`HABITSIM_FEET` and the usual robot namings (:func:`known_feet`), the
  geoms touching the ground at home (:func:`find_feet`), the colliding geom of each foot
  (:func:`foot_geoms`), foot soles along a trajectory (:func:`foot_soles`), the lowest
  point of geoms (:func:`lowest_z`);
* :func:`leg_length` — the model-side leg length (see there for the rule);
* a qpos trajectory checked against its model (:func:`check_qpos`) and its finite
  differences (:func:`finite_differences`).
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from dataclasses import dataclass

import mujoco
import numpy as np

from .errors import HabitsimError, SimulationError

__all__ = [
    "ModelLookupError",
    "HABITSIM_FEET",
    "ROBOT_FEET",
    "free_joints",
    "free_joint",
    "free_body",
    "body_free_joint",
    "free_dofs",
    "home_qpos",
    "resolve_points",
    "resolve_feet",
    "point_body",
    "point_pos",
    "known_feet",
    "find_feet",
    "standing_feet",
    "FootSearchOptions",
    "foot_geoms",
    "foot_soles",
    "lowest_z",
    "leg_length",
    "check_qpos",
    "finite_differences",
    "species_foot_geoms",
]

_FREE = int(mujoco.mjtJoint.mjJNT_FREE)

#: Foot names of the habitsim species models, in the order of contact labels (LF, RF,
#: LH, RH): sphere geoms.
HABITSIM_FEET = ("lf_foot", "rf_foot", "lh_foot", "rh_foot")
#: Usual robot foot namings in the order LF, RF, LH, RH (MuJoCo Menagerie's Unitree
#: robots name their foot geoms ``FL``, ``FR``, ``RL``, ``RR``).
ROBOT_FEET = (
    ("FL_foot", "FR_foot", "RL_foot", "RR_foot"),
    ("LF_FOOT", "RF_FOOT", "LH_FOOT", "RH_FOOT"),
    ("fl_foot", "fr_foot", "rl_foot", "rr_foot"),
    ("FL", "FR", "RL", "RR"),
)


class ModelLookupError(HabitsimError, ValueError):
    """A name the model does not have (the message lists the valid names)."""


# --------------------------------------------------------------------------- free joint
def free_joints(model: mujoco.MjModel) -> list[int]:
    """Ids of the model's free joints, in joint order."""
    return [j for j in range(model.njnt) if int(model.jnt_type[j]) == _FREE]


def free_joint(model: mujoco.MjModel) -> int:
    """Id of the model's first free joint; ``-1`` if there is none."""
    free = free_joints(model)
    return free[0] if free else -1


def free_body(model: mujoco.MjModel) -> int:
    """Id of the body carrying the model's (first) free joint; ``-1`` if there is none."""
    j = free_joint(model)
    return int(model.jnt_bodyid[j]) if j >= 0 else -1


def body_free_joint(model: mujoco.MjModel, body: int) -> int:
    """Id of the free joint of ``body`` (its first joint); ``-1`` if it has none."""
    jnt = int(model.body_jntadr[body]) if body >= 0 else -1
    if jnt < 0 or int(model.jnt_type[jnt]) != _FREE:
        return -1
    return jnt


def free_dofs(model: mujoco.MjModel) -> np.ndarray:
    """(6·k,) dof ids of the model's k free joints (empty without one)."""
    out = [
        np.arange(int(model.jnt_dofadr[j]), int(model.jnt_dofadr[j]) + 6)
        for j in free_joints(model)
    ]
    return np.concatenate(out) if out else np.array([], dtype=int)


# --------------------------------------------------------------------------- home pose
def home_qpos(model: mujoco.MjModel, key: str | int = "home") -> np.ndarray:
    """(nq,) the home pose: the keyframe named ``key`` (or with index ``key``) if the
    model has it, else ``qpos0``. Every habitsim model and the Menagerie robots have one
    keyframe, named ``home``."""
    if isinstance(key, str):
        kid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_KEY, key)
    else:
        kid = int(key) if 0 <= int(key) < model.nkey else -1
    if kid >= 0:
        return model.key_qpos[kid].copy()
    return model.qpos0.copy()


def _home_data(model: mujoco.MjModel, qpos: np.ndarray | None = None) -> mujoco.MjData:
    d = mujoco.MjData(model)
    d.qpos[:] = home_qpos(model) if qpos is None else qpos
    mujoco.mj_kinematics(model, d)
    return d


# --------------------------------------------------------------------------- named points
def resolve_points(model: mujoco.MjModel, names: Sequence[str]) -> list[tuple[str, int]]:
    """Each name as ``('site'|'geom'|'body', id)``, tried in that order; ``"#<id>"``
    names an unnamed geom.

    Raises:
        ModelLookupError: a name that is no site, geom or body (the message lists the
            model's named sites and geoms).
    """
    out = []
    for n in names:
        if n.startswith("#") and n[1:].isdigit() and int(n[1:]) < model.ngeom:
            out.append(("geom", int(n[1:])))
            continue
        for kind, obj in (
            ("site", mujoco.mjtObj.mjOBJ_SITE),
            ("geom", mujoco.mjtObj.mjOBJ_GEOM),
            ("body", mujoco.mjtObj.mjOBJ_BODY),
        ):
            i = mujoco.mj_name2id(model, obj, n)
            if i >= 0:
                out.append((kind, i))
                break
        else:
            sites = [model.site(i).name for i in range(model.nsite) if model.site(i).name]
            geoms = [model.geom(i).name for i in range(model.ngeom) if model.geom(i).name]
            raise ModelLookupError(
                f"foot {n!r} is not a site, geom or body of the model; named sites: "
                f"{', '.join(sites) or '(none)'}; named geoms: {', '.join(geoms) or '(none)'}"
            )
    return out


def resolve_feet(model: mujoco.MjModel, names: Sequence[str]) -> list[tuple[str, int]]:
    """Foot names as :func:`resolve_points` does, except that a foot named by its body is
    the body's foot sphere: its colliding sphere geom lowest at the home pose.

    A foot body's origin is its joint (a robot's shank body starts at the knee; ANYmal's
    feet are unnamed spheres on ``LF_SHANK`` …), so a body name taken literally would put
    the foot point, the leg IK, the ground forces and the leg length at the knee. A body
    without a colliding sphere keeps its origin.

    Raises:
        ModelLookupError: as :func:`resolve_points`.
    """
    out = resolve_points(model, names)
    colliding = (model.geom_contype != 0) | (model.geom_conaffinity != 0)
    sphere = model.geom_type == mujoco.mjtGeom.mjGEOM_SPHERE
    d: mujoco.MjData | None = None
    for k, (kind, i) in enumerate(out):
        if kind != "body":
            continue
        cand = np.flatnonzero((model.geom_bodyid == i) & colliding & sphere)
        if cand.size:
            d = _home_data(model) if d is None else d
            low = d.geom_xpos[cand, 2] - model.geom_size[cand, 0]
            out[k] = ("geom", int(cand[int(np.argmin(low))]))
    return out


def point_body(model: mujoco.MjModel, kind: str, i: int) -> int:
    """The body a resolved point (:func:`resolve_points`) moves with."""
    if kind == "site":
        return int(model.site_bodyid[i])
    if kind == "geom":
        return int(model.geom_bodyid[i])
    return i


def point_pos(data: mujoco.MjData, kind: str, i: int) -> np.ndarray:
    """(3,) world position of a resolved point (a view into ``data``)."""
    if kind == "site":
        return data.site_xpos[i]
    if kind == "geom":
        return data.geom_xpos[i]
    return data.xpos[i]


def _has_point(model: mujoco.MjModel, name: str) -> bool:
    return any(
        mujoco.mj_name2id(model, o, name) >= 0
        for o in (mujoco.mjtObj.mjOBJ_SITE, mujoco.mjtObj.mjOBJ_GEOM, mujoco.mjtObj.mjOBJ_BODY)
    )


# --------------------------------------------------------------------------- feet
def known_feet(model: mujoco.MjModel) -> tuple[str, ...] | None:
    """The model's feet in the order LF, RF, LH, RH by the usual names
    (:data:`HABITSIM_FEET`, then :data:`ROBOT_FEET`); None when no naming matches."""
    for names in (HABITSIM_FEET, *ROBOT_FEET):
        if all(_has_point(model, n) for n in names):
            return names
    return None


def find_feet(
    model: mujoco.MjModel, qpos: np.ndarray | None = None, *, tolerance: float | None = None
) -> list[str]:
    """Names of the geoms touching the world's geoms (the ground) at ``qpos``
    (default: home), as ``"#<id>"`` for unnamed geoms.

    Geoms within ``tolerance`` [m] of the ground count (default 1 % of the model's
    extent), since a home keyframe usually places the feet exactly at the surface.
    """
    tol = 0.01 * float(model.stat.extent) if tolerance is None else float(tolerance)
    model = copy.copy(model)
    model.geom_margin[:] = np.maximum(model.geom_margin, tol)
    data = mujoco.MjData(model)
    data.qpos[:] = home_qpos(model) if qpos is None else qpos
    mujoco.mj_forward(model, data)
    feet: list[str] = []
    for c in data.contact[: data.ncon]:
        if c.dist > tol:
            continue
        g1, g2 = int(c.geom[0]), int(c.geom[1])
        for mine, other in ((g1, g2), (g2, g1)):
            if model.geom_bodyid[other] == 0 and model.geom_bodyid[mine] != 0:
                name = model.geom(mine).name or f"#{mine}"
                if name not in feet:
                    feet.append(name)
    return feet


@dataclass(frozen=True)
class FootSearchOptions:
    """The knobs of finding a model's feet by geometry (:func:`standing_feet`).

    Attributes:
        height_share: legs whose lowest point stands within this share of the trunk's
            height above the lowest leg's count as standing on the ground [unitless].
    """

    height_share: float = 0.05


def standing_feet(
    model: mujoco.MjModel,
    qpos: np.ndarray | None = None,
    options: FootSearchOptions = FootSearchOptions(),
) -> tuple[str, ...]:
    """A quadruped's four feet in the order LF, RF, LH, RH, found by geometry at ``qpos``
    (default :func:`home_qpos`).

    The colliding geoms below each body hanging from the trunk (the free-joint body) are
    one leg; a leg whose lowest geom (:func:`lowest_z`) stands within
    :attr:`FootSearchOptions.height_share` of the trunk's height above the lowest leg's is a foot.
    There must be exactly four, ordered by where they stand in the trunk's frame (the
    two furthest ahead are fore; left is +y). A foot is named by its geom, or, for an
    unnamed sphere (Menagerie's A1 and ANYmal), by its body, which :func:`resolve_feet`
    turns back into that body's lowest sphere.

    Raises:
        ModelLookupError: no free joint, not four legs on the ground, or a foot that is
            an unnamed geom other than a sphere (the message says what was found).
    """
    trunk = free_body(model)
    if trunk < 0:
        raise ModelLookupError("cannot find the feet: the model has no free joint (no trunk)")
    d = _home_data(model, qpos)
    colliding = np.flatnonzero((model.geom_contype != 0) | (model.geom_conaffinity != 0))
    # the body directly under the trunk each body hangs from (-1: not below the trunk)
    root = np.full(model.nbody, -1)
    for b in range(1, model.nbody):  # MuJoCo numbers parents before their children
        p = int(model.body_parentid[b])
        root[b] = b if p == trunk else root[p]
    legs: dict[int, tuple[float, int]] = {}
    for g in colliding.tolist():
        leg = int(root[model.geom_bodyid[g]])
        if leg < 0:
            continue
        z = float(lowest_z(model, np.array([g]), d.geom_xpos[g][None], d.geom_xmat[g][None])[0])
        if leg not in legs or z < legs[leg][0]:
            legs[leg] = (z, g)
    ground = min((z for z, _ in legs.values()), default=0.0)
    height = float(d.xpos[trunk, 2]) - ground
    standing = [g for z, g in legs.values() if z <= ground + options.height_share * height]
    if len(standing) != 4:
        found = ", ".join(_geom_label(model, g) for g in standing) or "none"
        raise ModelLookupError(
            f"cannot find the feet: {len(standing)} leg(s) stand on the ground at the "
            f"standing pose ({found}), a quadruped needs 4"
        )
    rot = d.xmat[trunk].reshape(3, 3)
    local = (d.geom_xpos[standing] - d.xpos[trunk]) @ rot
    fore = set(np.argsort(-local[:, 0])[:2].tolist())
    order: list[int] = []
    for want_fore in (True, False):
        pair = [k for k in range(4) if (k in fore) == want_fore]
        order += sorted(pair, key=lambda k: -local[k, 1])  # left (+y) first
    out = []
    for k in order:
        g = int(standing[k])
        body = int(model.geom_bodyid[g])
        if model.geom(g).name:
            out.append(model.geom(g).name)
        elif model.geom_type[g] == mujoco.mjtGeom.mjGEOM_SPHERE and model.body(body).name:
            out.append(model.body(body).name)
        else:
            kind = mujoco.mjtGeom(model.geom_type[g]).name.removeprefix("mjGEOM_").lower()
            raise ModelLookupError(
                f"cannot name the foot {_geom_label(model, g)}: an unnamed {kind}"
            )
    return tuple(out)


def _geom_label(model: mujoco.MjModel, g: int) -> str:
    name = model.geom(g).name
    b = int(model.geom_bodyid[g])
    return repr(name) if name else f"geom #{g} of body {model.body(b).name or f'#{b}'!r}"


def lowest_z(
    model: mujoco.MjModel, geoms: np.ndarray, pos: np.ndarray, mat: np.ndarray
) -> np.ndarray:
    """(..., n) height [m] of the lowest point of each geom (exact for spheres, capsules,
    boxes, ellipsoids; other shapes by their bounding sphere).

    Args:
        geoms: (n,) geom ids; pos: (..., n, 3) their ``geom_xpos``; mat: (..., n, 9)
            their ``geom_xmat``.
    """
    z = pos[..., 2]
    rz = mat[..., 6:9]  # z-row of each rotation matrix
    size = model.geom_size[geoms]
    kind = model.geom_type[geoms]
    gt = mujoco.mjtGeom
    out = z - model.geom_rbound[geoms]
    for k, low in (
        (gt.mjGEOM_SPHERE, lambda s, r: s[..., 0] + 0 * r[..., 0]),
        (gt.mjGEOM_CAPSULE, lambda s, r: np.abs(r[..., 2]) * s[..., 1] + s[..., 0]),
        (gt.mjGEOM_BOX, lambda s, r: (np.abs(r) * s).sum(axis=-1)),
        (gt.mjGEOM_ELLIPSOID, lambda s, r: np.sqrt(((r * s) ** 2).sum(axis=-1))),
    ):
        sel = kind == k
        if sel.any():
            out[..., sel] = z[..., sel] - low(size[sel], rz[..., sel, :])
    return out


def foot_geoms(model: mujoco.MjModel, feet: Sequence[str] | None = None) -> np.ndarray:
    """(nf,) the colliding geom of each foot.

    Without ``feet``: :func:`species_foot_geoms`, the geoms :data:`HABITSIM_FEET` of a
    habitsim species model (a missing one is a :class:`~habitsim.errors.SimulationError`). With
    ``feet`` named as the robot names them (site, geom or body, tried in that order, see
    :func:`resolve_points`): a colliding geom of that name is taken as it is; for a site
    (or a non-colliding geom), the colliding geom of its body whose centre is nearest the
    named point at the home pose (the foot sphere, not the shank capsule); for a body,
    its lowest colliding geom at the home pose.

    Raises:
        ModelLookupError: an unknown name, a foot body without a colliding geom.
        SimulationError: without ``feet``, a missing habitsim foot geom.
    """
    if feet is None:
        return species_foot_geoms(model)
    pts = resolve_points(model, list(feet))
    d = _home_data(model)
    colliding = (model.geom_contype != 0) | (model.geom_conaffinity != 0)
    out = []
    for name, (kind, i) in zip(feet, pts, strict=True):
        geom = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, name)
        if geom >= 0 and colliding[geom]:
            out.append(geom)
            continue
        body = point_body(model, kind, i)
        cand = np.flatnonzero((model.geom_bodyid == body) & colliding)
        if cand.size == 0:
            raise ModelLookupError(
                f"foot {name!r} (body {model.body(body).name!r}) has no "
                "colliding geom to touch the ground with"
            )
        if kind == "body":  # the body's lowest colliding geom at home touches down
            low = lowest_z(model, cand, d.geom_xpos[cand], d.geom_xmat[cand])
            out.append(int(cand[int(np.argmin(low))]))
            continue
        point = d.site_xpos[i] if kind == "site" else d.geom_xpos[i]
        dist = np.linalg.norm(d.geom_xpos[cand] - point, axis=1)
        out.append(int(cand[int(np.argmin(dist))]))
    return np.array(out, dtype=int)


def species_foot_geoms(model: mujoco.MjModel) -> np.ndarray:
    """(4,) geom ids of the feet of a habitsim model: ``lf_foot, rf_foot, lh_foot, rh_foot``
    (a robot's feet, named its own way: :func:`habitsim.sim.foot_geoms`).

    Raises:
        SimulationError: a foot geom is missing (the message lists the model's geoms).
    """
    ids = []
    for name in HABITSIM_FEET:
        g = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, name)
        if g < 0:
            names = [model.geom(i).name for i in range(model.ngeom) if model.geom(i).name]
            raise SimulationError(
                f"the model has no foot geom '{name}'; geoms: {', '.join(names[:40])} "
                "(name a robot's feet with feet=[...])"
            )
        ids.append(g)
    return np.array(ids)


def foot_soles(model: mujoco.MjModel, qpos: np.ndarray, geoms: np.ndarray) -> np.ndarray:
    """(T, nf, 3) the lowest points of foot spheres ``geoms`` (geom centre minus the
    radius in z) at each pose of ``qpos`` (T, nq)."""
    geoms = np.asarray(geoms, dtype=int)
    d = mujoco.MjData(model)
    out = np.empty((len(qpos), len(geoms), 3))
    for k, q in enumerate(qpos):
        d.qpos[:] = q
        mujoco.mj_kinematics(model, d)
        out[k] = d.geom_xpos[geoms]
        out[k, :, 2] -= model.geom_size[geoms, 0]
    return out


# --------------------------------------------------------------------------- sizes
def leg_length(model: mujoco.MjModel, feet: Sequence[str] | None = None) -> float:
    """A model's leg length [m] when no species says it.

    The rule: the height of the trunk (the free-joint body's origin) above the mean
    height of the foot points at the home pose (:func:`home_qpos`), at least 1 mm. It is
    the model-side estimate of the species catalog's leg length
    (:attr:`habitsim.species.Species.leg_length`, the hind leg's hip-to-toe length,
    docs/metrics.md's normalising length): within 10 % of it on the catalog models.

    Args:
        feet: foot names (site, geom or body); default: the usual names
            (:func:`known_feet`).

    Raises:
        ModelLookupError: no free joint; no ``feet`` given and none found by name; an
            unknown foot name.
    """
    trunk = free_body(model)
    if trunk < 0:
        raise ModelLookupError("the model has no free joint")
    names = list(feet) if feet else known_feet(model)
    if not names:
        raise ModelLookupError(
            "cannot find the feet of the model by name (tried "
            + "; ".join(", ".join(n) for n in (HABITSIM_FEET, *ROBOT_FEET))
            + "); pass feet=[...] (site, geom or body names in the order LF, RF, LH, RH)"
        )
    pts = resolve_feet(model, names)
    d = _home_data(model)
    z = [point_pos(d, k, i)[2] for k, i in pts]
    return float(max(d.xpos[trunk, 2] - np.mean(z), 1e-3))


# --------------------------------------------------------------------------- trajectories
def check_qpos(model: mujoco.MjModel, qpos: np.ndarray) -> np.ndarray:
    """(T, nq) float copy of a qpos trajectory that fits the model, without NaN or inf.

    Raises:
        SimulationError: wrong shape for the model, a NaN or inf.
    """
    q = np.atleast_2d(np.asarray(qpos, dtype=np.float64))
    if q.ndim != 2 or q.shape[1] != model.nq:
        raise SimulationError(
            f"reference qpos must have shape (T, {model.nq}) for this model, got {q.shape}"
        )
    if not np.all(np.isfinite(q)):
        bad = np.argwhere(~np.isfinite(q))[0]
        raise SimulationError(
            f"reference qpos contains NaN or inf (frame {bad[0]}, coordinate {bad[1]})"
        )
    return q


def finite_differences(
    model: mujoco.MjModel, qpos: np.ndarray, fps: float
) -> tuple[np.ndarray, np.ndarray]:
    """Generalised velocities and accelerations of a qpos trajectory.

    Central differences inside, one-sided at the ends; the velocity between two frames is
    ``mj_differentiatePos`` (free-joint angular velocity in the body frame, as MuJoCo's
    qvel). A single frame gives zeros.

    Args:
        model: the model the qpos belongs to.
        qpos: (T, nq) positions at ``fps``.
        fps: frame rate [Hz].

    Returns:
        qvel (T, nv) and qacc (T, nv).
    """
    q = check_qpos(model, qpos)
    t = q.shape[0]
    dt = 1.0 / float(fps)
    if t < 2:
        return np.zeros((t, model.nv)), np.zeros((t, model.nv))
    seg = np.empty((t - 1, model.nv))  # velocity over (k, k+1)
    for k in range(t - 1):
        mujoco.mj_differentiatePos(model, seg[k], dt, q[k], q[k + 1])
    qvel = np.empty((t, model.nv))
    qvel[0], qvel[-1] = seg[0], seg[-1]
    qvel[1:-1] = 0.5 * (seg[:-1] + seg[1:])
    qacc = np.empty_like(qvel)
    qacc[1:-1] = (seg[1:] - seg[:-1]) / dt
    if t > 2:
        qacc[0], qacc[-1] = qacc[1], qacc[-2]
    else:
        qacc[:] = 0.0
    return qvel, qacc
