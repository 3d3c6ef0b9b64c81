"""``habitsim bench t2m``: the text-to-motion protocol of the papers (Guo et al. 2022).

Measured with a text–motion evaluator (:mod:`habitsim.evaluation.t2m_evaluator`), per
split (the prompts of each: :mod:`habitsim.evaluation.bench.t2m_splits`: ``val``,
held-out compositions ``compose``, held-out paraphrases ``paraphrase``, human-written
prompts ``human``), one prompt per clip (a caption drawn with the seed):

* **R-precision top-1/2/3**: the clips are shuffled (seeded) into batches of
  ``batch_size`` (32, as the papers; an incomplete last batch is dropped); in each batch
  every caption ranks the batch's motions by distance and counts whether its own motion
  is among the first k.
* **FID** between the motions' embeddings and those of the real ``train`` clips (the
  reference set). The ground-truth row's FID is the distance of the split's real clips to
  the reference, the floor a generator is compared with.
* **MM-Dist**: mean distance between each caption and its motion.
* **Diversity**: mean distance between the embeddings of random pairs of motions.
* **Prompt agreement**: the share of motions whose action, measured by
  :func:`habitsim.captions.clip_facts`, is the one the prompt asks for (the ground
  truth's: its own clips, the ceiling of the measurement). The human prompts have no
  real motion: their rows have this column only.

Rows per split: ground truth (the real clips) first, then the generator at each guidance
scale, generating from each prompt a motion of its species and length (seed + i). With
``physics`` > 0, the first walks, trots and turns of each split also go through
:func:`habitsim.pipeline.run_text` (refinement A, unassisted ``mpc``) and their survival
is reported; ``unsupported`` human prompts outside the test check the warning and
refusal path. Targets: R-precision top-3 ≥ 0.80 and FID ≤ 2× the ground truth's on the
held-out compositions, ≥ 70 % prompt agreement on the human prompts, ≥ 90 % of the
tracked clips surviving.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from habitsim.errors import HabitsimError
from habitsim.motion import Motion

from ..distribution import diversity, fid
from ..t2m_evaluator import (
    Embedder,
    captioned_clips,
    load_t2m_evaluator,
    matching_distance,
    r_precision,
)
from .targets import TargetCheck, Verdict, verdict

__all__ = [
    "T2MBenchOptions",
    "T2MRow",
    "PhysicsRow",
    "UnsupportedRow",
    "T2MBenchResult",
    "BenchT2MError",
    "run_t2m",
    "t2m_checks",
]


class BenchT2MError(HabitsimError, ValueError):
    """Input the text-to-motion protocol cannot run on (too few clips, no data set)."""


@dataclass(frozen=True)
class T2MBenchOptions:
    """Settings of the protocol.

    Attributes:
        guidances: guidance scales of the generator rows.
        splits: the splits measured (:data:`~habitsim.evaluation.bench.t2m_splits.SPLITS`:
            ``val``, ``compose``, ``paraphrase``, ``human``; ``train``).
        batch_size: R-precision batch (each caption against its motion and B − 1 others);
            a split with fewer prompts gets no R-precision (NaN).
        top_k: the largest k of R-precision.
        limit: measure at most this many prompts per split (None: all).
        diversity_pairs: random pairs of the diversity figure.
        seed: seed of the caption draw, the batch shuffle and the generation.
        r3_target: R-precision top-3 a generator row must reach (``compose``).
        fid_ratio_target: largest FID of a generator row, as a multiple of the ground
            truth's (``compose``).
        agreement_target: share of the human prompts whose generated clip shows the
            action asked for.
        physics: walks, trots and turns per split refined (stage A) and tracked
            unassisted under ``mpc`` (0: none).
        physics_seconds: their length [s].
        physics_guidance: their guidance scale.
        survival_target: share of them that must survive the whole clip.
        unsupported: human prompts outside the test answered per run (their warning or
            refusal is checked; 0: none).
    """

    guidances: tuple[float, ...] = (1.0, 2.0, 3.0)
    splits: tuple[str, ...] = ("val", "compose", "paraphrase", "human")
    batch_size: int = 32
    top_k: int = 3
    limit: int | None = None
    diversity_pairs: int = 300
    seed: int = 0
    r3_target: float = 0.80
    fid_ratio_target: float = 2.0
    agreement_target: float = 0.70
    physics: int = 0
    physics_seconds: float = 4.0
    physics_guidance: float = 2.0
    survival_target: float = 0.90
    unsupported: int = 40


@dataclass(frozen=True)
class T2MRow:
    """One row of the table.

    Attributes:
        split: the split of the prompts.
        name: ``ground truth`` or ``generator``.
        guidance: the generator's guidance scale (None for ground truth).
        clips: motions measured.
        r_precision: top-1 … top-k shares (NaN: fewer prompts than a batch, or no real
            motion to rank).
        fid: FID against the real train clips' embeddings (NaN for the human prompts).
        mm_dist: mean caption↔motion distance.
        diversity: mean distance of random motion pairs.
        prompt_agreement: share of the motions whose measured action
            (:func:`habitsim.captions.clip_facts`) is the one the prompt asks for.
    """

    split: str
    name: str
    guidance: float | None
    clips: int
    r_precision: tuple[float, ...]
    fid: float
    mm_dist: float
    diversity: float
    prompt_agreement: float


@dataclass(frozen=True)
class PhysicsRow:
    """Generated walks, trots and turns of one split, refined and tracked.

    Attributes:
        split: the split; clips: clips tracked; survived: share that survived the whole
        clip; mean_survival: mean survival share; refused: prompts skipped (a species
        the text and the split disagree on).
    """

    split: str
    clips: int
    survived: float
    mean_survival: float
    refused: int


@dataclass(frozen=True)
class UnsupportedRow:
    """Human prompts outside the test: how each was answered.

    Attributes:
        prompts: prompts tried; refused: refused with a typed error (no catalog species);
        warned: generated with a warning; silent: generated without one (the prompt
        named an action habitsim makes and the clip showed it).
    """

    prompts: int
    refused: int
    warned: int
    silent: int


@dataclass(frozen=True)
class T2MBenchResult:
    """The table and where it was measured."""

    data: str
    splits: tuple[str, ...]
    evaluator: str
    checkpoint: str | None
    rows: list[T2MRow] = field(default_factory=list)
    physics: list[PhysicsRow] = field(default_factory=list)
    unsupported: UnsupportedRow | None = None

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["rows"] = [asdict(r) for r in self.rows]
        return d


def batched_r_precision(
    text: np.ndarray, motion: np.ndarray, batch_size: int, top_k: int, seed: int
) -> tuple[np.ndarray, int]:
    """R-precision over seeded batches of ``batch_size`` (incomplete last batch dropped).

    Args:
        text: (N, D) caption embeddings; motion: (N, D), row i the motion of caption i.

    Returns:
        ((top_k,) mean shares over the batches, number of batches).

    Raises:
        BenchT2MError: fewer than ``batch_size`` pairs.
    """
    n = len(text)
    if n < batch_size or batch_size < 2:
        raise BenchT2MError(
            f"R-precision needs at least one batch of {batch_size} captioned clips (and a "
            f"batch of ≥ 2); there are {n}: use more clips or a batch size in 2…{max(n, 2)}"
        )
    order = np.random.default_rng(seed).permutation(n)
    batches = n // batch_size
    out = [
        r_precision(text[idx], motion[idx], top_k)
        for idx in np.split(order[: batches * batch_size], batches)
    ]
    return np.mean(out, axis=0), batches


def _row(
    split: str,
    name: str,
    guidance: float | None,
    zt: np.ndarray,
    zm: np.ndarray | None,
    ref: np.ndarray,
    agreement: float,
    opts: T2MBenchOptions,
) -> T2MRow:
    nan = float("nan")
    if zm is None:  # no motion to rank: prompt agreement only
        return T2MRow(split, name, guidance, len(zt), (nan,) * opts.top_k, nan, nan, nan, agreement)
    if len(zt) >= opts.batch_size and zm is not None:
        rp, _ = batched_r_precision(zt, zm, opts.batch_size, opts.top_k, opts.seed)
        rps = tuple(round(float(v), 4) for v in rp)
    else:
        rps = (nan,) * opts.top_k
    return T2MRow(
        split,
        name,
        guidance,
        len(zm),
        rps,
        round(fid(zm, ref), 4) if len(zm) >= 2 else nan,
        round(matching_distance(zt, zm), 4) if len(zt) else nan,
        round(diversity(zm, n_pairs=opts.diversity_pairs, seed=opts.seed), 4)
        if len(zm) >= 2
        else nan,
        round(agreement, 4),
    )


def _measured_agreement(motions: list[Motion], actions: list[str]) -> float:
    """Share of ``motions`` showing the action asked for (clip_facts)."""
    from habitsim.captions import clip_facts
    from habitsim.captions.prompts import action_agrees
    from habitsim.errors import CaptionError

    hits = 0
    for m, a in zip(motions, actions, strict=True):
        try:
            hits += action_agrees(a, clip_facts(m))
        except CaptionError:
            continue
    return hits / len(motions) if motions else float("nan")


def run_t2m(
    evaluator: str | Path,
    *,
    data: str | Path | None = None,
    checkpoint: str | Path | None = None,
    options: T2MBenchOptions | None = None,
    embed: Embedder | None = None,
    generator_embed: Embedder | None = None,
    human: str | Path | None = None,
) -> T2MBenchResult:
    """Measure ground truth and (with ``checkpoint``) the generator, per split (module
    docstring; the prompts of each split: :mod:`habitsim.evaluation.bench.t2m_splits`).

    Args:
        evaluator: text–motion evaluator folder.
        data: captioned data set (default: the one the checkpoint's code set was built from).
        checkpoint: text-to-motion checkpoint (None: the ground-truth rows only).
        options: protocol settings.
        embed: sentence embedder of the evaluator's text encoder (default: its text model).
        generator_embed: sentence embedder of the generator (default: ``embed`` when
            given, else the checkpoint's text model).
        human: the human prompts file (default: the shipped one).

    Raises:
        BenchT2MError: neither data nor checkpoint, too few train clips for FID.
        BenchSplitError: an unknown split, ``compose`` without a checkpoint.
        EvaluatorError: the evaluator cannot be loaded or the captions read.
    """
    from .t2m_splits import bench_split

    opts = options or T2MBenchOptions()
    ev = load_t2m_evaluator(evaluator)
    gpt, codes = None, None
    if checkpoint is not None:
        from habitsim.models.t2m import load_t2m
        from habitsim.models.t2m_data import load_code_set

        gpt = load_t2m(checkpoint)
        codes = gpt.meta["codes"]["dir"]
        if data is None:
            data = load_code_set(codes).meta["dataset"]
    if data is None:
        raise BenchT2MError("no data set: pass data=DIR (a captioned data set) or a checkpoint")
    ref_m, _ = captioned_clips(Path(data), "train")
    if len(ref_m) < 2:
        raise BenchT2MError(f"{data}: {len(ref_m)} captioned train clip(s); FID needs ≥ 2")
    ref = ev.embed_motions(ref_m)
    gen_embed = generator_embed if generator_embed is not None else embed
    rows: list[T2MRow] = []
    physics: list[PhysicsRow] = []
    for name in opts.splits:
        if name == "human" and gpt is None:
            continue  # no real motion: nothing to measure without a generator
        sp = bench_split(name, Path(data), seed=opts.seed, codes=codes, human=human)
        n = len(sp.texts) if opts.limit is None else min(opts.limit, len(sp.texts))
        texts, actions = sp.texts[:n], sp.actions[:n]
        zt = ev.embed_texts(texts, embed) if texts else np.zeros((0, ev.config.embed_dim))
        if sp.motions is not None:
            real = sp.motions[:n]
            zr = ev.embed_motions(real) if real else np.zeros((0, ev.config.embed_dim))
            rows.append(
                _row(
                    name,
                    "ground truth",
                    None,
                    zt,
                    zr,
                    ref,
                    _measured_agreement(real, actions),
                    opts,
                )
            )
        if gpt is None or checkpoint is None:
            continue
        from habitsim.models.t2m import text_to_motion

        per_step = gpt.rate / gpt.fps
        most = gpt.config.model.max_steps
        for g in opts.guidances:
            gen = []
            for i in range(n):
                steps = min(most, max(1, int(sp.seconds[i] / per_step)))
                gen.append(
                    text_to_motion(
                        texts[i],
                        sp.species[i],
                        steps * per_step,
                        seed=opts.seed + i,
                        guidance=float(g),
                        checkpoint=checkpoint,
                        embed=gen_embed,
                    )
                )
            zm = ev.embed_motions(gen) if gen else np.zeros((0, ev.config.embed_dim))
            agree = _measured_agreement(gen, actions)
            rows.append(
                _row(
                    name,
                    "generator",
                    float(g),
                    zt,
                    zm if sp.motions is not None else None,
                    ref,
                    agree,
                    opts,
                )
            )
        if opts.physics > 0:
            physics.append(
                _physics(name, texts, sp.species[:n], actions, checkpoint, gen_embed, opts)
            )
    unsupported = None
    if checkpoint is not None and opts.unsupported > 0 and "human" in opts.splits:
        unsupported = _unsupported(checkpoint, gen_embed, human, opts)
    return T2MBenchResult(
        str(data),
        tuple(opts.splits),
        str(evaluator),
        None if checkpoint is None else str(checkpoint),
        rows,
        physics,
        unsupported,
    )


#: The actions whose generated clips the physics check tracks.
_PHYSICS_ACTIONS = ("walk", "trot", "turn_left", "turn_right", "turn")


def _physics(
    split: str,
    texts: list[str],
    species: list[str],
    actions: list[str],
    checkpoint: str | Path,
    embed: Embedder | None,
    opts: T2MBenchOptions,
) -> PhysicsRow:
    """The first ``opts.physics`` walk / trot / turn prompts of a split through
    :func:`habitsim.pipeline.run_text` (refinement A, unassisted ``mpc``)."""
    import warnings

    from habitsim.captions.prompts import PromptWarning
    from habitsim.errors import PromptError
    from habitsim.pipeline import run_text

    survival: list[float] = []
    refused = 0
    for i, (t, sp, a) in enumerate(zip(texts, species, actions, strict=True)):
        if len(survival) >= opts.physics:
            break
        if a not in _PHYSICS_ACTIONS:
            continue
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", PromptWarning)
                tr = run_text(
                    t,
                    sp,
                    seconds=opts.physics_seconds,
                    seed=opts.seed + i,
                    guidance=opts.physics_guidance,
                    checkpoint=checkpoint,
                    embed=embed,
                    refine="A",
                    controller="mpc",
                    track=True,
                )
        except PromptError:
            refused += 1
            continue
        res = tr.run.track_result
        survival.append(0.0 if res is None else float(res.survival))
    s = np.asarray(survival, dtype=float)
    return PhysicsRow(
        split,
        len(s),
        round(float(np.mean(s >= 1.0 - 1e-9)), 4) if len(s) else float("nan"),
        round(float(np.mean(s)), 4) if len(s) else float("nan"),
        refused,
    )


def _unsupported(
    checkpoint: str | Path, embed: Embedder | None, human: str | Path | None, opts: T2MBenchOptions
) -> UnsupportedRow:
    """How :func:`habitsim.pipeline.run_text` answers human prompts outside the test
    (``opts.unsupported`` of them, spread evenly over the file)."""
    import warnings

    from habitsim.captions.prompts import PromptWarning
    from habitsim.errors import PromptError, UnknownSpeciesError
    from habitsim.pipeline import run_text

    from .t2m_splits import unsupported_prompts

    hp = unsupported_prompts(human)
    pick = np.unique(np.linspace(0, len(hp) - 1, min(opts.unsupported, len(hp))).astype(int))
    refused = warned = silent = 0
    for k, j in enumerate(pick):
        h = hp[int(j)]
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", PromptWarning)
                tr = run_text(
                    h.text,
                    h.species or None,
                    seconds=4.0,
                    seed=opts.seed + k,
                    guidance=opts.physics_guidance,
                    checkpoint=checkpoint,
                    embed=embed,
                )
        except (PromptError, UnknownSpeciesError):
            refused += 1
            continue
        if tr.warnings:
            warned += 1
        else:
            silent += 1
    return UnsupportedRow(len(pick), refused, warned, silent)


def t2m_checks(res: T2MBenchResult, options: T2MBenchOptions | None = None) -> list[TargetCheck]:
    """The targets: R-precision top-3 and FID of each generator row of the ``compose``
    split (of the first split measured when ``compose`` is not), prompt agreement of each
    ``human`` generator row, survival of each physics row."""
    opts = options or T2MBenchOptions()
    out = []
    gts = {r.split: r for r in res.rows if r.guidance is None}
    ranked = [r for r in res.rows if r.guidance is not None and r.split in gts]
    split = "compose" if any(r.split == "compose" for r in ranked) else None
    for r in ranked:
        if r.split != (split or ranked[0].split):
            continue
        gt = gts[r.split]
        r3 = r.r_precision[min(2, len(r.r_precision) - 1)]
        out.append(
            TargetCheck(
                f"{r.split}: R-precision top-3, guidance {r.guidance:g}",
                r3,
                f"{r3:.3f}",
                f"≥ {opts.r3_target:.2f}",
                _verdict(r3, r3 >= opts.r3_target),
            )
        )
        ratio = r.fid / gt.fid if gt.fid > 0 else float("inf")
        out.append(
            TargetCheck(
                f"{r.split}: FID / ground truth's, guidance {r.guidance:g}",
                ratio,
                f"{ratio:.2f}x",
                f"≤ {opts.fid_ratio_target:g}x",
                _verdict(ratio, ratio <= opts.fid_ratio_target),
            )
        )
    for r in res.rows:
        if r.split == "human" and r.guidance is not None:
            out.append(
                TargetCheck(
                    f"human: prompt agreement, guidance {r.guidance:g}",
                    r.prompt_agreement,
                    f"{r.prompt_agreement:.3f}",
                    f"≥ {opts.agreement_target:.2f}",
                    _verdict(r.prompt_agreement, r.prompt_agreement >= opts.agreement_target),
                )
            )
    for p in res.physics:
        out.append(
            TargetCheck(
                f"{p.split}: walks, trots and turns surviving {opts.physics_seconds:g} s (mpc)",
                p.survived,
                f"{p.survived:.2f} of {p.clips}",
                f"≥ {opts.survival_target:.2f}",
                _verdict(p.survived, p.survived >= opts.survival_target),
            )
        )
    return out


def _verdict(value: float, ok: bool) -> Verdict:
    """``n/a`` for a figure that could not be measured (NaN)."""
    return verdict(None if math.isnan(value) else bool(ok))
