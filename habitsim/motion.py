"""The :class:`Motion` container: a clip on one species' habitsim skeleton.

File format (``.npz``, written atomically, read with ``allow_pickle=False``):

==================  ===========  ==========================================================
key                 dtype/shape  meaning
==================  ===========  ==========================================================
``format_version``  int ()       currently 1
``species``         str ()       catalog species name
``fps``             float ()     frames per second [Hz]
``root_positions``  f8 (T, 3)    pelvis position per frame [m], z up, x forward
``rotations``       f8 (T, J, 4) local joint rotations, unit quaternions (w, x, y, z)
``joint_names``     str (J,)     must equal the habitsim skeleton's joint names
``contacts``        bool (T, 4)  optional foot contact labels, feet LF, RF, LH, RH
``metadata_json``   str ()       optional JSON object (action, gait, seed, …)
==================  ===========  ==========================================================
"""

from __future__ import annotations

import json
import math
import zipfile
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .errors import InvalidMotionError, MotionFileError, brief, brief_path
from .fileio import atomic_write
from .jsonfile import DocumentLimits, loads_json
from .rotations import quat_fix_continuity, quat_slerp
from .skeleton import JOINT_NAMES, Skeleton, get_skeleton
from .species import Species, load_species

if TYPE_CHECKING:  # pragma: no cover
    from .contacts import ContactOptions

__all__ = [
    "Motion",
    "load_motion",
    "resample_motion",
    "mirror_permutation",
    "FORMAT_VERSION",
    "FEATURE_DIM",
]

#: Format version of the ``.npz`` motion files this module writes (docs/formats.md).
FORMAT_VERSION = 1
#: Frame rates [Hz] a motion may have.
FPS_RANGE = (1.0, 1000.0)
#: Largest |coordinate| of the root [m]: beyond, a number is garbage, not a place.
MAX_ABS_POSITION_M = 1e5
#: Largest total decompressed size of a motion file's arrays [bytes] (read from the zip
#: headers before anything is decompressed: ~290,000 frames).
MAX_FILE_BYTES = 256 << 20
#: Deepest nesting of ``metadata_json`` and longest text of a string field.
MAX_METADATA_DEPTH = 32
MAX_TEXT_CHARS = 1 << 20
#: Types of the top-level ``metadata_json`` fields that habitsim reads back (other
#: fields are kept as they are): a string, an integer, a finite real number or an object;
#: every field but the numbers may be null.
METADATA_FIELD_KINDS: dict[str, str] = {
    **dict.fromkeys(("action", "gait", "generator", "bvh_file", "pair_key", "species"), "string"),
    **dict.fromkeys(("seed", "frames", "generator_version"), "integer"),
    **dict.fromkeys(
        (
            "fps",
            "duration_s",
            "speed_mps",
            "froude",
            "duty_factor",
            "turn_rate",
            "turn_rate_nd",
            "stride_frequency_hz",
        ),
        "number",
    ),
    **dict.fromkeys(("params", "footfall", "import", "transfer", "refine", "mapping"), "object"),
}
#: Per-frame feature size of the paper's representation: J·4 quaternions + J·3 velocities.
FEATURE_DIM = len(JOINT_NAMES) * 7
#: Actions that a sagittal reflection turns into one another (:meth:`Motion.mirrored`).
MIRROR_ACTIONS = {"turn_left": "turn_right", "turn_right": "turn_left"}


