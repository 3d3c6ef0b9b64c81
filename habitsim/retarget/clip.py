"""A robot reference: :class:`RobotClip`, its file, and tracking it."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from ..jsonfile import loads_json
from .errors import RetargetError

__all__ = ["RobotClip", "load_robot_clip", "track_clip", "CLIP_VERSION"]

#: File format version of a saved :class:`RobotClip`.
CLIP_VERSION = 1


@dataclass
class RobotClip:
    """A reference for a robot: qpos at a frame rate, contact labels, foot names.

    Attributes:
        qpos: (T, nq) frames; fps: frame rate [Hz]; contacts: (T, nf) bool stance labels
        in the order of ``feet``; feet: the robot's foot names.
        metadata: JSON-ready figures (source, scale, IK residual, clipped joints, …).
    """

    qpos: np.ndarray
    fps: float
    contacts: np.ndarray
    feet: tuple[str, ...]
    metadata: dict[str, Any] = field(default_factory=dict)

    @property
    def duration(self) -> float:
        return (len(self.qpos) - 1) / self.fps if len(self.qpos) > 1 else 0.0

    def trajectory(self) -> Any:
        """The frames as a :class:`~habitsim.qpos.QposTrajectory` (for
        :func:`habitsim.sim.track`)."""
        from ..qpos import QposTrajectory

        return QposTrajectory(
            qpos=self.qpos, fps=self.fps, residual_rad=np.zeros(len(self.qpos)), missing=()
        )

    def save(self, path: str | Path) -> Path:
        """Write the clip as ``.npz`` atomically (a temporary file renamed over ``path``)."""
        from ..fileio import atomic_write, json_safe

        path = Path(path)
        with atomic_write(path) as fh:
            np.savez_compressed(
                fh,
                version=np.array(CLIP_VERSION),
                qpos=self.qpos,
                fps=np.array(self.fps),
                contacts=self.contacts,
                feet=np.array(self.feet),
                metadata=np.array(json.dumps(json_safe(self.metadata))),
            )
        return path


def load_robot_clip(path: str | Path) -> RobotClip:
    """Read a clip written by :meth:`RobotClip.save`.

    Raises:
        RetargetError: missing file, not a robot clip, wrong version.
    """
    p = Path(path)
    try:
        with np.load(p, allow_pickle=False) as z:
            if "qpos" not in z or "feet" not in z:
                raise RetargetError(f"{str(p)!r} is not a robot clip (no qpos/feet arrays)")
            if int(z["version"]) != CLIP_VERSION:
                raise RetargetError(
                    f"{str(p)!r} has robot clip version {int(z['version'])}, "
                    f"this habitsim reads {CLIP_VERSION}"
                )
            return RobotClip(
                qpos=z["qpos"].astype(float),
                fps=float(z["fps"]),
                contacts=z["contacts"].astype(bool),
                feet=tuple(str(f) for f in z["feet"]),
                metadata=loads_json(str(z["metadata"]), f"{p}: metadata", error=RetargetError),
            )
    except (OSError, ValueError, KeyError) as e:
        raise RetargetError(f"cannot read robot clip {str(p)!r}: {e}") from e


def track_clip(
    clip: RobotClip, robot: mujoco.MjModel, *, controller: str | Any = "mpc", **options: Any
):
    """Track a :class:`RobotClip` on ``robot`` with :func:`habitsim.sim.track` (its feet,
    its contact labels; ``options`` are passed on, e.g. ``stop_on_fall``)."""
    from ..sim import track

    return track(
        clip.trajectory(),
        model=robot,
        feet=clip.feet,
        contacts=clip.contacts,
        controller=controller,
        **options,
    )
