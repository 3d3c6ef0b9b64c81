"""``habitsim demo --out DIR``: the whole pipeline, end to end, with the shipped models.

1. A small synthetic gait data set (4 clips per species, every catalog species) in
   ``DIR``, with its measured gait statistics per species × action: planned and measured
   Froude number and duty factor, relative stride length, footfall phase error and foot
   skating. Re-running on the same folder reuses the clips already there; a folder
   holding a data set of another configuration (an older generator, say) is rebuilt.
2. Two sources — a synthetic horse trot and the shipped BVH example (a dog walk,
   imported with :func:`habitsim.bvh_mapping.import_bvh`) — transferred to a cat, a bear
   and the held-out tiger with the shipped ``habit`` model, refined (CasADi/IPOPT),
   tracked in MuJoCo unassisted (``mpc``) and with measured root assistance (one call of
   :func:`habitsim.pipeline.run_clip` per pair, the stance labels passed along), with a
   progress bar over the pairs that names the pair and stage; each unassisted run
   rendered to MP4 (where an OpenGL backend exists) with the reference as a translucent
   ghost beside the body and the stance feet marked (:func:`habitsim.render.render_tracking`);
   a summary table printed with a legend under it and written to ``DIR/pipeline.json``,
   the report ``DIR/report.md`` and, next to it, ``DIR/report.html`` (the eval report's
   page writer: the table and legend, bar charts of survival and tracking error, a gait
   diagram and a tracking-error curve per pair, the videos).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import TYPE_CHECKING

from ..dataset import build_dataset, check_resumable, format_stats_table
from ..errors import DatasetError
from ..fileio import check_writable, make_dirs
from .conventions import add_list_option, split_names
from .synth_cmd import format_summary

if TYPE_CHECKING:  # pragma: no cover
    from ..motion import Motion
    from ..stance.report import TransferRecord

#: Clips per species of the demo data set.
DEMO_CLIPS_PER_SPECIES = 4


def register(sub: argparse._SubParsersAction) -> None:
    """Add the top-level ``demo`` command."""
    p = sub.add_parser(
        "demo",
        help="run the demo: synthetic data set, then transfer → refine → track",
        description=(
            "Build a small synthetic gait data set of every species in DIR and print its "
            "measured gait statistics; then transfer a synthetic horse trot and the shipped "
            "BVH example (a dog walk) to a cat, a bear and a held-out species (tiger) with "
            "the shipped model, refine each transfer, track it in MuJoCo unassisted (mpc "
            "controller) and with measured root assistance, render videos (the reference as "
            "a ghost beside the body, stance feet marked), and print a summary table with "
            "its legend (also in DIR/pipeline.json and the reports DIR/report.md and "
            "DIR/report.html)."
        ),
    )
    p.add_argument(
        "--out", default="demo_out", metavar="DIR", help="output folder (default demo_out)"
    )
    p.add_argument(
        "--clips-per-species",
        type=int,
        default=DEMO_CLIPS_PER_SPECIES,
        metavar="N",
        help=f"clips per species (default {DEMO_CLIPS_PER_SPECIES})",
    )
    p.add_argument("--seed", type=int, default=0, metavar="S", help="seed (default 0)")
    p.add_argument("--workers", type=int, metavar="W", help="worker processes (default: CPU count)")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    add_list_option(
        p,
        "--targets",
        default=["cat", "bear", "tiger"],
        metavar="SPECIES",
        help="target species of the transfer stage, built-in or user (default cat,bear,tiger)",
    )
    p.add_argument(
        "--no-video",
        action="store_true",
        help="do not render the MP4 of each unassisted tracking run",
    )
    p.add_argument(
        "--controller",
        default="mpc",
        choices=("balance", "mpc"),
        help="unassisted tracking controller (default mpc)",
    )
    p.add_argument("--data-only", action="store_true", help="stop after the data set stage")
    p.set_defaults(func=_demo)


def _check_outputs(ns: argparse.Namespace) -> None:
    """Every destination of the demo checked before its first minute of work (the data
    set folder itself is checked by :func:`~habitsim.dataset.build_dataset`).

    Raises:
        OutputPathError: a file where a folder should be, a read-only folder, …
    """
    from ..evaluation.report import check_report_outputs

    out = Path(ns.out)
    check_writable(out / "manifest.json", "--out")
    if ns.data_only:
        return
    for name in ("pipeline.json", "report.md"):
        check_writable(out / name, "--out")
    check_writable(out / "pipeline" / "motion.npz", "--out")
    check_report_outputs(out)


def _demo(ns: argparse.Namespace) -> int:
    from ..folders import claim_output_folder
    from ..species import load_species

    t0 = time.perf_counter()
    # the targets (built-in or user species) before the data set's minutes of work
    ns.targets = [load_species(t).name for t in split_names(ns.targets)]
    _check_outputs(ns)
    # one demo at a time in --out; an earlier demo (or data set build) there continues;
    # a folder holding files habitsim did not write is refused
    with claim_output_folder(
        ns.out,
        command="demo",
        resume=True,
        resume_flag=None,
        overwrite_flag=None,
        continues=("data synth",),
        log=print,
    ):
        return _demo_in(ns, t0)


def _demo_in(ns: argparse.Namespace, t0: float) -> int:
    """The demo in its claimed output folder."""
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


#: The shipped BVH example (a 4 s dog walk in habitsim's BVH layout; habitsim/examples).
BVH_EXAMPLE = "dog_walk.bvh"


def _sources(seed: int) -> list[tuple[str, Motion]]:
    """The demo's two sources: a synthetic horse trot and the shipped BVH dog walk."""
    from importlib import resources

    from ..bvh_mapping import import_bvh
    from ..gaits import generate

    trot = generate("horse", "trot", seed=seed, duration_s=3.0)
    path = Path(str(resources.files("habitsim.examples") / BVH_EXAMPLE))
    walk, _ = import_bvh(path, "dog")
    walk.metadata["action"] = "walk"  # the example's action (habitsim/examples/README.md)
    return [("horse_trot", trot), ("dog_walk_bvh", walk)]


