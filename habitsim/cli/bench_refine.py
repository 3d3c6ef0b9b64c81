"""``habitsim bench refine``: refinement speed, scaling, success rate and tracking survival.

The benchmark is :mod:`habitsim.evaluation.bench.refine`: per species and stage the time
to build the window problem and the median IPOPT solve, call and CPU time over artefact
clips; the tracking survival before and after stage-A refinement; the solve time of
longer clips; IPOPT's success rate over random artefact clips. This module parses its
options and prints one line per species, the scaling and the success rates against the
issue's targets (``--json``: also one JSON object at the end).

Benchmarks print figures; nothing here is a timed test.
"""

from __future__ import annotations

import argparse
import json
import math
from typing import Any

from ..evaluation.bench.refine import (
    ARTEFACTS,
    CLEAN_SECONDS,
    SURVIVAL_CONTROLLERS,
    TARGET_CLEAN_CHANGE,
    TARGET_S,
    TARGET_SUCCESS,
)
from .conventions import add_check_option, add_list_option, check_exit, format_legend


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``refine`` to the ``bench`` command group."""
    p = sub.add_parser(
        "refine",
        help="refinement solve time per species (stage A/B), scaling, success rate",
        description=(
            "Median solve time of 100-frame artefact clips per species and stage, tracking "
            "survival before/after, time for 100/300/1000 frames, IPOPT success rate."
        ),
    )
    add_list_option(p, "--species", help="species (default: all)")
    add_list_option(
        p,
        "--stages",
        choices=("A", "B"),
        default=["A", "B"],
        metavar="STAGE",
        help="stages to time (default A B)",
    )
    p.add_argument(
        "--clips",
        type=int,
        default=3,
        metavar="N",
        help="100-frame clips per species and stage (default 3)",
    )
    p.add_argument("--no-survival", action="store_true", help="skip the tracking survival")
    p.add_argument(
        "--survival-controller",
        default="mpc",
        choices=SURVIVAL_CONTROLLERS,
        help="unassisted controller of the survival runs (default mpc, the controller that "
        "keeps most clips up; plain servo PD falls within about a second whatever the "
        "motion, which would compare noise)",
    )
    p.add_argument(
        "--data",
        metavar="DIR",
        help="draw the success-rate clips from the test split of this data set (habitsim "
        "data synth; a random 100-frame window of a random clip, random artefact mix); "
        "default: freshly generated clips of random species and actions",
    )
    p.add_argument(
        "--scaling-species",
        default="dog",
        metavar="NAME",
        help="species of the scaling run (default dog)",
    )
    add_list_option(
        p,
        "--lengths",
        convert=int,
        default=[100, 300, 1000],
        metavar="T",
        help="clip lengths of the scaling run (default 100 300 1000)",
    )
    p.add_argument(
        "--success-clips",
        type=int,
        default=50,
        metavar="M",
        help="random artefact clips per stage for the success rate (default 50)",
    )
    p.add_argument(
        "--dir",
        metavar="DIR",
        help="the clean-input rows on real clips: the first 4 s window of every clip "
        "(BVH, glTF/GLB) of this folder, imported onto the dog as bench real imports "
        "them (default: the species' own synthetic walks)",
    )
    p.add_argument(
        "--clean-windows",
        type=int,
        default=1,
        metavar="N",
        help="with --dir: the first N 4 s locomotion windows of every clip (default 1)",
    )
    p.add_argument("--seed", type=int, default=0, metavar="S", help="seed (default 0)")
    p.add_argument("--json", action="store_true", help="also print one JSON object at the end")
    add_check_option(
        p,
        help="exit with code 1 when a target is MISSED: a stage's median solve "
        "time, the success rate, survival after refinement below survival "
        "before, or a clean clip moved by more than 1 %% of leg length (default: "
        "print the verdicts, exit 0)",
    )
    p.set_defaults(func=_bench_refine)


def _fmt(v: float, width: int = 7) -> str:
    return f"{v:{width}.3f}" if math.isfinite(v) else f"{'—':>{width}}"


def _bench_refine(ns: argparse.Namespace) -> int:
    from ..evaluation.bench.machine import cpu_count, os_threads
    from ..evaluation.bench.refine import (
        RefineBenchOptions,
        scaling,
        species_missed,
        species_of,
        species_timing,
        success_rates,
        test_split,
    )

    opts = RefineBenchOptions(
        species=tuple(ns.species or ()),
        stages=tuple(ns.stages),
        clips=ns.clips,
        survival=not ns.no_survival,
        survival_controller=ns.survival_controller,
        data=ns.data,
        scaling_species=ns.scaling_species,
        lengths=tuple(ns.lengths),
        success_clips=ns.success_clips,
        seed=ns.seed,
    )
    species = species_of(opts)
    out: dict[str, Any] = {"species": {}, "scaling": {}, "success": {}}
    print(
        f"bench refine: {ns.clips} clip(s) of 100 frames at 30 fps per species and stage, "
        f"artefacts {', '.join(ARTEFACTS)}; times [s]; targets: stage A ≤ "
        f"{TARGET_S['A']} s, stage B ≤ {TARGET_S['B']} s per clip"
    )
    head = f"{'species':10s}"
    for st in ns.stages:
        head += f" | {st}: build   solve    call     cpu  iters"
    if not ns.no_survival:
        head += " | survival before → after"
    print(head)
    timings = []
    for sp in species:
        t = species_timing(sp, opts)
        timings.append(t)
        rec = t.record
        row = f"{sp:10s}"
        for st in ns.stages:
            r = rec[st]
            flag = "!" if t.over_target[st] else ""
            row += (
                f" | {_fmt(r['build_s'], 8)} {_fmt(r['median_solve'])}{flag:1s}"
                f"{_fmt(r['median_call'])} {_fmt(r['median_cpu'])} {r['median_iterations']:5.0f}"
            )
        if not ns.no_survival:
            row += f" | {rec['survival_before']:.2f} → {_fmt(rec['survival_after'], 4)}"
        out["species"][sp] = rec
        print(row, flush=True)
    print(
        format_legend(
            "(build: building the window problem once, wall [s]; solve: IPOPT time summed over "
            "the windows; call: wall time of the refine() call, problems already built; cpu: "
            "process CPU time over that call, all threads (up to the core count × call; this "
            f"process runs {os_threads() or '?'} threads, {cpu_count()} CPU(s)); iters: "
            "IPOPT iterations; medians over the clips; ! = solve over the target"
            + (
                ""
                if ns.no_survival
                else f"; survival: unassisted {ns.survival_controller} tracking, share of the clip "
                "completed, before → after stage-A refinement"
            )
            + ")"
        )
    )
    missed = species_missed(timings, opts.stages)

    # ---------------------------------------------------------------- scaling
    print(f"\nscaling on {ns.scaling_species} (solve time summed over windows, one clip each):")
    for st in ns.stages:
        parts = []
        for n, r in scaling(opts, st):
            out["scaling"].setdefault(st, {})[n] = r.scaling_dict()
            parts.append(
                f"{n} frames: solve {_fmt(r.solve, 6)} s ({1000 * r.solve / n:5.2f} "
                f"ms/frame), call {_fmt(r.call, 6)} s wall, cpu {_fmt(r.cpu, 6)} s"
                + (" incl. a build" if r.cpu_includes_build else "")
            )
        print(f"  stage {st}: " + "; ".join(parts))
    print(
        format_legend(
            "(solve: IPOPT time summed over the windows; call and cpu: the whole "
            "refine() call, window problems built beforehand; cpu counts every "
            "thread of the process)",
            indent="  ",
        )
    )

    # ---------------------------------------------------------------- success
    test_clips = test_split(ns.data) if ns.data else None
    source = (
        f"windows of the {len(test_clips)} test-split clips of {ns.data}"
        if test_clips
        else "random species and action"
    )
    print(
        f"\nIPOPT success on {ns.success_clips} random artefact clips per stage "
        f"(100 frames, {source}, random artefact mix):"
    )
    for sr in success_rates(opts, species, test_clips):
        verdict = "met" if sr.missed is None else "MISSED"
        out["success"][sr.stage] = {"rate": sr.rate, "failed": sr.failed}
        if sr.missed is not None:
            missed.append(sr.missed)
        print(
            f"  stage {sr.stage}: {sr.ok}/{sr.tried} = {100 * sr.rate:.1f} % "
            f"(target ≥ {100 * TARGET_SUCCESS:.0f} %: {verdict})"
            + (f"; failed: {', '.join(sr.failed[:6])}" if sr.failed else "")
        )
    # ---------------------------------------------------------------- clean input
    from ..evaluation.bench.refine import clean_real, clean_synthetic

    kind = f"the first window of every clip of {ns.dir}" if ns.dir else "synthetic walks"
    print(f"\nclean input, refined as it is (stage A, {CLEAN_SECONDS:g} s at 30 fps, {kind}):")
    rows = (
        clean_real(ns.dir, windows_per_clip=ns.clean_windows)
        if ns.dir
        else clean_synthetic(species, ns.seed)
    )
    out["clean_input"] = []
    n = n_met = 0
    for c in rows:
        n += 1
        n_met += c.met
        out["clean_input"].append(dict(vars(c)))
        print(
            f"  {c.name:34s} change max {100 * c.max:5.2f} % median {100 * c.median:5.2f} % "
            f"(one joint {100 * c.joint_max:5.2f} %; model's closest pose max "
            f"{100 * c.floor_max:5.2f} % median {100 * c.floor_median:5.2f} %); "
            f"skate {c.skate_before:.2f} → "
            f"{c.skate_after:.2f} mm/frame, penetration {c.penetration_before:.2f} → "
            f"{c.penetration_after:.2f} mm; call {_fmt(c.call, 5)} s, cpu {_fmt(c.cpu, 5)} s"
            + (f", {c.retries} guard solve{'' if c.retries == 1 else 's'}" if c.retries else "")
            + ("" if c.ok else " FAILED")
        )
    verdict = "met" if n_met == n else "MISSED"
    print(
        f"  target: every frame of a clean clip within {100 * TARGET_CLEAN_CHANGE:g} % of leg "
        f"length of its input: {n_met} of {n} clips ({verdict})"
    )
    print(
        format_legend(
            "(change: per frame the mean over the joints of their position change / leg "
            "length, its max and median over the frames; one joint: the largest change of "
            "any joint in any frame; model's closest pose: the same of the model's poses "
            "nearest the input, every hinge in range, no contact, which no refinement can "
            "beat; call: wall time of the refine() call less builds; cpu: "
            "process CPU time over it)",
            indent="  ",
        )
    )
    if n_met < n:
        missed.append(
            f"clean input moved by more than {100 * TARGET_CLEAN_CHANGE:g} % of leg length "
            f"on {n - n_met} of {n} clips"
        )
    if ns.json:
        from ..refine.report import clean_json

        print(json.dumps(clean_json(out)))
    return check_exit(missed, ns.check)
