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
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .errors import InvalidMotionError, MotionFileError
from .fileio import atomic_write
from .rotations import quat_fix_continuity, quat_slerp
from .skeleton import JOINT_NAMES, Skeleton, get_skeleton
from .species import Species, load_species

__all__ = [
    "Motion",
    "load_motion",
    "resample_motion",
    "mirror_permutation",
    "FORMAT_VERSION",
    "FEATURE_DIM",
]

FORMAT_VERSION = 1
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
        try:
            self.fps = float(self.fps)
        except (TypeError, ValueError):
            raise InvalidMotionError(f"fps must be a number, got {self.fps!r}") from None
        if not np.isfinite(self.fps) or self.fps <= 0:
            raise InvalidMotionError(f"fps must be positive and finite, got {self.fps}")
        rp = np.asarray(self.root_positions, dtype=np.float64)
        q = np.asarray(self.rotations, dtype=np.float64)
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
            raise InvalidMotionError(f"empty slice {start}:{stop} of a {self.num_frames}-frame motion")
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
        start = get_skeleton(species).standing_pose()[0] if root_start is None else np.asarray(root_start, float)
        root = start[None] + np.cumsum(np.concatenate([np.zeros((1, 3)), v_root[1:]]), axis=0)
        return cls(species, fps, root, q)

    # ------------------------------------------------------------------ contacts
    def detect_contacts(self) -> np.ndarray:
        """(T, 4) foot contacts from toe height and speed with size-normalised thresholds."""
        from .contacts import detect_contacts

        return detect_contacts(self)

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
        arrays: dict[str, np.ndarray] = {
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


def resample_motion(motion: Motion, fps: float) -> Motion:
    """The motion at another frame rate, over the same duration.

    Rotations are slerped, the root interpolated linearly and contact labels taken from
    the nearest frame; ``(T − 1) / fps_old · fps`` is rounded to whole frames. The same
    motion object is returned when the rates match.

    Args:
        motion: the motion.
        fps: the new frame rate [Hz], > 0.

    Returns:
        A new :class:`Motion` (metadata copied).
    """
    if not (np.isfinite(fps) and fps > 0):
        raise InvalidMotionError(f"fps must be > 0, got {fps!r}")
    if abs(motion.fps - fps) < 1e-9:
        return motion
    n = motion.num_frames
    dur = (n - 1) / motion.fps
    m = max(1, int(round(dur * fps)) + 1)
    t = np.arange(m) / fps * motion.fps  # fractional source frame
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


def load_motion(path: str | Path) -> Motion:
    """Read a motion ``.npz`` written by :meth:`Motion.save`.

    Raises:
        MotionFileError: missing file, not an npz, missing keys, unknown format version or
            joint names that differ from the habitsim skeleton.
        InvalidMotionError / UnknownSpeciesError: bad array contents or species.
    """
    p = Path(path)
    if not p.is_file():
        raise MotionFileError(f"{p}: no such motion file")
    try:
        with np.load(p, allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as e:
        raise MotionFileError(f"{p}: not a readable .npz motion file ({e})") from e
    missing = [k for k in _REQUIRED if k not in data]
    if missing:
        raise MotionFileError(f"{p}: missing keys {missing}; a motion file has {list(_REQUIRED)}")
    version = int(data["format_version"])
    if version != FORMAT_VERSION:
        raise MotionFileError(f"{p}: format_version {version}; this habitsim reads {FORMAT_VERSION}")
    names = tuple(str(n) for n in data["joint_names"])
    if names != JOINT_NAMES:
        raise MotionFileError(
            f"{p}: joint names do not match the habitsim skeleton ({len(names)} vs {len(JOINT_NAMES)} joints)"
        )
    meta: dict[str, Any] = {}
    if "metadata_json" in data:
        try:
            meta = json.loads(str(data["metadata_json"]))
        except json.JSONDecodeError as e:
            raise MotionFileError(f"{p}: metadata_json is not valid JSON ({e})") from e
    return Motion(
        species=str(data["species"]),
        fps=float(data["fps"]),
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
