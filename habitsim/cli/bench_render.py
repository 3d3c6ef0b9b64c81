"""``habitsim bench render``: how fast a video renders (the benchmark is
:mod:`habitsim.evaluation.bench.render`). Prints, per setting, the seconds spent drawing
the frames (scene update, ``mjr_render``, ``readPixels``), encoding them, and the whole
video, and the video's speed as a multiple of real time; ``--json`` prints one object."""

from __future__ import annotations

import argparse
import json
import os
from dataclasses import asdict

from .conventions import add_check_option, check_exit


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``render`` to the ``bench`` command group."""
    p = sub.add_parser(
        "render",
        help="how fast a video renders (a trot drawn as track/retarget --video draw it)",
        description=(
            "Draw and write a trot of N frames at 640x480 as track --video and retarget "
            "--video do, with the default settings and with MuJoCo's own (shadows, "
            "reflections, anti-aliasing; timed on the first frames, scaled). Needs an "
            "OpenGL context: MUJOCO_GL=egl or osmesa."
        ),
    )
    p.add_argument("--species", default="dog", help="species whose trot is drawn (default dog)")
    p.add_argument("--robot", metavar="SCENE.xml", help="draw this robot's trot instead")
    p.add_argument("--frames", type=int, default=480, metavar="N", help="clip frames (480)")
    p.add_argument("--fps", type=float, default=50.0, metavar="HZ", help="clip rate [Hz] (50)")
    p.add_argument(
        "--before-frames",
        type=int,
        default=48,
        metavar="K",
        help="frames MuJoCo's own settings are timed on (0: not timed; default 48)",
    )
    p.add_argument("--json", action="store_true", help="print the figures as one JSON object")
    add_check_option(
        p,
        help="exit with code 1 when the video renders slower than 4x real time "
        "(default: print the verdict, exit 0)",
    )
    p.set_defaults(func=_bench_render)


def _bench_render(ns: argparse.Namespace) -> int:
    from ..evaluation.bench.render import RenderBenchOptions, render_checks, run_render
    from ..species import load_species

    load_species(ns.species)  # UnknownSpeciesError listing the catalog
    opts = RenderBenchOptions(
        species=ns.species,
        robot=ns.robot,
        frames=ns.frames,
        fps=ns.fps,
        before_frames=ns.before_frames,
    )
    res = run_render(opts)
    checks = render_checks(res)
    if ns.json:
        print(
            json.dumps(
                {
                    "subject": res.subject,
                    "rows": [asdict(r) for r in res.rows],
                    "load_average": res.load_average,
                    "targets": [t.to_dict() for t in checks],
                }
            )
        )
    else:
        print(
            f"{res.subject}: {opts.frames} frames at {opts.fps:g} Hz "
            f"({opts.frames / opts.fps:.1f} s), {res.width}x{res.height}:"
        )
        for r in res.rows:
            print(
                f"  {r.setting:13s} {r.frames_drawn:4.0f} frames drawn: draw "
                f"{r.draw_s:6.1f} s, encode {r.encode_s:5.1f} s; video {r.total_s:6.1f} s "
                f"= {r.x_real_time:.2f}x real time (CPU {r.cpu_s:.1f} s with the encoder)"
            )
        print(f"  load average {res.load_average:.1f} on {os.cpu_count()} CPUs")
        for t in checks:
            print(f"target: {t.name}: {t.shown} ({t.target}: {t.verdict})")
    return check_exit([t.name for t in checks if t.verdict == "MISSED"], ns.check)
