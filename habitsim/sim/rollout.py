"""In-engine servos without Python in the loop: many clips in one ``mujoco.rollout`` call."""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

import mujoco
import numpy as np

from .clip import _Clip
from .falls import FallDetector
from .loop import _frame_steps, _init_data
from .model import _touch, _touch_adr, foot_geoms
from .reference import build_reference
from .result import _Run
from .servo import _servo_power, servo_targets

_FULL = mujoco.mjtState.mjSTATE_FULLPHYSICS


def _state_offsets(model: mujoco.MjModel) -> dict[str, int]:
    """Offsets of time/qpos/qvel inside an mjSTATE_FULLPHYSICS vector."""
    off, out = 0, {}
    for name in ("TIME", "QPOS", "QVEL"):
        out[name] = off
        off += mujoco.mj_stateSize(model, getattr(mujoco.mjtState, f"mjSTATE_{name}"))
    return out


def _run_rollout(
    model: mujoco.MjModel,
    clips: Sequence[_Clip],
    threads: int,
    settle_s: float,
    stop_on_fall: bool,
    detectors: Sequence[FallDetector],
    v0_offsets: Sequence[np.ndarray | None] | None = None,
) -> list[_Run]:
    """All clips of one servo model in one ``mujoco.rollout`` call (no Python per step).

    Controls are :func:`servo_targets` of the reference at every step. Rollout freezes a
    clip's state after a MuJoCo warning, so a stalled clock or a NaN marks instability.
    Falls are found afterwards on the recorded frames (same :class:`FallDetector`).
    ``v0_offsets``: per clip, (nv,) added to its initial velocity (or None).
    """
    from mujoco import rollout

    dt = model.opt.timestep
    refs = [build_reference(model, c.qpos, c.fps, dt) for c in clips]
    fsteps = [_frame_steps(len(c.qpos), c.fps, dt) for c in clips]
    n_settle = int(round(settle_s / dt))
    nstep = max(1, max(int(f[-1]) for f in fsteps) + n_settle)
    wall0 = time.perf_counter()
    ctrl = np.empty((len(clips), nstep, model.nu))
    x0 = np.empty((len(clips), mujoco.mj_stateSize(model, _FULL)))
    for b, (c, r) in enumerate(zip(clips, refs, strict=True)):
        u = servo_targets(model, r.qpos, r.qvel)
        n = len(u)
        if n_settle:
            ctrl[b, :n_settle] = servo_targets(model, r.qpos[:1])[0]  # held at rest: no lead
        ctrl[b, n_settle : n_settle + n] = u
        ctrl[b, n_settle + n :] = u[-1]
        v0 = r.qvel[0] if n_settle == 0 else np.zeros(model.nv)
        dv = None if v0_offsets is None else v0_offsets[b]
        d = _init_data(model, c.qpos[0], v0 if dv is None else v0 + dv)
        mujoco.mj_getState(model, d, x0[b], _FULL)
    datas = [mujoco.MjData(model) for _ in range(max(1, threads))]
    state, _ = rollout.rollout(model, datas, x0, ctrl)
    off = _state_offsets(model)
    scratch = mujoco.MjData(model)
    runs = []
    for b, c in enumerate(clips):
        adr, feet = _touch_adr(model, c.feet), foot_geoms(model, c.feet)
        st = state[b]
        expect = x0[b, off["TIME"]] + dt * np.arange(1, nstep + 1)
        bad = ~np.isfinite(st).all(axis=1) | (np.abs(st[:, off["TIME"]] - expect) > 0.5 * dt)
        first_bad = int(np.argmax(bad)) if bad.any() else None
        start = x0[b] if n_settle == 0 else st[n_settle - 1]
        mujoco.mj_setState(model, scratch, start, _FULL)
        scratch.ctrl[:] = 0.0 if n_settle == 0 else ctrl[b, n_settle - 1]
        mujoco.mj_forward(model, scratch)
        qs = [scratch.qpos.copy()]
        touches = [_touch(model, scratch, adr, feet)]
        fall = unstable = None
        fall_reason = unstable_reason = None
        end_step = n_settle  # steps simulated up to the end of the survived part
        if first_bad is not None and first_bad < n_settle:
            unstable, unstable_reason = 0, "unstable while settling (NaN or MuJoCo warning)"
        detectors[b].reset()
        for k in range(1, len(fsteps[b])):
            if unstable is not None or (fall is not None and stop_on_fall):
                break
            s = n_settle + int(fsteps[b][k]) - 1
            if first_bad is not None and first_bad <= s:
                unstable, unstable_reason = k, "unstable: NaN or MuJoCo warning in rollout"
                break
            mujoco.mj_setState(model, scratch, st[s], _FULL)
            scratch.ctrl[:] = ctrl[b, s]  # the state holds no controls: the last applied
            mujoco.mj_forward(model, scratch)
            qs.append(scratch.qpos.copy())
            touches.append(_touch(model, scratch, adr, feet))
            reason = detectors[b].check(k, scratch)
            if reason is not None and fall is None:
                fall, fall_reason = k, reason
            if fall is None:
                end_step = s + 1
        # power of step i: servo torque at the state before the step (as MuJoCo's
        # qfrc_actuator in the Python loop) times the velocity after it
        sl = slice(n_settle, end_step)
        before = np.concatenate([start[None], st[:nstep]])[sl]
        q_pre = before[:, off["QPOS"] : off["QPOS"] + model.nq]
        v_pre = before[:, off["QVEL"] : off["QVEL"] + model.nv]
        v_post = st[sl, off["QVEL"] : off["QVEL"] + model.nv]
        work = float(_servo_power(model, q_pre, v_pre, v_post, ctrl[b, sl]).sum() * dt)
        sim_t = (n_settle + int(fsteps[b][len(qs) - 1]) - n_settle) * dt
        runs.append(
            _Run(
                np.array(qs),
                np.array(touches),
                fall,
                fall_reason,
                unstable,
                unstable_reason,
                work,
                0.0,
                sim_t,
            )
        )
    # wall time per clip: the shared rollout and all pre/post-processing, split evenly
    per_clip = (time.perf_counter() - wall0) / len(clips)
    for run in runs:
        run.wall_time_s = per_clip
    return runs


def _rollout_stats(threads: int) -> dict[str, Any]:
    return {
        "calls": 0,
        "mean_time_ms": 0.0,
        "max_time_ms": 0.0,
        "failures": 0,
        "notes": [f"in-engine servos via mujoco.rollout ({threads} thread(s))"],
    }
