"""One input clip resolved: reference qpos, contact labels, leg length, feet."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np

from ..contacts import contacts_from_feet
from ..errors import InvalidMotionError, SimulationError
from ..motion import Motion
from ..qpos import QposTrajectory, motion_to_qpos
from ..species import load_species
from ..stance.labels import StanceLabels, StanceSource
from .model import _foot_points, _model_leg_length, _species_model
from .reference import _check_qpos


@dataclass
class _Clip:
    species: str
    base: mujoco.MjModel  # the model the reference was mapped on (torque motors or servos)
    qpos: np.ndarray  # (T, nq)
    fps: float
    labels: StanceLabels  # (T, nf) reference stance labels and where they came from
    leg_length: float
    feet: tuple[str, ...] | None = None  # a robot's foot names (None: habitsim's)

    @property
    def contacts(self) -> np.ndarray:
        """(T, nf) bool reference contact labels (read-only)."""
        return self.labels.array


def _check_contacts(contacts: Any, n_frames: int, n_feet: int = 4) -> np.ndarray:
    """Explicit reference contact labels as (T, nf) bool."""
    c = np.asarray(contacts)
    if c.shape != (n_frames, n_feet):
        order = "feet LF, RF, LH, RH" if n_feet == 4 else f"{n_feet} feet"
        raise SimulationError(
            f"contacts must have shape ({n_frames}, {n_feet}) ({order}), got {c.shape}"
        )
    if c.dtype != bool and not np.isin(c, (0, 1)).all():
        raise SimulationError("contacts must be booleans (or 0/1)")
    return c.astype(bool)


def _resolve(
    motion_or_qpos: Motion | QposTrajectory | np.ndarray,
    species: str | None,
    model: mujoco.MjModel | None,
    fps: float | None = None,
    contacts: np.ndarray | None = None,
    feet: Sequence[str] | None = None,
) -> _Clip:
    """Reference qpos, contacts and sizes of one input clip (explicit ``contacts`` labels
    win over a motion's own and over detection). ``feet`` names a robot's feet: the
    clip is then a qpos trajectory of that robot (a Motion is retargeted first, see
    :mod:`habitsim.retarget`)."""
    if feet is not None:
        feet = tuple(feet)
        if not feet:
            raise SimulationError("feet=[] names no foot")
        if isinstance(motion_or_qpos, Motion):
            raise SimulationError(
                "a Motion is tracked on habitsim's own models; for a robot (feet=...) "
                "retarget it first (habitsim.retarget.retarget or `habitsim retarget`) and "
                "track the qpos trajectory"
            )
        if model is None:
            raise SimulationError("feet=... names a robot's feet: pass the robot as model=")
    if isinstance(motion_or_qpos, Motion):
        motion = motion_or_qpos
        if species is not None and load_species(species).name != motion.species:
            raise SimulationError(
                f"species {species!r} given but the motion is of {motion.species!r}"
            )
        base = _species_model(motion.species, False) if model is None else model
        try:
            traj = motion_to_qpos(motion, base)
        except InvalidMotionError as e:
            raise SimulationError(f"the motion does not fit the model: {e}") from e
        if contacts is not None:
            labels = StanceLabels(_check_contacts(contacts, motion.num_frames), StanceSource.GIVEN)
        elif motion.contacts is not None:
            labels = StanceLabels(np.asarray(motion.contacts, bool), StanceSource.INPUT)
        else:
            labels = StanceLabels(motion.detect_contacts(), StanceSource.DETECTED)
        sp = motion.species_info
        return _Clip(sp.name, base, _check_qpos(base, traj.qpos), motion.fps, labels, sp.leg_length)
    if isinstance(motion_or_qpos, QposTrajectory | np.ndarray):
        if species is None and model is None:
            raise SimulationError("a qpos trajectory needs species= (or model=)")
        spq = load_species(species) if species is not None else None
        if model is None:
            assert spq is not None  # species= is given without model= (checked above)
            base = _species_model(spq.name, False)
        else:
            base = model
        if isinstance(motion_or_qpos, QposTrajectory):
            q, f = motion_or_qpos.qpos, motion_or_qpos.fps
        else:
            if fps is None:
                raise SimulationError("a bare qpos array needs fps=")
            q, f = motion_or_qpos, fps
        q = _check_qpos(base, q)
        leg = spq.leg_length if spq is not None else _model_leg_length(base, feet)
        nf = 4 if feet is None else len(feet)
        if contacts is not None:
            labels = StanceLabels(_check_contacts(contacts, len(q), nf), StanceSource.GIVEN)
        else:
            labels = StanceLabels(
                contacts_from_feet(_foot_points(base, q, feet), f, leg), StanceSource.DETECTED
            )
        name = spq.name if spq is not None else "model"
        if spq is None and feet is not None:
            name = bytes(base.names).split(b"\0", 1)[0].decode() or "robot"
        return _Clip(name, base, q, float(f), labels, leg, feet)
    raise SimulationError(
        f"expected a Motion or a QposTrajectory, got {type(motion_or_qpos).__name__}"
    )
