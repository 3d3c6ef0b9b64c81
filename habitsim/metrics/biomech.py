"""Biomechanical consistency: how far a motion's gait is from its species' habits.

The measured numbers are docs/metrics.md's (from foot contacts, via
:func:`habitsim.gait_stats.gait_statistics`): ``froude`` v²/(g·h), ``duty_factor``,
``relative_stride_length`` λ/h and ``phase_offsets`` (touchdown phase of each foot
relative to the left hind foot). They are compared with each gait of the species' gait
table (``[gaits.*]`` of its catalog file: Froude band, duty-factor band, footfall
phases) and with Alexander's stride relation λ/h ≈ 2.3·Fr^0.3 (docs/biomechanics.md). Four
dimensionless components, each reading about 1 for a clear departure:

==========================  ==============================================================
key                         definition
==========================  ==============================================================
``biomech_froude_error``    distance of Fr outside the gait's band in log units,
                            max(0, ln(lo/Fr), ln(Fr/hi)) / ln 2 (1 = a factor of 2 out)
``biomech_duty_error``      distance of the duty factor outside the gait's band / 0.1 (with
                            contacts detected from the geometry the band's top is raised by
                            0.08, see below)
``biomech_phase_error``     mean over LF, RF, RH of the circular distance between measured
                            and table footfall phase [strides] / 0.1; the table is also
                            read mirrored (left ↔ right lead) and the closer one is used;
                            feet without a measurable touchdown phase (a short clip) are left
                            out, and 0.5 stride is counted when none has one
``biomech_stride_error``    |ln(λ/h ÷ 2.3·Fr^0.3)| / ln 1.5
``biomech_score``           the sum of the four (the total equals its parts exactly)
``biomech_gait``            the gait of the table with the smallest score (the species'
                            habit the motion is closest to)
==========================  ==============================================================

A motion that stays in place (Fr < 0.01) without a stride (standing, sitting: no foot
with two touchdowns) is not a gait: its errors and score are NaN and ``biomech_gait`` is
``""``. A motion that travels without a measurable stride (feet that never touch the
ground, a body sliding along) is a gait failure: its phase and stride errors are 5 each
(:data:`MISSING_ERROR`, as far as a half-stride phase error).

By default the motion is compared with its own species' table; ``species=`` compares it
with another species' habits (the Froude number and λ/h stay the motion's own, they are
dimensionless). Contacts: the motion's labels if it has them, else detected from the
geometry (:func:`habitsim.contacts.detect_contacts`); pass ``contacts=`` to choose (e.g.
the simulated foot contacts of a tracking run). Geometric detection marks a foot in
contact a frame or two before touchdown and after lift-off: on the synthetic data set
its duty factor exceeds the planned stance by 0.077 ± 0.021 (mean ± sd over every clip
of a 4-clips-per-species build), so when the contacts were detected the duty band's
upper edge is raised by :data:`DETECTED_DUTY_ALLOWANCE`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from habitsim.errors import InvalidMotionError
from habitsim.gait_stats import gait_statistics
from habitsim.motion import Motion
from habitsim.species import FEET, GaitHabit, Species, load_species

__all__ = [
    "BIOMECH_KEYS",
    "BiomechResult",
    "FROUDE_SCALE",
    "DUTY_SCALE",
    "PHASE_SCALE",
    "STRIDE_SCALE",
    "ALEXANDER_COEFF",
    "ALEXANDER_EXPONENT",
    "DETECTED_DUTY_ALLOWANCE",
    "MISSING_ERROR",
    "STANDING_FROUDE",
    "gait_errors",
    "biomech_metrics",
]

#: Scale of each component (see the module docstring).
FROUDE_SCALE = math.log(2.0)
DUTY_SCALE = 0.1
PHASE_SCALE = 0.1
STRIDE_SCALE = math.log(1.5)
#: λ/h ≈ 2.3·Fr^0.3 (Alexander 1976).
ALEXANDER_COEFF = 2.3
ALEXANDER_EXPONENT = 0.3
#: Upper duty band allowance when contacts are detected from the geometry (see module).
DETECTED_DUTY_ALLOWANCE = 0.08
#: Phase distance counted when no foot's phase can be measured [strides].
MISSING_PHASE = 0.5
#: Phase / stride error of a travelling motion without a measurable stride.
MISSING_ERROR = MISSING_PHASE / PHASE_SCALE
#: Below this Froude number a motion without a stride counts as standing (score NaN).
STANDING_FROUDE = 0.01
_COMPARED_FEET = ("LF", "RF", "RH")

#: Flat keys of :meth:`BiomechResult.to_dict` (report columns).
BIOMECH_KEYS = (
    "froude",
    "duty_factor",
    "relative_stride_length",
    "phase_offset_lf",
    "phase_offset_rf",
    "phase_offset_rh",
    "biomech_gait",
    "biomech_froude_error",
    "biomech_duty_error",
    "biomech_phase_error",
    "biomech_stride_error",
    "biomech_score",
)
_COMPONENTS = ("froude_error", "duty_error", "phase_error", "stride_error")


@dataclass(frozen=True)
class BiomechResult:
    """Measured gait numbers and their distance from a species' habits.

    Attributes:
        species: the species whose table was used.
        froude, duty_factor, relative_stride_length: measured (NaN if undefined).
        phase_offsets: measured phase per foot (LF, RF, LH, RH; LH = 0).
        gait: the closest gait of the table ("" when the motion has no stride).
        froude_error, duty_error, phase_error, stride_error: components (see module).
        score: their sum.
        per_gait: every gait's score (gait → score).
    """

    species: str
    froude: float
    duty_factor: float
    relative_stride_length: float
    phase_offsets: dict[str, float]
    gait: str
    froude_error: float
    duty_error: float
    phase_error: float
    stride_error: float
    score: float
    per_gait: dict[str, float] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """Flat dict with the keys :data:`BIOMECH_KEYS`."""
        return {
            "froude": self.froude,
            "duty_factor": self.duty_factor,
            "relative_stride_length": self.relative_stride_length,
            "phase_offset_lf": self.phase_offsets.get("LF", math.nan),
            "phase_offset_rf": self.phase_offsets.get("RF", math.nan),
            "phase_offset_rh": self.phase_offsets.get("RH", math.nan),
            "biomech_gait": self.gait,
            "biomech_froude_error": self.froude_error,
            "biomech_duty_error": self.duty_error,
            "biomech_phase_error": self.phase_error,
            "biomech_stride_error": self.stride_error,
            "biomech_score": self.score,
        }


def _band_log_error(x: float, band: tuple[float, float]) -> float:
    lo, hi = band
    if not math.isfinite(x):
        return math.nan
    x = max(x, 1e-6)
    return max(0.0, math.log(lo / x), math.log(x / hi)) / FROUDE_SCALE


def _band_error(x: float, band: tuple[float, float]) -> float:
    lo, hi = band
    if not math.isfinite(x):
        return math.nan
    return max(0.0, lo - x, x - hi) / DUTY_SCALE


def _circ(a: float, b: float) -> float:
    d = abs(a - b) % 1.0
    return min(d, 1.0 - d)


def _mirrored(footfall: dict[str, float]) -> dict[str, float]:
    """The same footfall pattern with left and right swapped, re-referenced to LH."""
    swap = {"LF": "RF", "RF": "LF", "LH": "RH", "RH": "LH"}
    m = {f: footfall[swap[f]] for f in FEET}
    ref = m["LH"]
    return {f: (v - ref) % 1.0 for f, v in m.items()}


def _phase_error(measured: dict[str, float], footfall: dict[str, float]) -> float:
    feet = [f for f in _COMPARED_FEET if math.isfinite(measured.get(f, math.nan))]
    if not feet:
        return MISSING_PHASE / PHASE_SCALE
    best = min(
        float(np.mean([_circ(measured[f], table[f]) for f in feet]))
        for table in (footfall, _mirrored(footfall))
    )
    return best / PHASE_SCALE


def _stride_error(froude: float, rel_stride: float) -> float:
    if not (math.isfinite(froude) and math.isfinite(rel_stride)):
        return math.nan
    # stepping in place (Fr = λ = 0) is far from any gait: clamp instead of log(0)
    pred = ALEXANDER_COEFF * max(froude, 1e-6) ** ALEXANDER_EXPONENT
    return abs(math.log(max(rel_stride, 1e-3) / pred)) / STRIDE_SCALE


def gait_errors(
    froude: float,
    duty_factor: float,
    relative_stride_length: float,
    phase_offsets: dict[str, float],
    habit: GaitHabit,
    duty_allowance: float = 0.0,
) -> dict[str, float]:
    """The four error components of measured numbers against one gait of a table.

    Args:
        duty_allowance: added to the upper edge of the duty-factor band.
    """
    lo, hi = habit.duty_factor
    return {
        "froude_error": _band_log_error(froude, habit.froude),
        "duty_error": _band_error(duty_factor, (lo, hi + duty_allowance)),
        "phase_error": _phase_error(phase_offsets, habit.footfall),
        "stride_error": _stride_error(froude, relative_stride_length),
    }


def biomech_metrics(
    motion: Motion,
    species: str | Species | None = None,
    contacts: np.ndarray | None = None,
    *,
    use_labels: bool = True,
) -> BiomechResult:
    """Measure a motion's gait and score it against a species' gait table.

    Args:
        motion: the motion.
        species: whose habits to compare with (default: the motion's species).
        contacts: optional (T, 4) bool foot contacts (LF, RF, LH, RH); default the
            motion's labels, else detected (with the duty allowance).
        use_labels: False ignores the motion's labels and detects contacts from the
            geometry (what the benchmark does, so every method is measured alike).

    Returns:
        The :class:`BiomechResult` (``to_dict()`` gives the flat report keys).
    """
    sp = load_species(species if species is not None else motion.species)
    detected = contacts is None and (motion.contacts is None or not use_labels)
    if detected:
        contacts = motion.detect_contacts()
    allowance = DETECTED_DUTY_ALLOWANCE if detected else 0.0
    st = gait_statistics(motion, contacts)
    phases = dict(st.phase_offsets)
    base: dict[str, Any] = dict(
        species=sp.name,
        froude=st.froude,
        duty_factor=st.duty_factor,
        relative_stride_length=st.relative_stride_length,
        phase_offsets=phases,
    )
    strided = math.isfinite(st.stride_period_s)
    if not strided and not st.froude >= STANDING_FROUDE:
        nan = math.nan
        return BiomechResult(
            **base,
            gait="",
            froude_error=nan,
            duty_error=nan,
            phase_error=nan,
            stride_error=nan,
            score=nan,
        )
    best: tuple[float, str, dict[str, Any]] | None = None
    per_gait: dict[str, float] = {}
    for name in sorted(sp.gaits):
        comp = gait_errors(
            st.froude, st.duty_factor, st.relative_stride_length, phases, sp.gaits[name], allowance
        )
        if not strided:  # travelling without steps
            comp["phase_error"] = comp["stride_error"] = MISSING_ERROR
        score = sum(comp[k] for k in _COMPONENTS)
        per_gait[name] = score
        if best is None or score < best[0]:
            best = (score, name, comp)
    if best is None:  # pragma: no cover - the catalog requires a walk
        raise InvalidMotionError(f"species {sp.name!r} has no gait table")
    score, gait, errors = best
    return BiomechResult(**base, gait=gait, score=score, per_gait=per_gait, **errors)
