"""Build a MuJoCo model (MJCF) of a species from its catalog entry.

The model follows the habitsim skeleton exactly: one body per rotating skeleton joint,
placed at the joint's canonical-pose offset, carrying the hinges of the convention in
:mod:`habitsim.skeleton` (shoulder / hip: abduction about x then flexion about y; other
leg joints: flexion about y; spine, neck, head, tail: yaw about z then pitch about y),
so a habitsim :class:`~habitsim.motion.Motion` maps onto ``qpos`` by joint name. End
points of the skeleton (toes, snout, tail tip) are sites.

Conventions (after MuJoCo Menagerie):

* joints ``<skeleton joint>_<axis>`` with ``axis`` in ``flex, abd, pitch, yaw``; one
  ``<default>`` class per joint role carrying damping, armature and the motor's
  ``ctrlrange``; ranges from the species' joint limits;
* visual geoms (meshes exported with trimesh) in group 2 with contype = conaffinity = 0;
  collision capsules in group 3; foot spheres ``<leg>_foot`` with touch-sensor sites
  ``<leg>_foot_touch``; a free joint ``root`` on the pelvis;
* a ``home`` keyframe standing in the species' posture, ``implicitfast`` integrator,
  timestep 2 ms; ``<species>.xml`` holds the animal, ``scene.xml`` adds floor, light and
  includes it.

Two models per species. ``<species>.xml`` (and ``scene.xml``), as in Menagerie, is the
model that stands in plain MuJoCo: position actuators (:func:`position_spec`, made by
:func:`to_position_actuators`) whose ``home`` keyframe holds the standing pose in
``ctrl`` (``python -m mujoco.viewer --mjcf=.../scene.xml``, or ``mj_resetDataKeyframe`` +
``mj_step``, with no habitsim code). ``<species>_torque.xml`` (and ``scene_torque.xml``)
is the same animal with one torque motor per hinge instead (:func:`build_spec`): the
model habitsim's controllers drive, which needs a controller to stand.
``preview.png`` shows the standing model on ``home``.

Mass properties: each bone is a capsule (radius from the species' girth, i.e.
circumference / 2π) made with trimesh, which gives its volume and inertia tensor; one
density for the whole animal is chosen so the total mass equals the species' mass.
Actuator torque limits scale with m·g·L (L = hind-leg length), damping and armature with
the size too (see :attr:`BuildRules.role_torque`). The builder's rules (timestep,
foot friction, torque per joint role, the position actuators' stiffness and damping) are
the fields of :class:`BuildRules`, an argument of every build function.
"""

from __future__ import annotations

import math
import shutil
import tempfile
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType

import mujoco
import numpy as np

from habitsim.errors import HabitsimError
from habitsim.physics_constants import GRAVITY
from habitsim.skeleton import ABDUCTION_SIGN, FOOT_JOINTS, JOINT_NAMES, PARENTS, fk, get_skeleton
from habitsim.species import Species, load_species

from .geometry import _body_meshes, _bones_by_body, _foot_radius, _gravity_moments

__all__ = [
    "MODELS_DIR",
    "models_root",
    "GRAVITY",
    "BuildRules",
    "HingeJoint",
    "hinge_joints",
    "build_spec",
    "write_model",
    "build_all",
    "model_path",
    "scene_path",
    "torque_model_path",
    "torque_scene_path",
    "to_position_actuators",
    "position_spec",
    "preview_path",
    "write_preview",
]

MODELS_DIR = Path(__file__).resolve().parent
END_POINTS = ("snout", "tail3", *FOOT_JOINTS)


def _role_torque() -> Mapping[str, float]:
    """The default :attr:`BuildRules.role_torque`."""
    return MappingProxyType(
        {
            "girdle": 0.40,
            "upper_flex": 0.40,
            "upper_abd": 0.15,
            "lower": 0.35,
            "distal": 0.25,
            "spine": 0.40,
            "neck": 0.06,
            "head": 0.02,
            "tail": 0.01,
        }
    )


