"""Species catalog: one TOML file per quadruped species in ``habitsim/catalog/``.

A :class:`Species` holds every number about an animal that habitsim uses (body mass,
segment lengths and girths, standing posture, joint limits, gait habits, habit text).
It is the single source of truth: skeleton offsets, the gait generator, the MJCF builder
and the metrics all read their numbers from here.

Units inside are SI (m, kg, rad). The TOML files write angles in degrees (keys ending in
``_deg``); they are converted on load.

Angle conventions (world frame z up, x forward, y left):

* leg segment inclinations (``[posture]``) are measured from the downward vertical in the
  sagittal plane, positive when the distal end of the segment lies ahead (+x) of its
  proximal end;
* neck / head / tail carriage are elevations above the horizontal, positive = up
  (for the tail: the tip above its base);
* joint limits are ranges of the *local* joint angle of the habitsim skeleton: flexion is a
  rotation about the joint's local +y axis (positive turns a downward-pointing segment
  backward), abduction about local +x, yaw about local +z. Local angle 0 is the canonical
  pose (legs straight down, spine, neck and head along +x, tail along -x).
"""

from __future__ import annotations

import functools
import math
import os
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from .errors import (
    SpeciesFileError,
    SpeciesNameClashError,
    SpeciesNameError,
    UnknownSpeciesError,
    brief,
)
from .jsonfile import load_toml

__all__ = [
    "POSTURES",
    "GAITS",
    "FEET",
    "SEGMENT_KEYS",
    "GIRTH_KEYS",
    "INCLINATION_KEYS",
    "LIMIT_KEYS",
    "GaitHabit",
    "Habits",
    "Species",
    "load_species",
    "load_species_file",
    "species_names",
    "USER_CATALOG_ENV",
    "user_catalog_dirs",
    "user_species",
    "check_new_species_name",
    "all_species",
    "training_species",
    "held_out_species",
    "standing_global_pitch",
    "standing_leg_angles",
]

POSTURES = ("crouched_digitigrade", "digitigrade", "unguligrade", "plantigrade", "columnar")
#: Gaits a species may list; footfall phases per foot (LH = 0) live in the species file.
GAITS = (
    "walk",
    "amble",
    "trot",
    "pace",
    "canter",
    "transverse_gallop",
    "rotary_gallop",
    "half_bound",
    "bound",
)
#: Feet in habitsim's fixed order (left fore, right fore, left hind, right hind).
FEET = ("LF", "RF", "LH", "RH")

SEGMENT_KEYS = (
    "trunk",  # pelvis (sacrum) to withers along the spine [m]
    "trunk_width_fore",  # distance between the left and right scapula roots [m]
    "trunk_width_hind",  # distance between the left and right hip joints [m]
    "neck",
    "head",  # skull base to snout tip
    "tail",
    "fore_girdle",  # scapula: dorsal border to shoulder joint
    "fore_upper",  # humerus
    "fore_lower",  # radius / ulna
    "fore_foot",  # carpus to toe tip (metacarpus + digits)
    "hind_girdle",  # sacrum level to hip joint (ilium)
    "hind_upper",  # femur
    "hind_lower",  # tibia
    "hind_foot",  # hock to toe tip (metatarsus + digits)
)
GIRTH_KEYS = (
    "trunk",
    "neck",
    "head",
    "tail",
    "fore_upper",
    "fore_lower",
    "fore_foot",
    "hind_upper",
    "hind_lower",
    "hind_foot",
)
INCLINATION_KEYS = (
    "fore_girdle",
    "fore_upper",
    "fore_lower",
    "fore_foot",
    "hind_girdle",
    "hind_upper",
    "hind_lower",
    "hind_foot",
)
#: Joint-limit roles (local angles, see module docstring).
LIMIT_KEYS = (
    "fore_girdle_flex",
    "fore_upper_flex",
    "fore_upper_abd",
    "fore_lower_flex",
    "fore_foot_flex",
    "hind_girdle_flex",
    "hind_upper_flex",
    "hind_upper_abd",
    "hind_lower_flex",
    "hind_foot_flex",
    "spine_pitch",
    "spine_yaw",
    "neck_pitch",
    "neck_yaw",
    "head_pitch",
    "head_yaw",
    "tail_pitch",
    "tail_yaw",
)


