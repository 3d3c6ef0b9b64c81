"""Headless video of a qpos trajectory (MP4 or GIF) with the model's tracking camera.

Given the reference it tracked (``reference=``), the video shows it as a translucent ghost
beside the simulated body (one body length behind it along the clip's heading, so the two
never share a surface; a camera that follows the pair from their side frames both), with the
feet that are in stance marked by discs on the floor (the simulation's contacts under the
body, the reference's labels under the ghost), the body in its species' colour
(:data:`SPECIES_COLOURS`) and the floor drawn a few millimetres low so soft-contact
penetration of the feet does not flicker. All of it changes the rendering scene only
(:class:`mujoco.MjvScene` geoms after ``update_scene``), never the model that was simulated.

Rendering uses :class:`mujoco.Renderer` off-screen. MuJoCo picks its OpenGL backend from
``MUJOCO_GL`` when it is first imported; when that variable is unset and there is no
display, :func:`render_frames` switches the renderer to EGL (GPU or Mesa) and then OSMesa
(software) — whichever loads — so it works on a headless server without any setup.

Writers, tried in this order (none is a hard dependency of habitsim):

* ``.mp4``: ``imageio`` with the ``imageio-ffmpeg`` plugin;
* ``.gif``: ``Pillow``, else ``imageio``.

A missing writer raises :class:`RenderError` naming the package to install; a missing
OpenGL backend raises it too (``render_available()`` tells beforehand).
"""

from __future__ import annotations

import copy
import importlib
import importlib.util
import os
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO, cast

import mujoco
import numpy as np

from .errors import HabitsimError, OutputWriteError, brief_path
from .fileio import atomic_path, atomic_write

__all__ = [
    "RenderError",
    "render_available",
    "render_frames",
    "save_video",
    "render_video",
    "VIDEO_FORMATS",
    "check_video_writer",
    "SPECIES_COLOURS",
    "GhostStyle",
    "render_tracking",
    "RenderOptions",
    "iter_frames",
]

VIDEO_FORMATS = (".mp4", ".gif")


class RenderError(HabitsimError, RuntimeError):
    """Rendering or video writing is impossible here (no OpenGL, no video writer), or a
    bad request (unknown camera, unsupported file type)."""


#: Body colour (RGB in [0, 1]) per catalog species in videos with a reference ghost.
SPECIES_COLOURS: dict[str, tuple[float, float, float]] = {
    "bear": (0.45, 0.30, 0.20),
    "camel": (0.85, 0.70, 0.45),
    "cat": (0.95, 0.55, 0.20),
    "cow": (0.30, 0.30, 0.30),
    "deer": (0.70, 0.45, 0.25),
    "dog": (0.80, 0.65, 0.40),
    "elephant": (0.55, 0.55, 0.60),
    "fox": (0.90, 0.40, 0.10),
    "giraffe": (0.95, 0.80, 0.35),
    "goat": (0.85, 0.85, 0.80),
    "horse": (0.50, 0.25, 0.12),
    "moose": (0.35, 0.22, 0.15),
    "pig": (0.95, 0.70, 0.70),
    "rabbit": (0.75, 0.72, 0.68),
    "tiger": (0.95, 0.50, 0.05),
    "wolf": (0.55, 0.55, 0.55),
    "zebra": (0.90, 0.90, 0.90),
}
#: Colour of the body of a model that is not a catalog species.
DEFAULT_COLOUR = (0.72, 0.58, 0.42)
#: Foot geoms of the species models (LF, RF, LH, RH), where stance is marked.
SPECIES_FEET = ("lf_foot", "rf_foot", "lh_foot", "rh_foot")


