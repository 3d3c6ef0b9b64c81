"""Make a user species from one clip (:func:`species_from_clip`): measure the rig, draft
its species file, build its MuJoCo models, check that the standing model stands, and move
``NAME.toml`` and ``NAME/`` into the user catalog folder together, or leave nothing.

The physics half of :mod:`habitsim.fromclip` (it builds and runs MuJoCo models).
"""

from __future__ import annotations

import math
import shutil
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import mujoco

from ..bvh_mapping import read_source
from ..errors import OutputPathError, brief_path
from ..mjcf_models.builder import ModelBuildError, write_model
from ..source import SourceOptions, cut_source
from ..species import Species, check_new_species_name, load_species_file, user_catalog_dirs
from .draft import Draft, draft_species
from .measure import RigMeasure, measure_rig
from .options import FromClipOptions

__all__ = ["StandCheck", "StandingError", "FromClipResult", "stand_check", "species_from_clip"]


@dataclass(frozen=True)
class StandCheck:
    """How the standing model stood on ``home`` in plain MuJoCo.

    Attributes:
        seconds: how long it was stepped [s].
        home_height: pelvis height on ``home`` [m].
        lowest, highest: lowest and highest pelvis height while stepping [m].
        tilt_deg: how far the pelvis' up axis turned from its ``home`` direction [deg].
        passed: whether it stayed within the options' share and tilt.
    """

    seconds: float
    home_height: float
    lowest: float
    highest: float
    tilt_deg: float
    passed: bool

    def describe(self) -> str:
        """The check in words."""
        return (
            f"pelvis {self.home_height:.3f} m on home, {self.lowest:.3f}–{self.highest:.3f} m "
            f"over {self.seconds:g} s ({100 * (self.lowest / self.home_height - 1):+.1f} % / "
            f"{100 * (self.highest / self.home_height - 1):+.1f} %), tilt {self.tilt_deg:.1f} deg"
        )


class StandingError(ModelBuildError):
    """The model of a drafted species does not stand on its ``home`` keyframe; the
    attribute ``check`` holds the :class:`StandCheck`."""

    def __init__(self, message: str, check: StandCheck):
        self.check = check
        super().__init__(message)


def stand_check(scene: str | Path, options: FromClipOptions | None = None) -> StandCheck:
    """Load a standing scene (``scene.xml``) in plain MuJoCo, reset it to ``home`` and
    step it ``options.stand_seconds``.

    Raises:
        ModelBuildError: the scene does not load or has no ``home`` keyframe.
    """
    o = options or FromClipOptions()
    try:
        m = mujoco.MjModel.from_xml_path(str(scene))
        key = m.key("home").id
    except (ValueError, KeyError) as e:
        raise ModelBuildError(f"{scene}: cannot load a scene with a home keyframe ({e})") from e
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, key)
    mujoco.mj_forward(m, d)
    pelvis = m.body("pelvis").id
    z0 = float(d.xpos[pelvis][2])
    up0 = d.xmat[pelvis].reshape(3, 3)[:, 2].copy()
    low = high = z0
    for _ in range(int(round(o.stand_seconds / m.opt.timestep))):
        mujoco.mj_step(m, d)
        z = float(d.xpos[pelvis][2])
        low, high = min(low, z), max(high, z)
    cos = float(up0 @ d.xmat[pelvis].reshape(3, 3)[:, 2])
    tilt = math.degrees(math.acos(max(-1.0, min(1.0, cos))))
    share = o.stand_height_share
    ok = (
        math.isfinite(low)
        and low >= share * z0
        and high <= (2.0 - share) * z0
        and tilt <= o.stand_upright_deg
    )
    return StandCheck(o.stand_seconds, z0, low, high, tilt, bool(ok))


@dataclass(frozen=True)
class FromClipResult:
    """A species made from a clip.

    Attributes:
        species: the new species, loaded from its written file.
        file: its species file ``<catalog>/<name>.toml``.
        models: its model folder ``<catalog>/<name>/``.
        measure: what the clip showed.
        draft: how the file was drafted (cousin, mass rule, estimated segments).
        stand: the standing check.
        seconds: wall time of the whole command [s].
    """

    species: Species
    file: Path
    models: Path
    measure: RigMeasure
    draft: Draft
    stand: StandCheck
    seconds: float