@dataclass
class Motion:
    """A motion clip on a species' skeleton.

    Attributes:
        species: catalog species name.
        fps: frame rate [Hz].
        root_positions: (T, 3) pelvis positions [m].
        rotations: (T, J, 4) local rotations, unit quaternions wxyz.
        contacts: optional (T, 4) bool foot contacts, feet LF, RF, LH, RH.
        metadata: JSON-serialisable extra information (action, gait, seed, …).
    """

    species: str
    fps: float
    root_positions: np.ndarray
    rotations: np.ndarray
    contacts: np.ndarray | None = None
    metadata: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        sp = load_species(self.species)  # raises UnknownSpeciesError with the list
        self.species = sp.name
        fps = self.fps
        if isinstance(fps, np.ndarray) and fps.ndim == 0:
            fps = fps[()]
        if isinstance(fps, bool | np.bool_) or not isinstance(fps, int | float | np.number):
            raise InvalidMotionError(f"fps must be a number, got {brief(fps)}")
        try:
            self.fps = float(fps)
        except (TypeError, ValueError, OverflowError):
            raise InvalidMotionError(f"fps must be a number, got {brief(fps)}") from None
        lo, hi = FPS_RANGE
        if not np.isfinite(self.fps) or self.fps <= 0:
            raise InvalidMotionError(f"fps must be positive and finite, got {self.fps:g}")
        if not lo <= self.fps <= hi:
            raise InvalidMotionError(f"fps {self.fps:g} Hz; valid: {lo:g} to {hi:g} Hz")
        rp = _float_array(self.root_positions, "root_positions")
        q = _float_array(self.rotations, "rotations")
        j = len(JOINT_NAMES)
        if q.ndim != 3 or q.shape[1:] != (j, 4):
            raise InvalidMotionError(f"rotations must have shape (T, {j}, 4), got {q.shape}")
        t = q.shape[0]
        if t < 1:
            raise InvalidMotionError("a motion needs at least one frame")
        if rp.shape != (t, 3):
            raise InvalidMotionError(f"root_positions must have shape ({t}, 3), got {rp.shape}")
        if not np.all(np.isfinite(rp)):
            raise InvalidMotionError("root_positions contain NaN or inf")
        if np.any(np.abs(rp) > MAX_ABS_POSITION_M):
            raise InvalidMotionError(
                f"root_positions reach {np.abs(rp).max():.3g} m; valid: |coordinate| <= "
                f"{MAX_ABS_POSITION_M:g} m"
            )
        if not np.all(np.isfinite(q)):
            raise InvalidMotionError("rotations contain NaN or inf")
        n = np.linalg.norm(q, axis=-1)
        if np.any(n < 1e-6):
            raise InvalidMotionError("rotations contain zero-norm quaternions")
        if np.any(np.abs(n - 1.0) > 1e-3):
            raise InvalidMotionError(
                f"rotations must be unit quaternions (max |norm-1| = {np.abs(n - 1).max():.3g})"
            )
        self.root_positions = rp
        self.rotations = q / n[..., None]
        if self.contacts is not None:
            c = np.asarray(self.contacts)
            if c.dtype.kind not in "biuf":
                raise InvalidMotionError(f"contacts must be booleans, got dtype {c.dtype.str}")
            if c.shape != (t, 4):
                raise InvalidMotionError(f"contacts must have shape ({t}, 4), got {c.shape}")
            self.contacts = c.astype(bool)
        if not isinstance(self.metadata, dict):
            raise InvalidMotionError("metadata must be a dict")

    # ------------------------------------------------------------------ basics
    @property
    def species_info(self) -> Species:
        return load_species(self.species)

    @property
    def skeleton(self) -> Skeleton:
        return get_skeleton(self.species)

    @property
    def num_frames(self) -> int:
        return int(self.rotations.shape[0])

    @property
    def duration(self) -> float:
        """Clip length [s] (frames / fps)."""
        return self.num_frames / self.fps

    def global_positions(self) -> np.ndarray:
        """(T, J, 3) global joint positions [m] by forward kinematics."""
        return self.skeleton.fk(self.root_positions, self.rotations)

    def foot_positions(self) -> np.ndarray:
        """(T, 4, 3) toe end-point positions [m], feet LF, RF, LH, RH."""
        return self.global_positions()[:, self.skeleton.foot_indices]

    def slice(self, start: int, stop: int | None = None) -> Motion:
        """Frames ``start:stop`` as a new Motion."""
        sl = slice(start, stop)
        if self.rotations[sl].shape[0] == 0:
            raise InvalidMotionError(
                f"empty slice {start}:{stop} of a {self.num_frames}-frame motion"
            )
        return Motion(
            self.species,
            self.fps,
            self.root_positions[sl].copy(),
            self.rotations[sl].copy(),
            None if self.contacts is None else self.contacts[sl].copy(),
            dict(self.metadata),
        )

    def mirrored(self) -> Motion:
        """The motion reflected in the body's sagittal plane (world y → −y).

        Left and right limbs swap (``lf_`` ↔ ``rf_``, ``lh_`` ↔ ``rh_``, contacts LF ↔ RF,
        LH ↔ RH) and every local rotation R becomes M·R·M with M = diag(1, −1, 1), i.e. the
        quaternion (w, x, y, z) becomes (w, −x, y, −z). The shared skeleton is left/right
        symmetric, so the joint positions of the result are the reflected positions of the
        original; a left turn becomes a right turn (``metadata["action"]`` is swapped).
        """
        perm = mirror_permutation()
        q = self.rotations[:, perm] * np.array([1.0, -1.0, 1.0, -1.0])
        root = self.root_positions * np.array([1.0, -1.0, 1.0])
        contacts = None if self.contacts is None else self.contacts[:, [1, 0, 3, 2]].copy()
        meta = dict(self.metadata)
        if meta.get("action") in MIRROR_ACTIONS:
            meta["action"] = MIRROR_ACTIONS[meta["action"]]
        return Motion(self.species, self.fps, root, q, contacts, meta)

    # ------------------------------------------------------------------ features
    def features(self) -> np.ndarray:
        """The paper's per-frame representation m_t = {q_t, v_t}, shape (T, J·7) float32.

        q_t: local quaternions (J·4, hemisphere-continuous in time); v_t: global joint
        velocities (J·3) [m/s], v_t = (x_t − x_{t−1})·fps with v_0 = 0 ("Behave Your
        Motion", Sec. 3.1).
        """
        q = quat_fix_continuity(self.rotations, axis=0)
        x = self.global_positions()
        v = np.zeros_like(x)
        v[1:] = (x[1:] - x[:-1]) * self.fps
        t = self.num_frames
        return np.concatenate([q.reshape(t, -1), v.reshape(t, -1)], axis=1).astype(np.float32)

    @classmethod
    def from_features(
        cls,
        features: np.ndarray,
        species: str,
        fps: float,
        root_start: np.ndarray | None = None,
    ) -> Motion:
        """Rebuild a Motion from :meth:`features` output.

        Rotations come from the quaternion part; the root path is the cumulative sum of the
        root velocity, starting at ``root_start`` (default: the standing pose's root).
        """
        f = np.asarray(features, dtype=np.float64)
        j = len(JOINT_NAMES)
        if f.ndim != 2 or f.shape[1] != j * 7:
            raise InvalidMotionError(f"features must have shape (T, {j * 7}), got {f.shape}")
        t = f.shape[0]
        q = f[:, : j * 4].reshape(t, j, 4)
        n = np.linalg.norm(q, axis=-1, keepdims=True)
        if np.any(n < 1e-6) or not np.all(np.isfinite(f)):
            raise InvalidMotionError("features hold zero or non-finite quaternions")
        q = q / n
        v_root = f[:, j * 4 : j * 4 + 3] / float(fps)
        if root_start is None:
            start = get_skeleton(species).standing_pose()[0]
        else:
            start = np.asarray(root_start, float)
        root = start[None] + np.cumsum(np.concatenate([np.zeros((1, 3)), v_root[1:]]), axis=0)
        return cls(species, fps, root, q)

    # ------------------------------------------------------------------ contacts
    def detect_contacts(self, options: ContactOptions | None = None) -> np.ndarray:
        """(T, 4) foot contacts from toe height and speed with size-normalised thresholds
        (``options``: :class:`habitsim.contacts.ContactOptions`, None: the defaults)."""
        from .contacts import ContactOptions, detect_contacts

        return detect_contacts(self, options or ContactOptions())

    def with_contacts(self, contacts: np.ndarray | None = None) -> Motion:
        """A copy with contact labels (detected when ``contacts`` is None)."""
        m = self.slice(0)
        m.contacts = self.detect_contacts() if contacts is None else np.asarray(contacts, bool)
        m.__post_init__()
        return m

    # ------------------------------------------------------------------ file I/O
    def save(self, path: str | Path) -> Path:
        """Write the motion as ``.npz`` (atomically; see the module docstring)."""
        path = Path(path)
        if path.suffix != ".npz":
            raise MotionFileError(f"motion files end in .npz, got {path.name!r}")
        arrays: dict[str, Any] = {  # arrays for np.savez_compressed
            "format_version": np.array(FORMAT_VERSION),
            "species": np.array(self.species),
            "fps": np.array(self.fps),
            "root_positions": self.root_positions,
            "rotations": self.rotations,
            "joint_names": np.array(JOINT_NAMES),
            "metadata_json": np.array(json.dumps(self.metadata, sort_keys=True)),
        }
        if self.contacts is not None:
            arrays["contacts"] = self.contacts
        with atomic_write(path) as fh:
            np.savez_compressed(fh, **arrays)
        return path


