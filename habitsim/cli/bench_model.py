"""``habitsim bench model``: what a model's transfers look like, on synthetic and real input.

For a checkpoint (default: the shipped ``habit`` model) it prints, against the targets of
the learning core:

* **Reconstruction** of the fixed reference clips
  (:func:`habitsim.models.evaluate.reconstruction_error`): whole-clip MPJPE (root path
  integrated) and root-relative MPJPE, as % of leg length (targets ≤ 5 % and ≤ 2.5 %).
* **Gait kept**, on two source sets separately — synthetic clips (a data set's split, or
  clips generated in memory) and real motion capture (``--real DIR``, imported with
  :func:`habitsim.bvh_mapping.import_bvh`) — each source sent to every target species:
  the footfall phase error of the transfer (the circular distance between its touchdown
  phases relative to LH and the source's, mean over LF, RF, RH,
  :func:`habitsim.gait_stats.gait_statistics`; target ≤ 0.1 cycle, median), the share of
  transfers whose duty factor lies in the target's band for the gait, and how the
  transfer found its stance labels. The phases are those of the transfer's labels; the
  same error on the contacts detected on the output's own toes
  (:meth:`habitsim.motion.Motion.detect_contacts`) says whether the feet follow them.
* **Feet that rest**: on the frames a transfer labels in stance (this frame and the one
  before), the share where the toe moves at ≤ 0.1 leg lengths per second (target ≥ 90 %),
  for the transfer as :func:`habitsim.models.transfer.transfer` returns it (feet planted
  on its labels by leg IK) and for the decoder's own kinematics (``plant=False``), with
  how far the decoder's stance legs carry its body (the travel left when the stance toes
  are held still, :func:`habitsim.stance.planting.stance_driven_root`, over the decoded travel:
  1 for legs that push the body, near 0 for feet that slide along with it).
* **What the frozen evaluator sees** (:mod:`habitsim.evaluation.evaluator`, the
  classifier behind ``habitsim eval``'s habit and action accuracy): the share of
  transfers it classifies as the target species (targets it was trained on; target
  ≥ 0.95) and, for sources with an action label, as the source's action (target ≥ 0.85).
  A checkpoint can reconstruct better and still transfer worse; these two figures say so.
* **Size and latency**: ``model.safetensors`` (target ≤ 30 MB) and one 64-frame transfer
  (:func:`habitsim.cli.bench_train.transfer_latency`, target ≤ 20 ms).
"""

from __future__ import annotations

import argparse
import math
import statistics
import time
from pathlib import Path
from typing import Any

import numpy as np

from .conventions import add_check_option, add_list_option, check_exit