@dataclass(frozen=True)
class BuildRules:
    """The rules the MJCF builder makes a species' models by (why each default:
    docs/formats.md, "Species models").

    Attributes:
        timestep: the models' simulation timestep [s].
        foot_friction: sliding friction of the feet [unitless] (dry ground).
        role_torque: peak actuator torque per joint role [multiple of m·g·L]; the keys
            are the roles of :func:`hinge_joints`.
        load_factor: each joint also gets at least this many times the gravity moment of
            the body parts it carries [unitless].
        position_full_torque_error: joint angle error [rad] at which a position actuator
            of the standing model reaches its torque limit (kp = τmax / this; each limit
            scales with m·g·L, so the stiffness scales with the animal's size).
        position_dampratio: damping ratio of the position actuators (MuJoCo's
            ``dampratio``: kv from the joint's reflected inertia; 1 = critical), integrated
            implicitly by ``implicitfast`` [unitless].
    """

    timestep: float = 0.002
    foot_friction: float = 1.0
    role_torque: Mapping[str, float] = field(default_factory=_role_torque)
    load_factor: float = 4.0
    position_full_torque_error: float = 0.05
    position_dampratio: float = 1.0


class ModelBuildError(HabitsimError, RuntimeError):
    """The MJCF of a species failed to compile or write."""


@dataclass(frozen=True)
class HingeJoint:
    """One hinge of a species model.

    Attributes:
        name: MJCF joint (and actuator) name, ``<skeleton joint>_<axis>``.
        skeleton_joint: the habitsim joint it belongs to.
        axis: unit axis in the body frame (x, y or z).
        kind: ``flex``, ``abd``, ``pitch`` or ``yaw``.
        role: the species joint-limit role (e.g. ``hind_upper_flex``).
        torque_role: key of :attr:`BuildRules.role_torque`.
        sign: +1, or -1 where the limit role is expressed as "outward" abduction for a
            left leg (the range is mirrored).
    """

    name: str
    skeleton_joint: str
    axis: tuple[float, float, float]
    kind: str
    role: str
    torque_role: str
    sign: float = 1.0


_X, _Y, _Z = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)
_LEG_SEG_ROLE = {
    "scapula": ("girdle", "girdle"),
    "shoulder": ("upper", "upper_flex"),
    "elbow": ("lower", "lower"),
    "wrist": ("foot", "distal"),
    "ilium": ("girdle", "girdle"),
    "hip": ("upper", "upper_flex"),
    "knee": ("lower", "lower"),
    "hock": ("foot", "distal"),
}


def hinge_joints() -> list[HingeJoint]:
    """Every hinge of the habitsim model, in MJCF order (same for all species)."""
    out: list[HingeJoint] = []
    for name in JOINT_NAMES:
        if name == "pelvis" or name in END_POINTS:
            continue
        if name.startswith("spine") or name in ("neck", "head") or name.startswith("tail"):
            base = (
                "spine"
                if name.startswith("spine")
                else ("tail" if name.startswith("tail") else name)
            )
            out.append(HingeJoint(f"{name}_yaw", name, _Z, "yaw", f"{base}_yaw", base))
            out.append(HingeJoint(f"{name}_pitch", name, _Y, "pitch", f"{base}_pitch", base))
            continue
        limb = "fore" if name[1] == "f" else "hind"
        seg = name[3:]
        part, trole = _LEG_SEG_ROLE[seg]
        if seg in ("shoulder", "hip"):
            out.append(
                HingeJoint(
                    f"{name}_abd",
                    name,
                    _X,
                    "abd",
                    f"{limb}_upper_abd",
                    "upper_abd",
                    ABDUCTION_SIGN[name[0]],
                )
            )
        out.append(HingeJoint(f"{name}_flex", name, _Y, "flex", f"{limb}_{part}_flex", trole))
    return out


def _qpos_addresses(spec: mujoco.MjSpec) -> tuple[dict[str, int], int]:
    """qpos address of each joint of a spec (tree order, as the compiler assigns it)."""
    size = {mujoco.mjtJoint.mjJNT_FREE: 7, mujoco.mjtJoint.mjJNT_BALL: 4}
    adr: dict[str, int] = {}
    n = 0
    for jnt in spec.joints:
        adr[jnt.name] = n
        n += size.get(jnt.type, 1)
    return adr, n


