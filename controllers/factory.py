"""The controller registry: every controller name, and ``make_controller(name, model)``.

:data:`CONTROLLERS` is the one list of controller names in habitsim: the tracking runner
(:func:`habitsim.sim.track`), the command line (``--controller`` choices) and the
evaluation all take it from here. Each name has a :class:`ControllerSpec` in
:data:`REGISTRY` (which actuators it drives, whether it plans with the whole clip, and
the constructor :func:`make_controller` calls):

* ``"servo"`` — :class:`~habitsim.controllers.ServoController`: in-engine position
  servos (``ctrl`` = target angle; the model must have servos, see
  :func:`~habitsim.controllers.configure_servos`).
* ``"servo+stance"``, ``"servo+id"``, ``"servo+id+stance"`` — the same servos plus the
  stance-leg trunk stabiliser (:class:`~habitsim.controllers.TrunkStabilizer`, virtual
  model control, no external force) and / or inverse-dynamics feed-forward torques of the
  reference (:class:`~habitsim.controllers.InverseDynamicsFeedforward`).
* ``"pd"`` — :class:`~habitsim.controllers.PDController` on the joint motors, stiffness by
  the torque rule (kp = τmax / 0.15 rad) and critical damping, both capped at half the
  explicit-integration stability limit; no balance, no external force.
* ``"balance"`` — :class:`~habitsim.controllers.balance.BalanceController`: stance-force QP
  every tick, swing legs on the motion's foot paths, posture PD.
* ``"mpc"`` — :class:`~habitsim.controllers.mpc.MPCController`: convex single-rigid-body
  MPC (30 Hz, horizon ≥ one stride) feeding the same stance QP.

Parameters scale with the body: its mass (from the model) and leg length (the species'
hind-leg length when ``species`` is given, else the model's trunk height over the feet).
``balance`` and ``mpc`` plan with the whole clip: pass it here (``qpos``, ``fps``,
``contacts``) or later with ``controller.set_plan(qpos, fps, contacts)`` before
``reset``.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Literal, Protocol, cast

import mujoco
import numpy as np

from habitsim.errors import unknown_choice

from .base import Controller, ControllerError, PDController, actuated_joints

if TYPE_CHECKING:
    from .balance import BalanceController

__all__ = [
    "ControllerConstructor",
    "CONTROLLERS",
    "CONTROLLER_NAMES",
    "REGISTRY",
    "ControllerSpec",
    "controller_spec",
    "make_controller",
    "default_pd",
]


class ControllerConstructor(Protocol):
    """``build(model, species, feet, options) -> Controller``: a registry entry's
    constructor. ``options`` are :func:`make_controller`'s ``**options`` (the constructor
    takes what it knows and raises :class:`ControllerError` on the rest); the reference
    clip of a planned controller is set afterwards (``set_plan``)."""

    def __call__(
        self,
        model: mujoco.MjModel,
        species: Any,
        feet: Sequence[str] | None,
        options: dict[str, Any],
    ) -> Controller: ...


@dataclass(frozen=True)
class ControllerSpec:
    """A controller name, what it needs of the model and the clip, and its constructor.

    Attributes:
        name: the name (``--controller`` on the command line).
        actuators: ``"servo"``: the model must have position servos (the tracking runner
            configures them, :func:`~habitsim.controllers.configure_servos`);
            ``"torque"``: torque motors (a robot's servos are turned into motors of the
            same strength, :func:`~habitsim.controllers.robot.torque_model`).
        planned: the controller plans with the whole clip (``set_plan``).
        summary: one line for help texts.
        build: the constructor (:class:`ControllerConstructor`) :func:`make_controller`
            calls.
    """

    name: str
    actuators: Literal["servo", "torque"]
    planned: bool
    summary: str
    build: ControllerConstructor


#: Foot geoms of habitsim's species models (LF, RF, LH, RH): the trunk stabiliser's default.
_SPECIES_FEET = ("lf_foot", "rf_foot", "lh_foot", "rh_foot")


def _leg_length(species: Any) -> float | None:
    if species is None:
        return None
    from habitsim.species import load_species

    return float(load_species(species).leg_length)


def _servo(
    name: str,
    model: mujoco.MjModel,
    species: Any,
    feet: Sequence[str] | None,
    options: dict[str, Any],
) -> Controller:
    """``servo``, optionally ``+id`` (inverse-dynamics feed-forward) and ``+stance`` (the
    trunk stabiliser on ``feet``, default habitsim's foot geoms); ``species`` unused."""
    if options:
        raise ControllerError(f"unknown {name} option(s): {', '.join(sorted(options))}")
    from .feedforward import InverseDynamicsFeedforward
    from .servo import ServoController

    ff = InverseDynamicsFeedforward(model) if "+id" in name else None
    servo = ServoController(model, feedforward=ff)
    if not name.endswith("+stance"):
        return servo
    from .stance import StabilizedController, TrunkStabilizer

    stab = TrunkStabilizer(model, _SPECIES_FEET if feet is None else feet)
    return StabilizedController(servo, stab)


def _pd(
    model: mujoco.MjModel,
    species: Any,
    feet: Sequence[str] | None,
    options: dict[str, Any],
) -> Controller:
    """``pd``: gains ``kp`` and ``kd`` given, or both by :func:`default_pd`; ``species``
    and ``feet`` unused."""
    kp, kd = options.pop("kp", None), options.pop("kd", None)
    joints, dt = options.pop("joints", None), options.pop("dt", None)
    if options:
        raise ControllerError(
            f"unknown pd option(s): {', '.join(sorted(options))}; valid: kp, kd, joints, dt"
        )
    if kp is None and kd is None:
        return default_pd(model, joints, dt)
    if kp is None or kd is None:
        raise ControllerError("pass both kp and kd (or neither for the default rule)")
    return PDController(model, kp, kd, joints)


def _balance_class() -> type:
    from .balance import BalanceController

    return BalanceController


def _mpc_class() -> type:
    from .mpc import MPCController

    return MPCController


def _leg_scaled(
    controller_class: Callable[[], type],
    model: mujoco.MjModel,
    species: Any,
    feet: Sequence[str] | None,
    options: dict[str, Any],
) -> Controller:
    """``balance`` / ``mpc`` (the class ``controller_class()`` returns, imported on first
    use), scaled by the species' leg length unless ``leg_length`` is given."""
    leg = _leg_length(species)
    if leg is not None:
        options.setdefault("leg_length", leg)
    ctl: Controller = controller_class()(model, feet, **options)
    return ctl


#: Every controller name, in the order help texts and tables list them.
REGISTRY: Mapping[str, ControllerSpec] = {
    s.name: s
    for s in (
        ControllerSpec(
            "servo",
            "servo",
            False,
            "in-engine position servos",
            functools.partial(_servo, "servo"),
        ),
        ControllerSpec("pd", "torque", False, "explicit PD torques on the motors", _pd),
        ControllerSpec(
            "servo+stance",
            "servo",
            False,
            "servos + stance-leg trunk stabiliser",
            functools.partial(_servo, "servo+stance"),
        ),
        ControllerSpec(
            "servo+id",
            "servo",
            False,
            "servos + inverse-dynamics feed-forward",
            functools.partial(_servo, "servo+id"),
        ),
        ControllerSpec(
            "servo+id+stance",
            "servo",
            False,
            "servos + inverse-dynamics feed-forward + trunk stabiliser",
            functools.partial(_servo, "servo+id+stance"),
        ),
        ControllerSpec(
            "balance",
            "torque",
            True,
            "stance-force QP + swing legs",
            functools.partial(_leg_scaled, _balance_class),
        ),
        ControllerSpec(
            "mpc",
            "torque",
            True,
            "convex MPC feeding the stance-force QP",
            functools.partial(_leg_scaled, _mpc_class),
        ),
    )
}
#: The controller names accepted by :func:`make_controller` and :func:`habitsim.sim.track`.
CONTROLLERS: tuple[str, ...] = tuple(REGISTRY)
#: Same tuple as :data:`CONTROLLERS` (the older name).
CONTROLLER_NAMES = CONTROLLERS


def controller_spec(name: str) -> ControllerSpec:
    """The :class:`ControllerSpec` of a name.

    Raises:
        ControllerError: unknown name (the message lists the valid ones).
    """
    try:
        return REGISTRY[name]
    except (KeyError, TypeError):
        raise ControllerError(unknown_choice("controller", name, CONTROLLERS)) from None


def default_pd(
    model: mujoco.MjModel, joints: Sequence[str] | None = None, dt: float | None = None
) -> PDController:
    """Explicit joint PD with the torque rule and critical damping, capped at half the
    explicit-integration stability limit for a control period ``dt`` (default: the
    model's time step)."""
    from .gains import critical_damping, max_stable_gains, stiffness_rule

    names = actuated_joints(model, joints).names
    kp_max, kd_max = max_stable_gains(model, dt, joints=names)
    kp = np.minimum(stiffness_rule(model, names, mode="torque"), kp_max)
    kd = np.minimum(critical_damping(model, kp, names), kd_max)
    return PDController(model, kp, kd, names)


def make_controller(
    name: str,
    model: mujoco.MjModel,
    species=None,
    *,
    qpos: np.ndarray | None = None,
    fps: float | None = None,
    contacts: np.ndarray | None = None,
    feet: Sequence[str] | None = None,
    **options,
) -> Controller:
    """A controller for ``model`` by name.

    Args:
        name: one of :data:`CONTROLLERS`.
        model: the model to control: torque motors on the joints (the shipped species
            models), or position servos (most robot MJCFs, e.g. MuJoCo Menagerie's):
            ``balance`` and ``mpc`` drive a servo with the target that makes it exert the
            torque they want (:class:`~habitsim.controllers.robot.ServoTorque`); ``pd``
            needs torque motors (:func:`~habitsim.controllers.robot.torque_model`).
        species: catalog species name or :class:`~habitsim.species.Species` (sets the
            leg length used for scaling); ``None`` for a user model.
        qpos, fps, contacts: the reference clip, (T, nq) at ``fps`` with (T, n_feet)
            contact labels (LF, RF, LH, RH), given to ``balance`` / ``mpc`` as their plan.
        feet: foot names as the model names them — sites, geoms or bodies, in the order
            of the contact labels, e.g. ``["FL", "FR", "RL", "RR"]`` on Menagerie's Unitree
            robots (default: ``lf_foot …`` or the usual robot names).
        **options: passed on — servo names: none; ``pd``: ``kp``, ``kd``, ``joints``,
            ``dt``; ``balance``: :class:`~habitsim.controllers.balance.BalanceConfig`
            fields, ``solver``, ``control_dt``; ``mpc``: those plus ``rate_hz``,
            ``horizon_s``, ``max_steps``, ``mpc_solver``, ``weights``, ``feedback_scale``,
            ``resolve_on_contact``.

    Raises:
        ControllerError: unknown name (the message lists the valid ones), a model the
            controller does not fit, bad options.
        UnknownSpeciesError: unknown species.
    """
    spec = controller_spec(name)
    ctl = spec.build(model, species, feet, options)
    if spec.planned and qpos is not None:
        if fps is None:
            raise ControllerError("a reference qpos needs fps")
        cast("BalanceController", ctl).set_plan(qpos, fps, contacts)  # balance, mpc
    return ctl
