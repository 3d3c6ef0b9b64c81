"""A robot as retargeting sees it: the model, loaded, its legs (:class:`RobotLegs`), and
a drawable copy for videos."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from .errors import RetargetError, RobotSourceError

__all__ = ["RobotLegs", "load_robot", "menagerie_robot", "drawable"]


@dataclass(frozen=True)
class RobotLegs:
    """A robot's legs as retargeting sees them.

    Attributes:
        model: the robot (with a floor or without).
        feet: foot names in the order of the contact labels (LF, RF, LH, RH for a
            habitsim motion).
        legs: the controllers' :class:`~habitsim.controllers.legs.LegSet` (foot points,
            the joints each leg owns).
        home: (nq,) the standing pose (:func:`robot_legs`: keyframe ``home``, else
            ``qpos0``, crouched when its legs are straight).
        height: trunk height over the ground when standing [m].
        nominal: (nf, 3) foot points in the trunk frame when standing [m].
        radius: (nf,) foot sphere radius [m] (the foot point is its centre).
        leg_length: L [m], the trunk origin's height over the foot points at home.
        qadr, dadr, lo, hi: per foot, the qpos / dof addresses of the leg's own joints
            and the leg IK's bounds: the joint ranges, narrowed to half a turn about the
            standing angle (``RetargetOptions.hinge_span``) and, for the knee, to the side it bends
            to when standing (±inf for an unlimited slide joint).
        home_source: where ``home`` comes from (``keyframe 'home'``, ``qpos0``, or
            ``qpos0`` crouched).
    """

    model: mujoco.MjModel
    feet: tuple[str, ...]
    legs: Any
    home: np.ndarray
    height: float
    nominal: np.ndarray
    radius: np.ndarray
    leg_length: float
    qadr: tuple[np.ndarray, ...]
    dadr: tuple[np.ndarray, ...]
    lo: tuple[np.ndarray, ...]
    hi: tuple[np.ndarray, ...]
    home_source: str = "keyframe 'home'"

    @property
    def trunk_qadr(self) -> int:
        return int(self.legs.qadr)


def load_robot(path: str | Path) -> mujoco.MjModel:
    """A robot MJCF (its scene, with a floor, for simulation), or a MuJoCo Menagerie
    model name (e.g. ``"unitree_go2"``: :func:`menagerie_robot`).

    A ``path`` that is no existing file, has no ``.xml`` suffix and no folder part is
    taken as a Menagerie name.

    Raises:
        RetargetError: the file is missing or does not compile.
        RobotSourceError: a Menagerie name that cannot be had here (see
            :func:`menagerie_robot`).
    """
    p = Path(path)
    if not p.is_file():
        if _is_model_name(str(path)):
            return menagerie_robot(str(path))
        raise RetargetError(
            f"robot model {str(p)!r} does not exist; give an MJCF file or a MuJoCo "
            "Menagerie name such as unitree_go2"
        )
    try:
        return mujoco.MjModel.from_xml_path(str(p))
    except ValueError as e:
        raise RetargetError(f"robot model {str(p)!r} does not load: {e}") from e


def _is_model_name(text: str) -> bool:
    return (
        bool(text)
        and Path(text).suffix == ""
        and "/" not in text
        and "\\" not in text
        and all(c.isalnum() or c in "_-" for c in text)
    )


#: What to do when a Menagerie robot cannot be had, the end of :class:`RobotSourceError`.
_INSTEAD = (
    "or vendor a copy: download the robot's folder of MuJoCo Menagerie and make a "
    "collision-only single-file model of it with `habitsim models vendor ROBOT.xml "
    "--out DIR`, then give --robot DIR/scene.xml"
)


def menagerie_robot(name: str) -> mujoco.MjModel:
    """The default scene (robot and floor) of the MuJoCo Menagerie model ``name``,
    through the optional package ``mujoco-menagerie`` (``mujoco_menagerie.load``), which
    fetches the model on its first use.

    Raises:
        RobotSourceError: the package is not installed (the message says how to install
            it, or to vendor a copy instead), or it cannot give the model (offline, an
            unknown name: the message carries the package's reason).
    """
    try:
        import mujoco_menagerie  # type: ignore[import-not-found,unused-ignore]
    except ImportError as e:
        raise RobotSourceError(
            f"{name!r} is no file; as a MuJoCo Menagerie robot name it needs the optional "
            "package mujoco-menagerie (pip install mujoco-menagerie; it downloads the "
            f"model on first use), {_INSTEAD}"
        ) from e
    try:
        model = mujoco_menagerie.load(name)
    except Exception as e:  # noqa: BLE001 - network, lookup and compile errors alike
        raise RobotSourceError(
            f"mujoco-menagerie cannot give the robot {name!r} ({type(e).__name__}: {e}); "
            "check the name (mujoco_menagerie.names() lists them) and the network, "
            f"{_INSTEAD}"
        ) from e
    if not isinstance(model, mujoco.MjModel):
        raise RobotSourceError(
            f"mujoco-menagerie gave {type(model).__name__} for {name!r}, not a MuJoCo "
            f"model; {_INSTEAD}"
        )
    return model


def _point_names(model: mujoco.MjModel) -> list[str]:
    """Names of the sites, geoms and bodies that could be feet (none on the world body)."""
    names: list[str] = []
    for n, get, body in (
        (model.nsite, model.site, model.site_bodyid),
        (model.ngeom, model.geom, model.geom_bodyid),
        (model.nbody, model.body, np.arange(model.nbody)),
    ):
        for i in range(n):
            nm = get(i).name
            if nm and nm not in names and body[i] != 0:
                names.append(nm)
    return names


def drawable(model: mujoco.MjModel) -> mujoco.MjModel:
    """A copy of ``model`` whose colliding geoms are drawn (for videos): a collision-only
    robot (Menagerie's style) keeps them in geom group 3, which MuJoCo's renderer hides
    by default. Physics is untouched."""
    import copy

    out = copy.copy(model)
    colliding = (out.geom_contype != 0) | (out.geom_conaffinity != 0)
    out.geom_group[colliding & (out.geom_group > 2)] = 0
    return out