def _home_qpos(sp: Species, joints: list[HingeJoint], spec: mujoco.MjSpec) -> np.ndarray:
    """qpos of the standing pose, placed by joint name (MuJoCo orders qpos depth-first)."""
    from habitsim.skeleton import standing_leg_angles

    skel = get_skeleton(sp)
    root, quats = skel.standing_pose()
    loc = standing_leg_angles(sp)
    adr, nq = _qpos_addresses(spec)
    q = np.zeros(nq)
    q[0:3] = root
    q[3:7] = quats[0]
    for h in joints:
        angle = 0.0
        if h.kind == "flex" or (
            h.kind == "pitch" and h.skeleton_joint in ("neck", "head", "tail1")
        ):
            angle = loc[h.role]
        q[adr[h.name]] = angle
    return q


def build_spec(
    species: str | Species,
    mesh_dir: str | Path | None = None,
    rules: BuildRules = BuildRules(),
) -> mujoco.MjSpec:
    """The MjSpec of a species' torque model (``<species>_torque.xml``, no floor; see
    :func:`write_model` for the scene): one torque motor per hinge, the model habitsim's
    controllers drive. :func:`position_spec` makes the standing model from it.

    Args:
        species: catalog name or Species.
        mesh_dir: folder the visual meshes are (or will be) written to as
            ``<body>.stl``; None builds the model without visual meshes.
        rules: the builder's rules.

    Returns:
        An MjSpec ready to compile.
    """
    sp = load_species(species)
    skel = get_skeleton(sp)
    g = GRAVITY
    mgl = sp.mass_kg * g * sp.leg_length
    spec = mujoco.MjSpec()
    spec.modelname = f"{sp.name}_torque"
    spec.compiler.degree = False
    spec.compiler.autolimits = True
    spec.option.timestep = rules.timestep
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.gravity = [0.0, 0.0, -g]
    spec.option.cone = mujoco.mjtCone.mjCONE_PYRAMIDAL
    if mesh_dir is not None:
        spec.meshdir = str(mesh_dir)

    # ---- default classes ------------------------------------------------------------
    root_def = spec.add_default(sp.name, spec.default)
    visual = spec.add_default("visual", root_def)
    visual.geom.group = 2
    visual.geom.contype = 0
    visual.geom.conaffinity = 0
    visual.geom.density = 0.0
    visual.geom.rgba = [0.72, 0.58, 0.42, 1.0]
    collision = spec.add_default("collision", root_def)
    collision.geom.group = 3
    collision.geom.contype = 1
    collision.geom.conaffinity = 0  # collide with the floor only, never with itself
    collision.geom.density = 0.0
    collision.geom.rgba = [0.5, 0.5, 0.9, 0.4]
    foot = spec.add_default("foot", collision)
    foot.geom.friction = [rules.foot_friction, 0.005, 0.0001]
    foot.geom.condim = 3
    classes = {}
    joints = hinge_joints()
    role_torque = rules.role_torque
    for role in role_torque:
        d = spec.add_default(role, root_def)
        tau = role_torque[role] * mgl
        d.actuator.ctrlrange = [-tau, tau]
        d.actuator.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
        d.joint.armature = 1e-3 * sp.mass_kg * sp.leg_length**2 * role_torque[role]
        # damping time constant ~5 % of the pendulum time sqrt(L/g) at peak torque
        d.joint.damping = [0.05 * tau * math.sqrt(sp.leg_length / g), 0.0, 0.0]
        classes[role] = d

    # ---- bodies -------------------------------------------------------------------
    root_pos, _ = skel.standing_pose()
    solids = _body_meshes(sp)
    bones = _bones_by_body(sp)
    _, home_rot = fk(skel, *skel.standing_pose(), return_rotations=True)  # (J, 3, 3)
    density = sp.mass_kg / sum(m.volume for m in solids.values())  # [kg/m^3]
    by_joint: dict[str, list[HingeJoint]] = {}
    for h in joints:
        by_joint.setdefault(h.skeleton_joint, []).append(h)
    bodies: dict[str, mujoco.MjsBody] = {}
    for j, name in enumerate(JOINT_NAMES):
        parent = PARENTS[j]
        if name in END_POINTS:
            continue
        if parent < 0:
            body = spec.worldbody.add_body(name=name, pos=list(root_pos), childclass=sp.name)
            body.add_freejoint(name="root")
            body.add_camera(
                name="track",
                mode=mujoco.mjtCamLight.mjCAMLIGHT_TRACKCOM,
                pos=[0.0, -4.0 * sp.hip_height, 1.0 * sp.hip_height],
                xyaxes=[1, 0, 0, 0, 0.25, 1],
            )
        else:
            body = bodies[JOINT_NAMES[parent]].add_body(name=name, pos=list(skel.offsets[j]))
        bodies[name] = body
        for h in by_joint.get(name, []):
            lo, hi = sp.joint_limits[h.role]
            rng = [lo, hi] if h.sign > 0 else [-hi, -lo]
            body.add_joint(
                classes[h.torque_role],
                name=h.name,
                axis=list(h.axis),
                range=rng,
                limited=mujoco.mjtLimited.mjLIMITED_TRUE,
            )
        # mass properties from the trimesh solids of this body's bones
        if name in solids:
            mesh = solids[name]
            body.mass = float(density * mesh.volume)
            body.ipos = list(mesh.center_mass)
            it = density * mesh.moment_inertia
            body.fullinertia = [it[0, 0], it[1, 1], it[2, 2], it[0, 1], it[0, 2], it[1, 2]]
            body.explicitinertial = True
        else:  # massless girdle root: a tiny inertia keeps the model well posed
            body.mass = 1e-4 * sp.mass_kg
            body.ipos = [0.0, 0.0, 0.0]
            r = 0.02 * sp.leg_length
            body.fullinertia = [0.4 * body.mass * r * r] * 3 + [0.0, 0.0, 0.0]
            body.explicitinertial = True
        for child, off, radius in bones.get(name, []):
            end = np.asarray(off, dtype=float)
            if child in FOOT_JOINTS:  # stop at the foot sphere's centre, never below it
                r_foot = _foot_radius(sp, child)
                end = end + home_rot[j].T @ np.array([0.0, 0.0, r_foot])
                radius = min(radius, 0.8 * r_foot)
            body.add_geom(
                collision,
                name=f"{name}_{child}_col",
                type=mujoco.mjtGeom.mjGEOM_CAPSULE,
                size=[radius, 0, 0],
                fromto=[0, 0, 0, *end],
            )
        if mesh_dir is not None and name in solids:
            mname = f"{name}_mesh"
            spec.add_mesh(name=mname, file=f"{name}.stl")
            body.add_geom(
                visual, name=f"{name}_visual", type=mujoco.mjtGeom.mjGEOM_MESH, meshname=mname
            )
    # end-point sites, feet; foot spheres sit straight above the toe in the home pose
    for j, name in enumerate(JOINT_NAMES):
        if name not in END_POINTS:
            continue
        parent_body = bodies[JOINT_NAMES[PARENTS[j]]]
        off = skel.offsets[j]
        parent_body.add_site(name=name, pos=list(off), size=[0.01 * sp.leg_length, 0, 0], group=4)
        if name in FOOT_JOINTS:
            leg = name[:2]
            r = _foot_radius(sp, name)
            up_local = home_rot[PARENTS[j]].T @ np.array([0.0, 0.0, r])
            centre = off + up_local  # sole tangent to the ground at the toe end point
            parent_body.add_geom(
                foot,
                name=f"{leg}_foot",
                type=mujoco.mjtGeom.mjGEOM_SPHERE,  # noqa: E501
                size=[r, 0, 0],
                pos=list(centre),
            )
            parent_body.add_site(
                name=f"{leg}_foot_touch", pos=list(centre), size=[1.05 * r, 0, 0], group=4
            )
            spec.add_sensor(
                name=f"{leg}_touch",
                type=mujoco.mjtSensor.mjSENS_TOUCH,
                objtype=mujoco.mjtObj.mjOBJ_SITE,
                objname=f"{leg}_foot_touch",
            )
    # ---- actuators: one torque motor per hinge --------------------------------------
    load = _gravity_moments(sp, solids, density)
    for h in joints:
        act = spec.add_actuator(
            classes[h.torque_role], name=h.name, target=h.name, trntype=mujoco.mjtTrn.mjTRN_JOINT
        )
        act.set_to_motor()
        tau = max(role_torque[h.torque_role] * mgl, rules.load_factor * load[h.skeleton_joint])
        if tau > role_torque[h.torque_role] * mgl:
            act.ctrlrange = [-tau, tau]
    spec.add_key(name="home", qpos=list(_home_qpos(sp, joints, spec)))
    return spec


