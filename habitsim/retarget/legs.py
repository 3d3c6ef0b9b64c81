"""A robot's legs: the standing pose (crouched off straight legs), the leg IK's bounds,
how straight a leg is, and the feet found when nobody names them."""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import mujoco
import numpy as np

from ..mjutils import free_body
from .errors import RetargetError, StandingPoseError
from .ik import leg_ik
from .keyframes import model_keys, standing_keyframe
from .options import RetargetOptions
from .robot import RobotLegs, _point_names

__all__ = [
    "robot_legs",
    "leg_extension",
    "find_robot_feet",
    "stand_check",
    "StandingPoseWarning",
]


def robot_legs(
    model: mujoco.MjModel,
    feet: Sequence[str],
    home: str = "home",
    options: RetargetOptions | None = None,
) -> RobotLegs:
    """The legs of ``model`` ending at ``feet`` (site, geom or body names; a body is its
    foot sphere, :func:`habitsim.mjutils.resolve_feet`).

    The standing pose is the keyframe named ``home`` (default ``"home"``; Menagerie's
    ``anymal_c_mjx.xml`` calls it ``"standing"``), or ``options.keyframe``, read from
    ``options.keyframe_from`` when that names another MJCF file
    (:func:`~habitsim.retarget.keyframes.standing_keyframe`); without a keyframe
    ``"home"``, ``qpos0``, crouched when its legs are straight (``options.straight_reach``):
    the trunk lowered to ``options.crouch_height`` of its height with the feet kept where
    they stand, the legs solved by :func:`leg_ik` from knees bent so that each foot moves
    forward (the knees point backward, as on most legged robots).
    :attr:`RobotLegs.home_source` says which. The pose is checked (:func:`stand_check`):
    a folded ``qpos0`` is refused, a folded keyframe warned about
    (:class:`StandingPoseWarning`).

    Raises:
        RetargetError: no free joint, an unknown foot (the message lists the model's
            sites, geoms and bodies), a foot without joints of its own, a keyframe name
            ``home`` other than ``"home"`` that the model does not have (the message lists
            its keyframes), a straight-legged ``qpos0`` the crouch cannot solve (add a
            ``home`` keyframe); a bad ``options.keyframe_from``.
        StandingPoseError: no keyframe and a folded ``qpos0``.
    """
    from ..controllers import ControllerError
    from ..controllers.legs import LegSet

    opts = options or RetargetOptions()
    feet = tuple(str(f) for f in feet)
    if not feet:
        raise RetargetError("no feet given; name the robot's feet, e.g. --feet FL,FR,RL,RR")
    if len(set(feet)) != len(feet):
        raise RetargetError(f"a foot is named twice: {', '.join(feet)}")
    if free_body(model) < 0:
        raise RetargetError(
            "the robot has no free joint: retargeting moves its trunk, which "
            "needs a <freejoint/> on the trunk body"
        )
    valid = _point_names(model)
    unknown = [f for f in feet if f not in valid]
    if unknown:
        raise RetargetError(
            f"unknown foot name(s) {', '.join(map(repr, unknown))}; the "
            f"robot's sites, geoms and bodies: {', '.join(valid)}"
        )
    try:
        legs = LegSet(model, feet)
    except ControllerError as e:
        raise RetargetError(str(e)) from e
    chosen = standing_keyframe(model, home, opts)
    if chosen is not None:
        rl = _legs_at(model, feet, legs, chosen[0], chosen[1], opts)
        check = stand_check(rl, opts)
        if check["problems"]:
            warnings.warn(
                f"the robot's standing pose ({rl.home_source}) looks folded: {_describe(check)}",
                StandingPoseWarning,
                stacklevel=2,
            )
        return rl
    rl = _legs_at(model, feet, legs, model.qpos0.copy(), "qpos0", opts)
    if float(leg_extension(rl).max()) > opts.straight_reach:
        crouched = _crouch(rl, opts)
        rl = _legs_at(
            model,
            feet,
            legs,
            crouched,
            f"qpos0 crouched to {opts.crouch_height:.0%} of its height",
            opts,
        )
    check = stand_check(rl, opts)
    if check["problems"]:
        raise StandingPoseError(
            f"the robot has no keyframe 'home' and its qpos0 is no standing pose: "
            f"{_describe(check)}; point at one: --keyframe NAME (options.keyframe) for "
            "another keyframe of the model, --keyframe-from FILE (options.keyframe_from) "
            "for one in another MJCF file (Menagerie keeps some robots' home in "
            'scene_mjx.xml), or add a <key name="home" qpos="..."/> to the model'
        )
    return rl


