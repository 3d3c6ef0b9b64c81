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
  (:func:`habitsim.evaluation.bench.train.transfer_latency`, target ≤ 20 ms).
"""

from __future__ import annotations

import math
import statistics
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "ModelOptions",
    "ModelInfo",
    "load",
    "phase_error",
    "quality_missed",
    "real_sources",
    "reconstruction",
    "resting_share",
    "size_and_latency",
    "source_sets",
    "synthetic_sources",
    "transfer_quality",
]

#: Targets of the learning core (issue "[2/5] Learning core v2"): reconstruction error,
#: whole and root-relative [% of leg length]; footfall phase error [share of a cycle];
#: stance toe speed [leg lengths/s]; resting share of stance frames; checkpoint size [MB];
#: transfer latency [ms]; evaluator habit and action accuracy [share].
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


@dataclass(frozen=True)
class ModelOptions:
    """What a ``bench model`` run does.

    Attributes:
        checkpoint: the checkpoint folder (None: the shipped model).
        data: synthetic data set whose ``split`` clips are the sources (None: clips
            generated in memory, 2 per training species and cyclic action).
        split: split of ``data``.
        max_sources: at most this many synthetic sources.
        real: folder of real motion-capture files (.bvh/.glb/.gltf) of ``real_species``.
        real_species: species of the ``real`` files.
        targets: target species (a source's own is skipped).
    """

    checkpoint: Path | None = None
    data: Path | None = None
    split: str = "test"
    max_sources: int = 40
    real: Path | None = None
    real_species: str = "dog"
    targets: tuple[str, ...] = DEFAULT_TARGETS


@dataclass(frozen=True)
class ModelInfo:
    """The checkpoint a run measures.

    Attributes:
        path: its folder.
        variant: the model variant.
        config: the name of its training configuration.
        targets: the run's target species (catalog names).
    """

    path: Path
    variant: str
    config: str
    targets: tuple[str, ...]


def load(options: ModelOptions) -> ModelInfo:
    """Check the targets, run torch on one thread and load the checkpoint.

    Raises:
        UnknownSpeciesError: an unknown target.
    """
    from habitsim.models.transfer import load_model
    from habitsim.species import load_species

    from .machine import torch_threads

    targets = tuple(load_species(t).name for t in options.targets)
    torch_threads(1)
    ck = load_model(options.checkpoint)
    assert ck.path is not None  # a checkpoint loaded from its folder
    return ModelInfo(Path(ck.path), ck.config.model.variant, ck.config.name, targets)


def reconstruction(options: ModelOptions) -> tuple[float, float, list[str]]:
    """Whole-clip and root-relative reconstruction error of the reference clips [% of
    leg length], and the targets they miss."""
    from habitsim.models.evaluate import reconstruction_error, reference_motions

    rec = reconstruction_error(reference_motions(), options.checkpoint)
    whole, rel = rec["pct_leg"], rec["root_relative_pct_leg"]
    missed = []
    if whole > TARGET_WHOLE_PCT:
        missed.append(f"reconstruction {whole:.2f} % > {TARGET_WHOLE_PCT:g} %")
    if rel > TARGET_ROOT_REL_PCT:
        missed.append(f"root-relative reconstruction {rel:.2f} % > {TARGET_ROOT_REL_PCT:g} %")
    return whole, rel, missed


def phase_error(out: dict[str, float], src: dict[str, float]) -> float:
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


def resting_share(motion: Any) -> tuple[int, int]:
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
    from habitsim.errors import HabitsimError
    from habitsim.evaluation.evaluator import load_evaluator
    from habitsim.gait_stats import gait_statistics
    from habitsim.gaits import action_gait
    from habitsim.models.transfer import transfer
    from habitsim.species import load_species
    from habitsim.stance.planting import stance_driven_root

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
            r, s = resting_share(out)
            rest, stance = rest + r, stance + s
            raw = transfer(src, to=t, method="habit", checkpoint=checkpoint, seed=0, plant=False)
            r, s = resting_share(raw.with_contacts(out.contacts))
            rest_raw, stance_raw = rest_raw + r, stance_raw + s
            carried.append(stance_driven_root(raw, out.contacts)[1])
            gs = gait_statistics(out)
            if src_phases:  # sources that step (a real clip has no action label)
                e = phase_error(gs.phase_offsets, src_phases)
                if math.isfinite(e):
                    phase.append(e)
                    # the same on the contacts the output's own toes show
                    seen = gait_statistics(out.with_contacts(out.detect_contacts()))
                    phase_feet.append(phase_error(seen.phase_offsets, src_phases))
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
    from habitsim.gaits import available_actions, generate
    from habitsim.species import training_species

    out = []
    if data is not None:
        from habitsim.dataset import iter_clips, load_manifest

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
    from habitsim.bvh_mapping import SOURCE_SUFFIXES, import_bvh
    from habitsim.errors import DatasetError

    files = sorted(p for p in folder.rglob("*") if p.suffix.lower() in SOURCE_SUFFIXES)
    if not files:
        raise DatasetError(f"{folder}: no motion file ({', '.join(SOURCE_SUFFIXES)}) for --real")
    return [import_bvh(f, species)[0] for f in files]


def source_sets(options: ModelOptions) -> list[tuple[str, list[Any]]]:
    """The source sets: ``synthetic``, and ``real`` with ``options.real``."""
    sets = [("synthetic", synthetic_sources(options.data, options.split, options.max_sources))]
    if options.real is not None:
        sets.append(("real", real_sources(options.real, options.real_species)))
    return sets


def quality_missed(name: str, q: dict[str, Any]) -> list[str]:
    """The targets :func:`transfer_quality`'s figures of source set ``name`` miss."""
    missed = []
    if not q["phase_error_median"] <= TARGET_PHASE_ERROR:
        missed.append(f"{name}: phase error {q['phase_error_median']:.3f}")
    if not q["resting_share"] >= TARGET_RESTING_SHARE:
        missed.append(f"{name}: stance toes at rest {100 * q['resting_share']:.1f} %")
    if q["habit_classified"] and q["habit_accuracy"] < TARGET_HABIT_ACCURACY:
        missed.append(f"{name}: habit accuracy {q['habit_accuracy']:.3f}")
    if q["action_classified"] and q["action_accuracy"] < TARGET_ACTION_ACCURACY:
        missed.append(f"{name}: action accuracy {q['action_accuracy']:.3f}")
    return missed


def size_and_latency(
    options: ModelOptions, info: ModelInfo
) -> tuple[float, dict[str, float], list[str]]:
    """The weights' size [MB], the transfer latency of 64 frames
    (:func:`habitsim.evaluation.bench.train.transfer_latency`, 10 repeats, [ms]) and the
    targets they miss."""
    from habitsim.models.checkpoint import MODEL_FILE

    from .train import transfer_latency

    size = (info.path / MODEL_FILE).stat().st_size / 1e6
    lat = transfer_latency(options.checkpoint, 10)
    missed = []
    if size > TARGET_SIZE_MB:
        missed.append(f"model size {size:.1f} MB")
    if lat["end_to_end_median_ms"] > TARGET_LATENCY_MS:
        missed.append(f"latency {lat['end_to_end_median_ms']:.1f} ms")
    return size, lat, missed