@dataclass(frozen=True)
class GhostStyle:
    """How the reference ghost, the stance markers and the floor are drawn.

    Attributes:
        offset: distance of the ghost behind the body [m] along the clip's heading (the
            reference's root displacement, or its first frame's facing for a clip that
            stays in place); None: the model's extent (``model.stat.extent``), more than
            a body length.
        alpha: opacity of the ghost.
        ghost_rgb: ghost colour.
        stance_rgba: colour of the stance discs under the simulated body; the ghost's
            discs use the same colour at the ghost's opacity.
        floor_drop: how far the floor is drawn below z = 0 [m]; None: 0.5 % of the
            model's extent, at least 2 mm.
    """

    offset: float | None = None
    alpha: float = 0.35
    ghost_rgb: tuple[float, float, float] = (0.55, 0.75, 1.0)
    stance_rgba: tuple[float, float, float, float] = (0.9, 0.1, 0.1, 1.0)
    floor_drop: float | None = None


@dataclass(frozen=True)
class RenderOptions:
    """How fast and how finely videos are drawn and encoded.

    The defaults draw a frame in a few milliseconds with a software OpenGL (Mesa's
    llvmpipe behind EGL or OSMesa, a headless server's): MuJoCo's shadow map
    (4096² by default) and floor reflection each cost more than the rest of the frame.

    Attributes:
        shadows: draw the lights' shadows (MuJoCo's ``mjRND_SHADOW``); without them no
            shadow map is made (Menagerie's scenes ask for 8192², 0.3 s to set up).
        reflections: draw reflections on reflective floors (``mjRND_REFLECTION``).
        multisamples: multisample anti-aliasing samples of the off-screen buffer
            (``visual/quality/offsamples``; MuJoCo's default is 4).
        video_fps: a video keeps every n-th frame, n the smallest whole number that
            brings the clip's rate to at most this [Hz]; None keeps every frame.
        preset: libx264's speed preset for MP4 (``ultrafast`` … ``veryslow``).
        floor_box: draw a floor plane of the world as a thin box under the same material
            (its top face where the plane is; an infinite plane as a box reaching the far
            clipping distance around the first body, moved by whole texture periods so
            the pattern stays put). MuJoCo draws a plane as a fine grid of quads, which
            costs a software OpenGL more than the rest of the frame. Not with
            ``reflections`` (MuJoCo reflects planes only), nor for a plane whose texture
            is stretched over it (``texuniform`` off).
        skybox: draw the model's skybox (``mjRND_SKYBOX``); off, the background is black
            and a frame takes about a fifth less time with a software OpenGL.
    """

    shadows: bool = False
    reflections: bool = False
    multisamples: int = 0
    video_fps: float | None = 30.0
    preset: str = "ultrafast"
    floor_box: bool = True
    skybox: bool = False

    def __post_init__(self) -> None:
        if int(self.multisamples) < 0:
            raise RenderError(f"multisamples must be >= 0, got {self.multisamples!r}")
        if self.video_fps is not None and not (np.isfinite(self.video_fps) and self.video_fps > 0):
            raise RenderError(f"video_fps must be > 0 or None, got {self.video_fps!r}")
        if self.preset not in X264_PRESETS:
            raise RenderError(
                f"preset must be one of {', '.join(X264_PRESETS)}, got {self.preset!r}"
            )

    def frame_step(self, fps: float) -> int:
        """Keep every n-th frame of a clip at ``fps`` [Hz] (see ``video_fps``)."""
        if self.video_fps is None or fps <= self.video_fps:
            return 1
        return int(np.ceil(fps / self.video_fps - 1e-9))


#: libx264's presets, fastest first.
X264_PRESETS = (
    "ultrafast",
    "superfast",
    "veryfast",
    "faster",
    "fast",
    "medium",
    "slow",
    "slower",
    "veryslow",
)

_backend_checked = False


def _headless_context() -> None:
    """Make mujoco.Renderer use EGL/OSMesa when MUJOCO_GL is unset and there is no display."""
    global _backend_checked
    if _backend_checked:
        return
    _backend_checked = True
    if os.environ.get("MUJOCO_GL") or os.environ.get("DISPLAY"):
        return
    from mujoco.rendering.classic import gl_context

    for mod in ("mujoco.egl", "mujoco.osmesa"):
        try:
            cls = importlib.import_module(mod).GLContext
            ctx = cls(16, 16)  # does the backend really load here?
            ctx.free()
        except Exception:  # noqa: BLE001 - any failure means "try the next backend"
            continue
        gl_context.GLContext = cls
        return