class StandingPoseWarning(UserWarning):
    """A keyframe the robot stands on looks folded (:func:`stand_check`)."""


def stand_check(rl: RobotLegs, options: RetargetOptions | None = None) -> dict[str, Any]:
    """How much the standing pose looks like one: figures and the problems found.

    Returns:
        ``joints_at_limit_share``: share of the legs' limited joints within
        ``options.stand_limit_margin`` of their range (or outside it);
        ``height_over_leg``: trunk height over the ground [m] over the legs' mean length
        (hip to knee plus knee to foot, :func:`leg_extension`'s joints);
        ``keyframes``: the model's keyframe names; ``problems``: what is off, in words
        (empty for a usable standing pose: at most ``options.stand_max_limit_share`` at a
        limit, height at least ``options.stand_min_height``).
    """
    opts = options or RetargetOptions()
    m = rl.model
    d, knees = _at_home(rl)
    pts = np.array(rl.legs.positions(d))
    lengths = [
        float(
            np.linalg.norm(d.xanchor[hk[1]] - d.xanchor[hk[0]])
            + np.linalg.norm(pts[i] - d.xanchor[hk[1]])
        )
        for i, hk in enumerate(knees)
        if hk is not None
    ]
    at = []
    for i in range(len(rl.feet)):
        jid = rl.legs.jmap.joint_ids[rl.legs.own[i]]
        for j, qa in zip(jid, rl.qadr[i], strict=True):
            if m.jnt_limited[j]:
                lo, hi = (float(v) for v in m.jnt_range[j])
                gap = opts.stand_limit_margin * (hi - lo)
                at.append(not (lo + gap < float(rl.home[qa]) < hi - gap))
    share = float(np.mean(at)) if at else 0.0
    ratio = rl.height / float(np.mean(lengths)) if lengths else float("nan")
    problems = []
    if share > opts.stand_max_limit_share:
        problems.append(
            f"{share:.0%} of its leg joints at a range limit (a standing pose has at most "
            f"{opts.stand_max_limit_share:.0%})"
        )
    if math.isfinite(ratio) and ratio < opts.stand_min_height:
        problems.append(
            f"trunk {rl.height:.3f} m over the ground, {ratio:.2f} of its "
            f"{float(np.mean(lengths)):.3f} m legs (a standing pose has at least "
            f"{opts.stand_min_height:.2f})"
        )
    return {
        "joints_at_limit_share": share,
        "height_over_leg": ratio,
        "keyframes": model_keys(m),
        "problems": problems,
    }


def _stand_figures(rl: RobotLegs) -> dict[str, Any]:
    """:func:`stand_check`'s figures and problems for a clip's metadata."""
    return {k: v for k, v in stand_check(rl).items() if k != "keyframes"}


def _describe(check: dict[str, Any]) -> str:
    keys = ", ".join(check["keyframes"]) or "(none)"
    return f"{'; '.join(check['problems'])}; the model's keyframes: {keys}"


def _legs_at(
    model: mujoco.MjModel,
    feet: tuple[str, ...],
    legs: Any,
    home: np.ndarray,
    source: str,
    opts: RetargetOptions,
) -> RobotLegs:
    """The :class:`RobotLegs` standing on ``home``."""
    d = mujoco.MjData(model)
    d.qpos[:] = home
    mujoco.mj_kinematics(model, d)
    tr = legs.trunk
    rot = d.xmat[tr].reshape(3, 3)
    pts = np.array(legs.positions(d))
    sole = pts[:, 2] - legs.radius
    ground = float(sole.min())
    nominal = (pts - d.xpos[tr]) @ rot
    jm = legs.jmap
    qadr, dadr, lo, hi = [], [], [], []
    for i in range(len(feet)):
        own = legs.own[i]
        jid = jm.joint_ids[own]
        lim = model.jnt_limited[jid].astype(bool)
        qadr.append(jm.qpos_adr[own].copy())
        dadr.append(jm.dof_adr[own].copy())
        lo.append(np.where(lim, model.jnt_range[jid, 0], -np.inf))
        hi.append(np.where(lim, model.jnt_range[jid, 1], np.inf))
    rl = RobotLegs(
        model=model,
        feet=feet,
        legs=legs,
        home=home,
        height=float(d.xpos[tr, 2] - ground),
        nominal=nominal,
        radius=legs.radius.copy(),
        leg_length=float(max(d.xpos[tr, 2] - pts[:, 2].mean(), 1e-3)),
        qadr=tuple(qadr),
        dadr=tuple(dadr),
        lo=tuple(lo),
        hi=tuple(hi),
        home_source=source,
    )
    return _bounded(rl, opts)