def _pipeline(ns: argparse.Namespace) -> None:
    """Transfer → refine → track → render for two sources and a few targets; a report."""
    from ..fileio import atomic_write_text
    from ..pipeline import run_clip, track_reference
    from ..render import RenderError, render_available, render_tracking
    from ..species import load_species
    from ..stance.report import TransferRecord

    out = make_dirs(Path(ns.out) / "pipeline", "--out")
    targets = [load_species(t).name for t in split_names(ns.targets)]
    videos = not ns.no_video and render_available()
    sources = _sources(ns.seed)
    print()
    print(
        "habitsim demo: transfer "
        + " and ".join(f"{name} ({m.num_frames} frames of {m.species})" for name, m in sources)
        + f" → {', '.join(targets)} with the shipped model; refine (CasADi/IPOPT); track in "
        f"MuJoCo unassisted ({ns.controller}) and with measured root assistance"
    )
    if not ns.no_video and not videos:
        print(
            "  (no OpenGL backend for off-screen rendering here: videos are skipped; "
            "install libegl1 and libgl1-mesa-dri, or libosmesa6)"
        )
    pairs = [(name, src, tgt) for name, src in sources for tgt in targets]
    rows: list[dict] = []
    figures: list[dict] = []
    bar = _bar(len(pairs), ns.no_progress)
    for name, src, tgt in pairs:
        src.save(out / f"{name}.npz")
        t1 = time.perf_counter()
        _stage(bar, f"{name} → {tgt}", "transfer → refine → track")
        # transfer → refine (stage A) → track unassisted, labels passed along;
        # a refinement that makes the clip track worse is reported and not kept
        run = run_clip(src, tgt, method="habit", refine="A", controller=ns.controller, seed=ns.seed)
        moved, ref = run.transferred.motion, run.refine_result
        assert moved is not None and ref is not None  # refine="A" runs every stage
        info = TransferRecord.from_metadata(moved.metadata)
        moved.save(out / f"{name}_to_{tgt}.npz")
        ref.motion.save(out / f"{name}_to_{tgt}_refined.npz")
        plain = run.track_result
        _stage(bar, f"{name} → {tgt}", "track with root assistance")
        # the same controller with root assistance: how much outside help it needed
        helped = track_reference(run, controller=ns.controller, assist="root")
        video = None
        if videos and plain is not None:
            _stage(bar, f"{name} → {tgt}", "video")
            video = out / f"{name}_to_{tgt}_{ns.controller}.mp4"
            try:
                render_tracking(plain, video)
            except RenderError as e:
                _note(bar, f"  video of {name} → {tgt} skipped: {e}")
                video = None
        pm = {} if plain is None else plain.metrics
        hm = helped.metrics
        rows.append(
            {
                "source": name,
                "target": tgt,
                "habit_from": _habit_from(info, tgt),
                "retrieval": None
                if info is None or info.retrieval is None
                else info.retrieval.explanation,
                "contacts": run.transferred.contacts_method,
                "refine_status": run.refined.status,
                "refine_check": run.refine_verdict,
                "refine_note": run.refine_note,
                "skate_mm_before": run.transferred.metrics.get("skate_mm"),
                "skate_mm_after": run.refined.metrics.get("skate_mm"),
                "controller": ns.controller,
                "survival_unassisted": pm.get("survival"),
                "sim_mpjpe_per_leg_unassisted": pm.get("sim_mpjpe_per_leg"),
                "survival_assisted": hm.get("survival"),
                "sim_mpjpe_per_leg_assisted": hm.get("sim_mpjpe_per_leg"),
                "assist_force_mg": hm.get("assist_force_mg"),
                "video": None if video is None else video.name,
                "seconds_per_stage": {k: round(v, 2) for k, v in run.times.items()},
                "seconds": round(time.perf_counter() - t1, 1),
            }
        )
        figures.append(_traces(src, run, plain, helped))
        if bar is not None:
            bar.update(1)
    if bar is not None:
        bar.close()
    atomic_write_text(Path(ns.out) / "pipeline.json", json.dumps(rows, indent=2) + "\n")
    table = _table(rows)
    atomic_write_text(Path(ns.out) / "report.md", _report(rows, table, ns))
    html = _html_report(Path(ns.out), rows, figures, table, ns)
    print(table)
    print(LEGEND)
    print(
        f"motions and videos in {out}/; report in {ns.out}/report.md and {html}, "
        f"table in {ns.out}/pipeline.json"
    )


