"""The file's frame: units, up and forward axes, and the conversion to habitsim's frame
(:class:`FrameConversion`, found by :func:`detect_frame`)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from ..bvh import BVHData
from ..errors import SkeletonMappingError
from ..species import Species, load_species
from .chains import _LEG_CHAINS
from .tree import _Tree

#: Known length units of BVH files and their size in metres.
UNIT_SCALES: dict[str, float] = {"m": 1.0, "cm": 0.01, "mm": 0.001, "in": 0.0254}
#: The units the detection chooses among. Inches are given explicitly (``units="in"``):
#: a leg of N inches is a plausible leg in centimetres too, and nothing in a file tells
#: the two apart.
DETECTED_UNITS: tuple[str, ...] = ("m", "cm", "mm")


def _axis_vector(axis: str) -> np.ndarray:
    v = np.zeros(3)
    v["xyz".index(axis[-1])] = -1.0 if axis.startswith("-") else 1.0
    return v


def _axis_name(v: np.ndarray) -> str:
    k = int(np.argmax(np.abs(v)))
    return ("-" if v[k] < 0 else "+") + "xyz"[k]


@dataclass(frozen=True)
class FrameConversion:
    """Conversion of file coordinates to habitsim's frame (z up, x forward, metres).

    Attributes:
        scale: size of one file unit [m].
        units: ``"m"``, ``"cm"``, ``"mm"`` or ``"x<scale>"`` for a custom scale.
        up: the file's up axis, ``"+y"`` style.
        forward: the file's forward axis (perpendicular to ``up``).
        matrix: (3, 3) rotation whose rows are the file's forward, left and up axes, so
            habitsim = scale · matrix @ file.
    """

    scale: float
    units: str
    up: str
    forward: str
    matrix: np.ndarray

    @classmethod
    def from_axes(cls, scale: float, units: str, up: str, forward: str) -> FrameConversion:
        u, f = _axis_vector(up), _axis_vector(forward)
        if abs(float(u @ f)) > 1e-9:
            raise SkeletonMappingError(f"forward axis {forward} is not perpendicular to up {up}")
        left = np.cross(u, f)
        return cls(scale, units, up, forward, np.stack([f, left, u]))

    @property
    def left(self) -> str:
        """The file axis that becomes habitsim's +y (left)."""
        return _axis_name(self.matrix[1])

    def apply(self, points: np.ndarray) -> np.ndarray:
        """Convert points (…, 3) from file units/axes to habitsim's frame [m]."""
        return self.scale * np.asarray(points, dtype=np.float64) @ self.matrix.T

    def describe(self) -> str:
        return (
            f"units {self.units} (x{self.scale:g} to m), up {self.up}, forward {self.forward}, "
            f"left {self.left}"
        )


def _parse_up(up: str) -> str:
    u = str(up).strip().lower()
    if u in ("x", "y", "z"):
        u = "+" + u
    if len(u) != 2 or u[0] not in "+-" or u[1] not in "xyz":
        raise SkeletonMappingError(
            f"unknown up axis {up!r}; valid: x, y, z (optionally signed, e.g. -y)"
        )
    return u


def _parse_units(units: str | float) -> tuple[float, str]:
    if isinstance(units, int | float) and not isinstance(units, bool):
        if not math.isfinite(units) or units <= 0:
            raise SkeletonMappingError(
                f"unit scale must be a positive number of metres, got {units}"
            )
        return float(units), f"x{units:g}"
    u = str(units).strip().lower()
    if u not in UNIT_SCALES:
        raise SkeletonMappingError(f"unknown units {units!r}; valid: {', '.join(UNIT_SCALES)}")
    return UNIT_SCALES[u], u


def _leg_ends(joints: Mapping[str, str | None], bvh: BVHData) -> list[int]:
    out = []
    for chain in _LEG_CHAINS.values():
        src = [s for n in chain if (s := joints.get(n))]
        if src:
            out.append(bvh.index(src[-1]))
    return out


def _forward_joint(joints: Mapping[str, str | None]) -> str | None:
    for n in ("spine3", "spine2", "spine1", "neck", "head", "snout"):
        if joints.get(n):
            return joints[n]
    return None