def _catalog_folder(catalog: str | Path | None) -> Path:
    if catalog is not None:
        return Path(catalog).expanduser()
    dirs = user_catalog_dirs()
    if not dirs:
        raise OutputPathError(
            "no user catalog folder to write the species to: pass --catalog DIR or set "
            "HABITSIM_SPECIES_PATH to a folder"
        )
    return dirs[0]


def species_from_clip(
    clip: str | Path,
    name: str,
    catalog: str | Path | None = None,
    mass_kg: float | None = None,
    posture: str | None = None,
    like: str | None = None,
    description: str | None = None,
    source: SourceOptions | None = None,
    replace: bool = False,
    options: FromClipOptions | None = None,
) -> FromClipResult:
    """Make the user species ``name`` from a motion-capture clip.

    Args:
        clip: a ``.bvh``, ``.glb`` or ``.gltf`` file.
        name: the new species' name (a lower-case identifier, no catalog species' name).
        catalog: the user catalog folder (None: the first of ``$HABITSIM_SPECIES_PATH``).
        mass_kg: body mass [kg] (None: the catalog's allometric rule).
        posture: posture class (None: classified from the legs).
        like: the built-in training species to borrow girths, limits, gaits and habits
            from (None: the nearest of the same posture).
        description: the habit description (None: made from the cousin's).
        source: how the clip is read (its ``joint_map``, ``units``, ``up``,
            ``animation``, ``fps`` and ``span``; the rest is ignored).
        replace: replace a user species of that name in ``catalog``.
        options: the knobs.

    Returns:
        The :class:`FromClipResult`.

    Raises:
        SpeciesNameError / SpeciesNameClashError: an invalid or taken name.
        ClipMeasureError: legs not found, a clip too short, no spine.
        StandingError: the built model does not stand (nothing is written).
        OutputPathError: no catalog folder, or one that cannot be written.
        SkeletonMappingError, BVHParseError, GLTFError, ArgumentRangeError,
        UnknownSpeciesError: from reading and mapping the clip, or a bad option.
    """
    t0 = time.perf_counter()
    o = options or FromClipOptions()
    s = source or SourceOptions()
    folder = _catalog_folder(catalog)
    check_new_species_name(name, folder, replace=replace)
    bvh = read_source(clip, animation=s.animation, fps=s.fps, strict=s.strict)
    bvh, _ = cut_source(bvh, s.span)
    measure = measure_rig(bvh, joint_map=s.joint_map, units=s.units, up=s.up, options=o)
    try:
        folder.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=f".{name}.", dir=folder))
    except OSError as e:
        raise OutputPathError(f"user catalog {brief_path(folder)} cannot be written: {e}") from e
    file, models = folder / f"{name}.toml", folder / name
    try:
        draft = draft_species(
            measure,
            name,
            mass_kg=mass_kg,
            posture=posture,
            like=like,
            description=description,
            path=file,
            user_catalog=folder,
            options=o,
        )
        scene = write_model(draft.species, root=tmp)
        check = stand_check(scene, o)
        if not check.passed:
            raise StandingError(
                f"the model of {name!r} drafted from {Path(clip).name} does not stand: "
                f"{check.describe()}; valid: its pelvis within "
                f"{100 * (1 - o.stand_height_share):g} % of its home height and tilted at most "
                f"{o.stand_upright_deg:g} deg for {o.stand_seconds:g} s. Cut the clip to frames "
                "where the animal stands (--start/--end), or give --posture or --like",
                check,
            )
        (tmp / file.name).write_text(draft.toml(), encoding="utf-8")
        _move_into_place(tmp, file, models)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    sp = load_species_file(file, user_catalog=folder)
    return FromClipResult(sp, file, models, measure, draft, check, time.perf_counter() - t0)


def _move_into_place(tmp: Path, file: Path, models: Path) -> None:
    """Move ``tmp/<name>/`` and ``tmp/<name>.toml`` to ``models`` and ``file``; an older
    species of that name is set aside first and restored if a move fails."""
    old = tmp / ".old"
    old.mkdir()
    moved_old: list[tuple[Path, Path]] = []
    try:
        for p in (file, models):
            if p.exists():
                p.rename(old / p.name)
                moved_old.append((old / p.name, p))
        (tmp / models.name).rename(models)
        try:
            (tmp / file.name).rename(file)
        except OSError:
            shutil.rmtree(models, ignore_errors=True)
            raise
    except OSError as e:
        for src, dst in moved_old:
            if not dst.exists():
                src.rename(dst)
        raise OutputPathError(f"cannot move the species into {brief_path(file.parent)}: {e}") from e