def _skybox_textures(model: mujoco.MjModel) -> list[int]:
    """Indices of the model's skybox textures larger than one texel per face."""
    return [
        i
        for i in range(model.ntex)
        if model.tex_type[i] == mujoco.mjtTexture.mjTEXTURE_SKYBOX
        and int(model.tex_width[i]) * int(model.tex_height[i]) > 6
    ]


def render_available() -> bool:
    """True if an off-screen OpenGL context can be created here."""
    try:
        model = mujoco.MjModel.from_xml_string("<mujoco><worldbody/></mujoco>")
        _headless_context()
        with mujoco.Renderer(model, 8, 8):
            pass
    except Exception:  # noqa: BLE001
        return False
    return True


def render_frames(
    model: mujoco.MjModel,
    qpos: np.ndarray,
    *,
    width: int = 640,
    height: int = 480,
    camera: str | int = "track",
    reference: np.ndarray | None = None,
    contacts: np.ndarray | None = None,
    reference_contacts: np.ndarray | None = None,
    feet: Sequence[str] | None = None,
    species: str | None = None,
    style: GhostStyle | None = None,
    options: RenderOptions | None = None,
) -> np.ndarray:
    """(T, height, width, 3) uint8 images of a qpos trajectory (every frame; arguments
    as :func:`iter_frames`)."""
    q = np.atleast_2d(np.asarray(qpos, dtype=np.float64))
    out = np.empty((len(q), height, width, 3), dtype=np.uint8)
    frames = iter_frames(
        model,
        q,
        width=width,
        height=height,
        camera=camera,
        reference=reference,
        contacts=contacts,
        reference_contacts=reference_contacts,
        feet=feet,
        species=species,
        style=style,
        options=options,
    )
    for k, frame in enumerate(frames):
        out[k] = frame
    return out