def to_position_actuators(
    spec: mujoco.MjSpec,
    keyframe: str = "home",
    full_torque_error: float = BuildRules.position_full_torque_error,
    dampratio: float = BuildRules.position_dampratio,
) -> mujoco.MjSpec:
    """Turn the joint torque motors of a spec into position actuators holding a keyframe.

    Each motor ``<general>`` / ``<motor>`` on a hinge with control range ±τmax becomes a
    MuJoCo position actuator with

    * ``kp = τmax / full_torque_error`` (full torque at that angle error) and
      ``dampratio`` (MuJoCo computes kv from the joint's reflected inertia);
    * ``forcerange = ±τmax``: the torque model's limit, so the actuators are no stronger;
    * ``ctrlrange`` = the joint's range (a target is an angle).

    The keyframe's ``ctrl`` becomes its joint angles, so ``mj_resetDataKeyframe`` starts
    the model holding that pose. Nothing else changes: bodies, masses, contacts, gravity
    and the options stay as they were. The default classes' actuator settings are
    converted the same way, so the written XML stays class-based. Modifies ``spec`` in
    place and returns it.

    Example::

        path = "mjcf_models/cat/scene_torque.xml"
        spec = to_position_actuators(mujoco.MjSpec.from_file(path))
        model = spec.compile()   # stands after mj_resetDataKeyframe(model, data, 0)

    Raises:
        ModelBuildError: no such keyframe, a non-positive ``full_torque_error``, or an
            actuator that is not a gear-1 torque motor on a hinge with a control range.
    """
    if not full_torque_error > 0:
        raise ModelBuildError(f"full_torque_error must be positive, got {full_torque_error}")
    keys = [k for k in spec.keys if k.name == keyframe]
    if not keys:
        raise ModelBuildError(f"model {spec.modelname!r} has no keyframe {keyframe!r}")
    key = keys[0]
    adr, nq = _qpos_addresses(spec)
    if len(key.qpos) != nq:
        raise ModelBuildError(f"keyframe {keyframe!r} has {len(key.qpos)} qpos, model {nq}")
    joints = {j.name: j for j in spec.joints}

    def tau_of(act: mujoco.MjsActuator | mujoco.MjsDefault) -> float:
        return float(max(abs(act.ctrlrange[0]), abs(act.ctrlrange[1])))

    def convert(act: mujoco.MjsActuator, tau: float) -> None:
        act.set_to_position(kp=tau / full_torque_error, dampratio=dampratio)
        act.forcerange = [-tau, tau]
        act.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE

    converted: set[str] = set()
    ctrl = []
    for act in spec.actuators:
        joint = joints.get(act.target)
        motor = (
            act.gaintype == mujoco.mjtGain.mjGAIN_FIXED
            and act.biastype == mujoco.mjtBias.mjBIAS_NONE
        )
        if (
            act.trntype != mujoco.mjtTrn.mjTRN_JOINT
            or joint is None
            or joint.type != mujoco.mjtJoint.mjJNT_HINGE
            or not motor
            or act.gear[0] != 1.0
            or tau_of(act) <= 0
        ):
            raise ModelBuildError(
                f"actuator {act.name!r} is not a gear-1 torque motor on a hinge with a "
                "control range; only those can become position actuators"
            )
        cls = act.classname
        if cls is not None and cls.name not in converted and tau_of(cls.actuator) > 0:
            convert(cls.actuator, tau_of(cls.actuator))
            cls.actuator.ctrlrange = [0.0, 0.0]
            cls.actuator.ctrllimited = mujoco.mjtLimited.mjLIMITED_AUTO
            converted.add(cls.name)
        convert(act, tau_of(act))
        act.ctrlrange = list(joint.range)
        act.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
        ctrl.append(float(key.qpos[adr[joint.name]]))
    key.ctrl = ctrl
    return spec


