"""The outcome of a run: the raw :class:`_Run` and the :class:`TrackResult` with metrics."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import mujoco
import numpy as np

from ..motion import Motion
from ..qpos import qpos_to_motion
from .model import TOUCH_THRESHOLD_MG, _total_mass

if TYPE_CHECKING:
    from .clip import _Clip


@dataclass
class TrackResult:
    """The outcome of tracking one clip.

    Attributes:
        species: species name (or the model name for a user model).
        fps: frame rate [Hz] of the reference and of the recorded frames.
        model: the simulated MuJoCo model (for the shipped species models a per-process
            cached instance shared by every run: copy it before modifying).
        qpos: (K, nq) simulated qpos at the reference frames that were reached (K ≤ T;
            K < T when the run stopped at a fall or instability).
        reference_qpos: (T, nq) reference frames.
        contacts: (K, 4) bool simulated foot contacts (touch > 1 % m·g), LF, RF, LH, RH.
        touch: (K, 4) foot normal forces [N].
        reference_contacts: (T, 4) bool reference contacts.
        fell: a fall by docs/metrics.md's rule; fall_time [s] and fall_reason say when/why.
        unstable: the simulation produced NaN or a MuJoCo warning (a failed run).
        survival: share of the clip completed before a fall or instability.
        controller: controller name; controller_stats: its ``stats.to_dict()``.
        assist: the assistance report (``{"assist_force_mg": 0.0}`` when off).
        work_j: Σ|τ·q̇|·dt over the survived part [J].
        wall_time_s: wall-clock time of the simulation loop [s].
        metrics: :data:`habitsim.metrics.simulated.SIMULATED_KEYS` → value.
        reference_resting: when a clause of the fall rule fired while the reference
            itself lay or sat (:class:`habitsim.sim.falls.ReferenceResting`), what and
            when, in words: not a fall of the controller (None otherwise).
    """

    species: str
    fps: float
    model: mujoco.MjModel
    qpos: np.ndarray
    reference_qpos: np.ndarray
    contacts: np.ndarray
    touch: np.ndarray
    reference_contacts: np.ndarray
    fell: bool
    fall_time: float | None
    fall_reason: str | None
    unstable: bool
    unstable_reason: str | None
    survival: float
    controller: str
    controller_stats: dict[str, Any]
    assist: dict[str, Any]
    work_j: float
    wall_time_s: float
    sim_time_s: float
    metrics: dict[str, Any] = field(default_factory=dict)
    reference_resting: str | None = None

    @property
    def failed(self) -> bool:
        return self.fell or self.unstable

    def motion(self) -> Motion:
        """The simulated frames as a habitsim Motion (with simulated contacts)."""
        m = qpos_to_motion(self.model, self.qpos, self.species, self.fps)
        m.contacts = self.contacts.copy()
        m.metadata = {
            "source": "habitsim.sim.track",
            "controller": self.controller,
            "fell": self.fell,
            "fall_time": self.fall_time,
            "unstable": self.unstable,
            "survival": self.survival,
        }
        return m

    def report(self) -> dict[str, Any]:
        """JSON-ready report: every metric, failure info, controller stats, assist report."""
        return _clean(
            {
                "species": self.species,
                "fps": self.fps,
                "frames": int(self.reference_qpos.shape[0]),
                "frames_simulated": int(self.qpos.shape[0]),
                "duration_s": (self.reference_qpos.shape[0] - 1) / self.fps,
                "controller": self.controller,
                "timestep_s": float(self.model.opt.timestep),
                "fell": self.fell,
                "fall_time_s": self.fall_time,
                "fall_reason": self.fall_reason,
                "reference_resting": self.reference_resting,
                "unstable": self.unstable,
                "unstable_reason": self.unstable_reason,
                "metrics": self.metrics,
                "controller_stats": self.controller_stats,
                "assist": self.assist,
                "mujoco_version": mujoco.__version__,
            }
        )


def _clean(v: Any) -> Any:
    if isinstance(v, dict):
        return {str(k): _clean(x) for k, x in v.items()}
    if isinstance(v, list | tuple):
        return [_clean(x) for x in v]
    if isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


@dataclass
class _Run:
    """Raw outcome of one simulated clip, before metrics."""

    qpos: np.ndarray  # (K, nq) recorded frames
    touch: np.ndarray  # (K, 4)
    fall_frame: int | None
    fall_reason: str | None
    unstable_frame: int | None
    unstable_reason: str | None
    work_j: float  # Σ|τ·q̇|dt up to the end of the survived part
    wall_time_s: float
    sim_time_s: float
    assist_report: dict[str, Any] = field(default_factory=dict)


def _finish(
    clip: _Clip,
    model: mujoco.MjModel,
    run: _Run,
    controller: str,
    stats: dict[str, Any],
) -> TrackResult:
    from ..metrics.simulated import simulated_metrics

    mg = _total_mass(model) * float(np.linalg.norm(model.opt.gravity))
    n_ref = len(clip.qpos)
    duration = (n_ref - 1) / clip.fps if n_ref > 1 else 0.0
    fall_t = None if run.fall_frame is None else run.fall_frame / clip.fps
    end = [f for f in (run.fall_frame, run.unstable_frame) if f is not None]
    survival = min(end) / clip.fps / duration if end and duration > 0 else 1.0
    if end and duration == 0:
        survival = 0.0
    contacts = run.touch > TOUCH_THRESHOLD_MG * mg
    report: dict[str, Any] = dict(run.assist_report) if run.assist_report else {"assist_on": False}
    report.setdefault("assist_force_mg", 0.0)
    res = TrackResult(
        species=clip.species,
        fps=clip.fps,
        model=model,
        qpos=run.qpos,
        reference_qpos=clip.qpos,
        contacts=contacts,
        touch=run.touch,
        reference_contacts=clip.contacts.copy(),
        fell=run.fall_frame is not None,
        fall_time=fall_t,
        fall_reason=run.fall_reason,
        unstable=run.unstable_frame is not None,
        unstable_reason=run.unstable_reason,
        survival=float(survival),
        controller=controller,
        controller_stats=stats,
        assist=report,
        work_j=run.work_j,
        wall_time_s=run.wall_time_s,
        sim_time_s=run.sim_time_s,
    )
    res.metrics = simulated_metrics(
        model,
        res.qpos,
        clip.qpos,
        res.contacts,
        clip.contacts,
        leg_length=clip.leg_length,
        survival=res.survival,
        fell=res.failed,
        work_j=run.work_j,
        assist_force_mg=float(report["assist_force_mg"]),
        sim_time_s=run.sim_time_s,
        wall_time_s=run.wall_time_s,
    )
    return res
