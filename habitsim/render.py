"""Headless video of a qpos trajectory (MP4 or GIF) with the model's tracking camera.

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

import importlib
import importlib.util
import os
from pathlib import Path

import mujoco
import numpy as np

from .errors import HabitsimError
from .fileio import atomic_path, atomic_write

__all__ = [
    "RenderError",
    "render_available",
    "render_frames",
    "save_video",
    "render_video",
    "VIDEO_FORMATS",
    "check_video_writer",
]

VIDEO_FORMATS = (".mp4", ".gif")


class RenderError(HabitsimError, RuntimeError):
    """Rendering or video writing is impossible here (no OpenGL, no video writer), or a
    bad request (unknown camera, unsupported file type)."""


_BACKEND_CHECKED = False


def _headless_context() -> None:
    """Make mujoco.Renderer use EGL/OSMesa when MUJOCO_GL is unset and there is no display."""
    global _BACKEND_CHECKED
    if _BACKEND_CHECKED:
        return
    _BACKEND_CHECKED = True
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
) -> np.ndarray:
    """(T, height, width, 3) uint8 images of a qpos trajectory.

    Args:
        model: the model (the frame buffer must fit: MJCF ``<visual><global offwidth>``
            bounds the size; the species scenes keep MuJoCo's default 640×480).
        qpos: (T, nq) positions.
        width, height: image size [px].
        camera: camera name or id (default the species models' tracking camera ``track``;
            falls back to the free camera when the model has no camera of that name).

    Raises:
        RenderError: no OpenGL backend, or a bad size/camera.
    """
    q = np.atleast_2d(np.asarray(qpos, dtype=np.float64))
    if q.shape[1] != model.nq:
        raise RenderError(f"qpos must have shape (T, {model.nq}), got {q.shape}")
    cam: str | int = camera
    if isinstance(camera, str) and mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, camera) < 0:
        cam = -1
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
    out = np.empty((len(q), height, width, 3), dtype=np.uint8)
    with renderer:
        for k, row in enumerate(q):
            data.qpos[:] = row
            mujoco.mj_forward(model, data)
            renderer.update_scene(data, camera=cam)
            out[k] = renderer.render()
    return out


def _has(module: str) -> bool:
    return importlib.util.find_spec(module) is not None


def save_video(frames: np.ndarray, fps: float, path: str | Path) -> Path:
    """Write (T, H, W, 3) uint8 frames as ``.mp4`` or ``.gif`` (atomically).

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
        import imageio.v2 as iio

        # the ffmpeg writer needs a file name: a temporary file, renamed when complete
        with atomic_path(path, suffix=".mp4") as tmp:
            with iio.get_writer(tmp, format="FFMPEG", mode="I", fps=float(fps),
                                codec="libx264", macro_block_size=8) as w:
                for f in frames:
                    w.append_data(f)
        return path
    duration_ms = max(int(round(1000.0 / float(fps))), 20)
    if _has("PIL"):
        from PIL import Image

        images = [Image.fromarray(f) for f in frames]
        with atomic_write(path, "wb") as fh:
            images[0].save(fh, format="GIF", save_all=True, append_images=images[1:],
                           duration=duration_ms, loop=0)
        return path
    import imageio.v2 as iio

    with atomic_write(path, "wb") as fh:
        iio.mimsave(fh, list(frames), format="GIF", duration=duration_ms / 1000.0)
    return path


def render_video(
    model: mujoco.MjModel,
    qpos: np.ndarray,
    fps: float,
    path: str | Path,
    *,
    width: int = 640,
    height: int = 480,
    camera: str | int = "track",
) -> Path:
    """Render a qpos trajectory and write it as MP4/GIF (see :func:`save_video`).

    The writer is checked BEFORE rendering, so a missing package fails fast.
    """
    path = Path(path)
    check_video_writer(path)
    frames = render_frames(model, qpos, width=width, height=height, camera=camera)
    return save_video(frames, fps, path)


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