@dataclass(frozen=True)
class GaitHabit:
    """How a species performs one gait.

    Attributes:
        footfall: touchdown phase of each foot as a fraction of the stride, LH = 0,
            keys ``LF, RF, LH, RH``.
        duty_factor: (min, max) stance time / stride time.
        froude: (min, max) Froude number v²/(g·h) band in which the species uses it.
    """

    footfall: dict[str, float]
    duty_factor: tuple[float, float]
    froude: tuple[float, float]


@dataclass(frozen=True)
class Habits:
    """Species-specific style numbers used by the gait generator.

    Attributes:
        stride_frequency_coeff_hz: c in f = c·M^-0.14 [Hz] (Heglund et al. 1974 give ≈4.5).
        spine_flex: amplitude [rad] of sagittal spine flexion at the fastest gait.
        head_bob: amplitude [rad] of neck pitch oscillation at the walk.
        tail_sway: amplitude [rad] of lateral tail sway at the walk.
        swing_height: peak toe lift in swing as a fraction of hind-leg length.
        trunk_sway: lateral trunk sway gain at slow walks (0 = none, 1 = full shift
            of the centre of mass toward the support-polygon centroid).
    """

    stride_frequency_coeff_hz: float
    spine_flex: float
    head_bob: float
    tail_sway: float
    swing_height: float
    trunk_sway: float

    def table(self) -> dict[str, float]:
        """The numbers as a species file's ``[habits]`` table writes them (angles in
        degrees, rounded to 1e-3)."""
        deg = math.degrees
        return {
            "stride_frequency_coeff_hz": self.stride_frequency_coeff_hz,
            "spine_flex_deg": round(deg(self.spine_flex), 3),
            "head_bob_deg": round(deg(self.head_bob), 3),
            "tail_sway_deg": round(deg(self.tail_sway), 3),
            "swing_height": self.swing_height,
            "trunk_sway": self.trunk_sway,
        }


