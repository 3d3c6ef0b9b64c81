"""``habitsim bench t2m``: the text-to-motion protocol of the papers (Guo et al. 2022).

Measured with a text–motion evaluator (:mod:`habitsim.evaluation.t2m_evaluator`), on the
captioned clips of one split of a data set (default ``val``), one caption per clip (drawn
with the seed):

* **R-precision top-1/2/3**: the clips are shuffled (seeded) into batches of
  ``batch_size`` (32, as the papers; an incomplete last batch is dropped); in each batch
  every caption ranks the batch's motions by distance and counts whether its own motion
  is among the first k.
* **FID** between the motions' embeddings and those of the real ``train`` clips (the
  reference set). The ground-truth row's FID is the distance of real held-out clips to
  the reference, the floor a generator is compared with.
* **MM-Dist**: mean distance between each caption and its motion.
* **Diversity**: mean distance between the embeddings of random pairs of motions.

Rows: ground truth (the real clips) first, then the generator at each guidance scale,
generating from each caption a motion of the clip's species and length (seed + i).
Targets: R-precision top-3 ≥ 0.80 and FID ≤ 2× the ground truth's, per generator row.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from habitsim.errors import HabitsimError

from ..distribution import diversity, fid
from ..t2m_evaluator import (
    Embedder,
    captioned_clips,
    load_t2m_evaluator,
    matching_distance,
    r_precision,
)
from .targets import TargetCheck, verdict

__all__ = ["T2MBenchOptions", "T2MRow", "T2MBenchResult", "BenchT2MError", "run_t2m", "t2m_checks"]


class BenchT2MError(HabitsimError, ValueError):
    """Input the text-to-motion protocol cannot run on (too few clips, no data set)."""


@dataclass(frozen=True)
class T2MBenchOptions:
    """Settings of the protocol.

    Attributes:
        guidances: guidance scales of the generator rows.
        split: the data set split whose captions are measured.
        batch_size: R-precision batch (each caption against its motion and B − 1 others).
        top_k: the largest k of R-precision.
        limit: measure at most this many clips (None: all of the split).
        diversity_pairs: random pairs of the diversity figure.
        seed: seed of the caption draw, the batch shuffle and the generation.
        r3_target: R-precision top-3 a generator row must reach.
        fid_ratio_target: largest FID of a generator row, as a multiple of the ground truth's.
    """

    guidances: tuple[float, ...] = (1.0, 2.0, 3.0)
    split: str = "val"
    batch_size: int = 32
    top_k: int = 3
    limit: int | None = None
    diversity_pairs: int = 300
    seed: int = 0
    r3_target: float = 0.80
    fid_ratio_target: float = 2.0


@dataclass(frozen=True)
class T2MRow:
    """One row of the table.

    Attributes:
        name: ``ground truth`` or ``generator``.
        guidance: the generator's guidance scale (None for ground truth).
        clips: motions measured.
        r_precision: top-1 … top-k shares.
        fid: FID against the real train clips' embeddings.
        mm_dist: mean caption↔motion distance.
        diversity: mean distance of random motion pairs.
    """

    name: str
    guidance: float | None
    clips: int
    r_precision: tuple[float, ...]
    fid: float
    mm_dist: float
    diversity: float


@dataclass(frozen=True)
class T2MBenchResult:
    """The table and where it was measured."""

    data: str
    split: str
    evaluator: str
    checkpoint: str | None
    batches: int
    rows: list[T2MRow] = field(default_factory=list)

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
    name: str,
    guidance: float | None,
    zt: np.ndarray,
    zm: np.ndarray,
    ref: np.ndarray,
    opts: T2MBenchOptions,
) -> tuple[T2MRow, int]:
    rp, batches = batched_r_precision(zt, zm, opts.batch_size, opts.top_k, opts.seed)
    return (
        T2MRow(
            name,
            guidance,
            len(zm),
            tuple(round(float(v), 4) for v in rp),
            round(fid(zm, ref), 4),
            round(matching_distance(zt, zm), 4),
            round(diversity(zm, n_pairs=opts.diversity_pairs, seed=opts.seed), 4),
        ),
        batches,
    )


def run_t2m(
    evaluator: str | Path,
    *,
    data: str | Path | None = None,
    checkpoint: str | Path | None = None,
    options: T2MBenchOptions | None = None,
    embed: Embedder | None = None,
    generator_embed: Embedder | None = None,
) -> T2MBenchResult:
    """Measure ground truth and (with ``checkpoint``) the generator (module docstring).

    Args:
        evaluator: text–motion evaluator folder.
        data: captioned data set (default: the one the checkpoint's code set was built from).
        checkpoint: text-to-motion checkpoint (None: the ground-truth row only).
        options: protocol settings.
        embed: sentence embedder of the evaluator's text encoder (default: its text model).
        generator_embed: sentence embedder of the generator (default: ``embed`` when
            given, else the checkpoint's text model).

    Raises:
        BenchT2MError: neither data nor checkpoint, too few clips for one batch.
        EvaluatorError: the evaluator cannot be loaded or the captions read.
    """
    opts = options or T2MBenchOptions()
    ev = load_t2m_evaluator(evaluator)
    gpt = None
    if checkpoint is not None:
        from habitsim.models.t2m import load_t2m
        from habitsim.models.t2m_data import load_code_set

        gpt = load_t2m(checkpoint)
        if data is None:
            data = load_code_set(gpt.meta["codes"]["dir"]).meta["dataset"]
    if data is None:
        raise BenchT2MError("no data set: pass data=DIR (a captioned data set) or a checkpoint")
    motions, caps = captioned_clips(Path(data), opts.split)
    motions, caps = motions[: opts.limit], caps[: opts.limit]
    ref_m, _ = captioned_clips(Path(data), "train")
    if len(ref_m) < 2:
        raise BenchT2MError(f"{data}: {len(ref_m)} captioned train clip(s); FID needs ≥ 2")
    rng = np.random.default_rng(opts.seed)
    texts = [c[int(rng.integers(len(c)))] for c in caps]
    zt = ev.embed_texts(texts, embed) if texts else np.zeros((0, ev.config.embed_dim))
    ref = ev.embed_motions(ref_m)
    row, batches = _row("ground truth", None, zt, ev.embed_motions(motions), ref, opts)
    rows = [row]
    if gpt is not None:
        from habitsim.models.t2m import text_to_motion

        per_step = gpt.rate / gpt.fps
        most = gpt.config.model.max_steps
        for g in opts.guidances:
            gen = []
            for i, (m, t) in enumerate(zip(motions, texts, strict=True)):
                steps = min(most, max(1, int(m.num_frames / m.fps / per_step)))
                gen.append(
                    text_to_motion(
                        t,
                        m.species,
                        steps * per_step,
                        seed=opts.seed + i,
                        guidance=float(g),
                        checkpoint=checkpoint,
                        embed=generator_embed if generator_embed is not None else embed,
                    )
                )
            rows.append(_row("generator", float(g), zt, ev.embed_motions(gen), ref, opts)[0])
    return T2MBenchResult(
        str(data),
        opts.split,
        str(evaluator),
        None if checkpoint is None else str(checkpoint),
        batches,
        rows,
    )


def t2m_checks(res: T2MBenchResult, options: T2MBenchOptions | None = None) -> list[TargetCheck]:
    """The targets of each generator row (none without a generator row)."""
    opts = options or T2MBenchOptions()
    gt = res.rows[0]
    out = []
    for r in res.rows[1:]:
        r3 = r.r_precision[min(2, len(r.r_precision) - 1)]
        out.append(
            TargetCheck(
                f"R-precision top-3, guidance {r.guidance:g}",
                r3,
                f"{r3:.3f}",
                f"≥ {opts.r3_target:.2f}",
                verdict(r3 >= opts.r3_target),
            )
        )
        ratio = r.fid / gt.fid if gt.fid > 0 else float("inf")
        out.append(
            TargetCheck(
                f"FID / ground truth's, guidance {r.guidance:g}",
                ratio,
                f"{ratio:.2f}x",
                f"≤ {opts.fid_ratio_target:g}x",
                verdict(ratio <= opts.fid_ratio_target),
            )
        )
    return out
