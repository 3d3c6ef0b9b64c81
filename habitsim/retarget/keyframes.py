"""Where a robot's standing pose comes from: a keyframe of the model, or a keyframe of
another MJCF file (Menagerie keeps some robots' ``home`` in ``scene_mjx.xml``).

:func:`standing_keyframe` picks the pose :func:`~habitsim.retarget.robot_legs` stands
on; :func:`file_keyframes` reads the ``<key>`` elements of a file without compiling it
(a scene that includes the robot, or a bare ``<mujoco><keyframe>`` fragment);
:func:`nearby_keyframes` lists the files beside a robot that hold a keyframe of its size,
for the message that asks the user to pick one.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from .errors import RetargetError
from .options import RetargetOptions

__all__ = ["FileKey", "file_keyframes", "standing_keyframe", "nearby_keyframes", "model_keys"]


@dataclass(frozen=True)
class FileKey:
    """A ``<key>`` of an MJCF file.

    Attributes:
        name: its name ("" when unnamed); index: its place among the file's keys.
        qpos: (n,) its qpos (empty when the key gives none).
    """

    name: str
    index: int
    qpos: np.ndarray

    @property
    def label(self) -> str:
        return repr(self.name) if self.name else f"#{self.index}"


def file_keyframes(path: str | Path) -> list[FileKey]:
    """The ``<key>`` elements of an MJCF file, in file order (not compiled: the file may
    be a fragment or a scene whose other files are elsewhere).

    Raises:
        RetargetError: the file is missing, not XML, or a key's qpos is not numbers.
    """
    p = Path(path)
    if not p.is_file():
        raise RetargetError(f"keyframe file {str(p)!r} does not exist; give an MJCF file")
    try:
        root = ET.parse(p).getroot()
    except ET.ParseError as e:
        raise RetargetError(f"keyframe file {str(p)!r} is not XML ({e}); give an MJCF file") from e
    out = []
    for i, key in enumerate(root.iter("key")):
        text = key.get("qpos", "")
        try:
            q = np.array([float(v) for v in text.split()], dtype=float)
        except ValueError as e:
            raise RetargetError(
                f"keyframe {key.get('name', f'#{i}')!r} of {str(p)!r} has a qpos that is "
                f"not numbers: {text[:60]!r}"
            ) from e
        out.append(FileKey(name=key.get("name", ""), index=i, qpos=q))
    return out


def model_keys(model: mujoco.MjModel) -> list[str]:
    """The model's keyframe names (``#i`` for an unnamed one)."""
    return [model.key(k).name or f"#{k}" for k in range(model.nkey)]


def standing_keyframe(
    model: mujoco.MjModel, home: str = "home", options: RetargetOptions | None = None
) -> tuple[np.ndarray, str] | None:
    """The keyframe the robot stands on, or None when it has none to stand on (then
    :func:`~habitsim.retarget.robot_legs` uses ``qpos0``).

    The name is ``options.keyframe`` when set, else ``home``. With
    ``options.keyframe_from`` the key is read from that file: the key of that name whose
    qpos has the model's size ``nq``; when the name is the default ``"home"`` and the file
    has no such key, its only key of size ``nq``.

    Returns:
        (qpos (nq,), where it comes from, e.g. ``keyframe 'home'`` or
        ``keyframe 'home' of scene_mjx.xml``), or None.

    Raises:
        RetargetError: a name other than ``"home"`` that the model (or the file) does not
            have, a file without a key of the model's size (both list the keys found),
            ``options.keyframe`` and a ``home`` other than the default that differ.
    """
    opts = options or RetargetOptions()
    if opts.keyframe is not None and home not in ("home", opts.keyframe):
        raise RetargetError(
            f"two keyframes asked for: home={home!r} and options.keyframe="
            f"{opts.keyframe!r}; give one"
        )
    name = opts.keyframe if opts.keyframe is not None else str(home)
    if opts.keyframe_from is not None:
        return _from_file(model, name, Path(opts.keyframe_from))
    if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_KEY, name) >= 0:
        return model.key(name).qpos.copy(), f"keyframe {name!r}"
    if name != "home":
        raise RetargetError(
            f"the robot has no keyframe {name!r}; its keyframes: "
            f"{', '.join(model_keys(model)) or '(none)'} (--keyframe-from FILE reads one "
            "from another MJCF file)"
        )
    return None


def _from_file(model: mujoco.MjModel, name: str, path: Path) -> tuple[np.ndarray, str]:
    keys = file_keyframes(path)
    fits = [k for k in keys if len(k.qpos) == model.nq]
    named = [k for k in fits if k.name == name]
    if named:
        return named[0].qpos.copy(), f"keyframe {name!r} of {path.name}"
    if name == "home" and len(fits) == 1:
        return fits[0].qpos.copy(), f"keyframe {fits[0].label} of {path.name}"
    found = ", ".join(f"{k.label} ({len(k.qpos)} values)" for k in keys) or "(none)"
    what = f"no keyframe {name!r}" if name != "home" or not fits else "more than one keyframe"
    raise RetargetError(
        f"{path.name} has {what} with the robot's {model.nq} qpos values; its keyframes: "
        f"{found} (name one with --keyframe NAME; a key of another size belongs to "
        "another model)"
    )


def nearby_keyframes(robot_path: str | Path, nq: int) -> list[str]:
    """Files beside a robot MJCF (its folder's ``*.xml``) holding a keyframe of ``nq``
    values, as ``"scene_mjx.xml (home)"``: where to point ``--keyframe-from``."""
    p = Path(robot_path)
    out = []
    for f in sorted(p.parent.glob("*.xml")):
        try:
            keys = [k for k in file_keyframes(f) if len(k.qpos) == nq]
        except RetargetError:
            continue
        if keys:
            names = ", ".join(k.name or f"#{k.index}" for k in keys)
            out.append(f"{f.name} ({names})")
    return out