@dataclass(frozen=True, eq=False)
class Species:
    """One quadruped species, loaded from its TOML file. All numbers SI."""

    name: str
    common_name: str
    taxonomy: str
    held_out: bool
    outlier: bool
    cousin: str | None
    posture: str
    mass_kg: float
    segments: dict[str, float]
    girths: dict[str, float]
    inclinations: dict[str, float]  # [rad], see module docstring
    neck_elevation: float  # [rad]
    head_pitch: float  # [rad]
    tail_carriage: float  # [rad]
    joint_limits: dict[str, tuple[float, float]]  # [rad]
    gaits: dict[str, GaitHabit]
    habits: Habits
    description: str
    sources: tuple[str, ...]
    #: other words for the animal a prompt may use ("puppy", "bull"; lower case), besides
    #: the name and the common name (:mod:`habitsim.captions.prompts`)
    synonyms: tuple[str, ...] = ()
    path: Path | None = field(default=None, compare=False)
    #: the user catalog folder the species was read from (None: the built-in catalog);
    #: its MuJoCo models are in ``<user_catalog>/<name>/``
    user_catalog: Path | None = field(default=None, compare=False)

    # ---- derived sizes (one source of truth: segment lengths + posture) -------------
    @property
    def hind_leg_length(self) -> float:
        """Hip joint to toe tip along the segments (femur + tibia + hind foot) [m]."""
        s = self.segments
        return s["hind_upper"] + s["hind_lower"] + s["hind_foot"]

    @property
    def fore_leg_length(self) -> float:
        """Shoulder joint to toe tip along the segments [m]."""
        s = self.segments
        return s["fore_upper"] + s["fore_lower"] + s["fore_foot"]

    @property
    def leg_length(self) -> float:
        """The normalising length of docs/metrics.md: the hind-leg length [m]."""
        return self.hind_leg_length

    def _vertical_extent(self, limb: str, with_girdle: bool) -> float:
        keys = ("girdle", "upper", "lower", "foot") if with_girdle else ("upper", "lower", "foot")
        return sum(
            self.segments[f"{limb}_{k}"] * math.cos(self.inclinations[f"{limb}_{k}"]) for k in keys
        )

    @property
    def hip_height(self) -> float:
        """Standing height of the hip joint above the ground [m] (from the posture)."""
        return self._vertical_extent("hind", with_girdle=False)

    @property
    def shoulder_height(self) -> float:
        """Standing height of the shoulder joint above the ground [m]."""
        return self._vertical_extent("fore", with_girdle=False)

    @property
    def trunk_pitch(self) -> float:
        """Standing trunk pitch [rad], positive = withers higher than the sacrum."""
        rise = self._vertical_extent("fore", True) - self._vertical_extent("hind", True)
        ratio = max(-0.95, min(0.95, rise / self.segments["trunk"]))
        return math.asin(ratio)

    @property
    def gallop(self) -> str | None:
        """The species' gallop form (``transverse_gallop`` / ``rotary_gallop``) if any."""
        for g in ("rotary_gallop", "transverse_gallop"):
            if g in self.gaits:
                return g
        return None

    def summary(self) -> dict[str, Any]:
        """Plain JSON-ready summary used by ``habitsim species list --json``."""
        return {
            "name": self.name,
            "common_name": self.common_name,
            "mass_kg": self.mass_kg,
            "hip_height_m": round(self.hip_height, 4),
            "leg_length_m": round(self.leg_length, 4),
            "posture": self.posture,
            "held_out": self.held_out,
            "cousin": self.cousin,
            "outlier": self.outlier,
            "gaits": sorted(self.gaits),
            "catalog": "built-in" if self.user_catalog is None else str(self.user_catalog),
        }


# ------------------------------------------------------------------ parsing


def _req(d: dict[str, Any], key: str, where: str) -> Any:
    if key not in d:
        raise SpeciesFileError(f"{where}: missing required key {key!r}")
    return d[key]


#: Largest magnitude of any number in a species file (kg, m or degrees): beyond it a
#: number is a typo, and arithmetic on it would overflow.
MAX_ABS_NUMBER = 1e6


def _table(d: dict[str, Any], key: str, where: str) -> dict[str, Any]:
    """A required TOML table (``[key]``)."""
    v = _req(d, key, where)
    if not isinstance(v, dict):
        raise SpeciesFileError(f"{where}: {key} must be a table ([{key}]), got {brief(v)}")
    return v


def _num(v: Any, where: str, positive: bool = False) -> float:
    if (
        isinstance(v, bool)
        or not isinstance(v, int | float)
        or not -MAX_ABS_NUMBER <= v <= MAX_ABS_NUMBER  # also refuses NaN
    ):
        raise SpeciesFileError(
            f"{where}: expected a finite number within ±{MAX_ABS_NUMBER:g}, got {brief(v)}"
        )
    if positive and v <= 0:
        raise SpeciesFileError(f"{where}: expected a positive number, got {brief(v)}")
    return float(v)


def _pair(v: Any, where: str) -> tuple[float, float]:
    if not isinstance(v, list) or len(v) != 2:
        raise SpeciesFileError(f"{where}: expected [min, max], got {brief(v)}")
    lo, hi = _num(v[0], where), _num(v[1], where)
    if lo > hi:
        raise SpeciesFileError(f"{where}: min {lo} > max {hi}")
    return lo, hi


