"""A robot habitsim did not build, under ``mpc``: stand, trot in place, trot forward.

Runs the README's "Using the controllers on your own robot" end to end on MuJoCo
Menagerie's Unitree Go1 (vendored with collision primitives only under
``tests/robots/unitree_go1`` of a source checkout), or on any four-legged MJCF with a free
joint given with ``--robot`` (and ``--feet``, when its feet are not found)::

    python -m habitsim.examples.robot_trot                       # 10 s each, the Go1
    python -m habitsim.examples.robot_trot --speed 0.8 --video out/
    python -m habitsim.examples.robot_trot --robot anymal_c/scene.xml \
        --feet LF_FOOT,RF_FOOT,LH_FOOT,RH_FOOT

Each case is a reference made by :mod:`habitsim.retarget` (:func:`~habitsim.retarget.stand`,
:func:`~habitsim.retarget.trot`) tracked by :func:`habitsim.sim.track` with
``controller="mpc"``, no assistance and no external force; the robot's position servos
are simulated as torque motors of the same strength. Prints survival, tracking error and
the MPC's solve time per case; exits 1 when a case falls.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

#: The vendored Go1 in a source checkout (tests/ is not installed with the package).
GO1_SCENE = Path(__file__).resolve().parents[2] / "tests" / "robots" / "unitree_go1" / "scene.xml"
GO1_FEET = ("FL", "FR", "RL", "RR")


def _forward_distance(qpos: np.ndarray, adr: int = 0) -> float:
    """Trunk displacement [m] along its horizontal forward axis (its x axis) at the
    start: a robot whose trunk frame faces −x at home (ANYmal C) walks forward too.
    ``adr``: the free joint's qpos address."""
    rot = np.zeros(9)
    mujoco.mju_quat2Mat(rot, qpos[0, adr + 3 : adr + 7])
    ahead = rot.reshape(3, 3)[:2, 0]
    ahead = ahead / max(float(np.linalg.norm(ahead)), 1e-9)
    return float((qpos[-1, adr : adr + 2] - qpos[0, adr : adr + 2]) @ ahead)


def run(
    robot: str | Path = GO1_SCENE,
    feet: tuple[str, ...] | None = GO1_FEET,
    *,
    duration_s: float = 10.0,
    speed: float = 0.5,
    video: str | Path | None = None,
) -> list[dict[str, Any]]:
    """Stand, trot in place and trot forward at ``speed`` for ``duration_s`` each under
    ``mpc``; one row of figures per case (``video``: a folder for an MP4 per case;
    ``feet=None``: found, :func:`habitsim.retarget.find_robot_feet`)."""
    from habitsim.mjutils import free_joint
    from habitsim.retarget import drawable, find_robot_feet, load_robot, stand, track_clip, trot

    model = load_robot(robot)
    if feet is None:
        feet = find_robot_feet(model)
    cases = (
        ("stand", stand(model, feet, duration_s=duration_s)),
        ("trot in place", trot(model, feet, speed=0.0, duration_s=duration_s)),
        (f"trot {speed:g} m/s", trot(model, feet, speed=speed, duration_s=duration_s)),
    )
    rows = []
    for name, clip in cases:
        res = track_clip(clip, model, controller="mpc")
        m, st = res.metrics, res.controller_stats
        rows.append(
            {
                "case": name,
                "duration_s": clip.duration,
                "survival": res.survival,
                "fall_reason": res.fall_reason,
                "sim_mpjpe_mm": m["sim_mpjpe_mm"],
                "root_drift_mm": m["root_drift_mm"],
                "contact_f1": m["contact_f1"],
                "distance_m": _forward_distance(
                    res.qpos, int(model.jnt_qposadr[free_joint(model)])
                ),
                "mpc_median_ms": st.get("mpc_median_ms", float("nan")),
                "realtime_factor": m["realtime_factor"],
            }
        )
        if video is not None:
            from habitsim.render import render_video

            out = Path(video) / f"{name.replace(' ', '_').replace('/', '_')}.mp4"
            render_video(drawable(res.model), res.qpos, res.fps, out, camera="tracking")
    return rows


def format_rows(rows: list[dict[str, Any]]) -> str:
    """The figures as a table with a legend."""
    head = (
        f"{'case':<16}{'time s':>7}{'surv':>6}{'MPJPE mm':>10}{'drift mm':>10}"
        f"{'F1':>6}{'dist m':>8}{'MPC ms':>8}{'RTF':>6}"
    )
    lines = [head]
    for r in rows:
        lines.append(
            f"{r['case']:<16}{r['duration_s']:>7.1f}{r['survival']:>6.2f}"
            f"{r['sim_mpjpe_mm']:>10.1f}{r['root_drift_mm']:>10.1f}"
            f"{r['contact_f1']:>6.2f}{r['distance_m']:>8.2f}{r['mpc_median_ms']:>8.2f}"
            f"{r['realtime_factor']:>6.1f}"
        )
        if r["fall_reason"]:
            lines.append(f"  fell: {r['fall_reason']}")
    from habitsim.cli.conventions import format_legend

    lines.append(
        format_legend(
            "surv: share of the clip before a fall; MPJPE: mean body-origin error to the "
            "reference; drift: horizontal trunk error at the end; F1: foot contacts vs. the "
            "reference's; dist: distance walked; MPC: median solve time; RTF: real-time factor"
        )
    )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        prog="python -m habitsim.examples.robot_trot", description=__doc__.split("\n\n")[0]
    )
    p.add_argument(
        "--robot",
        type=Path,
        default=GO1_SCENE,
        help="robot scene MJCF (default: the vendored Unitree Go1)",
    )
    p.add_argument(
        "--feet",
        default=None,
        help=(
            "foot names in the order LF,RF,LH,RH (default: the usual names, else the four "
            "legs standing on the ground at home)"
        ),
    )
    p.add_argument("--duration", type=float, default=10.0, help="seconds per case (default 10)")
    p.add_argument("--speed", type=float, default=0.5, help="forward trot speed [m/s] (0.5)")
    p.add_argument("--video", type=Path, help="write an MP4 per case into this folder")
    ns = p.parse_args(argv)
    from habitsim.errors import HabitsimError

    try:
        rows = run(
            ns.robot,
            None if ns.feet is None else tuple(f for f in ns.feet.split(",") if f),
            duration_s=ns.duration,
            speed=ns.speed,
            video=ns.video,
        )
    except HabitsimError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(format_rows(rows))
    return 0 if all(r["survival"] == 1.0 for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