def _habit_from(info: TransferRecord | None, target: str) -> str | None:
    """The species whose habits served ``target``: the record's ``habit_species`` as
    written (None too), ``target`` when the method wrote none."""
    if info is None or "habit_species" not in info.order:
        return target
    return info.habit_species


def _bar(total: int, off: bool):
    """The pipeline stage's progress bar over the pairs (stderr; None when switched off)."""
    if off:
        return None
    from tqdm.auto import tqdm

    return tqdm(total=total, unit="pair", desc="demo", dynamic_ncols=True)


def _stage(bar, pair: str, stage: str) -> None:
    if bar is not None:
        bar.set_description(f"demo {pair}")
        bar.set_postfix_str(stage)


def _note(bar, text: str) -> None:
    if bar is None:
        print(text)
    else:
        bar.write(text)


def _traces(src: Motion, run, plain, helped) -> dict:
    """What the HTML report plots of one pair: stance timelines of every stage and the
    tracking error over time (unassisted and assisted)."""
    from ..evaluation.pairs import _per_frame_error_mm

    panels = [
        ("source", src.contacts if src.contacts is not None else src.detect_contacts()),
        ("transferred", run.transferred.contacts),
        ("tracked ref.", run.reference_contacts),
    ]  # refined, unless reverted
    curves = []
    if plain is not None:
        panels.append((f"sim {plain.controller}", plain.contacts))
        curves.append((f"{plain.controller} (unassisted)", _per_frame_error_mm(plain), plain.fps))
    panels.append((f"sim {helped.controller}+assist", helped.contacts))
    curves.append(
        (f"{helped.controller} + root assistance", _per_frame_error_mm(helped), helped.fps)
    )
    return {
        "panels": [(n, c) for n, c in panels if c is not None],
        "curves": curves,
        "fps": float(run.transferred.motion.fps),
    }


