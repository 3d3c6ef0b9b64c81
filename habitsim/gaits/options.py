"""The knobs of the synthetic gait generator: :class:`GeneratorOptions`."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import GaitError

__all__ = ["GeneratorOptions", "resolve_generator"]


@dataclass(frozen=True)
class GeneratorOptions:
    """The tuning knobs of :func:`habitsim.gaits.generate`.

    Pass one as ``options`` to :func:`~habitsim.gaits.generate`; left out, the defaults
    apply (the clips of ``GENERATOR_VERSION``). Change a knob with
    :func:`dataclasses.replace`; a clip made with other options is not the versioned
    generator's clip. Pairs are (fore, hind).

    Attributes:
        duration_range_s: range a clip's length is drawn in when none is given [s].
        turn_rate_nd_range: range of the dimensionless turn rate ω·sqrt(h/g) of the turn
            actions.
        feasible_stance_error_m: a cyclic clip whose planted toes miss their footholds by
            more than this is drawn again at a lower speed / turn rate [m].
        max_attempts: most draws of a cyclic clip's speed and turn rate [count].
        retry_shrink: each new draw scales the drawn speed and turn rate (above their
            slow end) and the duty factor's rise by this factor [share, in (0, 1]].
        swing_ramp: share of the swing over which the foot speeds up (and, at its end,
            slows down) [share of the swing].
        girdle_sweep_gain: how much the scapula / ilium follows the leg's sweep angle
            [rad / rad], (fore, hind).
        foot_sweep_gain: how much the foot segment follows the leg's sweep angle
            [rad / rad], (fore, hind).
        swing_foot_fold_rad: foot fold in mid-swing, toe trailing [rad], (fore, hind).
        reach_margin: stance legs keep this share of their maximal upper + lower reach
            in reserve [share].
        fold_margin: stance legs keep at least this multiple of their minimal reach
            [factor].
        foot_compliance_rad: largest turn of the foot segment that takes up a leg's
            reach before the trunk has to come down (or up): the compliance of the
            fetlock / hock in stance [rad].
        limit_offset_rad: the foot-inclination offsets searched to keep a leg's
            flexion angles in range span ± this [rad].
        limit_offset_count: number of those offsets, evenly spaced [count].
        chain_transition_strides: a chained clip's change of gait or of turn rate takes
            this many strides (at the slower gait's stride frequency) [strides].
        chain_stop_strides: a chained stop (or start) speeds down (up) over this many
            strides of the gait it leaves (joins) [strides].
        chain_blend_s: the trunk eases between locomotion and a chained idle / sit over
            this long [s].
        chain_segment_s: range a drawn chain's segment lengths are drawn in, above each
            action's shortest [s] (:func:`~habitsim.gaits.chain.draw_chain`).
        chain_steps: range of the number of segments of a drawn chain [count].
    """

    duration_range_s: tuple[float, float] = (2.0, 6.0)
    turn_rate_nd_range: tuple[float, float] = (0.08, 0.25)
    feasible_stance_error_m: float = 5e-4
    max_attempts: int = 6
    retry_shrink: float = 0.7
    swing_ramp: float = 0.15
    girdle_sweep_gain: tuple[float, float] = (0.35, 0.0)
    foot_sweep_gain: tuple[float, float] = (0.5, 0.6)
    swing_foot_fold_rad: tuple[float, float] = (0.6, 0.3)
    reach_margin: float = 0.03
    fold_margin: float = 1.15
    foot_compliance_rad: float = 0.6
    limit_offset_rad: float = 0.6
    limit_offset_count: int = 25
    chain_transition_strides: float = 1.2
    chain_stop_strides: float = 2.0
    chain_blend_s: float = 0.3
    chain_segment_s: tuple[float, float] = (1.0, 2.5)
    chain_steps: tuple[int, int] = (2, 4)

    def __post_init__(self) -> None:
        for name in ("duration_range_s", "turn_rate_nd_range"):
            lo, hi = getattr(self, name)
            if not (math.isfinite(lo) and math.isfinite(hi) and 0.0 < lo <= hi):
                raise GaitError(f"{name} must be finite with 0 < lo ≤ hi, got {(lo, hi)!r}")
        positive = (
            "feasible_stance_error_m",
            "swing_ramp",
            "fold_margin",
            "limit_offset_rad",
            "chain_transition_strides",
            "chain_stop_strides",
            "chain_blend_s",
        )
        for name in positive:
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0.0):
                raise GaitError(f"{name} must be finite and > 0, got {v!r}")
        for name in ("reach_margin", "foot_compliance_rad"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0.0):
                raise GaitError(f"{name} must be finite and ≥ 0, got {v!r}")
        if not (0.0 < self.retry_shrink <= 1.0):
            raise GaitError(f"retry_shrink must lie in (0, 1], got {self.retry_shrink!r}")
        if self.swing_ramp > 0.5 or self.reach_margin >= 1.0:
            raise GaitError("swing_ramp must be ≤ 0.5 and reach_margin < 1")
        lo_s, hi_s = self.chain_segment_s
        if not (math.isfinite(lo_s) and math.isfinite(hi_s) and 0.0 <= lo_s <= hi_s):
            raise GaitError(
                f"chain_segment_s must be finite with 0 ≤ lo ≤ hi, got {(lo_s, hi_s)!r}"
            )
        lo_n, hi_n = self.chain_steps
        if not (2 <= lo_n <= hi_n <= 8):
            raise GaitError(f"chain_steps must satisfy 2 ≤ lo ≤ hi ≤ 8, got {(lo_n, hi_n)!r}")
        if self.max_attempts < 1 or self.limit_offset_count < 1:
            raise GaitError("max_attempts and limit_offset_count must be ≥ 1")

    def limb(self, pair: tuple[float, float], limb: str) -> float:
        """The fore or hind value of a (fore, hind) pair of these options."""
        return pair[0] if limb == "fore" else pair[1]

    def limit_offsets(self) -> np.ndarray:
        """The candidate foot-inclination offsets [rad] of ``respect_limits``."""
        return np.linspace(-self.limit_offset_rad, self.limit_offset_rad, self.limit_offset_count)


_DEFAULT_GENERATOR = GeneratorOptions()


def resolve_generator(options: GeneratorOptions | None) -> GeneratorOptions:
    """``options``, or the default :class:`GeneratorOptions` when it is None."""
    return _DEFAULT_GENERATOR if options is None else options