def iter_frames(
    model: mujoco.MjModel,
    qpos: np.ndarray,
    *,
    width: int = 640,
    height: int = 480,
    camera: str | int = "track",
    reference: np.ndarray | None = None,
    contacts: np.ndarray | None = None,
    reference_contacts: np.ndarray | None = None,
    feet: Sequence[str] | None = None,
    species: str | None = None,
    style: GhostStyle | None = None,
    options: RenderOptions | None = None,
) -> Iterator[np.ndarray]:
    """The (height, width, 3) uint8 images of a qpos trajectory, one per row of ``qpos``,
    drawn by one renderer into one buffer (the same array each time: copy a frame to keep
    it).

    Args:
        model: the model (the frame buffer must fit: MJCF ``<visual><global offwidth>``
            bounds the size; the species scenes keep MuJoCo's default 640×480).
        qpos: (T, nq) positions.
        width, height: image size [px].
        camera: camera name or id (default the species models' tracking camera ``track``;
            a model without a camera of that name is followed by a tracking camera on its
            first body, looking from the side). With a reference and the default, the pair
            camera: it looks across the heading from 15° above at the midpoint of the
            body's and the ghost's first bodies, from far enough to hold both.
        reference: (≥ T, nq) reference positions, drawn as a translucent ghost beside the
            body (:class:`GhostStyle`); frame k of the video shows reference frame k.
        contacts: (T, F) bool feet in stance in the simulation, marked under the body.
        reference_contacts: (≥ T, F) bool stance labels of the reference, marked under
            the ghost.
        feet: the F feet where stance is marked (geom, site or body names, in the
            contacts' order); default the species models' foot geoms (LF, RF, LH, RH).
        species: colour the body with :data:`SPECIES_COLOURS` (any other name gets
            :data:`DEFAULT_COLOUR`); None keeps the model's colours. Also the floor is
            drawn low (:attr:`GhostStyle.floor_drop`) whenever a reference, contacts or a
            species is given.
        style: the ghost's look (default :class:`GhostStyle`).
        options: shadows, reflections, anti-aliasing (default :class:`RenderOptions`;
            its ``video_fps`` applies to videos, :func:`render_video`).

    Raises:
        RenderError: no OpenGL backend, a bad size/camera, arrays of the wrong shape, a
            foot name the model does not have.
    """
    opts = options or RenderOptions()
    q = np.atleast_2d(np.asarray(qpos, dtype=np.float64))
    if q.shape[1] != model.nq:
        raise RenderError(f"qpos must have shape (T, {model.nq}), got {q.shape}")
    ref = None if reference is None else np.atleast_2d(np.asarray(reference, np.float64))
    if ref is not None and (ref.shape[1] != model.nq or len(ref) < len(q)):
        raise RenderError(f"reference must have shape (>= {len(q)}, {model.nq}), got {ref.shape}")
    marks = [
        _stance(c, len(q), name)
        for c, name in ((contacts, "contacts"), (reference_contacts, "reference_contacts"))
    ]
    decorate = ref is not None or species is not None or any(m is not None for m in marks)
    style = style or GhostStyle()
    foot_points = _feet(model, feet, marks) if any(m is not None for m in marks) else None
    cam: str | int | mujoco.MjvCamera = camera
    pair_camera = ref is not None and camera == "track" and model.nbody > 1
    if pair_camera and ref is not None:  # (pair_camera implies a reference)
        free = _tracking_camera(model)
        assert not isinstance(free, int)  # the model has a body to track
        free.type = mujoco.mjtCamera.mjCAMERA_FREE
        h = _heading(model, ref[: len(q)])
        free.azimuth = float(np.degrees(np.arctan2(h[1], h[0]))) + 90.0
        cam = free
    elif (
        isinstance(camera, str) and mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, camera) < 0
    ):
        cam = _tracking_camera(model)
    # the caller's model keeps its own settings; without shadows, no shadow map is made,
    # and without the skybox its texture is not uploaded (1×6 texels of it are)
    shadow_map = int(model.vis.quality.shadowsize) if opts.shadows else 1
    skies = [] if opts.skybox else _skybox_textures(model)
    if (
        int(model.vis.quality.offsamples) != int(opts.multisamples)
        or int(model.vis.quality.shadowsize) != shadow_map
        or skies
    ):
        model = copy.copy(model)
        model.vis.quality.offsamples = int(opts.multisamples)
        model.vis.quality.shadowsize = shadow_map
        for i in skies:
            model.tex_width[i], model.tex_height[i] = 1, 6
    _headless_context()
    try:
        renderer = mujoco.Renderer(model, height, width)
    except ValueError as e:  # frame buffer too small
        raise RenderError(str(e)) from e
    except Exception as e:  # noqa: BLE001 - GL backends raise many types
        raise RenderError(
            f"no OpenGL context for off-screen rendering ({e}); set MUJOCO_GL=egl or "
            "MUJOCO_GL=osmesa and install the matching system library"
        ) from e
    data = mujoco.MjData(model)
    dref = mujoco.MjData(model)
    opt, pert = mujoco.MjvOption(), mujoco.MjvPerturb()
    extent = float(model.stat.extent)
    offset = extent if style.offset is None else float(style.offset)
    shift = np.zeros(3)
    if ref is not None:
        shift = -offset * _heading(model, ref[: len(q)])
    drop = max(0.002, 0.005 * extent) if style.floor_drop is None else float(style.floor_drop)
    colour = None
    if species is not None:
        colour = SPECIES_COLOURS.get(species, DEFAULT_COLOUR)
    floors = {
        i
        for i in range(model.ngeom)
        if model.geom_bodyid[i] == 0 and model.geom_type[i] == mujoco.mjtGeom.mjGEOM_PLANE
    }
    boxes = _floor_boxes(model, floors) if opts.floor_box and not opts.reflections else {}
    buf = np.empty((height, width, 3), dtype=np.uint8)
    with renderer:
        scn = renderer.scene
        scn.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = bool(opts.shadows)
        scn.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = bool(opts.reflections)
        scn.flags[mujoco.mjtRndFlag.mjRND_SKYBOX] = bool(opts.skybox)
        for k, row in enumerate(q):
            data.qpos[:] = row
            mujoco.mj_forward(model, data)
            if ref is not None:
                dref.qpos[:] = ref[k]
                mujoco.mj_kinematics(model, dref)
            if pair_camera:
                assert isinstance(cam, mujoco.MjvCamera)
                mid = 0.5 * (data.xpos[1] + dref.xpos[1] + shift)
                cam.lookat[:] = (mid[0], mid[1], model.stat.center[2])
                cam.distance = 1.3 * extent + offset
            renderer.update_scene(data, camera=cam, scene_option=opt)
            if decorate:
                _restyle(model, scn, floors, drop, colour)
            if boxes:
                _box_floors(scn, boxes, data.xpos[min(1, model.nbody - 1)])
            if ref is not None:
                n0 = scn.ngeom
                mujoco.mjv_addGeoms(model, dref, opt, pert, mujoco.mjtCatBit.mjCAT_DYNAMIC, scn)
                for g in range(n0, scn.ngeom):
                    geom = scn.geoms[g]
                    geom.rgba[:] = (*style.ghost_rgb, style.alpha)
                    geom.pos[:] += shift
            if foot_points is not None:
                # the body's own contacts under it; the reference's labels under the
                # ghost (dref holds reference frame k, placed by mj_kinematics above)
                for m, d, dx, a in (
                    (marks[0], data, np.zeros(3), 1.0),
                    (marks[1], dref, shift, style.alpha),
                ):
                    if m is None or (d is dref and ref is None):
                        continue
                    for f in np.flatnonzero(m[k]):
                        _disc(
                            scn,
                            foot_points[f](d),
                            dx,
                            foot_points.radius,
                            (*style.stance_rgba[:3], style.stance_rgba[3] * a),
                        )
            yield renderer.render(out=buf)