def _html_report(
    out: Path, rows: list[dict], figures: list[dict], table: str, ns: argparse.Namespace
) -> Path:
    """``report.html`` next to ``report.md``: the table, its legend, a bar chart of the
    tracking figures, per pair a gait diagram and the tracking error over time, and the
    videos (with the eval report's page writer, :mod:`habitsim.evaluation.report`)."""
    from ..evaluation.report import _error_curves, _gait_diagram, _Page, clear_figures
    from ..fileio import atomic_write_text

    page = _Page(out / "report_files")
    clear_figures(out / "report_files")
    page.heading("habitsim demo report", 1)
    page.para(_INTRO.format(bvh=BVH_EXAMPLE, controller=ns.controller))
    lines = [ln for ln in table.splitlines() if not ln.startswith("|---")]
    cells = [[c.strip() for c in ln.strip().strip("|").split("|")] for ln in lines]
    page.table(cells[0], cells[1:])
    page.para(LEGEND)
    page.heading("Tracking per pair")
    page.image(
        _tracking_bars(rows, ns.controller),
        "tracking",
        "survival and simulated joint error (MPJPE / leg length) per pair, "
        f"with the {ns.controller} controller, unassisted and with root assistance",
    )
    page.heading("Gait diagrams and tracking error")
    for r, fig in zip(rows, figures, strict=True):
        title = f"{r['source']} → {r['target']}"
        slug = f"{r['source']}_{r['target']}"
        page.image(
            _gait_diagram(fig["panels"], fig["fps"], title),
            f"gait_{slug}",
            f"gait diagram (bars: foot in contact): {title}",
        )
        page.image(
            _error_curves(fig["curves"], title),
            f"err_{slug}",
            f"tracking error (simulated vs reference joints): {title}",
        )
    vids = [r for r in rows if r["video"]]
    page.heading("Videos")
    if not vids:
        page.para("No videos (--no-video, or no OpenGL backend here).")
    else:
        page.para(
            "The simulated body in its species' colour; the reference it tracks as a "
            "translucent blue ghost beside it; red discs under the feet in stance "
            "(solid: the simulation's foot contacts, faint: the reference's labels)."
        )
    for r in vids:
        page.video(
            f"pipeline/{r['video']}", f"{r['source']} → {r['target']}, {r['controller']} unassisted"
        )
    atomic_write_text(out / "report.html", page.document("habitsim demo report"))
    return out / "report.html"


def _tracking_bars(rows: list[dict], controller: str) -> bytes:
    from ..evaluation.report import _plt, _png

    plt = _plt()
    labels = [f"{r['source']} → {r['target']}" for r in rows]
    x = range(len(rows))
    fig, axes = plt.subplots(1, 2, figsize=(2.0 + 1.3 * len(rows), 3.4), squeeze=False)
    for ax, key, title in (
        (axes[0, 0], "survival", "survival ↑"),
        (axes[0, 1], "sim_mpjpe_per_leg", "sim MPJPE / leg ↓"),
    ):
        for j, (tag, colour) in enumerate((("unassisted", "#4477aa"), ("assisted", "#ee6677"))):
            vals = [r.get(f"{key}_{tag}") for r in rows]
            vals = [float("nan") if v is None else float(v) for v in vals]
            ax.bar(
                [i + (j - 0.5) * 0.38 for i in x],
                [0.0 if v != v else v for v in vals],
                width=0.38,
                color=colour,
                label=f"{controller} unassisted"
                if tag == "unassisted"
                else f"{controller} + assist",
            )
        ax.set_xticks(list(x))
        ax.set_xticklabels(labels, fontsize=7, rotation=30, ha="right")
        ax.set_title(title, fontsize=9)
        ax.tick_params(axis="y", labelsize=7)
    axes[0, 0].set_ylim(0, 1.05)
    handles, names = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, names, fontsize=7, loc="upper center", ncol=2, frameon=False)
    fig.tight_layout(rect=(0.0, 0.0, 1.0, 0.9))
    return _png(fig)


#: The legend printed under the console table (and under the table in the reports).
LEGEND = (
    "habit of = species whose habit prior was used (a held-out target borrows a training "
    "species'); contacts = how\nthe stance labels were found (decoded: the model's "
    "own, a foot that disagrees with the source taking\nthe source's footfalls; source "
    "footfalls; detected resting feet; or the target's duty factor);\nrefine/check = "
    "solver status and "
    "whether the refined clip was kept (reverted: it tracked worse); skate mm =\nfoot "
    "skating before → after refinement; survival = share of the clip before a fall (1 = "
    "no fall); MPJPE/leg =\nsimulated vs reference joint error / leg length (lower is "
    "better); assist m·g = mean external force that\nheld the assisted run up, in body "
    "weights; s = wall time of the pair. docs/metrics.md defines every metric."
)

