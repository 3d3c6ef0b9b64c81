"""Optional root assistance (an external wrench on the trunk) with whole-body gains."""

from __future__ import annotations

import math
from typing import Any

import mujoco
import numpy as np

from ..errors import SimulationError, unknown_choice
from ..mjutils import home_qpos
from .model import _free_body
from .options import TrackOptions


def root_assist(
    model: mujoco.MjModel, frequency_hz: float = TrackOptions().assist_frequency_hz
) -> Any:
    """:class:`~habitsim.controllers.assist.RootAssist` with gains for the WHOLE body.

    Translation: ``kp = M·ω²``, ``kd = 2M·ω`` (ω = 2π·frequency, M the total mass).
    Rotation: the same with ``I = min(I_max, I_0 / (2ω·dt))``: I_max is the largest
    diagonal entry of the joint-space inertia of the free joint's rotational dofs at home
    (the whole body's inertia about the trunk origin), I_0 = 1/``dof_invweight0`` the
    effective rotational inertia with the other joints free (a lower bound). The
    assist's torque is explicit (held over a step), so its damping must stay below the
    stability limit ``kd·dt < 2·I_eff``; the cap keeps ``kd·dt/I_0 ≤ 1``. Axes with
    more inertia then run at a lower frequency than ω. (The assist's own default uses the
    trunk BODY's inertia, tens of times too small for a quadruped: a dog held in the air
    pitches nose-down.)
    """
    from ..controllers.assist import RootAssist

    trunk = _free_body(model)
    dof = int(model.jnt_dofadr[model.body_jntadr[trunk]])
    d = mujoco.MjData(model)
    d.qpos[:] = home_qpos(model)
    mujoco.mj_forward(model, d)
    full = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, d, full)
    rot = np.diag(full)[dof + 3 : dof + 6]
    mass = float(model.body_subtreemass[trunk])
    w = 2.0 * math.pi * frequency_hz
    i0 = 1.0 / float(model.dof_invweight0[dof + 3 : dof + 6].max())
    inertia = float(min(rot.max(), i0 / (2.0 * w * model.opt.timestep)))
    return RootAssist(model, kp=(mass * w**2, inertia * w**2), kd=(2 * mass * w, 2 * inertia * w))


def _make_assist(assist: Any, model: mujoco.MjModel, options: TrackOptions) -> Any:
    """None, or a :class:`~habitsim.controllers.assist.RootAssist` (or the given object)."""
    if assist is False or assist is None:
        return None
    if assist is True or assist == "root":
        return root_assist(model, options.assist_frequency_hz)
    if isinstance(assist, str):
        raise SimulationError(unknown_choice("assist", assist, ("root",)))
    if not (hasattr(assist, "apply") and hasattr(assist, "report")):
        raise SimulationError("assist must be 'root', True/False or a RootAssist-like object")
    return assist