_REQUIRED = ("format_version", "species", "fps", "root_positions", "rotations", "joint_names")


def resample_motion(motion: Motion, fps: float, num_frames: int | None = None) -> Motion:
    """The motion at another frame rate, over the same duration.

    Rotations are slerped, the root interpolated linearly and contact labels taken from
    the nearest frame; ``(T − 1) / fps_old · fps`` is rounded to whole frames unless
    ``num_frames`` fixes the count (frames past the motion's end hold its last frame).
    The same motion object is returned when the rates and frame counts match.

    Args:
        motion: the motion.
        fps: the new frame rate [Hz], > 0.
        num_frames: the number of frames to return (default: the same duration).

    Returns:
        A new :class:`Motion` (metadata copied).

    Raises:
        InvalidMotionError: a rate that is not > 0 or a frame count < 1.
    """
    if not (np.isfinite(fps) and fps > 0):
        raise InvalidMotionError(f"fps must be > 0, got {fps!r}")
    if num_frames is not None and num_frames < 1:
        raise InvalidMotionError(f"num_frames must be ≥ 1, got {num_frames!r}")
    n = motion.num_frames
    if abs(motion.fps - fps) < 1e-9 and num_frames in (None, n):
        return motion
    dur = (n - 1) / motion.fps
    m = max(1, int(round(dur * fps)) + 1) if num_frames is None else int(num_frames)
    t = np.minimum(np.arange(m) / fps * motion.fps, n - 1)  # fractional source frame
    i0 = np.clip(np.floor(t).astype(int), 0, n - 1)
    i1 = np.minimum(i0 + 1, n - 1)
    a = (t - i0)[:, None]
    root = motion.root_positions[i0] * (1 - a) + motion.root_positions[i1] * a
    j = motion.rotations.shape[1]
    rot = quat_slerp(motion.rotations[i0], motion.rotations[i1], np.broadcast_to(a, (m, j)))
    contacts = (
        None
        if motion.contacts is None
        else motion.contacts[np.clip(np.round(t).astype(int), 0, n - 1)]
    )
    return Motion(motion.species, float(fps), root, rot, contacts, dict(motion.metadata))