def _parse(data: dict[str, Any], path: Path | None, user_catalog: Path | None = None) -> Species:
    where = str(path) if path else "<species>"
    name = _req(data, "name", where)
    if not isinstance(name, str) or not name.isidentifier() or name.lower() != name:
        raise SpeciesFileError(f"{where}: name must be a lower-case identifier, got {brief(name)}")
    posture_tbl = _table(data, "posture", where)
    posture = _req(posture_tbl, "class", f"{where} [posture]")
    if not isinstance(posture, str) or posture not in POSTURES:
        raise SpeciesFileError(
            f"{where}: posture class {brief(posture)}; valid: {', '.join(POSTURES)}"
        )

    segs_tbl = _table(data, "segments", where)
    segments = {
        k: _num(_req(segs_tbl, k, f"{where} [segments]"), f"{where} segments.{k}", True)
        for k in SEGMENT_KEYS
    }
    girth_tbl = _table(data, "girths", where)
    girths = {
        k: _num(_req(girth_tbl, k, f"{where} [girths]"), f"{where} girths.{k}", True)
        for k in GIRTH_KEYS
    }
    incl = {
        k: math.radians(
            _num(_req(posture_tbl, f"{k}_deg", f"{where} [posture]"), f"{where} posture.{k}_deg")
        )
        for k in INCLINATION_KEYS
    }
    lim_tbl = _table(data, "joint_limits", where)
    limits: dict[str, tuple[float, float]] = {}
    for k in LIMIT_KEYS:
        lo, hi = _pair(
            _req(lim_tbl, f"{k}_deg", f"{where} [joint_limits]"), f"{where} joint_limits.{k}_deg"
        )
        limits[k] = (math.radians(lo), math.radians(hi))

    gaits_tbl = _table(data, "gaits", where)
    gaits: dict[str, GaitHabit] = {}
    for g, tbl in gaits_tbl.items():
        gw = f"{where} [gaits.{brief(g)}]"
        if g not in GAITS:
            raise SpeciesFileError(f"{gw}: unknown gait {brief(g)}; valid: {', '.join(GAITS)}")
        if not isinstance(tbl, dict):
            raise SpeciesFileError(f"{gw}: must be a table, got {brief(tbl)}")
        ff = _table(tbl, "footfall", gw)
        if set(ff) != set(FEET):
            raise SpeciesFileError(f"{gw}: footfall needs exactly the feet {', '.join(FEET)}")
        footfall = {f: _num(ff[f], f"{gw} footfall.{f}") % 1.0 for f in FEET}
        if abs(footfall["LH"]) > 1e-9:
            raise SpeciesFileError(f"{gw}: footfall phases are relative to LH, so LH must be 0")
        df = _pair(_req(tbl, "duty_factor", gw), f"{gw} duty_factor")
        if not (0.0 < df[0] <= df[1] < 1.0):
            raise SpeciesFileError(f"{gw}: duty_factor must lie in (0, 1), got {df}")
        fr = _pair(_req(tbl, "froude", gw), f"{gw} froude")
        if fr[0] < 0.0:
            raise SpeciesFileError(f"{gw}: froude band must be non-negative, got {fr}")
        gaits[g] = GaitHabit(footfall=footfall, duty_factor=df, froude=fr)
    if "walk" not in gaits:
        raise SpeciesFileError(f"{where}: every species needs a 'walk' gait")

    hab = _table(data, "habits", where)
    hw = f"{where} [habits]"

    def habit(key: str, lo: float, hi: float) -> float:
        v = _num(_req(hab, key, hw), f"{hw} {key}")
        if not lo <= v <= hi:
            raise SpeciesFileError(f"{hw} {key} = {v} outside its valid range [{lo}, {hi}]")
        return v

    habits = Habits(
        stride_frequency_coeff_hz=habit("stride_frequency_coeff_hz", 0.5, 20.0),
        spine_flex=math.radians(habit("spine_flex_deg", 0.0, 45.0)),
        head_bob=math.radians(habit("head_bob_deg", 0.0, 30.0)),
        tail_sway=math.radians(habit("tail_sway_deg", 0.0, 60.0)),
        swing_height=habit("swing_height", 0.01, 0.5),
        trunk_sway=habit("trunk_sway", 0.0, 1.0),
    )
    desc = _req(data, "description", where)
    if not isinstance(desc, str) or len(desc.split()) < 15:
        raise SpeciesFileError(f"{where}: description must be a plain-language paragraph")
    sources = _req(data, "sources", where)
    if not isinstance(sources, list) or not sources or not all(isinstance(s, str) for s in sources):
        raise SpeciesFileError(f"{where}: sources must be a non-empty list of strings")
    held_out = bool(data.get("held_out", False))
    cousin = data.get("cousin") or None
    if cousin is not None and not isinstance(cousin, str):
        raise SpeciesFileError(f"{where}: cousin must be a species name, got {brief(cousin)}")
    if held_out and not cousin:
        raise SpeciesFileError(f"{where}: a held-out species must name its training cousin")

    synonyms = data.get("synonyms", [])
    if not isinstance(synonyms, list) or not all(
        isinstance(w, str) and w and w == w.lower() and len(w) <= 40 for w in synonyms
    ):
        raise SpeciesFileError(
            f"{where}: synonyms must be a list of lower-case words, got {brief(synonyms)}"
        )

    sp = Species(
        name=name,
        common_name=str(_req(data, "common_name", where)),
        taxonomy=str(_req(data, "taxonomy", where)),
        held_out=held_out,
        outlier=bool(data.get("outlier", False)),
        cousin=cousin,
        posture=posture,
        mass_kg=_num(_req(data, "mass_kg", where), f"{where} mass_kg", True),
        segments=segments,
        girths=girths,
        inclinations=incl,
        neck_elevation=math.radians(_num(_req(posture_tbl, "neck_deg", where), where)),
        head_pitch=math.radians(_num(_req(posture_tbl, "head_deg", where), where)),
        tail_carriage=math.radians(_num(_req(posture_tbl, "tail_deg", where), where)),
        joint_limits=limits,
        gaits=gaits,
        habits=habits,
        description=" ".join(desc.split()),
        sources=tuple(sources),
        synonyms=tuple(synonyms),
        path=path,
        user_catalog=user_catalog,
    )
    _check_limits_hold_posture(sp, where)
    return sp