def _stance(c: np.ndarray | None, n: int, name: str) -> np.ndarray | None:
    if c is None:
        return None
    a = np.asarray(c, dtype=bool)
    if a.ndim != 2 or len(a) < n:
        raise RenderError(f"{name} must have shape (>= {n}, F), got {a.shape}")
    return a


class _FootPoints(list):
    """Per foot, a function MjData → world position; ``radius`` of the stance disc."""

    radius: float = 0.01


def _feet(
    model: mujoco.MjModel, feet: Sequence[str] | None, marks: list[np.ndarray | None]
) -> _FootPoints:
    names = list(feet) if feet is not None else list(SPECIES_FEET)
    width = max(m.shape[1] for m in marks if m is not None)
    if len(names) != width:
        raise RenderError(f"{width} stance columns but {len(names)} feet ({', '.join(names)})")
    out = _FootPoints()
    sizes = []
    for name in names:
        gid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, name)
        sid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, name)
        bid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)
        if gid >= 0:
            out.append(lambda d, i=gid: d.geom_xpos[i])
            sizes.append(float(model.geom_size[gid][0]))
        elif sid >= 0:
            out.append(lambda d, i=sid: d.site_xpos[i])
            sizes.append(float(model.site_size[sid][0]))
        elif bid >= 0:
            out.append(lambda d, i=bid: d.xpos[i])
        else:
            raise RenderError(
                f"no foot geom, site or body {name!r} in the model to mark stance on"
                + (
                    ""
                    if feet is not None
                    else "; give feet=[...] for a model that is not a habitsim species"
                )
            )
    out.radius = 3.0 * max(sizes) if sizes else 0.02 * float(model.stat.extent)
    return out