#: Targets of the learning core (issue "[2/5] Learning core v2").
TARGET_WHOLE_PCT = 5.0
TARGET_ROOT_REL_PCT = 2.5
TARGET_PHASE_ERROR = 0.1
TARGET_TOE_SPEED = 0.1  # leg lengths per second
TARGET_RESTING_SHARE = 0.9
TARGET_SIZE_MB = 30.0
TARGET_LATENCY_MS = 20.0
TARGET_HABIT_ACCURACY = 0.95
TARGET_ACTION_ACCURACY = 0.85
#: Cyclic actions whose footfall phases are compared.
CYCLIC_ACTIONS = ("walk", "trot", "pace", "canter", "gallop", "turn_left", "turn_right")
DEFAULT_TARGETS = ("cat", "dog", "horse", "camel", "elephant")


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``model`` to the ``bench`` command group."""
    p = sub.add_parser(
        "model",
        help="transfer quality of a model: reconstruction, gait kept, feet at rest, size",
        description=(
            "Print a model's reference-clip reconstruction error, the footfall phase error "
            "and resting stance feet of its transfers (synthetic and real sources "
            "separately), its size and latency, against the learning core's targets."
        ),
    )
    p.add_argument("--checkpoint", type=Path, metavar="CKPT", help="default: the shipped model")
    p.add_argument(
        "--data",
        type=Path,
        metavar="DIR",
        help="synthetic data set whose --split clips are the sources (default: clips "
        "generated in memory, 2 per training species and cyclic action)",
    )
    p.add_argument("--split", default="test", help="split of --data (default test)")
    p.add_argument(
        "--max-sources",
        type=int,
        default=40,
        metavar="N",
        help="at most N synthetic sources (default 40)",
    )
    p.add_argument(
        "--real",
        type=Path,
        metavar="DIR",
        help="folder of real motion-capture files (.bvh/.glb/.gltf) of --real-species",
    )
    p.add_argument(
        "--real-species", default="dog", help="species of the --real files (default dog)"
    )
    add_list_option(
        p,
        "--targets",
        default=list(DEFAULT_TARGETS),
        metavar="SPECIES",
        help=f"target species (default {','.join(DEFAULT_TARGETS)}; a source's own is skipped)",
    )
    add_check_option(p)
    p.set_defaults(func=_bench_model)


def _phase_error(out: dict[str, float], src: dict[str, float]) -> float:
    """Mean circular distance [cycle] of the LF, RF, RH touchdown phases (relative to LH)
    of a transfer and its source, over the feet whose source phase is defined; a foot the
    transfer does not step with counts 0.5 (the largest distance). NaN if the source has
    no defined phase."""
    errs = []
    for f in ("LF", "RF", "RH"):
        x, y = out.get(f), src.get(f)
        if y is None or not math.isfinite(y):
            continue
        if x is None or not math.isfinite(x):
            errs.append(0.5)
            continue
        d = (x - y) % 1.0
        errs.append(min(d, 1.0 - d))
    return float(np.mean(errs)) if errs else math.nan


def _resting_share(motion: Any) -> tuple[int, int]:
    """(stance frames whose toe moves ≤ the target speed, stance frames), both-frame rule."""
    c = np.asarray(motion.contacts, dtype=bool)
    feet = motion.foot_positions()
    v = np.linalg.norm(np.diff(feet, axis=0), axis=-1) * motion.fps / motion.species_info.leg_length
    on = c[1:] & c[:-1]
    return int((on & (v <= TARGET_TOE_SPEED)).sum()), int(on.sum())


def transfer_quality(
    sources: list[Any], targets: list[str], checkpoint: str | Path | None = None
) -> dict[str, Any]:
    """Gait and stance figures of every source × target transfer (``habit`` method)."""
    from ..errors import HabitsimError
    from ..evaluation.evaluator import load_evaluator
    from ..gait_stats import gait_statistics
    from ..gaits import action_gait
    from ..models.transfer import transfer
    from ..species import load_species
    from ..stance.planting import stance_driven_root

    phase, in_band, rest, stance = [], [], 0, 0
    methods: dict[str, int] = {}
    rest_raw = stance_raw = n = 0
    carried: list[float] = []
    phase_feet: list[float] = []
    outs: list[Any] = []
    wanted: list[tuple[str, str | None]] = []  # (target, source action) of each output
    for src in sources:
        src_phases = gait_statistics(src).phase_offsets if src.contacts is not None else {}
        action = src.metadata.get("action")
        for t in targets:
            if t == src.species:
                continue
            out = transfer(src, to=t, method="habit", checkpoint=checkpoint, seed=0)
            assert out.contacts is not None  # a transfer labels its output's stance
            n += 1
            outs.append(out)
            wanted.append((t, None if action is None else str(action)))
            how = out.metadata["transfer"]["contacts"]
            key = how["method"] + ("+source feet" if how.get("feet_from_source") else "")
            methods[key] = methods.get(key, 0) + 1
            r, s = _resting_share(out)
            rest, stance = rest + r, stance + s
            raw = transfer(src, to=t, method="habit", checkpoint=checkpoint, seed=0, plant=False)
            r, s = _resting_share(raw.with_contacts(out.contacts))
            rest_raw, stance_raw = rest_raw + r, stance_raw + s
            carried.append(stance_driven_root(raw, out.contacts)[1])
            gs = gait_statistics(out)
            if src_phases:  # sources that step (a real clip has no action label)
                e = _phase_error(gs.phase_offsets, src_phases)
                if math.isfinite(e):
                    phase.append(e)
                    # the same on the contacts the output's own toes show
                    seen = gait_statistics(out.with_contacts(out.detect_contacts()))
                    phase_feet.append(_phase_error(seen.phase_offsets, src_phases))
            if action in CYCLIC_ACTIONS:
                try:
                    habit = load_species(t).gaits.get(action_gait(t, str(action)))
                except HabitsimError:
                    habit = None
                if habit is not None and math.isfinite(gs.duty_factor):
                    lo, hi = habit.duty_factor
                    in_band.append(lo <= gs.duty_factor <= hi)
    ev = load_evaluator()
    pred = ev.predict(outs) if outs else None
    habit_ok = [
        pred.species[i] == t
        for i, (t, _) in enumerate(wanted)
        if pred is not None and t in ev.config.species
    ]
    action_ok = [
        pred.actions[i] == a
        for i, (_, a) in enumerate(wanted)
        if pred is not None and a in ev.config.actions
    ]
    return {
        "transfers": n,
        "habit_accuracy": float(np.mean(habit_ok)) if habit_ok else math.nan,
        "habit_classified": len(habit_ok),
        "action_accuracy": float(np.mean(action_ok)) if action_ok else math.nan,
        "action_classified": len(action_ok),
        "phase_error_median": statistics.median(phase) if phase else math.nan,
        "phase_error_share_ok": float(np.mean(np.array(phase) <= TARGET_PHASE_ERROR))
        if phase
        else math.nan,
        "phase_measured": len(phase),
        "phase_error_feet_median": statistics.median(phase_feet) if phase_feet else math.nan,
        "duty_in_band": float(np.mean(in_band)) if in_band else math.nan,
        "resting_share": rest / stance if stance else math.nan,
        "resting_share_decoder": rest_raw / stance_raw if stance_raw else math.nan,
        "carried_travel_median": statistics.median(carried) if carried else math.nan,
        "stance_frames": stance,
        "contact_methods": methods,
    }


def synthetic_sources(data: Path | None, split: str, limit: int) -> list[Any]:
    """Synthetic source clips of training species (cyclic actions first)."""
    from ..gaits import available_actions, generate
    from ..species import training_species

    out = []
    if data is not None:
        from ..dataset import iter_clips, load_manifest

        man = load_manifest(data)
        names = [s.name for s in training_species()]
        for entry, m in iter_clips(
            man, split=split, species=[s for s in man.species_names if s in names]
        ):
            if entry.action in CYCLIC_ACTIONS:
                out.append(m)
    else:
        for sp in training_species():
            for k, action in enumerate(a for a in available_actions(sp) if a in CYCLIC_ACTIONS):
                for rep in range(2):
                    out.append(generate(sp, action, seed=5000 + 10 * k + rep, duration_s=4.0))
    step = max(1, len(out) // max(1, limit))
    return out[::step][:limit]


def real_sources(folder: Path, species: str) -> list[Any]:
    """Every motion file of a folder imported onto ``species`` (planted retargeting)."""
    from ..bvh_mapping import import_bvh
    from ..dataset_import import SOURCE_SUFFIXES
    from ..errors import DatasetError

    files = sorted(p for p in folder.rglob("*") if p.suffix.lower() in SOURCE_SUFFIXES)
    if not files:
        raise DatasetError(f"{folder}: no motion file ({', '.join(SOURCE_SUFFIXES)}) for --real")
    return [import_bvh(f, species)[0] for f in files]


def _row(name: str, q: dict[str, Any]) -> list[str]:
    ok_p = q["phase_error_median"] <= TARGET_PHASE_ERROR
    ok_r = q["resting_share"] >= TARGET_RESTING_SHARE
    return [
        f"  {name}: {q['transfers']} transfers",
        f"    footfall phase error   median {q['phase_error_median']:.3f} cycle over "
        f"{q['phase_measured']} stepping transfers, {100 * q['phase_error_share_ok']:.0f} % ≤ "
        f"{TARGET_PHASE_ERROR} (target median ≤ {TARGET_PHASE_ERROR}: "
        f"{'met' if ok_p else 'MISSED'})",
        f"    (on the contacts detected on the output's toes: median "
        f"{q['phase_error_feet_median']:.3f} cycle)",
        "    duty factor in the target's band  "
        + (
            f"{100 * q['duty_in_band']:.0f} %"
            if np.isfinite(q["duty_in_band"])
            else "- (the sources' gait is not known)"
        ),
        f"    stance toes at rest    {100 * q['resting_share']:.1f} % of {q['stance_frames']} "
        f"stance frames ≤ {TARGET_TOE_SPEED} leg/s (target ≥ {100 * TARGET_RESTING_SHARE:.0f} %: "
        f"{'met' if ok_r else 'MISSED'})",
        f"    (decoder alone, feet not planted: {100 * q['resting_share_decoder']:.1f} %; its "
        f"stance legs carry the body {100 * q['carried_travel_median']:.0f} % of its decoded "
        "travel, median)",
        "    stance labels          "
        + ", ".join(f"{k} {v}" for k, v in sorted(q["contact_methods"].items())),
        "    evaluator              " + _accuracy_text(q),
    ]


def _accuracy_text(q: dict[str, Any]) -> str:
    """The frozen evaluator's habit and action accuracy of a set of transfers."""
    parts = []
    for key, what, target in (
        ("habit", "habit accuracy", TARGET_HABIT_ACCURACY),
        ("action", "action accuracy", TARGET_ACTION_ACCURACY),
    ):
        acc, n = q[f"{key}_accuracy"], q[f"{key}_classified"]
        if not n:
            why = "no target it knows" if key == "habit" else "the sources' action is not known"
            parts.append(f"{what} - ({why})")
            continue
        verdict = "met" if acc >= target else "MISSED"
        parts.append(f"{what} {acc:.3f} of {n} (target ≥ {target:g}: {verdict})")
    return "; ".join(parts)