def _bounded(rl: RobotLegs, opts: RetargetOptions) -> RobotLegs:
    """``rl`` with the leg IK's bounds: every hinge within ``opts.hinge_span`` of its
    standing angle, and each knee (the outermost own hinge about the trunk's lateral
    axis) on the side it bends to when standing, up to the straight leg, so that a foot
    target out of reach straightens the leg instead of folding the knee the other way
    (not for a leg standing straight, ``opts.straight_reach``: the crouch bends it first).
    """
    m = rl.model
    d, knees = _at_home(rl)
    straight = _extensions(rl, d, knees) > opts.straight_reach
    hinge = mujoco.mjtJoint.mjJNT_HINGE
    lo, hi = [], []
    for i in range(len(rl.feet)):
        jid = rl.legs.jmap.joint_ids[rl.legs.own[i]]
        h = rl.home[rl.qadr[i]]
        turn = m.jnt_type[jid] == hinge
        a = np.where(turn, np.maximum(rl.lo[i], h - opts.hinge_span), rl.lo[i])
        b = np.where(turn, np.minimum(rl.hi[i], h + opts.hinge_span), rl.hi[i])
        hk = knees[i]
        if hk is not None and not straight[i]:
            k = int(np.flatnonzero(jid == hk[1])[0])
            flat = _straight_angle(rl, knees, i, int(rl.qadr[i][k]), float(a[k]), float(b[k]))
            if h[k] > flat:
                a[k] = max(a[k], flat)
            else:
                b[k] = min(b[k], flat)
        lo.append(a)
        hi.append(b)
    return replace(rl, lo=tuple(lo), hi=tuple(hi))


def _at_home(rl: RobotLegs) -> tuple[mujoco.MjData, list]:
    """Data at the standing pose (kinematics done) and its (hip, knee) joints per foot
    (:func:`_knee_joints`)."""
    d = mujoco.MjData(rl.model)
    d.qpos[:] = rl.home
    mujoco.mj_kinematics(rl.model, d)
    return d, _knee_joints(rl, d)


def _straight_angle(rl: RobotLegs, knees: list, i: int, adr: int, lo: float, hi: float) -> float:
    """The angle of the knee at qpos address ``adr`` in [lo, hi] (finite) that makes leg
    i straightest (:func:`leg_extension`, the rest of the standing pose kept; ``knees``:
    :func:`_knee_joints` at it): a 5° scan, then 0.25° about its best."""
    d = mujoco.MjData(rl.model)
    d.qpos[:] = rl.home

    def best(grid: np.ndarray) -> float:
        ext = np.empty(len(grid))
        for n, v in enumerate(grid):
            d.qpos[adr] = v
            mujoco.mj_kinematics(rl.model, d)
            ext[n] = _extensions(rl, d, knees)[i]
        return float(grid[int(np.argmax(ext))])

    coarse = best(np.linspace(lo, hi, max(2, int(math.ceil((hi - lo) / math.radians(5.0))) + 1)))
    step = math.radians(5.0)
    return best(np.clip(np.arange(coarse - step, coarse + step, math.radians(0.25)), lo, hi))


def _leg_chain(rl: RobotLegs, i: int) -> np.ndarray:
    """Joint ids of foot i's own joints, from the trunk outward (MuJoCo numbers bodies,
    and their joints, depth first: along one chain the ids grow outward)."""
    return np.sort(np.asarray(rl.legs.jmap.joint_ids[rl.legs.own[i]]))


def _knee_joints(rl: RobotLegs, d: mujoco.MjData) -> list[tuple[int, int] | None]:
    """Per foot (hip, knee): the first and the outermost own hinge turning about the
    trunk's lateral axis at ``d``'s pose (None for a leg with fewer than two)."""
    m = rl.model
    rot = d.xmat[rl.legs.trunk].reshape(3, 3)
    out: list[tuple[int, int] | None] = []
    for i in range(len(rl.feet)):
        lateral = [
            int(j)
            for j in _leg_chain(rl, i)
            if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE
            and abs(float(d.xaxis[j] @ rot[:, 1])) > 0.7
        ]
        out.append((lateral[0], lateral[-1]) if len(lateral) >= 2 else None)
    return out