# ---------------------------------------------------------------- standing posture
def standing_global_pitch(sp: Species) -> dict[str, float]:
    """Global rotation angle about +y [rad] of every posed bone in the standing pose."""
    g = {"trunk": -sp.trunk_pitch}
    for k, inc in sp.inclinations.items():
        g[k] = -inc  # +y rotation swings a downward bone backward, inclination is forward
    g["neck"] = -sp.neck_elevation
    g["head"] = -sp.head_pitch
    g["tail"] = sp.tail_carriage  # +y rotation lifts a backward-pointing bone
    return g


def standing_leg_angles(sp: Species) -> dict[str, float]:
    """Local flexion angles [rad] of the standing pose, keyed by joint-limit role."""
    g = standing_global_pitch(sp)
    out: dict[str, float] = {}
    for limb in ("fore", "hind"):
        prev = g["trunk"]
        for seg in ("girdle", "upper", "lower", "foot"):
            out[f"{limb}_{seg}_flex"] = g[f"{limb}_{seg}"] - prev
            prev = g[f"{limb}_{seg}"]
    out["neck_pitch"] = g["neck"] - g["trunk"]
    out["head_pitch"] = g["head"] - g["neck"]
    out["tail_pitch"] = g["tail"] - g["trunk"]
    return out


def _check_limits_hold_posture(sp: Species, where: str) -> None:
    """The standing posture's local joint angles must lie inside the joint limits."""
    standing = standing_leg_angles(sp)
    # Joints resting at 0 in the standing pose: tail2 (tail_pitch), spine, yaws, abductions.
    rest_zero = {
        "tail_pitch",
        "spine_pitch",
        "spine_yaw",
        "neck_yaw",
        "head_yaw",
        "tail_yaw",
        "fore_upper_abd",
        "hind_upper_abd",
    }
    for role, angle in [*standing.items(), *((r, 0.0) for r in sorted(rest_zero))]:
        lo, hi = sp.joint_limits[role]
        if not lo - 1e-9 <= angle <= hi + 1e-9:
            raise SpeciesFileError(
                f"{where}: standing {role} angle {math.degrees(angle):.1f} deg lies outside "
                f"its joint limits [{math.degrees(lo):.1f}, {math.degrees(hi):.1f}] deg"
            )


