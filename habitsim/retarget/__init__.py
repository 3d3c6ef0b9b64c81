"""Animal motion on a legged robot: foot paths and trunk path mapped onto its joints.

:func:`retarget` maps a habitsim :class:`~habitsim.motion.Motion` (a synthetic gait, a
transfer, an imported BVH) onto a robot MJCF with a free joint and named feet:

1. **Source paths.** The motion is played on its species' model (MuJoCo FK): per frame
   the trunk (pelvis) position and orientation, the lowest point of each foot and the
   contact labels (the motion's own, else detected).
2. **Scaling.** Lengths are scaled by ``k = L_robot / L_species`` (leg lengths: the
   species' hind-leg length, the robot's trunk height over its feet at ``home``). The
   trunk keeps its path and its orientation relative to the standing pose::

       c_r,xy = k·c_s,xy      c_r,z = H_r + k·(c_s,z − c̄_s,z)
       (roll, pitch, yaw)_r = (roll − r̄oll, pitch − p̄itch, yaw)_s

   ``H_r`` the robot's standing trunk height, ``c̄_s,z`` the source's mean trunk height,
   r̄oll and p̄itch its mean trunk roll and pitch (a pelvis slopes; the robot's trunk
   stands level). Each foot keeps its scaled path, moved
   horizontally (in the trunk's heading frame) from the source's mean stance offset
   under the trunk to the robot's own::

       p_r,i = k·p_s,i + Rz(ψ)·(n_r,i − k·n̄_s,i)ₓᵧ

   and during every stance run of the labels it is held where it is at mid-stance, on
   the ground, so the robot's stance feet do not slide whatever the source's did.
3. **Leg IK** (:func:`leg_ik`) on the robot's own leg joints: damped least squares on
   the feet's translational Jacobians (``mujoco.mj_jac``), the trunk set to its pose,
   every joint kept inside its range, warm-started from the previous frame.

The result is a :class:`RobotClip` (qpos at the motion's frame rate, contact labels,
foot names, figures of the fit), saved atomically as ``.npz``; track it with
``habitsim.sim.track(clip.trajectory(), model=robot, feet=clip.feet,
contacts=clip.contacts, controller="mpc")`` (:func:`track_clip`).

:func:`trot` and :func:`stand` make a robot reference from nothing: trotting in place
or forward (the same IK), standing on ``home``.

Bad input raises :class:`RetargetError`; units are SI, world z up, ground at z = 0.
"""

from __future__ import annotations

from .clip import CLIP_VERSION as CLIP_VERSION
from .clip import RobotClip, load_robot_clip, track_clip
from .errors import RetargetError, RobotSourceError, StandingPoseError, VendorError
from .ik import leg_ik
from .keyframes import file_keyframes, nearby_keyframes, standing_keyframe
from .legs import StandingPoseWarning, find_robot_feet, leg_extension, robot_legs, stand_check
from .legs import _knee_joints as _knee_joints
from .mapping import retarget
from .options import CROUCH_BEND as CROUCH_BEND
from .options import CROUCH_HEIGHT as CROUCH_HEIGHT
from .options import HINGE_SPAN as HINGE_SPAN
from .options import LOWER_PASSES as LOWER_PASSES
from .options import MAX_IK_STEP as MAX_IK_STEP
from .options import STRAIGHT_REACH as STRAIGHT_REACH
from .options import RetargetOptions
from .references import stand, trot
from .robot import RobotLegs, drawable, load_robot, menagerie_robot
from .vendor import VendorOptions, VendorReport, vendor_robot

__all__ = [
    "RetargetError",
    "StandingPoseError",
    "StandingPoseWarning",
    "RobotSourceError",
    "VendorError",
    "VendorOptions",
    "VendorReport",
    "vendor_robot",
    "stand_check",
    "standing_keyframe",
    "file_keyframes",
    "nearby_keyframes",
    "RetargetOptions",
    "RobotLegs",
    "RobotClip",
    "robot_legs",
    "find_robot_feet",
    "load_robot",
    "menagerie_robot",
    "leg_ik",
    "leg_extension",
    "retarget",
    "trot",
    "stand",
    "track_clip",
    "load_robot_clip",
    "drawable",
]