def _float_array(v: Any, what: str) -> np.ndarray:
    """``v`` as a float64 array; strings, objects or ragged lists are an InvalidMotionError."""
    a = np.asarray(v) if not isinstance(v, np.ndarray) else v
    if a.dtype.kind not in "biuf":
        raise InvalidMotionError(f"{what} must hold numbers, got dtype {a.dtype.str}")
    return a.astype(np.float64, copy=False)


def _check_zip(p: Path) -> None:
    """Refuse a file that is not a zip archive of ``.npy`` members, or whose members would
    decompress to more than :data:`MAX_FILE_BYTES` (read from the zip headers: no member
    is decompressed here)."""
    try:
        with p.open("rb") as fh:
            magic = fh.read(4)
    except OSError as e:
        raise MotionFileError(f"{brief_path(p)}: cannot read motion file ({e.strerror})") from None
    if magic == b"\x93NUM":
        raise MotionFileError(
            f"{brief_path(p)}: not a readable .npz motion file (a single .npy array saved "
            "under a .npz name); a motion file is the .npz archive written by Motion.save"
        )
    if magic[:2] != b"PK":
        raise MotionFileError(
            f"{brief_path(p)}: not a readable .npz motion file (not a zip archive); a motion "
            "file is the .npz archive written by Motion.save"
        )
    try:
        with zipfile.ZipFile(p) as zf:
            infos = zf.infolist()
    except (OSError, zipfile.BadZipFile, ValueError, EOFError, NotImplementedError) as e:
        raise MotionFileError(
            f"{brief_path(p)}: not a readable .npz motion file (corrupt zip: {brief(str(e))})"
        ) from None
    if len(infos) > 64:
        raise MotionFileError(f"{brief_path(p)}: {len(infos)} arrays; a motion file has at most 8")
    total = sum(i.file_size for i in infos)
    if total > MAX_FILE_BYTES:
        raise MotionFileError(
            f"{brief_path(p)}: its arrays would decompress to {total / 2**20:.0f} MB; valid: at "
            f"most {MAX_FILE_BYTES >> 20} MB (~290,000 frames)"
        )


