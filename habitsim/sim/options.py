"""The tracking runner's knobs (:class:`TrackOptions`)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class TrackOptions:
    """The tuning knobs of :func:`~habitsim.sim.track` and :func:`~habitsim.sim.track_many`.

    Attributes:
        mpc_control_hz: control rate of the ``"mpc"`` controller's torque layer when it is
            named and no ``control_hz`` is given [Hz] (the MPC itself solves at its own
            rate); ``balance`` keeps the full rate.
        assist_frequency_hz: natural frequency of the root assistance's gains
            (:func:`~habitsim.sim.root_assist`) [Hz].
    """

    mpc_control_hz: float = 250.0
    assist_frequency_hz: float = 5.0
