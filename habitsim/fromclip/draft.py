"""A species file drafted from what a clip shows (:func:`draft_species`).

What the clip measures (:mod:`habitsim.fromclip.measure`) is taken as it is: segment
lengths, standing inclinations of the leg segments, neck, head and tail carriage. The rest
comes by the catalog's own rules:

* **cousin**: the built-in training species the new one borrows from: given (``like``),
  or the nearest of the same posture class by size and proportions (:func:`choose_cousin`);
* **posture class**: given, or that of the catalog species whose leg angles and
  proportions are nearest (:func:`classify_posture`);
* **mass**: given, or M = k · S^b with S = √(trunk · hip height) the size length and b the
  exponent of geometric similarity (3), k fitted to the catalog's own species
  (:func:`mass_rule`; docs/biomechanics.md);
* **segments the rig lacks** (a collarbone, a made-up toe tip, a head without a snout
  joint): the cousin's, scaled by the limb's (or the trunk's) size ratio; a span over an
  unmapped middle joint is split by the cousin's proportions;
* **girths**: the cousin's, scaled by the size-length ratio; **joint limits**: the
  cousin's, widened where the measured standing angle would lie outside them; **gaits and
  habits**: the cousin's. Motor strengths are not in a species file: the MJCF builder
  sizes them by m·g·L (:class:`habitsim.mjcf_models.builder.BuildRules`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w

from ..errors import ArgumentRangeError, UnknownSpeciesError
from ..species import (
    GIRTH_KEYS,
    POSTURES,
    Species,
    _parse,
    all_species,
    standing_leg_angles,
    training_species,
)
from .measure import RigMeasure
from .options import FromClipOptions

__all__ = [
    "Draft",
    "size_length",
    "mass_rule",
    "classify_posture",
    "choose_cousin",
    "draft_species",
]


def size_length(trunk: float, hip_height: float) -> float:
    """The size length S = √(trunk · hip height) [m] the mass rule scales with."""
    return math.sqrt(trunk * hip_height)


def mass_rule(options: FromClipOptions | None = None) -> tuple[float, float, float]:
    """The mass rule M = k · S^b fitted to the built-in catalog.

    Returns:
        ``(k [kg/m^b], b, rms error of log10 M over the catalog)``.
    """
    b = (options or FromClipOptions()).mass_exponent
    sps = all_species()
    log_m = np.log([s.mass_kg for s in sps])
    log_s = np.log([size_length(s.segments["trunk"], s.hip_height) for s in sps])
    log_k = float(np.mean(log_m - b * log_s))
    rms = float(np.sqrt(np.mean((log_m - log_k - b * log_s) ** 2)) / math.log(10.0))
    return math.exp(log_k), b, rms


def _posture_features(
    hind_foot: float, fore_foot: float, crouch: float, foot_share: float
) -> np.ndarray:
    return np.array([hind_foot, fore_foot, crouch, foot_share])


def _species_features(sp: Species) -> np.ndarray:
    inc, seg = sp.inclinations, sp.segments
    return _posture_features(
        inc["hind_foot"],
        inc["fore_foot"],
        sp.hip_height / sp.hind_leg_length,
        seg["hind_foot"] / sp.hind_leg_length,
    )


def _measure_features(m: RigMeasure) -> np.ndarray:
    def foot(limb: str) -> tuple[float, float]:
        last = m.spans[limb][-1]
        return last.inclination, last.length

    hind_incl, hind_foot = foot("hind")
    leg = m.leg_length("hind")
    return _posture_features(hind_incl, foot("fore")[0], m.hip_height / leg, hind_foot / leg)


def classify_posture(m: RigMeasure) -> tuple[str, str]:
    """The posture class of the measured legs: that of the built-in species nearest in
    (hind and fore foot inclination, hip height / hind-leg length, hind foot / hind-leg
    length), each feature divided by its spread over the catalog.

    Returns:
        ``(posture class, the species it was nearest to)``.
    """
    sps = all_species()
    table = np.stack([_species_features(s) for s in sps])
    spread = np.maximum(table.std(axis=0), 1e-9)
    d = np.linalg.norm((table - _measure_features(m)) / spread, axis=1)
    best = sps[int(np.argmin(d))]
    return best.posture, best.name


def choose_cousin(
    posture: str, hip_height: float, trunk: float, like: str | None = None
) -> Species:
    """The built-in training species a new one borrows from: ``like`` when given, else
    the nearest of the same posture class (of all training species when none has it) in
    |ln(hip height ratio)| + |ln(trunk / hip height ratio)|.

    Raises:
        UnknownSpeciesError: ``like`` is not a built-in training species (lists them).
    """
    train = training_species()
    if like is not None:
        names = {s.name: s for s in train}
        if like not in names:
            raise UnknownSpeciesError(like, names)
        return names[like]
    pool = [s for s in train if s.posture == posture] or train

    def dist(s: Species) -> float:
        return abs(math.log(hip_height / s.hip_height)) + abs(
            math.log((trunk / hip_height) / (s.segments["trunk"] / s.hip_height))
        )

    return min(pool, key=lambda s: (dist(s), s.name))


@dataclass(frozen=True)
class Draft:
    """A drafted species.

    Attributes:
        species: the parsed :class:`~habitsim.species.Species`.
        data: the species file's table (file units: metres, kg, degrees).
        cousin: the built-in species it borrows from.
        posture_from: ``"given"`` or the catalog species whose legs it was nearest to.
        mass_from: ``"given"`` or the rule, ``"k·S^b"`` with its numbers.
        estimated: the segments not measured on the clip (taken from the cousin).
        widened: the joint-limit roles widened to hold the measured standing pose.
    """

    species: Species
    data: dict[str, Any]
    cousin: str
    posture_from: str
    mass_from: str
    estimated: tuple[str, ...]
    widened: tuple[str, ...]

    def toml(self) -> str:
        """The species file's text."""
        return "# Made by `habitsim species from-clip`; see docs/species.md.\n" + tomli_w.dumps(
            self.data
        )