def position_spec(
    species: str | Species,
    mesh_dir: str | Path | None = None,
    rules: BuildRules = BuildRules(),
) -> mujoco.MjSpec:
    """The MjSpec of a species' standing model (``<species>.xml``, no floor):
    :func:`build_spec` with position actuators holding ``home``
    (:func:`to_position_actuators`, with the stiffness and damping of ``rules``)."""
    sp = load_species(species)
    spec = to_position_actuators(
        build_spec(sp, mesh_dir=mesh_dir, rules=rules),
        full_torque_error=rules.position_full_torque_error,
        dampratio=rules.position_dampratio,
    )
    spec.modelname = sp.name
    return spec


_SCENE = """<mujoco model="{name} scene">
  <include file="{name}.xml"/>

  <statistic center="0 0 {cz:.4f}" extent="{extent:.4f}"/>

  <visual>
    <headlight diffuse="0.6 0.6 0.6" ambient="0.3 0.3 0.3" specular="0 0 0"/>
    <global azimuth="-120" elevation="-20"/>
  </visual>

  <asset>
    <texture type="skybox" builtin="gradient" rgb1="0.3 0.5 0.7" rgb2="0 0 0" width="512"
      height="3072"/>
    <texture type="2d" name="groundplane" builtin="checker" mark="edge" rgb1="0.2 0.3 0.4"
      rgb2="0.1 0.2 0.3" markrgb="0.8 0.8 0.8" width="300" height="300"/>
    <material name="groundplane" texture="groundplane" texuniform="true" texrepeat="5 5"
      reflectance="0.2"/>
  </asset>

  <worldbody>
    <light pos="0 0 {light:.3f}" dir="0 0 -1" directional="true"/>
    <geom name="floor" size="0 0 0.05" type="plane" material="groundplane" contype="1"
      conaffinity="1" friction="1 0.005 0.0001"/>
  </worldbody>
</mujoco>
"""