def _text(data: dict[str, np.ndarray], key: str, p: Path) -> str:
    """A 0-d string field of a motion file."""
    v = data[key]
    if v.ndim != 0 or v.dtype.kind != "U":
        raise MotionFileError(
            f"{brief_path(p)}: {key} must be a single string, got dtype {v.dtype.str} "
            f"shape {v.shape}"
        )
    text = str(v[()])
    if len(text) > MAX_TEXT_CHARS:
        raise MotionFileError(
            f"{brief_path(p)}: {key} holds {len(text)} characters; valid: at most {MAX_TEXT_CHARS}"
        )
    return text


def _number(data: dict[str, np.ndarray], key: str, p: Path) -> float:
    """A 0-d real number field of a motion file."""
    v = data[key]
    if v.ndim != 0 or v.dtype.kind not in "iuf":
        raise MotionFileError(
            f"{brief_path(p)}: {key} must be a single number, got dtype {v.dtype.str} "
            f"shape {v.shape}"
        )
    return float(v[()])


def _check_metadata_fields(meta: dict[str, Any], p: Path) -> None:
    """Refuse a ``metadata_json`` field of :data:`METADATA_FIELD_KINDS` of the wrong type."""
    for key, kind in METADATA_FIELD_KINDS.items():
        if key not in meta:
            continue
        v = meta[key]
        if kind == "number":
            ok = isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
        elif v is None:
            ok = True
        elif kind == "integer":
            ok = isinstance(v, int) and not isinstance(v, bool)
        else:
            ok = isinstance(v, str if kind == "string" else dict)
        if not ok:
            what = "a finite number" if kind == "number" else f"{kind} or null"
            raise MotionFileError(
                f"{brief_path(p)}: metadata_json field {key!r} is of type {type(v).__name__}; "
                f"valid: {what}"
            )


