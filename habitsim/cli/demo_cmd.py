"""``habitsim demo --out DIR``: the furthest pipeline stage that exists, end to end.

Until transfer, refinement and simulation exist, the demo builds a small synthetic gait
data set (4 clips per species, every catalog species) in ``DIR`` and prints its measured
gait statistics per species × action: planned and measured Froude number and duty
factor, relative stride length, footfall phase error and foot skating. Re-running on the
same folder reuses the clips already there; a folder holding a data set of another
configuration (an older generator, say) is rebuilt.
"""

from __future__ import annotations

import argparse
import time

from ..dataset import build_dataset, check_resumable, format_stats_table
from ..errors import DatasetError
from .synth_cmd import format_summary

#: Clips per species of the demo data set.
DEMO_CLIPS_PER_SPECIES = 4


def register(sub: argparse._SubParsersAction) -> None:
    """Add the top-level ``demo`` command."""
    p = sub.add_parser(
        "demo",
        help="run the demo: synthetic data set, then transfer → refine → track",
        description=(
            "Build a small synthetic gait data set of every species in DIR and print its "
            "measured gait statistics; then transfer a synthetic horse trot to a cat, a bear "
            "and a held-out species (tiger) with the shipped model, refine each transfer, "
            "track it in MuJoCo unassisted (balance controller) and with measured root "
            "assistance, and print a summary table (also written to DIR/pipeline.json)."
        ),
    )
    p.add_argument(
        "--out", default="demo_out", metavar="DIR", help="output folder (default demo_out)"
    )
    p.add_argument(
        "--clips-per-species", type=int, default=DEMO_CLIPS_PER_SPECIES, metavar="N",
        help=f"clips per species (default {DEMO_CLIPS_PER_SPECIES})",
    )
    p.add_argument("--seed", type=int, default=0, metavar="S", help="seed (default 0)")
    p.add_argument("--workers", type=int, metavar="W", help="worker processes (default: CPU count)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--targets", default="cat,bear,tiger", metavar="A,B",
                   help="target species of the transfer stage (default cat,bear,tiger)")
    p.add_argument("--video", action="store_true",
                   help="also render an MP4 of each unassisted tracking run")
    p.add_argument("--data-only", action="store_true", help="stop after the data set stage")
    p.set_defaults(func=_demo)


def _demo(ns: argparse.Namespace) -> int:
    t0 = time.perf_counter()
    try:
        check_resumable(ns.out, seed=ns.seed)
        overwrite = False
    except DatasetError:
        overwrite = True  # an earlier demo with another configuration: rebuild it
    print("habitsim demo: synthetic gait data set of every species (the pipeline's first stage)")
    build = build_dataset(
        ns.out,
        clips_per_species=ns.clips_per_species,
        seed=ns.seed,
        workers=ns.workers,
        progress=not ns.no_progress,
        overwrite=overwrite,
    )
    print(format_summary(build))
    print()
    print(format_stats_table(build.stats))
    print()
    print(
        "Fr = v²/(g·h) measured from the root path, duty = stance share, stride/h = stride "
        "length / hip height,\nphase err = |measured − planned footfall phase| [stride], "
        "skate/pen = foot skating / ground penetration [mm],\nstable = share of frames with "
        "≥ 3 feet down whose centre of mass is inside the support polygon; for jump, "
        "Fr plan is the take-off Froude number."
    )
    print(f"clips: {ns.out}/{{train,val,test}}/<species>/*.npz, listed in {ns.out}/manifest.json;")
    print(f"this table is also in {ns.out}/stats.md and {ns.out}/stats.csv")
    if not ns.data_only:
        _pipeline(ns)
    print(f"demo finished in {time.perf_counter() - t0:.1f} s")
    return 0


def _pipeline(ns: argparse.Namespace) -> None:
    """Transfer → refine → track for one synthetic horse trot and a few targets."""
    import json
    from pathlib import Path

    from ..fileio import atomic_write_text
    from ..gaits import generate
    from ..models import transfer
    from ..refine import refine
    from ..sim import track
    from ..species import load_species

    out = Path(ns.out) / "pipeline"
    out.mkdir(parents=True, exist_ok=True)
    targets = [load_species(t).name for t in ns.targets.split(",") if t.strip()]
    src = generate("horse", "trot", seed=ns.seed, duration_s=3.0)
    src.save(out / "horse_trot.npz")
    print()
    print(f"habitsim demo: transfer a horse trot ({src.num_frames} frames, Fr "
          f"{src.metadata['froude']:.2f}) → {', '.join(targets)}; refine; track in MuJoCo")
    rows = []
    for tgt in targets:
        t1 = time.perf_counter()
        moved = transfer(src, to=tgt, method="habit", seed=ns.seed)
        info = moved.metadata.get("transfer", {})
        ref = refine(moved, fallback=True)
        ref.motion.save(out / f"{tgt}_refined.npz")
        video = str(out / f"{tgt}_balance.mp4") if ns.video else None
        plain = track(ref.motion, controller="balance")
        if video:
            from ..render import render_video

            render_video(plain.model, plain.qpos, plain.fps, video)
        helped = track(ref.motion, controller="servo", assist="root")
        pm, hm = plain.metrics, helped.metrics
        rows.append({
            "target": tgt,
            "habit_from": info.get("habit_species", tgt),
            "refine_status": ref.status,
            "skate_mm_before": ref.report.get("metrics_before", {}).get("skate_mm"),
            "skate_mm_after": ref.report.get("metrics_after", {}).get("skate_mm"),
            "survival_balance": pm.get("survival"),
            "sim_mpjpe_per_leg_balance": pm.get("sim_mpjpe_per_leg"),
            "survival_assisted": hm.get("survival"),
            "sim_mpjpe_per_leg_assisted": hm.get("sim_mpjpe_per_leg"),
            "assist_force_mg": hm.get("assist_force_mg"),
            "seconds": round(time.perf_counter() - t1, 1),
        })
    atomic_write_text(Path(ns.out) / "pipeline.json", json.dumps(rows, indent=2) + "\n")

    def f(v: object, nd: int = 3) -> str:
        return "-" if not isinstance(v, int | float) else f"{v:.{nd}f}"

    head = ("target", "habit of", "refine", "skate mm before→after", "survival (balance)",
            "MPJPE/leg", "survival (assisted)", "MPJPE/leg", "assist m·g", "s")
    print("  ".join(head))
    for r in rows:
        print("  ".join([
            r["target"], str(r["habit_from"]), str(r["refine_status"]),
            f"{f(r['skate_mm_before'], 2)}→{f(r['skate_mm_after'], 2)}",
            f(r["survival_balance"], 2), f(r["sim_mpjpe_per_leg_balance"]),
            f(r["survival_assisted"], 2), f(r["sim_mpjpe_per_leg_assisted"]),
            f(r["assist_force_mg"]), f(r["seconds"], 1),
        ]))
    print(f"motions in {out}/, table in {ns.out}/pipeline.json")