def detect_frame(
    bvh: BVHData,
    joints: Mapping[str, str | None],
    units: str | float | None = None,
    up: str | None = None,
    species: str | Species | None = None,
) -> FrameConversion:
    """Units, up and forward axis of a BVH file, as a conversion to habitsim's frame.

    * units: explicit, else the candidate (m, cm, mm) that makes the source's hind-leg
      length (hip joint to toe along the bones) a plausible animal leg (0.02–4 m); if
      several or none are plausible, the one closest (in log scale) to the species' leg
      length (default: 0.5 m).
    * up: explicit, else the coordinate axis closest to the mean direction from the feet
      (most distal mapped leg joints) to the hips over the clip.
    * forward: the coordinate axis perpendicular to up closest to the hips → chest
      direction in the first frame (rest pose as a fallback).

    Args:
        bvh: the source file.
        joints: habitsim → source mapping (at least ``pelvis``; legs and a spine/neck/
            head joint unless ``up`` is given and forward can be found).
        units: ``"m"``, ``"cm"``, ``"mm"``, a scale in metres per unit, or None to detect.
        up: ``"y"``, ``"z"``, ``"-y"``… or None to detect.
        species: target species (for unit detection).

    Returns:
        The :class:`FrameConversion`.

    Raises:
        SkeletonMappingError: unknown units / axis names, or too few mapped joints to
            detect what was not given.
    """
    hips_name = joints.get("pelvis")
    if not hips_name:
        raise SkeletonMappingError("cannot detect the file's frame without a pelvis (hips) joint")
    hips = bvh.index(hips_name)
    t = _Tree(bvh)
    pos = bvh.fk()
    rest = bvh.fk(rest=True)
    feet = _leg_ends(joints, bvh)

    # Units.
    if units is not None:
        scale, uname = _parse_units(units)
    else:
        leg = None
        target = 0.5
        sp = load_species(species) if species is not None else None
        for a, b, fore in (
            ("lh_hip", "lh_toe", False),
            ("rh_hip", "rh_toe", False),
            ("lf_shoulder", "lf_toe", True),
            ("rf_shoulder", "rf_toe", True),
            ("lh_hip", "lh_hock", False),
            ("lf_shoulder", "lf_wrist", True),
        ):
            ja, jb = joints.get(a), joints.get(b)
            if ja and jb:
                leg = t.path_length(bvh.index(ja), bvh.index(jb))
                if sp is not None:
                    target = sp.fore_leg_length if fore else sp.hind_leg_length
                    if b.endswith(("hock", "wrist")):
                        seg = sp.segments
                        target -= seg["fore_foot"] if fore else seg["hind_foot"]
                break
        if leg is None or leg <= 0:
            ext = pos[0].max(axis=0) - pos[0].min(axis=0)
            leg = float(ext.max()) / 2.0
        plausible = [u for u in DETECTED_UNITS if 0.02 <= leg * UNIT_SCALES[u] <= 4.0]
        if len(plausible) == 1:
            uname = plausible[0]
        else:
            uname = min(DETECTED_UNITS, key=lambda u: abs(math.log(leg * UNIT_SCALES[u] / target)))
        scale = UNIT_SCALES[uname]

    # Up.
    if up is not None:
        up_ax = _parse_up(up)
    else:
        if not feet:
            raise SkeletonMappingError(
                "cannot detect the up axis: no leg joints are mapped; pass up='y' or 'z' (--up)"
            )
        v = (pos[:, hips] - pos[:, feet].mean(axis=1)).mean(axis=0)
        if np.linalg.norm(v) < 1e-9:
            v = rest[0, hips] - rest[0, feet].mean(axis=0)
        if np.linalg.norm(v) < 1e-9:
            raise SkeletonMappingError("cannot detect the up axis (feet at hip level); pass up=")
        up_ax = _axis_name(v)
    u_vec = _axis_vector(up_ax)

    # Forward.
    fwd_vec = None
    fname = _forward_joint(joints)
    cands: list[np.ndarray] = []
    if fname:
        c = bvh.index(fname)
        cands += [pos[0, c] - pos[0, hips], rest[0, c] - rest[0, hips]]
    tail = joints.get("tail1") or joints.get("tail2")
    if tail:
        c = bvh.index(tail)
        cands += [pos[0, hips] - pos[0, c]]
    for v in cands:
        h = v - (v @ u_vec) * u_vec
        if np.linalg.norm(h) > 1e-6 * max(1.0, float(np.linalg.norm(v))):
            fwd_vec = h
            break
    if fwd_vec is None:
        raise SkeletonMappingError(
            "cannot detect the forward axis: map a spine, neck or head joint ahead of the pelvis"
        )
    fwd_vec = fwd_vec.copy()
    fwd_vec[int(np.argmax(np.abs(u_vec)))] = 0.0
    return FrameConversion.from_axes(scale, uname, up_ax, _axis_name(fwd_vec))