def load_species_file(path: str | Path, user_catalog: str | Path | None = None) -> Species:
    """Load and validate one species TOML file.

    Args:
        path: the TOML file.
        user_catalog: the user catalog folder it belongs to (None: not one).

    Raises:
        SpeciesFileError: unreadable TOML, a missing key or inconsistent numbers.
    """
    p = Path(path)
    data = load_toml(p, "species file", error=SpeciesFileError)
    return _parse(data, p, None if user_catalog is None else Path(user_catalog))


@functools.cache
def _catalog() -> dict[str, Species]:
    out: dict[str, Species] = {}
    root = resources.files("habitsim.catalog")
    for entry in sorted(root.iterdir(), key=lambda e: e.name):
        if entry.name.endswith(".toml"):
            sp = load_species_file(Path(str(entry)))
            if sp.name in out:
                raise SpeciesFileError(f"duplicate species name {sp.name!r} in the catalog")
            out[sp.name] = sp
    for sp in out.values():
        if sp.cousin is not None and (sp.cousin not in out or out[sp.cousin].held_out):
            raise SpeciesFileError(
                f"{sp.path}: cousin {sp.cousin!r} must be a training species of the catalog"
            )
    return out


# ------------------------------------------------------------------ user catalogs
#: Environment variable naming the user catalog folders (several joined by ``os.pathsep``),
#: searched after the built-in catalog.
USER_CATALOG_ENV = "HABITSIM_SPECIES_PATH"


def user_catalog_dirs() -> list[Path]:
    """The user catalog folders of ``$HABITSIM_SPECIES_PATH``, in search order."""
    raw = os.environ.get(USER_CATALOG_ENV, "")
    return [Path(p).expanduser() for p in raw.split(os.pathsep) if p.strip()]


@functools.lru_cache(maxsize=256)
def _user_file(path: str, folder: str, stamp: tuple[int, int]) -> Species:
    """A user species file, parsed once per (path, modification time, size)."""
    del stamp  # part of the cache key only
    sp = load_species_file(path, user_catalog=folder)
    stem = Path(path).stem
    if sp.name != stem:
        raise SpeciesFileError(
            f"{path}: a user species file must be named after its species "
            f"({sp.name}.toml), not {stem}.toml"
        )
    _check_user_species(sp)
    return sp


def _check_user_species(sp: Species) -> None:
    """A user species names a built-in training species as its cousin, if any."""
    cat = _catalog()
    if sp.cousin is not None and (sp.cousin not in cat or cat[sp.cousin].held_out):
        raise SpeciesFileError(
            f"{sp.path}: cousin {sp.cousin!r} must be a training species of the built-in "
            f"catalog: {', '.join(s.name for s in cat.values() if not s.held_out)}"
        )


def _read_user(path: Path, folder: Path) -> Species:
    st = path.stat()
    return _user_file(str(path), str(folder), (st.st_mtime_ns, st.st_size))


def _user_files(dirs: list[Path]) -> dict[str, list[tuple[Path, Path]]]:
    """``{name: [(file, folder), …]}`` of every ``*.toml`` in the user folders."""
    found: dict[str, list[tuple[Path, Path]]] = {}
    for d in dirs:
        if not d.is_dir():
            continue
        for f in sorted(d.glob("*.toml")):
            if f.is_file() and not f.name.startswith("."):
                found.setdefault(f.stem, []).append((f, d))
    return found


def _clash_places(name: str, files: list[tuple[Path, Path]]) -> list[str]:
    places = ["a built-in species"] if name in _catalog() else []
    return places + [f"in user catalog {d}" for _, d in files]


