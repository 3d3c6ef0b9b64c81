"""How fast a robot video renders: a 480-frame clip at 640×480, the way ``habitsim retarget
--video`` draws it, with :class:`habitsim.render.RenderOptions`' defaults and with MuJoCo's
own settings (shadows, reflections, 4× anti-aliasing, every frame, libx264's ``medium``)::

    MUJOCO_GL=egl python -m habitsim.examples.render_speed          # the Go1 trotting
    MUJOCO_GL=egl python -m habitsim.examples.render_speed --robot R.xml --before-frames 0

Prints, per setting, the seconds spent drawing the frames (scene update, ``mjr_render``
and ``readPixels``), encoding them, and the whole video, and the video's speed as a
multiple of real time. MuJoCo's settings are timed on the first ``--before-frames``
frames and scaled to the clip (they take about half a second a frame with a software
OpenGL).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

#: The vendored Go1 in a source checkout (tests/ is not installed with the package).
GO1_SCENE = Path(__file__).resolve().parents[2] / "tests" / "robots" / "unitree_go1" / "scene.xml"


def measure(
    robot: str | Path = GO1_SCENE,
    *,
    frames: int = 480,
    fps: float = 50.0,
    before_frames: int = 48,
) -> list[dict[str, float | str]]:
    """Seconds to draw and encode a trot of ``frames`` frames at ``fps`` [Hz] (a
    :func:`habitsim.retarget.trot` reference: the same poses a tracked clip shows), one
    row per setting: ``draw_s``, ``encode_s``, ``total_s`` (the video written by
    :func:`habitsim.render.render_video`), ``x_real_time`` (clip length over total)."""
    from habitsim.render import RenderOptions, render_frames, render_video, save_video
    from habitsim.retarget import drawable, find_robot_feet, load_robot, trot

    model = load_robot(robot)
    clip = trot(model, find_robot_feet(model), speed=0.5, duration_s=(frames - 1) / fps, fps=fps)
    vis = drawable(model)
    cam = "tracking" if "tracking" in [vis.camera(i).name for i in range(vis.ncam)] else "track"
    length = len(clip.qpos) / fps
    settings = [("defaults", RenderOptions(), len(clip.qpos))]
    if before_frames > 0:
        mujoco_own = RenderOptions(
            shadows=True, reflections=True, multisamples=4, video_fps=None, preset="medium"
        )
        settings.append(("MuJoCo's own", mujoco_own, min(before_frames, len(clip.qpos))))
    rows: list[dict[str, float | str]] = []
    with tempfile.TemporaryDirectory() as tmp:
        for name, opts, n in settings:
            q = clip.qpos[:n]
            scale = len(clip.qpos) / n
            step = opts.frame_step(fps)
            t0 = time.perf_counter()
            drawn = render_frames(vis, q[::step], camera=cam, options=opts)
            t1 = time.perf_counter()
            save_video(drawn, fps / step, Path(tmp) / "a.mp4", opts)
            t2 = time.perf_counter()
            render_video(vis, q, fps, Path(tmp) / "b.mp4", camera=cam, options=opts)
            t3 = time.perf_counter()
            total = (t3 - t2) * scale
            rows.append(
                {
                    "setting": name,
                    "frames_drawn": float(len(drawn) * scale),
                    "draw_s": (t1 - t0) * scale,
                    "encode_s": (t2 - t1) * scale,
                    "total_s": total,
                    "x_real_time": length / total,
                }
            )
    return rows


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--robot", default=str(GO1_SCENE), help="robot scene (default the Go1)")
    p.add_argument("--frames", type=int, default=480, help="clip length in frames (480)")
    p.add_argument("--fps", type=float, default=50.0, help="clip frame rate [Hz] (50)")
    p.add_argument(
        "--before-frames",
        type=int,
        default=48,
        help="frames MuJoCo's own settings are timed on (0: not timed)",
    )
    ns = p.parse_args(argv)
    rows = measure(ns.robot, frames=ns.frames, fps=ns.fps, before_frames=ns.before_frames)
    print(f"{ns.frames} frames at {ns.fps:g} Hz ({ns.frames / ns.fps:.1f} s), 640x480:")
    for r in rows:
        print(
            f"  {r['setting']:13s} {r['frames_drawn']:4.0f} frames drawn: draw "
            f"{r['draw_s']:6.1f} s, encode {r['encode_s']:5.1f} s; video {r['total_s']:6.1f} s "
            f"= {r['x_real_time']:.2f}x real time"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