def _legs(m: RigMeasure, nb: Species) -> tuple[dict[str, float], dict[str, float], list[str]]:
    """Leg segment lengths [m], inclinations [rad] and the segments not measured."""
    segs: dict[str, float] = {}
    incl: dict[str, float] = {}
    estimated: list[str] = []
    for limb, spans in m.spans.items():
        real = [s for s in spans if s.measured]
        own = sum(s.length for s in real)
        theirs = sum(nb.segments[f"{limb}_{k}"] for s in real for k in s.segments)
        scale = own / theirs if theirs > 0 else m.trunk / nb.segments["trunk"]
        for s in spans:
            keys = [f"{limb}_{k}" for k in s.segments]
            share = sum(nb.segments[k] for k in keys)
            for k in keys:
                segs[k] = (
                    (s.length * nb.segments[k] / share) if s.measured else (scale * nb.segments[k])
                )
                incl[k] = s.inclination
                if not s.measured or len(keys) > 1:
                    estimated.append(k)
        for part in ("girdle", "upper", "lower", "foot"):
            k = f"{limb}_{part}"
            if k not in segs:
                segs[k] = scale * nb.segments[k]
                incl[k] = nb.inclinations[k]
                estimated.append(k)
    return segs, incl, estimated


def _widen(
    nb: Species, sp_data: dict[str, Any], margin_deg: float
) -> tuple[dict[str, list[float]], list[str]]:
    """The cousin's joint limits [deg], widened to hold the draft's standing angles."""
    probe = _parse(sp_data | {"joint_limits": _open_limits(nb)}, None)
    standing = standing_leg_angles(probe)
    out: dict[str, list[float]] = {}
    widened = []
    for role, (lo, hi) in nb.joint_limits.items():
        lo_d, hi_d = math.degrees(lo), math.degrees(hi)
        if role in standing:
            a = math.degrees(standing[role])
            new_lo, new_hi = min(lo_d, a - margin_deg), max(hi_d, a + margin_deg)
            if (new_lo, new_hi) != (lo_d, hi_d):
                widened.append(role)
            lo_d, hi_d = new_lo, new_hi
        out[f"{role}_deg"] = [round(lo_d, 3), round(hi_d, 3)]
    return out, widened


def _open_limits(nb: Species) -> dict[str, list[float]]:
    return {f"{role}_deg": [-360.0, 360.0] for role in nb.joint_limits}