def models_root(species: str | Species) -> Path:
    """The folder holding a species' model folder: :data:`MODELS_DIR` for a built-in
    species, its user catalog folder for a user species."""
    sp = load_species(species)
    return MODELS_DIR if sp.user_catalog is None else sp.user_catalog


def _species_file(species: str | Species, filename: str, root: str | Path | None) -> Path:
    """``<root>/<species>/<filename>`` (root: :func:`models_root`); ``{name}`` in the
    file name is the species name."""
    sp = load_species(species)
    return Path(root or models_root(sp)) / sp.name / filename.format(name=sp.name)


def model_path(species: str | Species, root: str | Path | None = None) -> Path:
    """Path of ``<species>/<species>.xml`` in the models folder (or ``root``): the
    standing model (position actuators holding ``home``), no floor."""
    return _species_file(species, "{name}.xml", root)


def scene_path(species: str | Species, root: str | Path | None = None) -> Path:
    """Path of ``<species>/scene.xml`` in the models folder (or ``root``): floor, light
    and the standing model; it stands in plain MuJoCo from ``home``."""
    return _species_file(species, "scene.xml", root)


def torque_model_path(species: str | Species, root: str | Path | None = None) -> Path:
    """Path of ``<species>/<species>_torque.xml``: the torque model habitsim's
    controllers drive, no floor."""
    return _species_file(species, "{name}_torque.xml", root)


def torque_scene_path(species: str | Species, root: str | Path | None = None) -> Path:
    """Path of ``<species>/scene_torque.xml``: floor, light and the torque model (what
    :func:`habitsim.qpos.load_species_model` loads)."""
    return _species_file(species, "scene_torque.xml", root)


def preview_path(species: str | Species, root: str | Path | None = None) -> Path:
    """Path of ``<species>/preview.png``."""
    return _species_file(species, "preview.png", root)


#: Size of the preview images [px].
PREVIEW_SIZE = (320, 240)
#: Preview camera: distance in units of the scene's extent (body length), and
#: (azimuth, elevation) [deg] — a three-quarter view from the front left.
PREVIEW_DISTANCE = 1.7
PREVIEW_VIEW = (-60.0, -15.0)