def _disc(
    scn: mujoco.MjvScene,
    at: np.ndarray,
    dx: np.ndarray,
    radius: float,
    rgba: tuple[float, float, float, float],
) -> None:
    """A flat disc on the floor under a foot (1 mm thick, its top 1 mm above z = 0),
    moved by ``dx``."""
    if scn.ngeom >= scn.maxgeom:
        return
    pos = np.array([at[0] + dx[0], at[1] + dx[1], 0.0005])
    mujoco.mjv_initGeom(
        scn.geoms[scn.ngeom],
        mujoco.mjtGeom.mjGEOM_CYLINDER,
        np.array([radius, 0.0005, 0.0]),
        pos,
        np.eye(3).ravel(),
        np.asarray(rgba, dtype=np.float32),
    )
    scn.ngeom += 1


def _restyle(
    model: mujoco.MjModel,
    scn: mujoco.MjvScene,
    floors: set[int],
    drop: float,
    colour: tuple[float, float, float] | None,
) -> None:
    """Floor drawn ``drop`` low; the body's visible geoms in ``colour``."""
    for g in range(scn.ngeom):
        geom = scn.geoms[g]
        if geom.objtype != mujoco.mjtObj.mjOBJ_GEOM:
            continue
        if geom.objid in floors:
            geom.pos[2] -= drop
        elif colour is not None and model.geom_bodyid[geom.objid] != 0:
            geom.rgba[:3] = colour


def _floor_boxes(model: mujoco.MjModel, floors: set[int]) -> dict[int, np.ndarray | None]:
    """Per floor plane drawn as a box (:attr:`RenderOptions.floor_box`): its half size in
    x and y and the texture period its centre moves by [m] (None: a finite plane, which
    stays where it is)."""
    out: dict[int, np.ndarray | None] = {}
    far = float(model.vis.map.zfar * model.stat.extent)
    for g in sorted(floors):
        mat = int(model.geom_matid[g])
        tex = mat >= 0 and int(model.mat_texid[mat][mujoco.mjtTextureRole.mjTEXROLE_RGB]) >= 0
        if tex and not model.mat_texuniform[mat]:
            continue  # a texture stretched over the plane would stretch over the box
        size = model.geom_size[g]
        if size[0] > 0 and size[1] > 0:
            out[g] = None
            continue
        # a uniform texture repeats every 2 / texrepeat metres on a box's face
        period = 2.0 / np.maximum(model.mat_texrepeat[mat], 1e-9) if tex else np.zeros(2)
        out[g] = np.array([far, far, period[0], period[1]])
    return out


def _box_floors(
    scn: mujoco.MjvScene, boxes: dict[int, np.ndarray | None], centre: np.ndarray
) -> None:
    """The floor planes of ``boxes`` in the scene, as thin boxes (see
    :attr:`RenderOptions.floor_box`), those of infinite planes around ``centre``."""
    for i in range(scn.ngeom):
        geom = scn.geoms[i]
        if geom.objtype != mujoco.mjtObj.mjOBJ_GEOM or geom.objid not in boxes:
            continue
        spec = boxes[geom.objid]
        half = geom.size[:2].copy() if spec is None else spec[:2]
        thick = 1e-3 * float(max(half))
        normal = geom.mat.reshape(3, 3)[:, 2].copy()
        if spec is not None and normal[2] > 1.0 - 1e-6:  # level: follow the body
            for k in range(2):
                step = spec[2 + k]
                geom.pos[k] = np.round(centre[k] / step) * step if step > 0 else centre[k]
        geom.type = mujoco.mjtGeom.mjGEOM_BOX
        geom.size[:] = (half[0], half[1], thick)
        geom.pos[:] -= thick * normal


def _heading(model: mujoco.MjModel, ref: np.ndarray) -> np.ndarray:
    """Unit horizontal heading of a reference: its first body's displacement over the clip,
    or (moving less than a tenth of the model's extent) that body's facing at the start."""
    d = mujoco.MjData(model)
    ends = []
    for row in (ref[0], ref[-1]):
        d.qpos[:] = row
        mujoco.mj_kinematics(model, d)
        ends.append((d.xpos[1].copy(), d.xmat[1].reshape(3, 3)[:, 0].copy()))
    h = ends[1][0] - ends[0][0]
    h[2] = 0.0
    if np.linalg.norm(h) < 0.1 * float(model.stat.extent):
        h = ends[0][1]
        h[2] = 0.0
    n = float(np.linalg.norm(h))
    return np.array([1.0, 0.0, 0.0]) if n < 1e-9 else h / n


