"""A collision-only, single-file copy of a robot model, for vendoring it:
:func:`vendor_robot` (``habitsim models vendor``).

MuJoCo Menagerie robots ship their visual meshes and, for some (Spot), collision meshes
as separate files. The copy keeps the bodies, inertials, joints, actuators, sensors,
keyframes and primitive geoms as they are, drops every visual mesh geom (one that neither
collides nor is collided with: ``contype == conaffinity == 0``), replaces every colliding
mesh geom by a primitive fitted to its mesh by MuJoCo's compiler (the ``mesh`` attribute
on a box, capsule or sphere geom; ``fitaabb`` and ``fitscale`` as :class:`VendorOptions`
says) and removes the mesh and file texture assets, so that the MJCF written holds no
reference to another file. Includes are merged into the one file. A colliding mesh whose
file cannot be read is fitted instead to the largest readable visual mesh of its body
(:attr:`VendorReport.stand_ins`).

The inertials do not move: a body whose mass came from its meshes' volume (no
``<inertial>``, ``inertiafromgeom``) keeps the mass and inertia the meshes gave it, written
as an explicit ``<inertial>``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import mujoco
import numpy as np

from .errors import VendorError

__all__ = ["VendorOptions", "VendorReport", "vendor_robot", "SHAPES"]

#: Primitives a collision mesh can become (``auto``: the one closest to the mesh's volume).
SHAPES = ("auto", "box", "capsule", "sphere")
_GEOM = {
    "box": mujoco.mjtGeom.mjGEOM_BOX,
    "capsule": mujoco.mjtGeom.mjGEOM_CAPSULE,
    "sphere": mujoco.mjtGeom.mjGEOM_SPHERE,
}
#: Files copied beside the model when the robot's folder has them (its licence).
LICENCE_FILES = ("LICENSE", "LICENSE.txt", "LICENCE", "COPYING")


@dataclass(frozen=True)
class VendorOptions:
    """Knobs of :func:`vendor_robot`.

    Attributes:
        shape: the primitive each collision mesh becomes (:data:`SHAPES`); ``auto`` fits
            each of box, capsule and sphere and keeps the one whose volume is closest to
            the mesh's.
        fit_aabb: fit the primitive to the mesh's bounding box in its principal frame
            (MuJoCo's ``compiler/fitaabb``) instead of to its equivalent-inertia box.
        fit_scale: scale of the fitted primitive (MuJoCo's ``geom/fitscale``).
    """

    shape: str = "auto"
    fit_aabb: bool = True
    fit_scale: float = 1.0

    def __post_init__(self) -> None:
        if self.shape not in SHAPES:
            raise VendorError(f"shape must be one of {', '.join(SHAPES)}, got {self.shape!r}")
        if not (np.isfinite(self.fit_scale) and self.fit_scale > 0):
            raise VendorError(f"fit_scale must be > 0, got {self.fit_scale!r}")


@dataclass
class VendorReport:
    """What :func:`vendor_robot` did.

    Attributes:
        out: the model written; licence: the licence file copied beside it (or None).
        dropped: names (``body/#i`` when unnamed) of the visual mesh geoms dropped.
        fitted: per colliding mesh geom replaced, (name, primitive, size (3,) [m]).
        assets_removed: the mesh and texture assets removed.
        inertia_without_visuals: bodies whose inertia comes from their geoms and whose
            visual mesh files were missing: their inertia is that of the geoms left.
        stand_ins: per colliding mesh geom whose file could not be read, (name, the
            visual mesh of its body its primitive was fitted to instead).
    """

    out: Path
    licence: Path | None = None
    dropped: list[str] = field(default_factory=list)
    fitted: list[tuple[str, str, tuple[float, float, float]]] = field(default_factory=list)
    assets_removed: list[str] = field(default_factory=list)
    inertia_without_visuals: list[str] = field(default_factory=list)
    stand_ins: list[tuple[str, str]] = field(default_factory=list)


def _load(path: Path) -> mujoco.MjSpec:
    if not path.is_file():
        raise VendorError(f"robot model {str(path)!r} does not exist; give an MJCF file")
    try:
        return mujoco.MjSpec.from_file(str(path))
    except ValueError as e:
        raise VendorError(f"robot model {str(path)!r} does not load: {e}") from e


def _visual_mesh(g: mujoco.MjsGeom) -> bool:
    return g.type == mujoco.mjtGeom.mjGEOM_MESH and g.contype == 0 and g.conaffinity == 0


def _label(model: mujoco.MjModel, gid: int) -> str:
    name = model.geom(gid).name
    return name or f"{model.body(int(model.geom_bodyid[gid])).name}/#{gid}"


def _mesh_volume(model: mujoco.MjModel, mid: int) -> float:
    import trimesh

    va, vn = int(model.mesh_vertadr[mid]), int(model.mesh_vertnum[mid])
    fa, fn = int(model.mesh_faceadr[mid]), int(model.mesh_facenum[mid])
    mesh = trimesh.Trimesh(
        model.mesh_vert[va : va + vn], model.mesh_face[fa : fa + fn], process=False
    )
    vol = abs(float(mesh.volume))
    return vol if vol > 0 else float(mesh.convex_hull.volume)


def _primitive_volume(kind: str, size: np.ndarray) -> float:
    if kind == "box":
        return float(8.0 * np.prod(size[:3]))
    if kind == "sphere":
        return float(4.0 / 3.0 * np.pi * size[0] ** 3)
    r, h = float(size[0]), float(size[1])
    return float(np.pi * r * r * 2.0 * h + 4.0 / 3.0 * np.pi * r**3)


def _fits(
    base: mujoco.MjSpec, kind: str, ids: list[int], opts: VendorOptions
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(size, pos, quat) per geom id of ``ids`` fitted as ``kind`` by MuJoCo's compiler
    (body frame)."""
    spec = base.copy()
    spec.compiler.fitaabb = bool(opts.fit_aabb)
    geoms = list(spec.geoms)
    for gid in ids:
        geoms[gid].type = _GEOM[kind]
        geoms[gid].fitscale = float(opts.fit_scale)
    m = spec.compile()
    return m.geom_size[ids].copy(), m.geom_pos[ids].copy(), m.geom_quat[ids].copy()


def _mesh_box(spec: mujoco.MjSpec, name: str) -> float | None:
    """Volume of the bounding box of mesh asset ``name`` as MuJoCo reads it from its file
    (in a copy of ``spec`` holding no other mesh), or None when it cannot be read."""
    trial = spec.copy()
    for g in [g for g in trial.geoms if g.type == mujoco.mjtGeom.mjGEOM_MESH]:
        g.type, g.meshname = mujoco.mjtGeom.mjGEOM_SPHERE, ""  # the bodies keep a mass
        g.size = np.array([0.01, 0.0, 0.0])
    for m in [m for m in trial.meshes if m.name != name]:
        trial.delete(m)
    try:
        model = trial.compile()
    except ValueError:
        return None
    verts = model.mesh_vert[: int(model.mesh_vertnum[0])]
    return float(np.prod(np.ptp(verts, axis=0))) if len(verts) else None


def _stand_ins(spec: mujoco.MjSpec, report: VendorReport) -> None:
    """A colliding mesh whose file cannot be read (missing, a format left out of the
    download) is fitted instead to the largest readable visual mesh of its body, placed
    as that visual geom is (``report.stand_ins``); with none, a :class:`VendorError`."""
    trial = spec.copy()
    for g in [g for g in trial.geoms if _visual_mesh(g)]:
        trial.delete(g)
    used = {g.meshname for g in trial.geoms if g.type == mujoco.mjtGeom.mjGEOM_MESH}
    for m in [m for m in trial.meshes if m.name not in used]:
        trial.delete(m)
    try:
        trial.compile()
        return  # every collision mesh reads: nothing to stand in
    except ValueError:
        pass
    geoms = list(spec.geoms)
    readable: dict[str, float | None] = {}

    def box(name: str) -> float | None:
        if name not in readable:
            readable[name] = _mesh_box(spec, name)
        return readable[name]

    for i, g in enumerate(geoms):
        if g.type != mujoco.mjtGeom.mjGEOM_MESH or _visual_mesh(g) or box(g.meshname):
            continue
        label = g.name or f"{g.parent.name}/#{i}"
        visuals = [v for v in geoms if _visual_mesh(v) and v.parent == g.parent]
        sized = [(box(v.meshname) or 0.0, k, v) for k, v in enumerate(visuals)]
        sized = [s for s in sized if s[0] > 0]
        if not sized:
            raise VendorError(
                f"the collision mesh {g.meshname!r} of geom {label} cannot be read and no "
                f"visual mesh of body {g.parent.name!r} can stand in for it; put its file "
                "where the model says (or replace the geom by a primitive by hand)"
            )
        _, _, v = max(sized, key=lambda s: (s[0], -s[1]))
        report.stand_ins.append((label, v.meshname))
        g.meshname = v.meshname
        g.pos = v.pos.copy()
        g.quat = v.quat.copy()
        g.alt.type = v.alt.type
        for attr in ("axisangle", "euler", "xyaxes", "zaxis"):
            setattr(g.alt, attr, getattr(v.alt, attr).copy())


def vendor_robot(
    path: str | Path, out_dir: str | Path, options: VendorOptions | None = None
) -> VendorReport:
    """Write a collision-only, single-file copy of the robot MJCF ``path`` (see the
    module) as ``out_dir/<its file name>``, atomically, and its folder's licence file
    beside it.

    Args:
        path: the robot's MJCF (or its scene); includes and mesh files are read from
            where it says.
        out_dir: the folder to write into (made if missing).
        options: the knobs (default :class:`VendorOptions`).

    Returns:
        The :class:`VendorReport`.

    Raises:
        VendorError: a model that does not load, a mesh geom inside a ``<frame>``, a
            height field or skin read from a file (the copy could not be one file), an
            output that is the input.
    """
    from ..fileio import atomic_write_text

    opts = options or VendorOptions()
    src = Path(path)
    spec = _load(src)
    out = Path(out_dir) / src.name
    if out.resolve() == src.resolve():
        raise VendorError(f"the copy would overwrite {str(src)!r}; give another --out folder")
    for what, items in (("height field", spec.hfields), ("skin", spec.skins)):
        files = [x.name for x in items if getattr(x, "file", "")]
        if files:
            raise VendorError(
                f"{str(src)!r} reads a {what} from a file ({', '.join(files)}); the copy "
                "could not be one file: remove it first"
            )
    try:  # the whole model, visual meshes included: the bodies' inertia as shipped
        full: mujoco.MjModel | None = spec.compile()
    except ValueError:  # visual mesh files left out of the download: not needed
        full = None
    report = VendorReport(out=out)
    removed = set()
    for tex in list(spec.textures):
        if tex.file or any(tex.cubefiles):
            removed.add(tex.name)
            report.assets_removed.append(f"texture {tex.name}")
            spec.delete(tex)
    for mat in spec.materials:
        mat.textures = ["" if t in removed else t for t in mat.textures]
    _stand_ins(spec, report)
    for i, g in enumerate(list(spec.geoms)):
        if _visual_mesh(g):
            report.dropped.append(g.name or f"{g.parent.name}/#{i}")
            spec.delete(g)
    used = {g.meshname for g in spec.geoms if g.type == mujoco.mjtGeom.mjGEOM_MESH}
    for mesh in [m for m in spec.meshes if m.name not in used]:
        report.assets_removed.append(f"mesh {mesh.name}")
        spec.delete(mesh)
    try:
        m0 = spec.compile()
    except ValueError as e:
        raise VendorError(
            f"{str(src)!r} does not compile without its visual meshes and file textures: "
            f"{e} (a collision mesh's file is needed to fit its primitive)"
        ) from e
    geoms = list(spec.geoms)
    colliding = [i for i in range(m0.ngeom) if m0.geom_type[i] == mujoco.mjtGeom.mjGEOM_MESH]
    for i in colliding:
        if geoms[i].frame is not None:
            raise VendorError(
                f"the collision mesh geom {_label(m0, i)} sits in a <frame>; move it onto "
                "its body before vendoring"
            )
    kinds = ["box", "capsule", "sphere"] if opts.shape == "auto" else [opts.shape]
    fitted = {}
    for k in kinds if colliding else []:
        try:
            fitted[k] = _fits(spec, k, colliding, opts)
        except ValueError:  # e.g. a capsule along a sphere-like mesh has no length
            continue
    kinds = [k for k in kinds if k in fitted]
    if colliding and not kinds:
        raise VendorError(
            f"no {' or '.join(_GEOM) if opts.shape == 'auto' else opts.shape} fits the "
            f"collision meshes of {str(src)!r}; try another --shape"
        )
    for n, gid in enumerate(colliding):
        vol = _mesh_volume(m0, int(m0.geom_dataid[gid]))
        best = min(
            kinds, key=lambda k: abs(_primitive_volume(k, fitted[k][0][n]) - vol) / max(vol, 1e-12)
        )
        size, pos, quat = (a[n] for a in fitted[best])
        g = geoms[gid]
        g.type = _GEOM[best]
        g.size = size
        g.pos = pos
        g.quat = quat
        g.alt.type = mujoco.mjtOrientation.mjORIENTATION_QUAT
        g.meshname = ""
        report.fitted.append(
            (_label(m0, gid), best, (float(size[0]), float(size[1]), float(size[2])))
        )
    # the bodies keep the mass and inertia their meshes gave them
    source = full if full is not None else m0
    for body in list(spec.bodies):
        b = int(body.id)
        if b <= 0 or body.explicitinertial:
            continue
        if full is None:
            report.inertia_without_visuals.append(body.name or f"#{b}")
        body.explicitinertial = True
        body.mass = float(source.body_mass[b])
        body.ipos = source.body_ipos[b].copy()
        body.iquat = source.body_iquat[b].copy()
        body.inertia = source.body_inertia[b].copy()
    for mesh in list(spec.meshes):
        report.assets_removed.append(f"mesh {mesh.name}")
        spec.delete(mesh)
    spec.meshdir = ""
    spec.texturedir = ""
    try:
        spec.compile()
        xml = spec.to_xml()
        mujoco.MjModel.from_xml_string(xml)  # no file left to read
    except ValueError as e:
        raise VendorError(f"the collision-only copy of {str(src)!r} does not load: {e}") from e
    out.parent.mkdir(parents=True, exist_ok=True)
    note = (
        f"<!-- A collision-only copy of {src.name} made by `habitsim models vendor`: "
        f"{len(report.dropped)} visual mesh geoms dropped, {len(report.fitted)} collision "
        "meshes replaced by fitted primitives, mesh and file texture assets removed. -->\n"
    )
    atomic_write_text(out, note + xml)
    for name in LICENCE_FILES:
        lic = src.parent / name
        if lic.is_file():
            report.licence = out.parent / name
            if lic.resolve() != report.licence.resolve():
                atomic_write_text(report.licence, lic.read_text(encoding="utf-8"))
            break
    return report