def write_preview(species: str | Species, root: str | Path | None = None) -> Path:
    """Render ``<species>/preview.png`` (320×240): the standing model on its ``home``
    keyframe, in a three-quarter view from the front left.

    Rendering is headless (EGL or OSMesa when there is no display, see
    :mod:`habitsim.render`).

    Raises:
        RenderError: no OpenGL context here.
        ModelBuildError: the standing scene is missing (run :func:`write_model` first).
    """
    from PIL import Image

    from habitsim.render import RenderError, _headless_context

    sp = load_species(species)
    scene = scene_path(sp, root)
    if not scene.is_file():
        raise ModelBuildError(f"{scene} missing: build the model first")
    model = mujoco.MjModel.from_xml_path(str(scene))
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key("home").id)
    mujoco.mj_forward(model, data)
    cam = mujoco.MjvCamera()
    cam.type = mujoco.mjtCamera.mjCAMERA_FREE
    cam.lookat[:] = data.subtree_com[model.body("pelvis").id]
    cam.distance = PREVIEW_DISTANCE * model.stat.extent
    cam.azimuth, cam.elevation = PREVIEW_VIEW
    width, height = PREVIEW_SIZE
    _headless_context()
    try:
        with mujoco.Renderer(model, height, width) as renderer:
            renderer.update_scene(data, camera=cam)
            image = renderer.render()
    except Exception as e:  # noqa: BLE001 - GL backends raise many types
        raise RenderError(
            f"no OpenGL context for off-screen rendering ({e}); set MUJOCO_GL=egl or "
            "MUJOCO_GL=osmesa, or build with --no-preview"
        ) from e
    out = preview_path(sp, root)
    tmp = out.with_name(f".{out.name}.tmp")
    Image.fromarray(image).quantize(colors=128).save(tmp, format="PNG", optimize=True)
    tmp.replace(out)
    return out


def _readme(sp: Species, model: mujoco.MjModel, density: float, rules: BuildRules) -> str:
    hinges = hinge_joints()
    lines = [
        f"# {sp.common_name} (`{sp.name}`)",
        "",
        (
            f"Generated by `habitsim models build` from `habitsim/catalog/{sp.name}.toml`"
            if sp.user_catalog is None
            else f"Generated by `habitsim species from-clip` with `{sp.name}.toml` beside"
            " this folder (rebuild: `habitsim models build --species "
            f"{sp.name}`)"
        )
        + "; do not edit by hand.",
        "",
        "## How it was derived",
        "",
        "* Kinematic tree: the habitsim quadruped skeleton (30 joints) with this species'"
        " segment lengths as bone offsets; bodies sit at skeleton joints and carry the"
        " hinges of habitsim's convention (shoulder/hip abduction then flexion, other leg"
        " joints flexion, spine/neck/head/tail yaw then pitch).",
        "* Joint ranges: the species' joint limits (radians).",
        "* Solids: one capsule per bone, radius = girth / 2π, built with trimesh, which gives"
        " each body's volume, centre of mass and inertia tensor. One density"
        f" ({density:.0f} kg/m³) makes the total mass equal the species' mass"
        f" ({sp.mass_kg:g} kg; compiled total {model.body_mass.sum():.3f} kg).",
        "* Feet: spheres tangent to the toe end points (friction 1.0), with touch sensors.",
        f"* Actuators: one per hinge ({len(hinges)}), torque limit = role factor × m·g·L"
        f" (m·g·L = {sp.mass_kg * GRAVITY * sp.leg_length:.1f} N·m, L = hind-leg length"
        f" {sp.leg_length:.3f} m); joint damping and armature scale with the same size.",
        f"* `home` keyframe: the species' standing posture (hip height {sp.hip_height:.3f} m).",
        f"* Integrator implicitfast, timestep {rules.timestep * 1000:g} ms,"
        " pyramidal friction cones.",
        "",
        "## Files",
        "",
        "| file | what |",
        "|---|---|",
        f"| `scene.xml` | floor, light and `{sp.name}.xml`: open this one |",
        f"| `{sp.name}.xml` | the standing model: position actuators holding the `home`"
        " keyframe, so it stands in plain MuJoCo |",
        f"| `scene_torque.xml` | floor, light and `{sp.name}_torque.xml` |",
        f"| `{sp.name}_torque.xml` | the same animal with torque motors instead: the model"
        " habitsim's controllers drive (it needs a controller to stand) |",
        "| `assets/` | the visual meshes |",
        "| `preview.png` | the standing model on `home` |",
        "",
        "## Standing model",
        "",
        "```",
        "python -m mujoco.viewer --mjcf=scene.xml",
        "```",
        "",
        "The viewer opens at `qpos0` (straight legs); load the `home` keyframe (Simulation"
        " panel: Key 0, Load key) and it stands. In code: `mj_resetDataKeyframe(model, data,"
        " model.key('home').id)`, then `mj_step`.",
        "",
        f"* kp = τmax / {rules.position_full_torque_error:g} rad (each actuator's torque limit is"
        f" reached at {rules.position_full_torque_error:g} rad of error), damping ratio"
        f" {rules.position_dampratio:g}; force range = the torque motor's limit; control range ="
        " the joint's range; the `home` keyframe's `ctrl` holds the standing pose.",
        "* Made from the torque model by"
        " `habitsim.mjcf_models.builder.to_position_actuators`, which converts any such torque"
        " model in one call.",
        "",
        "## Sources of the species numbers",
        "",
        *[f"* {s}" for s in sp.sources],
        "",
    ]
    return "\n".join(lines)


