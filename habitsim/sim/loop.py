"""The Python loop: the controller (and assistance) called at the control rate, the state
recorded at the reference frames, falls and instability checked there."""

from __future__ import annotations

import time
from typing import Any

import mujoco
import numpy as np

from .clip import _Clip
from .falls import FallDetector
from .model import _joint_dofs, _touch, _touch_adr, foot_geoms
from .reference import build_reference
from .result import _Run


def _frame_steps(n_frames: int, fps: float, dt: float) -> np.ndarray:
    """Number of mj_steps after which frame k is recorded (frame 0: 0 steps)."""
    return np.round(np.arange(n_frames) / fps / dt).astype(int)


def _init_data(model: mujoco.MjModel, q0: np.ndarray, v0: np.ndarray) -> mujoco.MjData:
    d = mujoco.MjData(model)
    d.qpos[:] = q0
    d.qvel[:] = v0
    mujoco.mj_forward(model, d)
    return d


def _warnings(data: mujoco.MjData) -> int:
    return int(sum(w.number for w in data.warning))


def _warning_names(data: mujoco.MjData) -> str:
    names = [mujoco.mjtWarning(i).name for i, w in enumerate(data.warning) if w.number]
    return ", ".join(names) or "NaN state"


def _run_python(
    model: mujoco.MjModel,
    clip: _Clip,
    ctl: Any,
    assist: Any,
    control_every: int,
    settle_s: float,
    stop_on_fall: bool,
    detector: FallDetector,
    v0_offset: np.ndarray | None = None,
) -> _Run:
    """Step-by-step loop with the controller (and assistance) called in Python
    (``v0_offset``: (nv,) added to the initial velocity)."""
    from ..controllers import Reference

    dt = model.opt.timestep
    ref = build_reference(model, clip.qpos, clip.fps, dt)
    fsteps = _frame_steps(len(clip.qpos), clip.fps, dt)
    n_total = int(fsteps[-1])
    adr, feet = _touch_adr(model, clip.feet), foot_geoms(model, clip.feet)
    jdofs = _joint_dofs(model)
    v0 = ref.qvel[0] if settle_s <= 0 else np.zeros(model.nv)
    data = _init_data(model, clip.qpos[0], v0 if v0_offset is None else v0 + v0_offset)
    # the assist rides on the controller when it can (Controller.control applies it)
    external_assist = None
    if assist is not None:
        if hasattr(ctl, "assist"):
            ctl.assist = assist
        else:
            external_assist = assist
    ctl.reset(model, data)
    if external_assist is not None:
        external_assist.reset(model, data)
    zeros = np.zeros(model.nv)

    def reference(i: int, hold: bool) -> Any:
        if hold:
            return Reference(0.0, ref.qpos[0], zeros, zeros, clip.contacts[0])
        k = min(int(ref.time[i] * clip.fps + 0.5), len(clip.contacts) - 1)
        return Reference(
            float(ref.time[i]), ref.qpos[i], ref.qvel[i], ref.qacc[i], clip.contacts[k]
        )

    def tick(r: Any) -> None:
        data.ctrl[:] = ctl.control(model, data, r)
        if external_assist is not None:
            external_assist.apply(model, data, r)

    wall0 = time.perf_counter()
    qs = [data.qpos.copy()]
    touches = [_touch(model, data, adr, feet)]
    fall = unstable = None
    fall_reason = unstable_reason = None
    for i in range(int(round(settle_s / dt))):  # optional hold of the first frame
        if i % control_every == 0:
            tick(reference(0, True))
        mujoco.mj_step(model, data)
    if settle_s > 0:
        if _warnings(data) or not np.all(np.isfinite(data.qpos)):
            unstable, unstable_reason = 0, f"unstable while settling: {_warning_names(data)}"
            n_total = 0
        qs[0] = data.qpos.copy()
        touches[0] = _touch(model, data, adr, feet)
        data.time = 0.0
    work = 0.0
    work_at_end = 0.0
    k = 1
    for i in range(n_total):
        if i % control_every == 0:
            tick(reference(i, False))
        mujoco.mj_step(model, data)
        tau = data.qfrc_actuator[jdofs] + data.qfrc_applied[jdofs]
        work += float(np.abs(tau * data.qvel[jdofs]).sum()) * dt
        while k < len(fsteps) and fsteps[k] == i + 1:
            if _warnings(data) or not np.all(np.isfinite(data.qpos)):
                unstable, unstable_reason = k, f"unstable: {_warning_names(data)}"
                break
            # mj_step leaves kinematics and sensors of the pre-step state: refresh them
            # (no effect on the next step) so frames, falls and touch match the state
            mujoco.mj_forward(model, data)
            qs.append(data.qpos.copy())
            touches.append(_touch(model, data, adr, feet))
            reason = detector.check(k, data)
            if reason is not None and fall is None:
                fall, fall_reason = k, reason
            if fall is None:
                work_at_end = work
            k += 1
        if unstable is not None or (fall is not None and stop_on_fall):
            break
    wall = time.perf_counter() - wall0
    rep: dict[str, Any] = {}
    if assist is not None:
        rep = dict(assist.report(data))
    return _Run(
        np.array(qs),
        np.array(touches).reshape(-1, len(feet)),
        fall,
        fall_reason,
        unstable,
        unstable_reason,
        work_at_end,
        wall,
        float(data.time),
        rep,
    )