def _tracking_camera(model: mujoco.MjModel) -> mujoco.MjvCamera | int:
    """A camera that follows the model's first body from its side (−y), or the free one."""
    if model.nbody < 2:
        return -1
    cam = mujoco.MjvCamera()
    cam.type = mujoco.mjtCamera.mjCAMERA_TRACKING
    cam.trackbodyid = 1
    cam.distance = 1.6 * float(model.stat.extent)
    cam.azimuth = 90.0
    cam.elevation = -15.0
    return cam


def _has(module: str) -> bool:
    return importlib.util.find_spec(module) is not None


def save_video(
    frames: np.ndarray, fps: float, path: str | Path, options: RenderOptions | None = None
) -> Path:
    """Write (T, H, W, 3) uint8 frames as ``.mp4`` or ``.gif`` (atomically), every frame
    at ``fps`` [Hz] (``options.preset``: libx264's speed preset).

    Raises:
        RenderError: unsupported suffix, or no installed writer (the message names the
            package to install: ``imageio`` + ``imageio-ffmpeg`` for MP4, ``Pillow`` for GIF).
    """
    path = Path(path)
    check_video_writer(path)
    suffix = path.suffix.lower()
    frames = np.asarray(frames, dtype=np.uint8)
    if frames.ndim != 4 or frames.shape[-1] != 3 or len(frames) == 0:
        raise RenderError(f"frames must have shape (T, H, W, 3) with T > 0, got {frames.shape}")
    if suffix == ".mp4":
        return write_mp4(frames, fps, path, options or RenderOptions())
    duration_ms = max(int(round(1000.0 / float(fps))), 20)
    if _has("PIL"):
        from PIL import Image

        images = [Image.fromarray(f) for f in frames]
        with atomic_write(path, "wb") as fh:
            images[0].save(
                fh,
                format="GIF",
                save_all=True,
                append_images=images[1:],
                duration=duration_ms,
                loop=0,
            )
        return path
    import imageio.v2 as iio

    with atomic_write(path, "wb") as fh:
        iio.mimsave(cast(BinaryIO, fh), list(frames), format="GIF", duration=duration_ms / 1000.0)
    return path


def write_mp4(frames: Iterable[np.ndarray], fps: float, path: Path, opts: RenderOptions) -> Path:
    """Stream frames into ffmpeg (libx264 at ``opts.preset``; it encodes in its own
    process while the next frames are drawn), into a temporary file renamed only once
    the encoder has finished it.

    imageio-ffmpeg does not report how ffmpeg ended, so the finished file is read back
    (:func:`imageio_ffmpeg.count_frames_and_secs`: its packets, not decoded): a file
    that does not hold every frame sent, or cannot be read (ffmpeg stopped on a full
    disk before writing the index), is an :class:`~habitsim.errors.OutputWriteError`.

    Raises:
        OutputWriteError: ffmpeg stopped taking frames, or left an incomplete file; the
            temporary file is removed and nothing appears under ``path``.
    """
    import imageio.v2 as iio
    import imageio_ffmpeg

    sent = 0
    with atomic_path(path, suffix=".mp4") as tmp:
        writer = iio.get_writer(
            tmp,
            format="FFMPEG",
            mode="I",
            fps=float(fps),
            codec="libx264",
            macro_block_size=8,
            ffmpeg_params=["-preset", opts.preset],
        )
        with writer as w:
            for f in frames:
                try:
                    w.append_data(f)  # type: ignore[attr-defined]  # imageio's stub: base class
                except OSError:  # imageio-ffmpeg: the pipe into ffmpeg broke
                    raise _encoder_failed(path, f"it stopped after {sent} frames") from None
                sent += 1
        try:
            got = imageio_ffmpeg.count_frames_and_secs(tmp)[0]
        except (RuntimeError, OSError):
            raise _encoder_failed(path, "the file it wrote cannot be read") from None
        if got != sent:
            raise _encoder_failed(path, f"the file it wrote holds {got} of {sent} frames")
    return path


