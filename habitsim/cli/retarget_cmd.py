"""``habitsim retarget``: a habitsim motion on a legged robot (qpos), optionally tracked."""

from __future__ import annotations

import argparse
import dataclasses
import json
import warnings
from pathlib import Path
from typing import TYPE_CHECKING

from .conventions import add_list_option, add_source_options, source_options

if TYPE_CHECKING:  # pragma: no cover
    from ..motion import Motion

#: Controllers ``--track`` can use (the torque-based ones; a robot's servos are driven
#: as torques).
TRACK_CONTROLLERS = ("mpc", "balance", "pd")


def register(sub: argparse._SubParsersAction) -> None:
    """Add the top-level ``retarget`` command."""
    p = sub.add_parser(
        "retarget",
        help="map a habitsim motion onto a legged robot MJCF (and track it with mpc)",
        description=(
            "Map a habitsim motion (.npz: a synthetic gait, a transfer, an imported BVH; or a "
            ".bvh/.glb/.gltf imported first with --from SPECIES) onto "
            "a robot with a free joint and four named feet: foot paths and trunk path scaled "
            "by the ratio of leg lengths, trunk orientation kept, leg IK on the robot's joints "
            "(damped least squares on MuJoCo Jacobians, joint ranges respected). Writes the "
            "robot's qpos, fps, contact labels and foot names to OUT.npz (atomically); "
            "--track then simulates it (default controller mpc; no assistance). A clip "
            "that starts lying or sitting is retargeted from its first standing or "
            "locomotion segment (said in the output)."
        ),
    )
    p.add_argument(
        "source",
        type=Path,
        metavar="SRC",
        help="habitsim motion (.npz), or motion capture (.bvh, .glb, .gltf) with --from",
    )
    p.add_argument(
        "--from",
        "--species",
        dest="from_species",
        metavar="SPECIES",
        help=(
            "skeleton a .bvh/.glb/.gltf source is imported onto first (its stance found on "
            "its own feet, feet planted; `habitsim data import-bvh` does the same alone)"
        ),
    )
    add_source_options(p, of="the source")
    p.add_argument(
        "--robot",
        required=True,
        metavar="MJCF|NAME",
        help=(
            "robot model; its scene (with a floor) for --track; or a MuJoCo Menagerie name "
            "(e.g. unitree_go2) through the optional package mujoco-menagerie"
        ),
    )
    add_list_option(
        p,
        "--feet",
        metavar="FOOT",
        help=(
            "the robot's foot sites, geoms or bodies in the order LF, RF, LH, RH (e.g. "
            "FL,FR,RL,RR; default: the usual names, else the four legs standing on the "
            "ground at the standing pose, printed)"
        ),
    )
    p.add_argument(
        "--keyframe",
        "--home",
        dest="home",
        default="home",
        metavar="NAME",
        help=(
            "keyframe the robot stands on (default home; without a keyframe home, qpos0, "
            "crouched when its legs are straight, refused when folded)"
        ),
    )
    p.add_argument(
        "--keyframe-from",
        type=Path,
        metavar="FILE",
        help=(
            "MJCF file whose <keyframe> holds the standing pose (a key of the robot's qpos "
            "size, named by --keyframe or the file's only one; e.g. Menagerie's "
            "scene_mjx.xml)"
        ),
    )
    p.add_argument("--out", type=Path, required=True, metavar="Q.npz", help="robot clip to write")
    p.add_argument("--track", action="store_true", help="track the result in MuJoCo")
    p.add_argument(
        "--controller",
        default="mpc",
        choices=TRACK_CONTROLLERS,
        help="controller of --track (default mpc)",
    )
    p.add_argument(
        "--report", type=Path, metavar="JSON", help="write the tracking report (--track)"
    )
    p.add_argument("--video", type=Path, metavar="MP4", help="render the tracked run (--track)")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.set_defaults(func=_retarget)


def _retarget(ns: argparse.Namespace) -> int:
    from ..fileio import output_transaction

    # every destination checked before the work; written together or not at all
    with output_transaction({"--out": ns.out, "--report": ns.report, "--video": ns.video}):
        return _retarget_outputs(ns)


def _default_start(motion: Motion) -> tuple[float, str]:
    """Where the clip's default span starts [s] (its first standing or locomotion
    segment, :func:`habitsim.activity.default_span`) and what it leaves out, in words
    ("" when it starts at the first frame).

    Raises:
        ActivityError: the clip never stands or moves on its legs.
    """
    from ..activity import default_span, timeline

    tl = timeline(motion)
    start, _ = default_span(tl)
    if start == 0:
        return 0.0, ""
    left = [s for s in tl.segments if s.start < start]
    what = ", ".join(f"{s.activity.value} {s.start_s:.2f}–{s.end_s:.2f} s" for s in left)
    return start / tl.fps, (
        f"start left out: the clip begins {what} (the trunk on the ground, not a gait a "
        f"robot can take up); retargeting from {start / tl.fps:.2f} s (--start 0 keeps it; "
        "`habitsim data inspect-bvh` prints the whole timeline)"
    )