def leg_extension(rl: RobotLegs, qpos: np.ndarray | None = None) -> np.ndarray:
    """(nf,) how straight each leg is at ``qpos`` (default the standing pose): in the
    trunk's sagittal plane, the hip-to-foot distance over the summed hip-to-knee and
    knee-to-foot lengths (hip and knee: the first and the outermost own joint turning
    about the trunk's lateral axis). 1 is a straight leg; 0 for a leg without a knee."""
    m = rl.model
    d = mujoco.MjData(m)
    d.qpos[:] = rl.home if qpos is None else qpos
    mujoco.mj_kinematics(m, d)
    return _extensions(rl, d, _knee_joints(rl, d))


def _extensions(rl: RobotLegs, d: mujoco.MjData, knees: list) -> np.ndarray:
    """:func:`leg_extension` at ``d``'s pose (kinematics done) for (hip, knee) ``knees``."""
    rot = d.xmat[rl.legs.trunk].reshape(3, 3)
    pts = np.array(rl.legs.positions(d))
    out = np.zeros(len(rl.feet))
    for i, hk in enumerate(knees):
        if hk is None:
            continue
        hip, knee, foot = ((p @ rot)[[0, 2]] for p in (d.xanchor[hk[0]], d.xanchor[hk[1]], pts[i]))
        full = float(np.linalg.norm(knee - hip) + np.linalg.norm(foot - knee))
        out[i] = float(np.linalg.norm(foot - hip)) / full if full > 0 else 0.0
    return out


def _crouch(rl: RobotLegs, opts: RetargetOptions) -> np.ndarray:
    """A standing pose off the straight-leg singularity (see :func:`robot_legs`)."""
    m = rl.model
    d = mujoco.MjData(m)
    q = rl.home.copy()
    d.qpos[:] = q
    mujoco.mj_kinematics(m, d)
    feet = np.array(rl.legs.positions(d))
    rot = d.xmat[rl.legs.trunk].reshape(3, 3)
    for i, hk in enumerate(_knee_joints(rl, d)):
        if hk is None:
            continue
        adr = int(m.jnt_qposadr[hk[1]])
        k = int(np.flatnonzero(rl.qadr[i] == adr)[0])
        best, ahead = q[adr], -np.inf
        for sign in (1.0, -1.0):
            trial = q.copy()
            trial[adr] = np.clip(q[adr] + sign * opts.crouch_bend, rl.lo[i][k], rl.hi[i][k])
            d.qpos[:] = trial
            mujoco.mj_kinematics(m, d)
            x = float((rl.legs.positions(d)[i] - d.xpos[rl.legs.trunk]) @ rot[:, 0])
            if x > ahead:
                best, ahead = trial[adr], x
        q[adr] = best
    q[rl.trunk_qadr + 2] -= (1.0 - opts.crouch_height) * rl.height
    q, res = leg_ik(rl, q, feet, iterations=300, data=d, options=opts)
    if float(res.max()) > 0.01 * rl.leg_length:
        raise RetargetError(
            f"the robot has no 'home' keyframe and its qpos0 stands on straight legs; "
            f"crouching it left a foot {1000 * float(res.max()):.1f} mm from the ground "
            'point: add a <key name="home" qpos="..."/> standing pose to the model'
        )
    return q


def _need_feet(
    feet: Sequence[str] | None,
    model: mujoco.MjModel | None = None,
    home: str = "home",
    options: RetargetOptions | None = None,
) -> Sequence[str]:
    if feet is not None:
        return feet
    if model is None:
        raise RetargetError(
            "name the robot's feet (feet=[...], --feet FL,FR,RL,RR) in the order LF, RF, LH, RH"
        )
    return find_robot_feet(model, home, options)


def find_robot_feet(
    model: mujoco.MjModel, home: str = "home", options: RetargetOptions | None = None
) -> tuple[str, ...]:
    """The robot's four feet in the order LF, RF, LH, RH when nobody names them: the
    usual names (:func:`habitsim.mjutils.known_feet`: ``FL``, ``FL_foot``, ``LF_FOOT``
    …), else the four legs standing on the ground at the standing pose (the keyframe
    :func:`~habitsim.retarget.keyframes.standing_keyframe` picks with ``home`` and
    ``options``, else ``qpos0``; :func:`habitsim.mjutils.standing_feet`).

    Raises:
        RetargetError: not four legs standing on the ground, or a foot that is an
            unnamed geom other than a sphere (the message says what was found).
    """
    from ..mjutils import ModelLookupError, known_feet, standing_feet

    names = known_feet(model)
    if names is not None:
        return tuple(names)
    try:
        key = standing_keyframe(model, home, options)
        return standing_feet(model, model.qpos0.copy() if key is None else key[0])
    except ModelLookupError as e:
        raise RetargetError(
            f"{e}; name them (feet=[...], --feet FL,FR,RL,RR) in the order LF, RF, LH, RH"
        ) from e