def draft_species(
    m: RigMeasure,
    name: str,
    mass_kg: float | None = None,
    posture: str | None = None,
    like: str | None = None,
    description: str | None = None,
    path: Path | None = None,
    user_catalog: Path | None = None,
    options: FromClipOptions | None = None,
) -> Draft:
    """Draft the species file of a measured rig (see the module docs).

    Args:
        m: the measured rig.
        name: the new species' name (checked by the caller).
        mass_kg: body mass [kg] (None: the mass rule).
        posture: posture class (None: classified from the legs).
        like: the built-in training species to borrow from (None: chosen).
        description: the plain-language habit description (None: made from the
            cousin's).
        path, user_catalog: where the file will be (for the parsed species).
        options: the knobs.

    Raises:
        ArgumentRangeError: a non-positive or non-finite mass, an unknown posture.
        UnknownSpeciesError: ``like`` is not a built-in training species.
        SpeciesFileError: a description too short, or numbers the species file refuses.
    """
    o = options or FromClipOptions()
    if posture is not None and posture not in POSTURES:
        raise ArgumentRangeError(f"unknown posture {posture!r}; valid: {', '.join(POSTURES)}")
    if mass_kg is not None and not (math.isfinite(mass_kg) and 0 < mass_kg <= 1e5):
        raise ArgumentRangeError(f"--mass must be a body mass in (0, 1e5] kg, got {mass_kg!r}")
    posture_from = "given"
    if posture is None:
        posture, posture_from = classify_posture(m)
    nb = choose_cousin(posture, m.hip_height, m.trunk, like)
    segs, incl, estimated = _legs(m, nb)
    size = m.trunk / nb.segments["trunk"]
    for key, value in (("neck", m.neck), ("head", m.head), ("tail", m.tail)):
        if value is None:
            estimated.append(key)
        segs[key] = value if value is not None else size * nb.segments[key]
    segs["trunk"] = m.trunk
    for key, w in (
        ("trunk_width_fore", m.trunk_width_fore),
        ("trunk_width_hind", m.trunk_width_hind),
    ):
        if w is None:
            estimated.append(key)
        segs[key] = w if w is not None else size * nb.segments[key]
    k, b, rms = mass_rule(o)
    s_len = size_length(m.trunk, m.hip_height)
    mass_from = "given"
    if mass_kg is None:
        mass_kg = k * s_len**b
        mass_from = f"{k:.0f} kg/m^{b:g} x S^{b:g}, S = {s_len:.3f} m (catalog rms x{10**rms:.2f})"
    ratio = s_len / size_length(nb.segments["trunk"], nb.hip_height)
    deg = math.degrees

    def carriage(v: float | None, theirs: float) -> float:
        return round(deg(theirs if v is None else v), 3)

    posture_tbl: dict[str, Any] = {"class": posture}
    posture_tbl.update({f"{k2}_deg": round(deg(v), 3) for k2, v in sorted(incl.items())})
    posture_tbl["neck_deg"] = carriage(m.neck_elevation, nb.neck_elevation)
    posture_tbl["head_deg"] = carriage(m.head_pitch, nb.head_pitch)
    posture_tbl["tail_deg"] = carriage(m.tail_carriage, nb.tail_carriage)
    h = nb.habits
    text = description or (
        f"Made from the clip {m.source}: a {posture.replace('_', ' ')} quadruped of about "
        f"{mass_kg:.3g} kg standing {m.hip_height:.2f} m at the hip, measured from its rig. "
        f"Its gaits and habits are borrowed from the {nb.common_name.lower()}: " + nb.description
    )
    data: dict[str, Any] = {
        "name": name,
        "common_name": f"{name} (from {Path(m.source).name})",
        "taxonomy": f"Mammalia; user species (gaits of {nb.name})",
        "held_out": True,
        "outlier": False,
        "cousin": nb.name,
        "mass_kg": round(float(mass_kg), 4),
        "description": text,
        "sources": [
            f"segments, standing posture and carriage measured from {Path(m.source).name} "
            "by habitsim species from-clip",
            "mass: "
            + (
                "given"
                if mass_from == "given"
                else "geometric similarity, M = k S^3,"
                " k fitted to the built-in catalog (docs/biomechanics.md)"
            ),
            f"girths, joint limits, gaits and habits of the catalog's {nb.name}: "
            + "; ".join(nb.sources),
        ],
        "segments": {k2: round(float(segs[k2]), 5) for k2 in sorted(segs)},
        "girths": {g: round(ratio * nb.girths[g], 5) for g in GIRTH_KEYS},
        "posture": posture_tbl,
        "gaits": {
            g: {
                "footfall": dict(gh.footfall),
                "duty_factor": list(gh.duty_factor),
                "froude": list(gh.froude),
            }
            for g, gh in nb.gaits.items()
        },
        "habits": h.table(),
    }
    limits, widened = _widen(nb, data, o.limit_margin_deg)
    data["joint_limits"] = limits
    sp = _parse(data, path, user_catalog)
    return Draft(
        species=sp,
        data=data,
        cousin=nb.name,
        posture_from=posture_from,
        mass_from=mass_from,
        estimated=tuple(estimated),
        widened=tuple(widened),
    )