def _bench_model(ns: argparse.Namespace) -> int:
    import torch

    from ..models.checkpoint import MODEL_FILE
    from ..models.evaluate import reconstruction_error, reference_motions
    from ..models.transfer import load_model
    from ..species import load_species
    from .bench_train import transfer_latency

    targets = [load_species(t).name for t in ns.targets]
    torch.set_num_threads(1)
    ck = load_model(ns.checkpoint)
    t0 = time.perf_counter()
    print(f"bench model ({ck.path}, variant {ck.config.model.variant}, config {ck.config.name})")
    missed: list[str] = []
    rec = reconstruction_error(reference_motions(), ns.checkpoint)
    whole, rel = rec["pct_leg"], rec["root_relative_pct_leg"]
    print(
        f"  reference clips  reconstruction {whole:.2f} % of leg length (target ≤ "
        f"{TARGET_WHOLE_PCT:g}: {'met' if whole <= TARGET_WHOLE_PCT else 'MISSED'}), "
        f"root-relative {rel:.2f} % (target ≤ {TARGET_ROOT_REL_PCT:g}: "
        f"{'met' if rel <= TARGET_ROOT_REL_PCT else 'MISSED'})"
    )
    if whole > TARGET_WHOLE_PCT:
        missed.append(f"reconstruction {whole:.2f} % > {TARGET_WHOLE_PCT:g} %")
    if rel > TARGET_ROOT_REL_PCT:
        missed.append(f"root-relative reconstruction {rel:.2f} % > {TARGET_ROOT_REL_PCT:g} %")
    sets = [("synthetic", synthetic_sources(ns.data, ns.split, ns.max_sources))]
    if ns.real is not None:
        sets.append(("real", real_sources(ns.real, ns.real_species)))
    for name, sources in sets:
        q = transfer_quality(sources, targets, ns.checkpoint)
        for line in _row(f"{name} sources ({len(sources)})", q):
            print(line)
        if not q["phase_error_median"] <= TARGET_PHASE_ERROR:
            missed.append(f"{name}: phase error {q['phase_error_median']:.3f}")
        if not q["resting_share"] >= TARGET_RESTING_SHARE:
            missed.append(f"{name}: stance toes at rest {100 * q['resting_share']:.1f} %")
        if q["habit_classified"] and q["habit_accuracy"] < TARGET_HABIT_ACCURACY:
            missed.append(f"{name}: habit accuracy {q['habit_accuracy']:.3f}")
        if q["action_classified"] and q["action_accuracy"] < TARGET_ACTION_ACCURACY:
            missed.append(f"{name}: action accuracy {q['action_accuracy']:.3f}")
    assert ck.path is not None  # a checkpoint loaded from its folder
    size = (Path(ck.path) / MODEL_FILE).stat().st_size / 1e6
    lat = transfer_latency(ns.checkpoint, 10)
    print(
        f"  model size       {size:.1f} MB (target ≤ {TARGET_SIZE_MB:g}: "
        f"{'met' if size <= TARGET_SIZE_MB else 'MISSED'}); transfer of 64 frames "
        f"{lat['end_to_end_median_ms']:.1f} ms median (target ≤ {TARGET_LATENCY_MS:g}: "
        f"{'met' if lat['end_to_end_median_ms'] <= TARGET_LATENCY_MS else 'MISSED'})"
    )
    if size > TARGET_SIZE_MB:
        missed.append(f"model size {size:.1f} MB")
    if lat["end_to_end_median_ms"] > TARGET_LATENCY_MS:
        missed.append(f"latency {lat['end_to_end_median_ms']:.1f} ms")
    print(f"  bench wall time  {time.perf_counter() - t0:.0f} s")
    return check_exit(missed, ns.check)
