"""Motion ↔ MuJoCo ``qpos`` by joint name.

A habitsim :class:`~habitsim.motion.Motion` maps onto any MJCF model whose joints follow
the naming ``<skeleton joint>_<flex|abd|pitch|yaw>`` plus one free joint on the pelvis
(the habitsim species models do; see :mod:`habitsim.mjcf_models.builder`): the free joint
takes the root position and the pelvis orientation, each hinge the angle obtained by
decomposing the local rotation onto the hinge axes (:func:`habitsim.hinges.hinge_angles`).
What the hinges cannot represent (e.g. a twist of a knee) is reported as a residual.

MJCF abduction hinges are raw rotations about +x; the species' limits read "outward =
positive", so ``qpos = ABDUCTION_SIGN[side] · abd``.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import mujoco
import numpy as np

from .errors import InvalidMotionError
from .hinges import HINGE_JOINTS, HINGE_NAMES, compose_hinges, hinge_angles
from .mjutils import free_joints
from .motion import Motion
from .rotations import quat_angle, quat_fix_continuity, quat_normalize
from .skeleton import ABDUCTION_SIGN, JOINT_NAMES

__all__ = [
    "QposTrajectory",
    "load_species_model",
    "species_model",
    "motion_to_qpos",
    "qpos_to_motion",
    "qpos_joint_positions",
]


@dataclass(frozen=True)
class QposTrajectory:
    """A qpos trajectory for a model.

    Attributes:
        qpos: (T, nq) generalised positions.
        fps: frame rate [Hz].
        residual_rad: (T,) largest angle [rad] per frame between a joint's rotation in the
            motion and what the model's hinges represent (0 within the hinge space).
        missing: habitsim hinges the model does not have (their motion is dropped).
    """

    qpos: np.ndarray
    fps: float
    residual_rad: np.ndarray
    missing: tuple[str, ...]


def load_species_model(species: str) -> mujoco.MjModel:
    """The shipped torque scene (``scene_torque.xml``: torque model + floor) of a catalog
    species, the model habitsim's controllers drive; a fresh compile on every call."""
    from .mjcf_models.builder import torque_scene_path

    path = torque_scene_path(species)
    if not path.is_file():
        raise InvalidMotionError(
            f"no MJCF model for species {species!r} at {path}; run `habitsim models build`"
        )
    return mujoco.MjModel.from_xml_path(str(path))


def species_model(species: str, servos: bool = False) -> mujoco.MjModel:
    """The shipped model of a catalog species, compiled once per process.

    The one model cache of habitsim: tracking (:mod:`habitsim.sim`), the pipeline
    (:mod:`habitsim.pipeline`, which hands it to refinement), the dynamic metrics and the
    benchmarks share it, so a species is compiled once however many stages use it.
    The instance is shared: never modify it (copy it first; :func:`load_species_model`
    compiles a fresh one).

    Args:
        species: catalog species name.
        servos: the variant whose joint motors are in-engine position servos
            (:func:`habitsim.sim.servo_model`).

    Raises:
        UnknownSpeciesError: unknown species.
        InvalidMotionError: no MJCF model for it.
    """
    from .species import load_species

    return _compiled(load_species(species).name, bool(servos))


@functools.lru_cache(maxsize=64)
def _compiled(species: str, servos: bool) -> mujoco.MjModel:
    if servos:
        from .controllers.servo import configure_servos

        return configure_servos(_compiled(species, False))
    return load_species_model(species)


def _free_joint(model: mujoco.MjModel) -> int:
    free = free_joints(model)
    if len(free) != 1:
        raise InvalidMotionError(f"the model needs exactly one free joint, found {len(free)}")
    return free[0]


def _hinge_sign(name: str) -> float:
    return ABDUCTION_SIGN[name[0]] if name.endswith("_abd") else 1.0


