"""``habitsim bench refine``: refinement speed, scaling, success rate and tracking survival.

In one run:

* per species (or ``--species``) and stage (``--stages``, default A and B): the time to
  build the window problem (once per process), and the median over ``--clips``
  100-frame, 30 fps synthetic clips with injected artefacts (slide, sink, jitter,
  limits; :func:`habitsim.refine.inject_artefacts`) of the IPOPT solve time summed over
  the windows (``solve``), of the wall time of the whole :func:`habitsim.refine.refine`
  call without metrics (``call``) and of the process CPU time over that same call
  (``cpu``: every thread's, so up to the core count × ``call`` when IPOPT's linear
  algebra runs threaded; on a shared machine the fairest of the three). The window
  problems are built before the clocks start, so no column counts building (the
  ``build`` column times it once). The legend gives the process' thread count: IPOPT's
  linear algebra runs on the OpenBLAS thread pool, whose threads spin on a busy machine
  (with ``OMP_NUM_THREADS=1``, ``cpu`` ≈ ``call``). Targets of the issue: stage A
  ≤ 0.5 s, stage B ≤ 2 s per clip;
* survival of unassisted tracking (:func:`habitsim.sim.track`; ``--survival-controller``,
  default ``mpc``) of the same clips before and after stage-A refinement, per species
  (target: after ≥ before);
* scaling on ``--scaling-species``: solve time of 100, 300 and 1000 frames (``--lengths``)
  per stage, with the time per frame (linear growth = constant time per frame);
* IPOPT success rate over ``--success-clips`` clips per stage of random species, action
  and artefact mix (target ≥ 98 %).

Benchmarks print figures; nothing here is a timed test.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from typing import Any

import numpy as np

from .conventions import add_check_option, add_list_option, check_exit, format_legend

#: Median solve-time targets per 100-frame clip [s].
TARGET_S = {"A": 0.5, "B": 2.0}
#: Controllers the survival runs may use (unassisted).
_SURVIVAL_CONTROLLERS = ("servo", "servo+stance", "balance", "mpc")
#: Target IPOPT success rate on artefact clips.
TARGET_SUCCESS = 0.98
_ARTEFACTS = ("slide", "sink", "jitter", "limits")
#: A reported build time below this [s] is a cache lookup, not a build.
_BUILD_NOISE_S = 0.01


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
        choices=_SURVIVAL_CONTROLLERS,
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
    p.add_argument("--seed", type=int, default=0, metavar="S", help="seed (default 0)")
    p.add_argument("--json", action="store_true", help="also print one JSON object at the end")
    add_check_option(
        p,
        help="exit with code 1 when a target is MISSED: a stage's median solve "
        "time, the success rate, or survival after refinement below survival "
        "before (default: print the verdicts, exit 0)",
    )
    p.set_defaults(func=_bench_refine)


def _clip(
    species: str,
    frames: int,
    seed: int,
    action: str | None = None,
    kinds: tuple[str, ...] = _ARTEFACTS,
) -> Any:
    from ..gaits import available_actions, generate
    from ..refine import inject_artefacts

    rng = np.random.default_rng(seed)
    acts = [a for a in available_actions(species) if a not in ("sit",)]
    act = action or ("walk" if "walk" in acts else acts[0])
    clean = generate(
        species, act, seed=int(rng.integers(1 << 30)), fps=30.0, duration_s=frames / 30.0
    )
    return inject_artefacts(clean, kinds, seed=seed)


def _test_split(data: str) -> list[tuple[str, str, Any]]:
    """(species, action, motion) of every test-split clip of a data set."""
    from ..dataset import iter_clips

    return [(e.species, e.action, m) for e, m in iter_clips(data, split="test")]


def _test_window(
    clips: list[tuple[str, str, Any]], rng: np.random.Generator, frames: int, kinds: tuple[str, ...]
) -> tuple[str, str, Any]:
    """A random ``frames``-long window of a random test clip with artefacts injected."""
    from ..refine import inject_artefacts

    sp, act, m = clips[int(rng.integers(len(clips)))]
    start = int(rng.integers(max(m.num_frames - frames, 0) + 1))
    win = m.slice(start, start + frames)
    return sp, act, inject_artefacts(win, kinds, seed=int(rng.integers(1 << 30)))


def _prebuild(motion: Any, opts: Any) -> float:
    """Build (or fetch from the cache) the window problems of a clip; wall time [s]."""
    from ..refine.solve import get_problem

    t0 = time.perf_counter()
    for n in sorted({w.length for w in opts.plan(motion.num_frames)}):
        get_problem(motion.species, n, opts.dynamics, opts.settings)
    return time.perf_counter() - t0


def _os_threads() -> int | None:
    """Threads of this process (native ones too, e.g. the BLAS pool); None off Linux."""
    try:
        return len(os.listdir("/proc/self/task"))
    except OSError:
        return None


def _timed(motion: Any, stage: str) -> dict[str, float | bool]:
    """Solve, wall and CPU time of one refinement, its problems built beforehand.

    ``call`` and ``cpu`` cover the same interval; a problem the call still builds (a
    retry with other solver settings) is taken off ``call`` and counted in ``build``,
    and ``cpu`` then includes it (``cpu_includes_build``).
    """
    from ..refine import RefineConvergenceError, RefineOptions, refine

    opts = RefineOptions(dynamics=stage == "B", metrics=False)
    prebuilt = _prebuild(motion, opts)
    w0, c0 = time.perf_counter(), time.process_time()
    try:
        res = refine(motion, opts)
        ok, solve, build = True, res.report["solve_time_s"], res.report["build_time_s"]
        iters = res.report["iterations"]
    except RefineConvergenceError as e:
        ok, solve, build = False, float("nan"), e.report.get("build_time_s", 0.0)
        iters = e.report.get("iterations", 0)
        res = None
    cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    return {
        "ok": ok,
        "solve": solve,
        "call": wall - build,
        "cpu": cpu,
        "cpu_includes_build": build > _BUILD_NOISE_S,
        "build": prebuilt + build,
        "iterations": iters,
        "result": res,
    }


def _survival(motion: Any, controller: str) -> float:
    from ..sim import track

    return float(track(motion, controller=controller).survival)


def _fmt(v: float, width: int = 7) -> str:
    return f"{v:{width}.3f}" if np.isfinite(v) else f"{'—':>{width}}"


def _bench_refine(ns: argparse.Namespace) -> int:
    from ..errors import HabitsimError
    from ..gaits import available_actions
    from ..refine import RefineOptions
    from ..refine.solve import get_problem
    from ..species import species_names

    species = ns.species or species_names()
    out: dict[str, Any] = {"species": {}, "scaling": {}, "success": {}}
    missed: list[str] = []
    print(
        f"bench refine: {ns.clips} clip(s) of 100 frames at 30 fps per species and stage, "
        f"artefacts {', '.join(_ARTEFACTS)}; times [s]; targets: stage A ≤ "
        f"{TARGET_S['A']} s, stage B ≤ {TARGET_S['B']} s per clip"
    )
    head = f"{'species':10s}"
    for st in ns.stages:
        head += f" | {st}: build   solve    call     cpu  iters"
    if not ns.no_survival:
        head += " | survival before → after"
    print(head)
    for sp in species:
        row = f"{sp:10s}"
        rec: dict[str, Any] = {}
        clips = [_clip(sp, 100, ns.seed + k) for k in range(ns.clips)]
        for st in ns.stages:
            t0 = time.perf_counter()
            opts = RefineOptions(dynamics=st == "B")
            get_problem(sp, opts.plan(100)[0].length, opts.dynamics, opts.settings)
            build = time.perf_counter() - t0
            runs = [_timed(c, st) for c in clips]
            good = [r for r in runs if r["ok"]]
            med = {
                k: statistics.median([r[k] for r in good]) if good else float("nan")
                for k in ("solve", "call", "cpu", "iterations")
            }
            rec[st] = {
                "build_s": build,
                **{f"median_{k}": v for k, v in med.items()},
                "failed": len(runs) - len(good),
            }
            flag = "" if not good or med["solve"] <= TARGET_S[st] else "!"
            row += (
                f" | {_fmt(build, 8)} {_fmt(med['solve'])}{flag:1s}{_fmt(med['call'])}"
                f" {_fmt(med['cpu'])} {med['iterations']:5.0f}"
            )
            if st == "A":
                rec["_results"] = [r["result"] for r in runs]
        if not ns.no_survival:
            ctl = ns.survival_controller
            before = [_survival(c, ctl) for c in clips]
            after = [_survival(r.motion, ctl) for r in rec.get("_results", []) if r is not None]
            rec["survival_before"] = float(np.mean(before))
            rec["survival_after"] = float(np.mean(after)) if after else float("nan")
            row += f" | {rec['survival_before']:.2f} → {_fmt(rec['survival_after'], 4)}"
        rec.pop("_results", None)
        out["species"][sp] = rec
        print(row, flush=True)
    print(
        format_legend(
            "(build: building the window problem once, wall [s]; solve: IPOPT time summed over "
            "the windows; call: wall time of the refine() call, problems already built; cpu: "
            "process CPU time over that call, all threads (up to the core count × call; this "
            f"process runs {_os_threads() or '?'} threads, {os.cpu_count()} CPU(s)); iters: "
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
    for sp, rec in out["species"].items():
        for st in ns.stages:
            med = rec[st]["median_solve"]
            if not med <= TARGET_S[st]:  # NaN (every clip failed) misses too
                missed.append(f"{sp} stage {st} median solve {med:.3f} s > {TARGET_S[st]} s")
        s_before, s_after = rec.get("survival_before"), rec.get("survival_after")
        if s_before is not None and not s_after >= s_before:
            missed.append(f"{sp} survival after refinement {s_after:.2f} < before {s_before:.2f}")

    # ---------------------------------------------------------------- scaling
    print(f"\nscaling on {ns.scaling_species} (solve time summed over windows, one clip each):")
    for st in ns.stages:
        parts = []
        for n in ns.lengths:
            r = _timed(_clip(ns.scaling_species, n, ns.seed + 100), st)
            out["scaling"].setdefault(st, {})[n] = {
                k: r[k] for k in ("ok", "solve", "call", "cpu", "build")
            }
            parts.append(
                f"{n} frames: solve {_fmt(r['solve'], 6)} s ({1000 * r['solve'] / n:5.2f} "
                f"ms/frame), call {_fmt(r['call'], 6)} s wall, cpu {_fmt(r['cpu'], 6)} s"
                + (" incl. a build" if r["cpu_includes_build"] else "")
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
    rng = np.random.default_rng(ns.seed + 7)
    test_clips = _test_split(ns.data) if ns.data else None
    source = (
        f"windows of the {len(test_clips)} test-split clips of {ns.data}"
        if test_clips
        else "random species and action"
    )
    print(
        f"\nIPOPT success on {ns.success_clips} random artefact clips per stage "
        f"(100 frames, {source}, random artefact mix):"
    )
    for st in ns.stages:
        ok = tried = 0
        fails = []
        drawn = []
        for _ in range(ns.success_clips):
            kinds = tuple(a for a in _ARTEFACTS + ("float",) if rng.random() < 0.5) or ("slide",)
            sp = act = "?"
            try:
                if test_clips:
                    sp, act, m = _test_window(test_clips, rng, 100, kinds)
                else:
                    sp = str(rng.choice(species))
                    act = str(rng.choice(available_actions(sp)))
                    m = _clip(sp, 100, int(rng.integers(1 << 30)), act, kinds)
            except HabitsimError as e:  # an action that cannot be generated at this length
                fails.append(f"{sp}/{act}: {e}")
                continue
            drawn.append((sp, act, kinds, m))
        # solved grouped by species: the process keeps only a few built problems
        for sp, act, kinds, m in sorted(drawn, key=lambda d: d[0]):
            r = _timed(m, st)
            tried += 1
            ok += bool(r["ok"])
            if not r["ok"]:
                fails.append(f"{sp}/{act}/{'+'.join(kinds)}")
        rate = ok / max(tried, 1)
        verdict = "met" if rate >= TARGET_SUCCESS else "MISSED"
        out["success"][st] = {"rate": rate, "failed": fails}
        if rate < TARGET_SUCCESS:
            missed.append(
                f"stage {st} IPOPT success {100 * rate:.1f} % < {100 * TARGET_SUCCESS:.0f} %"
            )
        print(
            f"  stage {st}: {ok}/{tried} = {100 * rate:.1f} % "
            f"(target ≥ {100 * TARGET_SUCCESS:.0f} %: {verdict})"
            + (f"; failed: {', '.join(fails[:6])}" if fails else "")
        )
    if ns.json:
        from ..refine.report import clean_json

        print(json.dumps(clean_json(out)))
    return check_exit(missed, ns.check)
