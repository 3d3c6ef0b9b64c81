"""The front door: :func:`track` (one clip) and :func:`track_many` (many, in threads)."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import mujoco
import numpy as np

from ..controllers import CONTROLLERS
from ..errors import SimulationError, unknown_choice
from ..motion import Motion
from ..qpos import QposTrajectory
from .assist import _make_assist
from .clip import _resolve
from .control import _control_every, _make_controller
from .falls import FallDetector
from .loop import _run_python
from .options import TrackOptions
from .result import TrackResult, _finish
from .rollout import _rollout_stats, _run_rollout
from .servo import _sim_model


def _check_settle(settle_s: float) -> None:
    if not (math.isfinite(settle_s) and settle_s >= 0):
        raise SimulationError(f"settle_s must be finite and >= 0, got {settle_s}")


def _velocity_noise(model: mujoco.MjModel, std: float, seed: int | None) -> np.ndarray | None:
    """(nv,) Gaussian noise of ``std`` on the hinge joints' velocities (None for 0)."""
    if std == 0:
        return None
    dv = np.zeros(model.nv)
    hinge = np.flatnonzero(model.jnt_type == mujoco.mjtJoint.mjJNT_HINGE)
    dofs = model.jnt_dofadr[hinge]
    dv[dofs] = np.random.default_rng(0 if seed is None else int(seed)).normal(0.0, std, len(dofs))
    return dv


