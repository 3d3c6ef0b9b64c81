"""How well generated motions do what their prompts say, per guidance scale.

:func:`prompt_agreement` takes the captioned clips of a code set's split (by default the
``val`` clips, which the transformer never trained on), generates from each clip's first
caption a motion of the clip's species and length, measures it with
:func:`habitsim.captions.clip_facts` (the facts the captions are written from), and
compares with the facts of the clip the caption was written for: the same action, the
same turning direction, the speed. Run at several guidance scales with the same seeds, it
measures what classifier-free guidance does.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .t2m_data import Embedder, load_code_set

__all__ = ["PromptAgreement", "prompt_agreement"]


@dataclass(frozen=True)
class PromptAgreement:
    """Agreement of generated motions with their prompts at one guidance scale.

    Attributes:
        guidance: the scale s.
        clips: prompts generated from.
        action: share of motions whose measured action is the prompt's clip's.
        turning: share whose turning direction (left, right, straight) is the clip's.
        speed_error_mps: median |measured − clip's| mean speed [m/s].
        no_action: share of motions that show none of the generator's actions.
    """

    guidance: float
    clips: int
    action: float
    turning: float
    speed_error_mps: float
    no_action: float

    def to_dict(self) -> dict[str, float | int]:
        return {k: round(v, 4) if isinstance(v, float) else v for k, v in self.__dict__.items()}


def prompt_agreement(
    checkpoint: str | Path,
    guidances: Sequence[float] = (0.0, 1.0, 2.0, 3.0),
    *,
    codes: str | Path | None = None,
    split: str = "val",
    seed: int = 0,
    limit: int | None = None,
    embed: Embedder | None = None,
) -> list[PromptAgreement]:
    """Generate from the first caption of each clip of a split and compare (module
    docstring), once per guidance scale with the same seeds.

    Args:
        checkpoint: the transformer's checkpoint folder.
        guidances: the scales to measure.
        codes: the code set (default: the one the checkpoint was trained on).
        split: which clips' captions to use.
        seed: seed of the first clip's draws (clip i uses seed + i).
        limit: use at most this many clips (the first in the code set's order).
        embed: sentence embedder (as :func:`~habitsim.models.t2m.text_to_motion`'s).

    Raises:
        CodeSetError: the code set or its data set's captions cannot be read, or the
            split has no clip.
    """
    from ..captions import FactsOptions, clip_facts
    from ..captions.store import load_captions
    from ..errors import CaptionError, MotionFileError
    from .errors import CodeSetError
    from .t2m import load_t2m, text_to_motion

    gpt = load_t2m(checkpoint)
    cs = load_code_set(codes if codes is not None else gpt.meta["codes"]["dir"])
    clips = cs.split(split)[:limit]
    if not clips:
        raise CodeSetError(
            f"{cs.root}: no {split!r} clip to measure; valid splits: train, val, compose"
        )
    try:
        facts = load_captions(cs.meta["dataset"]).facts
    except MotionFileError as e:
        raise CodeSetError(f"the code set's data set has no readable captions ({e})") from None
    per_step = gpt.rate / gpt.fps
    thr = FactsOptions().turning_rate_nd
    out = []
    for g in guidances:
        acts, turns, speeds, none = [], [], [], 0
        for i, c in enumerate(clips):
            ref: dict[str, Any] = facts.get(c.source, {})
            steps = min(c.steps, gpt.config.model.max_steps)
            m = text_to_motion(
                c.captions[0],
                c.species,
                steps * per_step,
                seed=seed + i,
                guidance=g,
                checkpoint=checkpoint,
                embed=embed,
            )
            try:
                f = clip_facts(m)
            except CaptionError:
                none += 1
                acts.append(False)
                turns.append(False)
                continue
            acts.append(f.action == ref.get("action"))
            turns.append(f.turning == _turning(ref, thr))
            if isinstance(ref.get("speed_mps"), int | float):
                speeds.append(abs(f.speed_mps - float(ref["speed_mps"])))
        n = len(clips)
        out.append(
            PromptAgreement(
                float(g),
                n,
                float(np.mean(acts)),
                float(np.mean(turns)),
                float(np.median(speeds)) if speeds else float("nan"),
                none / n,
            )
        )
    return out


def _turning(facts: dict[str, Any], threshold: float) -> str | None:
    """``left`` / ``right`` / None of stored facts (as :class:`ClipFacts` decides it)."""
    rate = facts.get("turn_rate_nd")
    if not isinstance(rate, int | float) or abs(rate) < threshold:
        return None
    return "left" if rate > 0 else "right"
