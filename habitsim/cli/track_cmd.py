"""``habitsim track IN.npz``: track a motion in MuJoCo and report how it went.

::

    habitsim track IN.npz --out SIM.npz --report R.json [--controller mpc]
                          [--assist root] [--video V.mp4|V.gif] [--control-hz HZ]
                          [--settle S] [--no-stop] [--json]

* ``--out``: the simulated frames as a habitsim motion file (with the simulated foot
  contacts; shorter than the input when the run fell or went unstable).
* ``--report``: one JSON object (written atomically): ``input``, the tracking report of
  :meth:`habitsim.sim.TrackResult.report` (``metrics`` with every key of
  :data:`habitsim.metrics.simulated.SIMULATED_KEYS`, ``fell``/``fall_time_s``/
  ``fall_reason``, ``unstable``/``unstable_reason``, ``controller_stats``, ``assist``),
  ``reference_dynamic`` (:data:`habitsim.metrics.dynamic.DYNAMIC_KEYS` of the input)
  and ``simulated_kinematic`` (:data:`habitsim.metrics.kinematic.KINEMATIC_KEYS` of the
  simulated frames, skating judged on the simulated contacts). Non-finite numbers are
  ``null``.

The output paths are checked before the simulation, and the files are written together
or not at all (a failure leaves none of them).
* ``--video``: MP4 (needs ``imageio`` + ``imageio-ffmpeg``) or GIF (needs ``Pillow``),
  rendered headless with the model's tracking camera: the simulated body in its species'
  colour, the input drawn as a translucent ghost beside it, stance feet marked
  (:func:`habitsim.render.render_tracking`). The writer is checked before the simulation
  runs.
* ``--beside OTHER.npz`` (with ``--video``): OTHER is tracked too, with the same options,
  and the video shows the two runs side by side, this one on the left
  (:func:`habitsim.render_side.render_side_by_side`); ``--out``, ``--report`` and ``--json``
  stay this run's, OTHER's summary line follows.
* ``--controller``: ``mpc`` by default (convex MPC on the stance forces, trunk and swing
  legs, the controller the README recommends: a synthetic walk of every training species
  survives it unassisted); ``servo`` (in-engine position servos, no balance: most clips
  fall within a second), ``pd`` and ``balance`` on request.

A fall or an unstable simulation is a result (exit code 0, reported), not an error; bad
input (unreadable file, unknown species or controller, NaN) is ``error: ...``, exit 2.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

from .conventions import add_source_options, source_options


def register(sub: argparse._SubParsersAction) -> None:
    """Add the top-level ``track`` command."""
    from ..controllers import CONTROLLERS

    p = sub.add_parser(
        "track",
        help="track a motion in MuJoCo (mpc controller), detect falls, report metrics",
        description=(
            "Play a motion file through a controller in MuJoCo at the simulation rate, "
            "detect falls and instability, and report the simulated-tracking metrics."
        ),
    )
    p.add_argument("input", metavar="IN.npz", help="motion file")
    add_source_options(p, of="the motion", motion_capture=False)
    p.add_argument("--out", metavar="SIM.npz", help="write the simulated motion here")
    p.add_argument("--report", metavar="R.json", help="write the JSON report here")
    p.add_argument(
        "--controller",
        default="mpc",
        choices=CONTROLLERS,
        help="controller (default mpc: convex MPC with balance; servo: in-engine "
        "position servos, no balance)",
    )
    p.add_argument(
        "--assist",
        choices=("root",),
        default=None,
        help="external root assistance (a PD wrench on the trunk; reported)",
    )
    p.add_argument("--video", metavar="V.mp4", help="render a video (.mp4 or .gif)")
    p.add_argument(
        "--beside",
        metavar="OTHER.npz",
        help="also track OTHER.npz (same options) and put its run to the right of this "
        "one in --video; its summary is printed after this one's",
    )
    p.add_argument(
        "--control-hz",
        type=float,
        metavar="HZ",
        help="control rate [Hz] (default: every simulation step; mpc: 250 Hz)",
    )
    p.add_argument(
        "--settle",
        type=float,
        default=0.0,
        metavar="S",
        help="hold the first frame S seconds before the clip (default 0)",
    )
    p.add_argument(
        "--no-stop",
        action="store_true",
        help="keep simulating after a fall (metrics still use the survived part)",
    )
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.set_defaults(func=_track)


def _finite(v: Any) -> Any:
    if isinstance(v, dict):
        return {k: _finite(x) for k, x in v.items()}
    if isinstance(v, list):
        return [_finite(x) for x in v]
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def track_report(ns: argparse.Namespace, path: str | None = None) -> tuple[dict[str, Any], Any]:
    """Run the tracking of ``path`` (default ``ns.input``) and build the JSON report (and
    the result)."""
    from ..metrics.dynamic import dynamic_metrics
    from ..metrics.kinematic import kinematic_metrics
    from ..motion import load_motion
    from ..sim import track

    path = ns.input if path is None else path
    motion = source_options(ns).shape(load_motion(path), what=str(path))
    result = track(
        motion,
        controller=ns.controller,
        assist=ns.assist or False,
        control_hz=ns.control_hz,
        settle_s=ns.settle,
        stop_on_fall=not ns.no_stop,
    )
    report: dict[str, Any] = {"input": str(path)}
    report.update(result.report())
    report["reference_dynamic"] = dynamic_metrics(motion)
    report["simulated_kinematic"] = kinematic_metrics(result.motion(), contacts=result.contacts)
    return _finite(report), result


def _summary(report: dict[str, Any]) -> str:
    m = report["metrics"]

    def f(v: Any, spec: str = ".4g") -> str:
        return "n/a" if v is None else format(v, spec)

    if report["unstable"]:
        status = f"UNSTABLE ({report['unstable_reason']})"
    elif report["fell"]:
        status = f"fell at {report['fall_time_s']:.2f} s ({report['fall_reason']})"
    else:
        status = "completed"
    lines = [
        f"track {report['input']}: {report['species']}, {report['frames']} frames at "
        f"{report['fps']:g} fps, controller {report['controller']}, "
        f"assist {'on' if report['assist'].get('assist_on') else 'off'}",
        f"  {status}",
        f"  survival            {f(m['survival'], '.3f')}",
        f"  sim_mpjpe_mm        {f(m['sim_mpjpe_mm'])}   ({f(m['sim_mpjpe_per_leg'], '.3f')} leg)",
        f"  root_drift_mm       {f(m['root_drift_mm'])}   "
        f"({f(m['root_drift_per_leg'], '.3f')} leg)",
        f"  contact_f1          {f(m['contact_f1'], '.3f')}",
        f"  assist_force_mg     {f(m['assist_force_mg'], '.3f')}",
        f"  cost_of_transport   {f(m['cost_of_transport'], '.3f')}",
        f"  realtime_factor     {f(m['realtime_factor'], '.1f')}",
    ]
    dyn = report["reference_dynamic"]
    lines.append(
        f"  reference: root_residual_mg {f(dyn['root_residual_mg'], '.3f')}, "
        f"root_residual_torque_mgl {f(dyn['root_residual_torque_mgl'], '.3f')}, "
        f"torque_saturation {f(dyn['torque_saturation'], '.3f')}"
    )
    return "\n".join(lines)


def _track(ns: argparse.Namespace) -> int:
    from ..fileio import output_transaction

    if ns.beside and not ns.video:
        from ..errors import ArgumentRangeError

        raise ArgumentRangeError("--beside puts a second run in the video: give --video too")
    if ns.video:
        from ..render import check_video_writer

        check_video_writer(Path(ns.video))  # fail before simulating
    # destinations checked before the simulation; the files appear together or not at all
    with output_transaction({"--out": ns.out, "--report": ns.report, "--video": ns.video}):
        return _track_outputs(ns)


def _track_outputs(ns: argparse.Namespace) -> int:
    from ..fileio import atomic_write_text

    report, result = track_report(ns)
    other = track_report(ns, ns.beside) if ns.beside else None
    if ns.out:
        result.motion().save(ns.out)
    if ns.report:
        atomic_write_text(ns.report, json.dumps(report, indent=2, allow_nan=False) + "\n")
    if ns.video and other is not None:
        from ..render_side import render_side_by_side

        render_side_by_side([result, other[1]], ns.video)
    elif ns.video:
        from ..render import render_tracking

        render_tracking(result, ns.video)
    if ns.json:
        print(json.dumps(report, allow_nan=False))
    else:
        print(_summary(report))
    if other is not None:
        # the other run's summary (on stderr under --json: stdout holds one JSON object)
        print(
            "beside: " + _summary(other[0]).removeprefix("track "),
            file=sys.stderr if ns.json else sys.stdout,
        )
    return 0