def _retarget_outputs(ns: argparse.Namespace) -> int:
    import mujoco

    from ..fileio import atomic_write_text, json_safe
    from ..retarget import (
        RetargetError,
        RetargetOptions,
        StandingPoseError,
        StandingPoseWarning,
        drawable,
        load_robot,
        nearby_keyframes,
        retarget,
        track_clip,
    )
    from ..source import Span, load_clip

    suffix = ns.source.suffix.lower()
    if suffix not in (".npz", ".bvh", ".glb", ".gltf"):
        raise RetargetError(
            f"SRC must be a habitsim motion (.npz) or motion capture (.bvh, .glb, .gltf), "
            f"got {str(ns.source)!r}"
        )
    if suffix != ".npz" and ns.from_species is None:
        raise RetargetError(
            f"a {suffix} source needs --from SPECIES (the skeleton to import it onto, "
            "e.g. --from dog)"
        )
    if (ns.report or ns.video) and not ns.track:
        raise RetargetError("--report and --video describe the tracked run: add --track")
    robot = load_robot(ns.robot)
    opts = source_options(ns, ns.from_species if suffix != ".npz" else None)
    loaded = load_clip(ns.source, opts)
    trimmed = ""
    if ns.start is None and ns.end is None:  # a span the user gives is taken as given
        start_s, trimmed = _default_start(loaded.motion)
        if trimmed:  # cut before the import, as --start does
            loaded = load_clip(ns.source, dataclasses.replace(opts, span=Span(start_s)))
    if loaded.mapping is not None and not ns.json:
        print(loaded.mapping)
    if trimmed and not ns.json:
        print(trimmed)
    if loaded.cut and not ns.json:
        print(f"source span: {loaded.kept()}")
    motion = loaded.motion
    if ns.track and not any(robot.geom_bodyid == 0):
        raise RetargetError(
            f"{str(ns.robot)!r} has no floor (no geom on the world body): "
            "--track needs the robot's scene"
        )
    if ns.video:
        from ..render import check_video_writer

        check_video_writer(ns.video)  # fail before the work
    ropts = RetargetOptions(keyframe_from=ns.keyframe_from)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", StandingPoseWarning)
        try:
            clip = retarget(motion, robot, ns.feet or None, home=ns.home, options=ropts)
        except StandingPoseError as e:
            near = nearby_keyframes(ns.robot, robot.nq) if Path(ns.robot).is_file() else []
            if near:
                raise StandingPoseError(
                    f"{e}; beside {ns.robot} a keyframe of its size is in: {', '.join(near)}"
                ) from e
            raise
    for w in caught:
        if not issubclass(w.category, StandingPoseWarning):
            warnings.showwarning(w.message, w.category, w.filename, w.lineno)
        elif not ns.json:
            print(f"warning: {w.message}")
    if clip.metadata["feet_found"] and not ns.json:
        print(f"feet (found, LF, RF, LH, RH): {', '.join(clip.feet)}")
    clip.save(ns.out)
    summary: dict = {
        "out": str(ns.out),
        "trimmed_start": trimmed or None,
        "frames": len(clip.qpos),
        "fps": clip.fps,
        "duration_s": clip.duration,
        **clip.metadata,
    }
    if ns.track:
        res = track_clip(clip, robot, controller=ns.controller)
        rep = res.report()
        summary["track"] = {
            k: rep[k]
            for k in ("controller", "fell", "fall_time_s", "fall_reason", "reference_resting")
        }
        summary["track"].update(
            {
                k: rep["metrics"][k]
                for k in ("survival", "sim_mpjpe_mm", "root_drift_mm", "contact_f1")
            }
        )
        summary["track"]["mpc_median_ms"] = rep["controller_stats"].get("mpc_median_ms")
        if ns.report:
            atomic_write_text(ns.report, json.dumps(rep, indent=2, allow_nan=False) + "\n")
        if ns.video:
            from ..render import render_video

            cam = (
                "tracking"
                if mujoco.mj_name2id(robot, mujoco.mjtObj.mjOBJ_CAMERA, "tracking") >= 0
                else "track"
            )
            render_video(drawable(res.model), res.qpos, res.fps, ns.video, camera=cam)
    if ns.json:
        print(json.dumps(json_safe(summary), allow_nan=False))
        return 0
    print(
        f"{ns.source} -> {ns.out}: {summary['frames']} frames at {clip.fps:g} fps "
        f"({summary['duration_s']:.2f} s); scale {summary['scale']:.3f}, IK residual max "
        f"{1e3 * summary['ik_residual_max_m']:.2f} mm, joints at a range limit "
        f"{100 * summary['joints_at_limit_share']:.1f} %"
    )
    if ns.track:
        t = summary["track"]
        line = (
            f"tracked with {t['controller']}: survival {t['survival']:.2f}, sim MPJPE "
            f"{t['sim_mpjpe_mm']:.1f} mm, root drift {t['root_drift_mm']:.1f} mm, contact F1 "
            f"{t['contact_f1']:.2f}"
        )
        if t["mpc_median_ms"] is not None:
            line += f", MPC {t['mpc_median_ms']:.2f} ms"
        print(line)
        if t["reference_resting"]:
            print(t["reference_resting"])
        if t["fell"]:
            print(f"fell at {t['fall_time_s']:.2f} s: {t['fall_reason']}")
    return 0