def load_motion(path: str | Path) -> Motion:
    """Read a motion ``.npz`` written by :meth:`Motion.save`.

    The file is checked before any array is decompressed: it must be a zip archive (not
    a bare ``.npy``, not pickled objects) whose arrays decompress to at most
    :data:`MAX_FILE_BYTES`. Every field is then checked for its dtype and shape.

    Raises:
        MotionFileError: missing file, not an npz, too large, missing keys, a field of the
            wrong type or shape, unknown format version, joint names that differ from the
            habitsim skeleton, ``metadata_json`` that is not a JSON object of at most
            :data:`MAX_METADATA_DEPTH` levels.
        InvalidMotionError / UnknownSpeciesError: bad array contents or species.
    """
    p = Path(path)
    if not p.is_file():
        raise MotionFileError(f"{brief_path(p)}: no such motion file")
    _check_zip(p)
    try:
        with np.load(p, allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
    except ValueError as e:
        if "pickle" in str(e).lower():  # numpy's advice (allow_pickle=True) is not ours
            raise MotionFileError(
                f"{brief_path(p)}: holds Python objects (pickled data), which habitsim never "
                "loads; a motion file holds numeric and string arrays only"
            ) from None
        raise MotionFileError(
            f"{brief_path(p)}: not a readable .npz motion file ({brief(str(e))})"
        ) from None
    except (
        OSError,
        zipfile.BadZipFile,
        zlib.error,
        EOFError,
        NotImplementedError,
        MemoryError,
    ) as e:
        raise MotionFileError(
            f"{brief_path(p)}: not a readable .npz motion file ({brief(str(e))})"
        ) from None
    except Exception as e:  # noqa: BLE001 - only numpy's and zipfile's decoding ran here
        # a corrupt .npy header reaches numpy's header parser (tokenize / ast errors)
        raise MotionFileError(
            f"{brief_path(p)}: not a readable .npz motion file (corrupt array header: "
            f"{type(e).__name__})"
        ) from None
    missing = [k for k in _REQUIRED if k not in data]
    if missing:
        raise MotionFileError(
            f"{brief_path(p)}: missing keys {missing}; a motion file has {list(_REQUIRED)}"
        )
    v = data["format_version"]
    if v.ndim != 0 or v.dtype.kind not in "iu":
        raise MotionFileError(
            f"{brief_path(p)}: format_version must be a single integer, got dtype "
            f"{v.dtype.str} shape {v.shape}; this habitsim reads {FORMAT_VERSION}"
        )
    version = int(v[()])
    if version != FORMAT_VERSION:
        raise MotionFileError(
            f"{brief_path(p)}: format_version {version}; this habitsim reads {FORMAT_VERSION}"
        )
    jn = data["joint_names"]
    if jn.ndim != 1 or jn.dtype.kind != "U":
        raise MotionFileError(
            f"{brief_path(p)}: joint_names must be a list of strings, got dtype {jn.dtype.str} "
            f"shape {jn.shape}"
        )
    names = tuple(str(n) for n in jn)
    if names != JOINT_NAMES:
        raise MotionFileError(
            f"{brief_path(p)}: joint names do not match the habitsim skeleton ({len(names)} vs "
            f"{len(JOINT_NAMES)} joints)"
        )
    meta: dict[str, Any] = {}
    if "metadata_json" in data:
        text = _text(data, "metadata_json", p)
        meta = loads_json(
            text,
            f"{brief_path(p)}: metadata_json",
            error=MotionFileError,
            options=DocumentLimits(max_bytes=4 * MAX_TEXT_CHARS, max_depth=MAX_METADATA_DEPTH),
        )
        if not isinstance(meta, dict):
            raise MotionFileError(
                f"{brief_path(p)}: metadata_json must be a JSON object, got {type(meta).__name__}"
            )
        _check_metadata_fields(meta, p)
    for key in ("root_positions", "rotations", "contacts"):
        if key in data and data[key].dtype.kind not in "biuf":
            raise MotionFileError(
                f"{brief_path(p)}: {key} must hold numbers, got dtype {data[key].dtype.str}"
            )
    return Motion(
        species=_text(data, "species", p),
        fps=_number(data, "fps", p),
        root_positions=data["root_positions"],
        rotations=data["rotations"],
        contacts=data.get("contacts"),
        metadata=meta,
    )


def mirror_permutation() -> np.ndarray:
    """Joint index permutation that swaps each left limb joint with its right twin."""
    index = {n: i for i, n in enumerate(JOINT_NAMES)}
    twin = {"lf_": "rf_", "rf_": "lf_", "lh_": "rh_", "rh_": "lh_"}
    return np.array(
        [index[twin[n[:3]] + n[3:]] if n[:3] in twin else index[n] for n in JOINT_NAMES]
    )