def motion_to_qpos(motion: Motion, model: mujoco.MjModel | None = None) -> QposTrajectory:
    """Map a motion onto a model's ``qpos`` by joint name.

    Args:
        motion: the motion.
        model: a MuJoCo model following habitsim's joint naming (default: the species'
            shipped model). Joints of the model that are not habitsim hinges keep their
            ``qpos0``.

    Returns:
        The qpos trajectory with the per-frame residual.

    Raises:
        InvalidMotionError: the model has no single free joint or no habitsim hinge.
    """
    model = load_species_model(motion.species) if model is None else model
    free = _free_joint(model)
    angles = hinge_angles(motion)
    t = motion.num_frames
    qpos = np.tile(model.qpos0, (t, 1))
    a = model.jnt_qposadr[free]
    qpos[:, a : a + 3] = motion.root_positions
    qpos[:, a + 3 : a + 7] = quat_fix_continuity(motion.rotations[:, 0], axis=0)
    found = []
    for name in HINGE_NAMES:
        jid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)
        if jid < 0:
            continue
        if model.jnt_type[jid] != mujoco.mjtJoint.mjJNT_HINGE:
            raise InvalidMotionError(f"model joint {name!r} is not a hinge")
        qpos[:, model.jnt_qposadr[jid]] = _hinge_sign(name) * angles[name]
        found.append(name)
    if not found:
        raise InvalidMotionError(
            "the model has none of the habitsim hinge joints (names like 'lh_knee_flex')"
        )
    missing = tuple(n for n in HINGE_NAMES if n not in found)
    # What the model represents: the kept hinges composed on identity; compare per joint.
    ident = np.tile([1.0, 0.0, 0.0, 0.0], (t, len(JOINT_NAMES), 1))
    rebuilt = compose_hinges({n: angles[n] for n in found}, base=ident)
    hinged = [JOINT_NAMES.index(j) for j in HINGE_JOINTS]
    residual = quat_angle(motion.rotations[:, hinged], rebuilt[:, hinged]).max(axis=1)
    return QposTrajectory(qpos, motion.fps, residual, missing)


def qpos_to_motion(model: mujoco.MjModel, qpos: np.ndarray, species: str, fps: float) -> Motion:
    """Rebuild a habitsim Motion from a qpos trajectory of a habitsim-named model."""
    qpos = np.atleast_2d(np.asarray(qpos, dtype=np.float64))
    if qpos.shape[1] != model.nq:
        raise InvalidMotionError(f"qpos must have shape (T, {model.nq}), got {qpos.shape}")
    if not np.all(np.isfinite(qpos)):
        raise InvalidMotionError("qpos contains NaN or inf")
    free = _free_joint(model)
    a = model.jnt_qposadr[free]
    angles = {}
    for name in HINGE_NAMES:
        jid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)
        if jid >= 0:
            angles[name] = _hinge_sign(name) * qpos[:, model.jnt_qposadr[jid]]
    base = np.tile([1.0, 0.0, 0.0, 0.0], (qpos.shape[0], len(JOINT_NAMES), 1))
    base[:, 0] = quat_normalize(qpos[:, a + 3 : a + 7])
    rot = compose_hinges(angles, base=base)
    return Motion(species, fps, qpos[:, a : a + 3].copy(), rot)


def qpos_joint_positions(model: mujoco.MjModel, qpos: np.ndarray) -> np.ndarray:
    """(T, J, 3) world positions of the habitsim joints by MuJoCo's own FK.

    Joints are read from bodies of the same name, end points from sites of the same name.
    """
    qpos = np.atleast_2d(np.asarray(qpos, dtype=np.float64))
    data = mujoco.MjData(model)
    src = []
    for name in JOINT_NAMES:
        bid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)
        if bid >= 0:
            src.append(("b", bid))
            continue
        sid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, name)
        if sid < 0:
            raise InvalidMotionError(f"model has neither a body nor a site named {name!r}")
        src.append(("s", sid))
    bodies = np.array([i for k, i in src if k == "b"])
    sites = np.array([i for k, i in src if k == "s"])
    is_body = np.array([k == "b" for k, _ in src])
    out = np.empty((qpos.shape[0], len(JOINT_NAMES), 3))
    for t in range(qpos.shape[0]):
        data.qpos[:] = qpos[t]
        mujoco.mj_kinematics(model, data)
        out[t, is_body] = data.xpos[bodies]
        out[t, ~is_body] = data.site_xpos[sites]
    return out