def track(
    motion_or_qpos: Motion | QposTrajectory,
    *,
    species: str | None = None,
    controller: str | Any = "servo",
    assist: bool | str | Any = False,
    model: mujoco.MjModel | None = None,
    control_hz: float | None = None,
    settle_s: float = 0.0,
    stop_on_fall: bool = True,
    seed: int | None = None,
    use_rollout: bool | None = None,
    contacts: np.ndarray | None = None,
    feet: Sequence[str] | None = None,
    init_noise: float = 0.0,
    options: TrackOptions | None = None,
) -> TrackResult:
    """Track a reference motion in MuJoCo with a controller.

    The simulation starts at the reference's first frame (position and velocity; feet on
    the ground as the reference has them), the controller is called every
    ``1/control_hz`` s with the reference interpolated at that time
    (:func:`build_reference`), and the state is recorded at every reference frame, where
    falls (:class:`FallDetector`) and instability (NaN, any MuJoCo warning) are checked.

    Args:
        motion_or_qpos: a :class:`~habitsim.motion.Motion` or a
            :class:`~habitsim.qpos.QposTrajectory` (then ``species`` or ``model``).
        species: catalog species (checked against a Motion's).
        controller: a name of :data:`CONTROLLERS` — ``"servo"`` (in-engine position
            servos, ``ctrl`` = target angle), ``"pd"`` (explicit PD torques on the motors),
            ``"servo+stance"`` (plus the stance-leg trunk stabiliser, no external force),
            ``"balance"`` (stance-force QP every tick + swing-leg control on the torque
            motors) and ``"mpc"`` (convex single-rigid-body MPC feeding that QP), both
            planned from the clip's reference and contact table,
            ``"servo+id"`` / ``"servo+id+stance"`` (plus inverse-dynamics feed-forward) —
            or a :class:`~habitsim.controllers.Controller` instance for ``model``.
        assist: ``False``; ``True`` or ``"root"`` for
            :class:`~habitsim.controllers.assist.RootAssist` (an external wrench on the
            trunk, reported in ``assist``); or such an object.
        model: the model (default: the species' shipped model). Named servo controllers
            configure servos on it unless it has them already.
        control_hz: control rate [Hz] (default: every simulation step; for ``"mpc"`` by
            name :attr:`TrackOptions.mpc_control_hz`, also with a root assist whose damping
            the model integrates, :meth:`~habitsim.controllers.assist.RootAssist.damped_model`).
        settle_s: seconds to hold the first frame (from rest) before the clip starts.
        stop_on_fall: stop at the first fall (else simulate to the end; metrics still
            use the survived part only).
        seed: seed of the ``init_noise`` draw (default 0). Without noise every stage
            here is deterministic and the seed is not used.
        use_rollout: force (True) or forbid (False) the ``mujoco.rollout`` path; by
            default it is used for ``"servo"`` without assistance at the full rate.
        contacts: (T, 4) bool reference contact labels (LF, RF, LH, RH): the contact
            schedule of ``balance`` / ``mpc`` and the reference of ``contact_f1``.
            Default: a Motion's own labels, else contacts detected on the reference
            (for a qpos trajectory always detected). Pass the labels an earlier stage
            decided (refinement's) so they are not detected again. With ``feet``:
            (T, nf) in the order of ``feet``.
        feet: a robot's foot names (sites, geoms or bodies, as the robot names them,
            e.g. ``["FL", "FR", "RL", "RR"]`` on Menagerie's Unitree robots) when
            ``model`` is not a habitsim species model: the controllers' feet, the touch
            and contact labels, and the fall rule's allowed ground contacts. The input is
            then a qpos trajectory of the robot (:func:`habitsim.retarget.retarget` makes
            one from a Motion). A robot with position servos is simulated with torque
            motors of the same strength for ``pd``, ``balance`` and ``mpc``
            (:func:`habitsim.controllers.robot.torque_model`).
        init_noise: standard deviation [rad/s] of Gaussian noise added to the initial
            velocity of every hinge joint (the free joint keeps the reference's), drawn
            from ``seed``. A tracking whose outcome changes under noise far below any
            measurement's (10⁻³ rad/s) sits at its balance limit; repeating it with a few
            seeds measures how often it survives (``habitsim bench real --repeats``).
            0 (default): the reference's velocity exactly.
        options: the runner's tuning knobs (the mpc's default control rate, the root
            assistance's frequency; default :class:`TrackOptions`).

    Returns:
        The :class:`TrackResult` (metrics in :attr:`TrackResult.metrics`).

    Raises:
        SimulationError: unknown controller or assist, bad rates, a reference that does
            not fit the model (joints, nq) or is not finite, contacts of the wrong shape.
        UnknownSpeciesError: unknown species.
    """
    _check_settle(settle_s)
    options = options or TrackOptions()
    if not (math.isfinite(init_noise) and init_noise >= 0):
        raise SimulationError(f"init_noise must be finite and >= 0 [rad/s], got {init_noise}")
    clip = _resolve(motion_or_qpos, species, model, contacts=contacts, feet=feet)
    sim_model = _sim_model(controller, clip, model)
    dv0 = _velocity_noise(sim_model, init_noise, seed)
    asst = _make_assist(assist, sim_model, options)
    implicit = False
    if asst is not None and hasattr(asst, "damped_model"):
        # the assist's damping integrated implicitly (controllers.assist: held explicitly
        # it chattered against the balance and mpc controllers' own trunk feedback)
        if sim_model.opt.integrator != mujoco.mjtIntegrator.mjINT_RK4:
            sim_model = asst.damped_model(sim_model)
            implicit = True
    if control_hz is None and controller == "mpc" and (asst is None or implicit):
        # an assist whose damping is explicit keeps the full rate: held over a control
        # period of two steps it diverged; its stiffness alone is far inside the limit
        # (ω·dt = 0.13 at 5 Hz and 250 Hz)
        control_hz = options.mpc_control_hz
    every = _control_every(sim_model, control_hz)
    fast = controller == "servo" and asst is None and every == 1
    if use_rollout and not fast:
        raise SimulationError("use_rollout needs controller='servo', no assist, full rate")
    detector = FallDetector(sim_model, clip.qpos, clip.fps, clip.leg_length, clip.feet)
    if use_rollout if use_rollout is not None else fast:
        run = _run_rollout(sim_model, [clip], 1, settle_s, stop_on_fall, [detector], [dv0])[0]
        return _resting(_finish(clip, sim_model, run, "servo", _rollout_stats(1)), detector)
    ctl = _make_controller(
        controller, sim_model, clip, None if every == 1 else every * sim_model.opt.timestep
    )
    run = _run_python(sim_model, clip, ctl, asst, every, settle_s, stop_on_fall, detector, dv0)
    name = controller if isinstance(controller, str) else str(getattr(ctl, "name", "custom"))
    return _resting(_finish(clip, sim_model, run, name, ctl.stats.to_dict()), detector)