_INTRO = (
    "Sources: a synthetic horse trot (habitsim.generate) and the shipped BVH example "
    "(habitsim/examples/{bvh}, imported onto the dog). Each is transferred with the "
    "shipped habit model, refined by CasADi/IPOPT (stage A: planted stance feet, no "
    "skating or penetration, joint limits) and tracked in MuJoCo: unassisted with the "
    "{controller} controller (no external force) and with the same controller plus "
    "measured root assistance (the external force it needed)."
)


def _fmt(v: object, nd: int = 3) -> str:
    return "-" if not isinstance(v, int | float) else f"{v:.{nd}f}"


def _table(rows: list[dict]) -> str:
    """The summary table (Markdown pipe table, readable as plain text)."""
    head = (
        "source",
        "target",
        "habit of",
        "contacts",
        "refine",
        "check",
        "skate mm before→after",
        "survival (unassisted)",
        "MPJPE/leg",
        "survival (assisted)",
        "MPJPE/leg",
        "assist m·g",
        "s",
    )
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        cells = [
            r["source"],
            r["target"],
            str(r["habit_from"]),
            str(r["contacts"]),
            str(r["refine_status"]),
            str(r["refine_check"]),
            f"{_fmt(r['skate_mm_before'], 2)}→{_fmt(r['skate_mm_after'], 2)}",
            _fmt(r["survival_unassisted"], 2),
            _fmt(r["sim_mpjpe_per_leg_unassisted"]),
            _fmt(r["survival_assisted"], 2),
            _fmt(r["sim_mpjpe_per_leg_assisted"]),
            _fmt(r["assist_force_mg"]),
            _fmt(r["seconds"], 1),
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _report(rows: list[dict], table: str, ns: argparse.Namespace) -> str:
    """The demo's Markdown report: what ran, the table, retrievals and videos."""
    out = [
        "# habitsim demo report",
        "",
        "Sources: a synthetic horse trot (`habitsim.generate`) and the shipped BVH example "
        f"(`habitsim/examples/{BVH_EXAMPLE}`, imported onto the dog). Each is transferred "
        "with the shipped `habit` model, refined by CasADi/IPOPT (stage A: planted stance "
        "feet, no skating or penetration, joint limits) and tracked in MuJoCo: unassisted "
        f"with the `{ns.controller}` controller (no external force) and with the same "
        "controller plus measured root assistance (the external force it needed).",
        "",
        table,
        "",
        "Columns: *habit of* = the species whose habit prior gave z_c (a held-out target "
        "borrows its nearest training species'); *contacts* = how the transfer's stance "
        "labels were found (`source`: the source's footfalls, `detected` from resting "
        "feet, `duty` from the target's duty factor where feet slide); *skate* = "
        "docs/metrics.md `skate_mm` before and after refinement; *check* = the refinement "
        "check (`kept`, or `reverted` when the refined clip tracked worse); *survival* = "
        "share of the clip before a fall; *MPJPE/leg* = simulated vs reference joint "
        "positions / leg length; *assist m·g* = mean assisting force.",
        "",
        "## Refinement check",
        "",
        "The refined clip is tracked against the unrefined one; a refinement that makes "
        "the clip track worse (lower survival, or equal survival and a clearly higher "
        "sim MPJPE) is not kept, and said so here.",
        "",
    ]
    out += [
        f"* {r['source']} → {r['target']}: {r['refine_check']}: {r['refine_note']}" for r in rows
    ]
    out.append("")
    held = [r for r in rows if r["retrieval"]]
    if held:
        out += ["## Held-out targets", ""]
        out += [f"* {r['source']} → {r['target']}: {r['retrieval']}" for r in held]
        out.append("")
    vids = [r for r in rows if r["video"]]
    if vids:
        out += ["## Videos", ""]
        out += [f"* [{r['source']} → {r['target']}](pipeline/{r['video']})" for r in vids]
        out.append("")
    return "\n".join(out)
