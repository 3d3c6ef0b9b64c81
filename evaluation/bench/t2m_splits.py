"""The prompts of ``habitsim bench t2m``, per split (:func:`bench_split`).

======================  ===================================================================
split                   prompts
======================  ===================================================================
``val`` (``train``)     one caption per captioned clip of the data set's split
``compose``             the train clips of the species × action pairs the code set held out
                        of training (:func:`habitsim.models.t2m_data.held_out_compositions`),
                        one of their captions each
``paraphrase``          the val clips (one action each), captioned anew with the held-out
                        lexicon (:class:`habitsim.captions.CaptionOptions`
                        ``lexicon="held_out"``: verbs and sentence frames no training
                        caption uses)
``human``               the human-written prompts (``evaluation/human_prompts``) of a
                        catalog species naming an action habitsim makes, in a seeded
                        order (a limit takes a spread of animals); no real motion
======================  ===================================================================

Each prompt carries the action it asks for (the clip's measured action, or the human
prompt's), which :func:`habitsim.captions.prompts.action_agrees` compares with what the
generated clip shows. :func:`unsupported_prompts` gives the other human prompts (an
action habitsim does not make, or an animal the catalog does not have).
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from habitsim.captions.prompts import RUN, TURN
from habitsim.errors import HabitsimError
from habitsim.motion import Motion

__all__ = [
    "SPLITS",
    "HUMAN_PROMPTS",
    "BenchSplit",
    "HumanPrompt",
    "bench_split",
    "human_prompts",
    "unsupported_prompts",
]

#: The splits :func:`bench_split` builds.
SPLITS: tuple[str, ...] = ("val", "train", "compose", "paraphrase", "human")
#: The human-written prompts shipped with habitsim (MIT, see the folder's README.md).
HUMAN_PROMPTS = Path(__file__).resolve().parents[1] / "human_prompts" / "animalml3d_captions.tsv"
#: The human prompts' action names → what a prompt of them asks for.
_HUMAN_ACTIONS = {"run": RUN, "run_then_stop": RUN, "turn": TURN}


class BenchSplitError(HabitsimError, ValueError):
    """A split the benchmark cannot build (unknown, or without what it needs)."""


@dataclass(frozen=True)
class BenchSplit:
    """The prompts of one split.

    Attributes:
        name: the split.
        texts: one prompt per item.
        species: the species of each prompt.
        seconds: the length to generate for each [s].
        actions: the action each prompt asks for (an action name, ``run`` or ``turn``).
        motions: the real clips the prompts describe (None: the human prompts).
    """

    name: str
    texts: list[str]
    species: list[str]
    seconds: list[float]
    actions: list[str]
    motions: list[Motion] | None


@dataclass(frozen=True)
class HumanPrompt:
    """One human-written prompt: its text, the catalog species ("" when none fits) and
    the action (an action name, ``run``, ``turn``, or ``unsupported:<name>``)."""

    text: str
    species: str
    action: str

    @property
    def supported(self) -> bool:
        return bool(self.species) and not self.action.startswith("unsupported")


def human_prompts(path: str | Path | None = None) -> list[HumanPrompt]:
    """The human-written prompts (default: the shipped file), in file order.

    Raises:
        BenchSplitError: the file cannot be read or lacks a column.
    """
    p = Path(path) if path is not None else HUMAN_PROMPTS
    try:
        with open(p, encoding="utf-8", newline="") as fh:
            rows = list(csv.DictReader(fh, delimiter="\t"))
    except (OSError, UnicodeDecodeError, csv.Error) as e:
        raise BenchSplitError(f"{p}: cannot read the human prompts ({e})") from None
    out = []
    for r in rows:
        try:
            text, sp, act = r["caption"], r["catalog_species"], r["action"]
        except KeyError as e:
            raise BenchSplitError(f"{p}: no column {e}") from None
        out.append(HumanPrompt(text.strip(), sp.strip(), _HUMAN_ACTIONS.get(act, act)))
    return out


def unsupported_prompts(path: str | Path | None = None) -> list[HumanPrompt]:
    """The human prompts outside the test: an unsupported action or animal."""
    return [h for h in human_prompts(path) if not h.supported]


def _clip_action(m: Motion) -> str | None:
    from habitsim.captions import clip_facts
    from habitsim.errors import CaptionError

    try:
        return clip_facts(m).action
    except CaptionError:
        return None


def bench_split(
    name: str,
    data: Path,
    *,
    seed: int = 0,
    codes: str | Path | None = None,
    human: str | Path | None = None,
) -> BenchSplit:
    """The prompts of split ``name`` (module docstring).

    Args:
        name: one of :data:`SPLITS`.
        data: the captioned data set.
        seed: seed of the caption drawn per clip.
        codes: the code set (needed by ``compose``).
        human: the human prompts file (default: the shipped one).

    Raises:
        BenchSplitError: an unknown split, ``compose`` without a code set.
        EvaluatorError: the data set's captions cannot be read.
    """
    from habitsim.evaluation.t2m_evaluator import captioned_clips

    rng = np.random.default_rng(seed)
    if name == "human":
        test = [h for h in human_prompts(human) if h.supported]
        hp = [test[int(i)] for i in rng.permutation(len(test))]  # a limit takes a spread
        return BenchSplit(
            name,
            [h.text for h in hp],
            [h.species for h in hp],
            [4.0] * len(hp),
            [h.action for h in hp],
            None,
        )
    if name in ("val", "train"):
        motions, caps = captioned_clips(data, name)
        texts = [c[int(rng.integers(len(c)))] for c in caps]
    elif name == "compose":
        if codes is None:
            raise BenchSplitError("the compose split needs the code set (give a checkpoint)")
        from habitsim.models.t2m_data import COMPOSE_SPLIT, load_code_set

        held = {c.source: c for c in load_code_set(codes).split(COMPOSE_SPLIT)}
        motions, caps = captioned_clips(data, "train", only=set(held))
        texts = [c[int(rng.integers(len(c)))] for c in caps]
    elif name == "paraphrase":
        from habitsim.captions import CaptionOptions, captions, clip_facts
        from habitsim.errors import CaptionError

        motions, texts = [], []
        opts = CaptionOptions(per_clip=1, lexicon="held_out")
        for i, m in enumerate(captioned_clips(data, "val")[0]):
            try:
                texts.append(captions(clip_facts(m), seed=seed + i, options=opts)[0].text)
            except CaptionError:  # a chained clip: no held-out phrasing of chains
                continue
            motions.append(m)
    else:
        raise BenchSplitError(f"unknown split {name!r}; valid: {', '.join(SPLITS)}")
    actions = [_clip_action(m) for m in motions]
    keep = [i for i, a in enumerate(actions) if a is not None]
    return BenchSplit(
        name,
        [texts[i] for i in keep],
        [motions[i].species for i in keep],
        [motions[i].num_frames / motions[i].fps for i in keep],
        [str(actions[i]) for i in keep],
        [motions[i] for i in keep],
    )