def write_model(
    species: str | Species,
    root: str | Path | None = None,
    preview: bool = False,
    rules: BuildRules = BuildRules(),
) -> Path:
    """Write ``<root>/<species>/{<species>.xml, scene.xml, <species>_torque.xml,
    scene_torque.xml, README.md, assets/*.stl}`` (and ``preview.png`` with ``preview``).

    ``<species>.xml`` is the standing model (:func:`position_spec`), ``<species>_torque.xml``
    the torque model (:func:`build_spec`); each ``scene*.xml`` adds floor and light.

    A previous ``preview.png`` is kept when ``preview`` is False; ``rules`` are the
    builder's rules (:class:`BuildRules`).

    Everything is built in a temporary folder, compiled from the written XML as a check,
    then moved into place, so a failed build leaves the previous model untouched.

    Returns:
        The path of the written ``scene.xml`` (the standing scene).

    Raises:
        ModelBuildError: the generated model does not compile.
    """
    sp = load_species(species)
    final = Path(root or models_root(sp)) / sp.name
    final.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{sp.name}.", dir=final.parent))
    try:
        assets = tmp / "assets"
        assets.mkdir()
        for body, mesh in _body_meshes(sp).items():
            mesh.export(assets / f"{body}.stl")
        for make, name in ((position_spec, sp.name), (build_spec, f"{sp.name}_torque")):
            spec = make(sp, mesh_dir="assets", rules=rules)
            spec.modelfiledir = str(tmp)  # resolve "assets/" while compiling for to_xml
            (tmp / f"{name}.xml").write_text(spec.to_xml(), encoding="utf-8")
        solids = _body_meshes(sp)
        density = sp.mass_kg / sum(m.volume for m in solids.values())
        extent = 2.0 * sp.segments["trunk"] + sp.segments["neck"] + sp.segments["head"]
        for scene, animal in (
            ("scene.xml", sp.name),
            ("scene_torque.xml", f"{sp.name}_torque"),
        ):
            (tmp / scene).write_text(
                _SCENE.format(
                    name=animal,
                    cz=0.6 * sp.hip_height,
                    extent=extent,
                    light=3.0 * sp.hip_height + 1.0,
                ),
                encoding="utf-8",
            )
        try:
            model = mujoco.MjModel.from_xml_path(str(tmp / "scene.xml"))
            mujoco.MjModel.from_xml_path(str(tmp / "scene_torque.xml"))
        except ValueError as e:
            raise ModelBuildError(f"generated model of {sp.name!r} does not compile: {e}") from e
        if (final / "preview.png").is_file():
            shutil.copy2(final / "preview.png", tmp / "preview.png")
        (tmp / "README.md").write_text(_readme(sp, model, density, rules), encoding="utf-8")
        if final.exists():
            old = final.with_name(f".{sp.name}.old")
            shutil.rmtree(old, ignore_errors=True)
            final.rename(old)
            tmp.rename(final)
            shutil.rmtree(old, ignore_errors=True)
        else:
            tmp.rename(final)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    if preview:
        write_preview(sp, root)
    return final / "scene.xml"


def build_all(
    root: str | Path | None = None,
    species: list[str] | None = None,
    preview: bool = False,
    rules: BuildRules = BuildRules(),
) -> list[Path]:
    """Write the models of the given (default: all catalog) species by ``rules``."""
    from habitsim.species import species_names

    return [write_model(n, root, preview, rules) for n in (species or species_names())]
