"""How fast a video renders (``habitsim bench render``).

A clip of ``frames`` frames at ``fps`` is drawn and written the way ``habitsim track
--video`` and ``habitsim retarget --video`` write it (:func:`habitsim.render.render_video`
with :class:`habitsim.render.RenderOptions`' defaults): a species' synthetic trot on its
standing model by default, or a robot's trot (:func:`habitsim.retarget.trot`) with
``robot``. Optionally the same frames are timed with MuJoCo's own renderer settings
(shadows, reflections, 4× anti-aliasing, the skybox, the floor as MuJoCo draws it, every
frame, libx264's ``medium``) on the first ``before_frames`` frames, scaled to the clip.

Target of issue 50: a 480-frame clip at the default size renders at ≥ 4× real time.
"""

from __future__ import annotations

import os
import resource
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .targets import TargetCheck, verdict

__all__ = ["RenderBenchOptions", "RenderRow", "RenderBenchResult", "run_render", "render_checks"]


@dataclass(frozen=True)
class RenderBenchOptions:
    """What ``habitsim bench render`` draws.

    Attributes:
        species: the species whose synthetic trot is drawn (without ``robot``).
        robot: a robot MJCF scene whose trot is drawn instead (None: the species).
        frames: the clip's length in frames.
        fps: the clip's frame rate [Hz].
        before_frames: frames timed with MuJoCo's own settings (0: not timed).
        target_x_real_time: the target: video seconds per second of rendering.
    """

    species: str = "dog"
    robot: str | None = None
    frames: int = 480
    fps: float = 50.0
    before_frames: int = 48
    target_x_real_time: float = 4.0


@dataclass(frozen=True)
class RenderRow:
    """One setting's figures (``draw_s`` and ``encode_s`` from drawing all frames and
    encoding them apart; ``total_s`` from :func:`~habitsim.render.render_video`, which
    streams frames into the encoder; ``cpu_s`` the CPU time of that video, habitsim's
    process and the encoder's together, which does not grow with the machine's load as
    ``total_s`` does on a shared machine)."""

    setting: str
    frames_drawn: float
    draw_s: float
    encode_s: float
    total_s: float
    x_real_time: float
    cpu_s: float


@dataclass(frozen=True)
class RenderBenchResult:
    """The figures of one run."""

    options: RenderBenchOptions
    subject: str
    width: int
    height: int
    rows: list[RenderRow] = field(default_factory=list)
    load_average: float = 0.0


def _subject(o: RenderBenchOptions) -> tuple[object, np.ndarray, str, str]:
    """(drawable model, qpos (T, nq), camera, name) of the clip to draw."""
    duration = (o.frames - 1) / o.fps
    if o.robot is not None:
        from habitsim.retarget import drawable, find_robot_feet, load_robot, trot

        model = load_robot(o.robot)
        clip = trot(model, find_robot_feet(model), speed=0.5, duration_s=duration, fps=o.fps)
        vis = drawable(model)
        cams = [vis.camera(i).name for i in range(vis.ncam)]
        return vis, clip.qpos, ("tracking" if "tracking" in cams else "track"), Path(o.robot).name
    from habitsim.gaits import generate
    from habitsim.qpos import motion_to_qpos, species_model

    model = species_model(o.species)
    m = generate(o.species, "trot", seed=0, duration_s=duration, fps=o.fps)
    return model, motion_to_qpos(m, model).qpos, "track", f"{o.species} trot"


def run_render(options: RenderBenchOptions | None = None) -> RenderBenchResult:
    """Draw and write the clip with the default settings (and MuJoCo's own).

    Raises:
        RenderError: no OpenGL context (set ``MUJOCO_GL=egl`` or ``osmesa``).
    """
    from habitsim.render import RenderOptions, render_frames, render_video, save_video

    o = options or RenderBenchOptions()
    model, qpos, camera, name = _subject(o)
    length = len(qpos) / o.fps
    settings = [("defaults", RenderOptions(), len(qpos))]
    if o.before_frames > 0:
        own = RenderOptions(
            shadows=True,
            reflections=True,
            multisamples=4,
            video_fps=None,
            preset="medium",
            floor_box=False,
            skybox=True,
        )
        settings.append(("MuJoCo's own", own, min(o.before_frames, len(qpos))))
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for setting, opts, n in settings:
            q = qpos[:n]
            scale = len(qpos) / n
            step = opts.frame_step(o.fps)
            t0 = time.perf_counter()
            drawn = render_frames(model, q[::step], camera=camera, options=opts)
            t1 = time.perf_counter()
            save_video(drawn, o.fps / step, Path(tmp) / "a.mp4", opts)
            t2, c2 = time.perf_counter(), _cpu()
            render_video(model, q, o.fps, Path(tmp) / "b.mp4", camera=camera, options=opts)
            t3, c3 = time.perf_counter(), _cpu()
            total = (t3 - t2) * scale
            rows.append(
                RenderRow(
                    setting,
                    float(len(drawn) * scale),
                    (t1 - t0) * scale,
                    (t2 - t1) * scale,
                    total,
                    length / total,
                    (c3 - c2) * scale,
                )
            )
    return RenderBenchResult(o, name, 640, 480, rows, os.getloadavg()[0])


def _cpu() -> float:
    """CPU seconds of this process and of its finished children (the encoder) [s]."""
    own, kids = (resource.getrusage(w) for w in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN))
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def render_checks(res: RenderBenchResult) -> list[TargetCheck]:
    """The target: the default settings' video at ≥ ``target_x_real_time`` × real time."""
    row = next((r for r in res.rows if r.setting == "defaults"), None)
    x = None if row is None else row.x_real_time
    t = res.options.target_x_real_time
    return [
        TargetCheck(
            f"a {res.options.frames}-frame video at {res.width}x{res.height}",
            x,
            "-" if x is None else f"{x:.2f}x real time",
            f">= {t:g}x real time",
            verdict(None if x is None else x >= t),
        )
    ]