def user_species(dirs: list[Path] | None = None) -> list[Species]:
    """Every species of the user catalog folders (default :func:`user_catalog_dirs`),
    sorted by name.

    Raises:
        SpeciesNameClashError: a user species named like a built-in one, or found in two
            folders.
        SpeciesFileError: a user file that does not load.
    """
    found = _user_files(user_catalog_dirs() if dirs is None else dirs)
    out = []
    for name, files in sorted(found.items()):
        places = _clash_places(name, files)
        if len(places) > 1:
            raise SpeciesNameClashError(
                name, places, "rename or remove the user species file (NAME.toml, NAME/)"
            )
        out.append(_read_user(*files[0]))
    return out


def check_new_species_name(name: object, folder: str | Path, replace: bool = False) -> str:
    """Check that a new user species may be called ``name`` in the user catalog
    ``folder``.

    Args:
        name: the name asked for.
        folder: the user catalog folder it is to be written to.
        replace: an existing species of that name in ``folder`` may be replaced.

    Returns:
        The name.

    Raises:
        SpeciesNameError: not a lower-case identifier (letters, digits, ``_``).
        SpeciesNameClashError: the name of a built-in species, or of a user species in
            another folder of ``$HABITSIM_SPECIES_PATH`` (or in ``folder`` without
            ``replace``).
    """
    if not isinstance(name, str) or not name.isidentifier() or name.lower() != name:
        raise SpeciesNameError(
            f"species name {brief(name)} is not valid: use a lower-case identifier "
            "(letters, digits and _, not starting with a digit), e.g. mydog"
        )
    target = Path(folder).expanduser()
    if name in _catalog():
        raise SpeciesNameClashError(
            name,
            ["a built-in species"],
            "choose another name (built-in: " + ", ".join(species_names()) + ")",
        )
    dirs = [target, *[d for d in user_catalog_dirs() if d.resolve() != target.resolve()]]
    files = _user_files(dirs).get(name, [])
    places = [
        f"in user catalog {d}"
        for f, d in files
        if not (replace and d.resolve() == target.resolve())
    ]
    if places:
        hint = "choose another name" + ("" if replace else ", or replace it (--overwrite)")
        raise SpeciesNameClashError(name, places, hint)
    return name


def _user_lookup(name: str) -> Species | None:
    """The user species ``name`` (None: in no user folder)."""
    if not name.isidentifier():
        return None
    files = [(d / f"{name}.toml", d) for d in user_catalog_dirs() if (d / f"{name}.toml").is_file()]
    if not files:
        return None
    if len(files) > 1:
        raise SpeciesNameClashError(name, _clash_places(name, files), "keep one of them")
    return _read_user(*files[0])


def species_names(include_user: bool = False) -> list[str]:
    """Names of every species in the built-in catalog (and, with ``include_user``, of
    the user catalogs), sorted."""
    if not include_user:
        return sorted(_catalog())
    return sorted([*_catalog(), *(s.name for s in user_species())])


def load_species(name: str | Species) -> Species:
    """The species called ``name``: the built-in catalog first, then the user catalog
    folders of ``$HABITSIM_SPECIES_PATH`` (a :class:`Species` passes through).

    Raises:
        UnknownSpeciesError: with the list of known names.
        SpeciesNameClashError: the name is in two user folders.
    """
    if isinstance(name, Species):
        return name
    cat = _catalog()
    if isinstance(name, str) and name in cat:
        return cat[name]
    found = _user_lookup(name) if isinstance(name, str) else None
    if found is None:
        known = list(cat)
        for d in user_catalog_dirs():
            known += [f.stem for f in d.glob("*.toml")] if d.is_dir() else []
        raise UnknownSpeciesError(name, sorted(set(known)))
    return found


def all_species(include_user: bool = False) -> list[Species]:
    """Every built-in species (and, with ``include_user``, every user species), sorted
    by name."""
    out = dict(_catalog())
    if include_user:
        out.update({s.name: s for s in user_species()})
    return [v for _, v in sorted(out.items())]


def training_species() -> list[Species]:
    """Built-in species whose motions may be used for training (``held_out = false``)."""
    return [s for s in all_species() if not s.held_out]


def held_out_species() -> list[Species]:
    """Built-in species never used for training."""
    return [s for s in all_species() if s.held_out]