def _resting(result: TrackResult, detector: FallDetector) -> TrackResult:
    """The result with what the fall rule left uncounted because the reference lay."""
    if detector.resting is not None:
        result.reference_resting = detector.resting.describe(result.fps)
    return result


def track_many(
    motions: Sequence[Motion | QposTrajectory],
    *,
    species: str | None = None,
    controller: str | Callable[[mujoco.MjModel], Any] = "servo",
    assist: bool | str = False,
    control_hz: float | None = None,
    settle_s: float = 0.0,
    stop_on_fall: bool = True,
    threads: int | None = None,
    options: TrackOptions | None = None,
) -> list[TrackResult]:
    """Track many clips in parallel threads.

    With ``controller="servo"``, no assistance and the full control rate, the clips of
    each species run in ONE ``mujoco.rollout`` call over ``threads`` threads (the PD lives
    in the actuators, no Python per step). Otherwise a thread pool runs :func:`track` per
    clip (MuJoCo releases the GIL while stepping, the controllers' Python does not).

    Args:
        motions: the clips.
        species: species of QposTrajectory inputs.
        controller: a controller name, or a factory ``model -> Controller`` called once
            per clip with the model to simulate (controllers keep state).
        assist, control_hz, settle_s, stop_on_fall, options: as in :func:`track`.
        threads: worker threads (default: the CPU count).

    Returns:
        One :class:`TrackResult` per clip, in input order.
    """
    import os

    threads = int(threads or os.cpu_count() or 1)
    if threads < 1:
        raise SimulationError(f"threads must be >= 1, got {threads}")
    _check_settle(settle_s)
    if isinstance(controller, str) and controller not in CONTROLLERS:
        raise SimulationError(unknown_choice("controller", controller, CONTROLLERS))
    if not motions:
        return []
    fast = controller == "servo" and not assist and control_hz is None
    if not fast:

        def one(m: Motion | QposTrajectory) -> TrackResult:
            ctl: Any = controller
            mdl = None
            if not isinstance(controller, str):
                mdl = _resolve(m, species, None).base
                ctl = controller(mdl)
            return track(
                m,
                species=species,
                controller=ctl,
                assist=assist,
                model=mdl,
                control_hz=control_hz,
                settle_s=settle_s,
                stop_on_fall=stop_on_fall,
                use_rollout=False,
                options=options,
            )

        with ThreadPoolExecutor(max_workers=threads) as ex:
            return list(ex.map(one, motions))
    clips = [_resolve(m, species, None) for m in motions]
    results: list[TrackResult | None] = [None] * len(clips)
    groups: dict[str, list[int]] = {}
    for i, c in enumerate(clips):
        groups.setdefault(c.species, []).append(i)
    for idx in groups.values():
        sim_model = _sim_model("servo", clips[idx[0]], None)
        group = [clips[i] for i in idx]
        dets = [FallDetector(sim_model, c.qpos, c.fps, c.leg_length) for c in group]
        runs = _run_rollout(sim_model, group, threads, settle_s, stop_on_fall, dets)
        for i, c, r, det in zip(idx, group, runs, dets, strict=True):
            results[i] = _resting(_finish(c, sim_model, r, "servo", _rollout_stats(threads)), det)
    return [r for r in results if r is not None]