def _encoder_failed(path: Path, what: str) -> OutputWriteError:
    return OutputWriteError(
        f"video {brief_path(path)}: the video encoder (ffmpeg) did not finish: {what}; "
        "nothing was left under that name; check the disk has free space and the folder "
        "is writable (ffmpeg's own message is printed above), or write elsewhere"
    )


def render_video(
    model: mujoco.MjModel,
    qpos: np.ndarray,
    fps: float,
    path: str | Path,
    *,
    width: int = 640,
    height: int = 480,
    camera: str | int = "track",
    reference: np.ndarray | None = None,
    contacts: np.ndarray | None = None,
    reference_contacts: np.ndarray | None = None,
    feet: Sequence[str] | None = None,
    species: str | None = None,
    style: GhostStyle | None = None,
    options: RenderOptions | None = None,
) -> Path:
    """Render a qpos trajectory at ``fps`` [Hz] and write it as MP4/GIF (see
    :func:`save_video`; the reference ghost, stance marks and species colour as in
    :func:`iter_frames`).

    The video keeps every n-th frame when ``fps`` is above ``options.video_fps`` (its
    rate ``fps / n``, its length the clip's); an MP4's frames stream into the encoder as
    they are drawn. The writer is checked BEFORE rendering, so a missing package fails
    fast.
    """
    opts = options or RenderOptions()
    path = Path(path)
    check_video_writer(path)
    step = opts.frame_step(float(fps))
    q = np.atleast_2d(np.asarray(qpos, dtype=np.float64))
    if len(q) == 0:
        raise RenderError("qpos holds no frame; a video needs at least one")

    def every(a: np.ndarray | None) -> np.ndarray | None:
        return None if a is None else np.asarray(a)[::step]

    kw: dict[str, Any] = {
        "width": width,
        "height": height,
        "camera": camera,
        "reference": every(reference),
        "contacts": every(contacts),
        "reference_contacts": every(reference_contacts),
        "feet": feet,
        "species": species,
        "style": style,
        "options": opts,
    }
    if path.suffix.lower() == ".mp4":
        return write_mp4(iter_frames(model, q[::step], **kw), fps / step, path, opts)
    return save_video(render_frames(model, q[::step], **kw), fps / step, path, opts)


def check_video_writer(path: Path) -> None:
    suffix = path.suffix.lower()
    if suffix not in VIDEO_FORMATS:
        raise RenderError(f"unsupported video type {suffix!r}; valid: {', '.join(VIDEO_FORMATS)}")
    if suffix == ".mp4" and not (_has("imageio") and _has("imageio_ffmpeg")):
        raise RenderError(
            "writing MP4 needs the packages 'imageio' and 'imageio-ffmpeg' "
            "(pip install imageio imageio-ffmpeg); or ask for a .gif"
        )
    if suffix == ".gif" and not (_has("PIL") or _has("imageio")):
        raise RenderError(
            "writing GIF needs the package 'Pillow' (pip install pillow) or 'imageio'"
        )


def render_tracking(
    result,
    path: str | Path,
    *,
    width: int = 640,
    height: int = 480,
    camera: str | int = "track",
    feet: Sequence[str] | None = None,
    style: GhostStyle | None = None,
    options: RenderOptions | None = None,
) -> Path:
    """The video of a tracking run (:class:`habitsim.sim.TrackResult`): the simulated body
    in its species' colour, the reference it tracked as a ghost beside it, stance marked
    under both (the simulation's foot contacts, the reference's labels).

    Raises:
        RenderError: as :func:`render_video`.
    """
    return render_video(
        result.model,
        result.qpos,
        result.fps,
        path,
        width=width,
        height=height,
        camera=camera,
        reference=result.reference_qpos,
        contacts=result.contacts,
        reference_contacts=result.reference_contacts,
        feet=feet,
        species=result.species,
        style=style,
        options=options,
    )
