"""Controllers usable on any MuJoCo model (installed as ``habitsim.controllers``).

* :class:`PDController`: explicit joint PD torques for torque motors, clipped to limits.
* :func:`configure_servos` / :class:`ServoController`: PD inside the engine (position or
  pid actuators), torque limits preserved.
* :mod:`~habitsim.controllers.gains`: stiffness rules, critical damping, stability limits.
* :class:`InverseDynamicsFeedforward`: ``mj_inverse`` on the reference.
* :class:`TrunkStabilizer` / :class:`StabilizedController`: stance-leg virtual model
  control of the trunk (a wrench distributed over the stance feet by a QP, applied as
  ``Jᵀf`` joint torques), no external force.
* :data:`CONTROLLERS` / :func:`make_controller`: every controller name, and one by name
  (:mod:`~habitsim.controllers.factory`, the one registry).
* :class:`RootAssist`: optional external PD wrench on the free joint, off unless created,
  always recorded.
"""

from .assist import RootAssist
from .base import (
    BaseController,
    Controller,
    ControllerError,
    ControllerStats,
    JointActuatorMap,
    PDController,
    Reference,
    actuated_joints,
    check_reference,
)
from .feedforward import FeedforwardOptions, InverseDynamicsFeedforward
from .gains import (
    critical_damping,
    effective_inertia,
    max_stable_gains,
    max_stable_kd,
    stiffness_rule,
)
from .servo import ServoController, ServoMap, configure_servos, servo_map
from .stance import StabilizedController, TrunkStabilizer, distribute_wrench

__all__ = [
    "BaseController",
    "Controller",
    "ControllerError",
    "ControllerStats",
    "FeedforwardOptions",
    "InverseDynamicsFeedforward",
    "JointActuatorMap",
    "PDController",
    "Reference",
    "RootAssist",
    "ServoController",
    "ServoMap",
    "StabilizedController",
    "TrunkStabilizer",
    "actuated_joints",
    "check_reference",
    "configure_servos",
    "critical_damping",
    "distribute_wrench",
    "effective_inertia",
    "max_stable_gains",
    "max_stable_kd",
    "servo_map",
    "stiffness_rule",
]

# Balance-aware tracking (issue [6/6]): stance-force QP, convex MPC, swing legs, factory.
from .balance import BalanceConfig, BalanceController, StanceQP  # noqa: E402
from .factory import (  # noqa: E402
    CONTROLLER_NAMES,
    CONTROLLERS,
    REGISTRY,
    ControllerSpec,
    controller_spec,
    make_controller,
)
from .legs import LegSet  # noqa: E402
from .mpc import ConvexMPC, MPCController, MPCWeights  # noqa: E402
from .plan import MotionPlan, plan_from_qpos  # noqa: E402

__all__ += [
    "BalanceConfig",
    "BalanceController",
    "CONTROLLER_NAMES",
    "CONTROLLERS",
    "REGISTRY",
    "ControllerSpec",
    "controller_spec",
    "ConvexMPC",
    "LegSet",
    "MPCController",
    "MPCWeights",
    "MotionPlan",
    "StanceQP",
    "make_controller",
    "plan_from_qpos",
]

# Robots habitsim did not build (issue [4/5]): position servos driven as torques, feet by
# the robot's own names.
from .robot import ServoTorque, foot_geoms, torque_model  # noqa: E402

__all__ += ["ServoTorque", "foot_geoms", "torque_model"]
