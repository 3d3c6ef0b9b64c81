"""Captions of clips that chain actions: "walks, then breaks into a trot".

Used by :func:`habitsim.captions.captions` when a clip's facts hold a chain
(:attr:`~habitsim.captions.facts.ClipFacts.chain`). Each step gets a phrase true of that
step: its gait (named by the step's action), its speed in words (the third of the
species' own Froude band of that gait its measured speed lies in, as for single clips),
the way it changes from the step before (a faster gait "breaks into" or "picks up speed
to", a slower one "slows to"), a turn's side, a stop, standing, sitting down. The steps
are joined in order by varied connectives (", then", "and then", "before", "after
that"), in the sentence forms of single clips (:data:`~habitsim.captions.FORMS`), at
three levels of detail (1: the steps; 2: with speed words and how sharply a turn turns;
3: with each step's duration and the clip's top speed).
"""

from __future__ import annotations

import numpy as np

from ..physics_constants import GRAVITY
from ..species import load_species
from .facts import ChainStep, ClipFacts

__all__ = ["chain_caption"]

_ORDER = ("walk", "trot", "pace", "amble", "canter", "gallop", "bound")
#: action → (third person, gerund, noun phrase with its article)
_PLAIN = {
    "walk": [("walks", "walking", "a walk"), ("steps along", "stepping along", "a walk")],
    "trot": [("trots", "trotting", "a trot")],
    "pace": [("paces", "pacing", "a pace")],
    "amble": [("ambles", "ambling", "an amble")],
    "canter": [("canters", "cantering", "a canter"), ("lopes", "loping", "a lope")],
    "gallop": [
        ("gallops", "galloping", "a gallop"),
        ("runs flat out", "running flat out", "a gallop"),
    ],
    "bound": [("bounds", "bounding", "a bounding run")],
    "walk_backward": [("walks backwards", "walking backwards", "a backward walk")],
    "idle": [
        ("stands still", "standing still", "a pause"),
        ("stands for a moment", "standing for a moment", "a moment standing"),
        ("waits on all fours", "waiting on all fours", "a short wait"),
    ],
    "stop": [
        ("stops", "stopping", "a stop"),
        ("comes to a halt", "coming to a halt", "a halt"),
        ("pulls up", "pulling up", "a halt"),
    ],
    "sit": [
        ("sits down", "sitting down", "a sit"),
        ("settles into a sit", "settling into a sit", "a sit"),
        ("lowers itself onto its haunches", "lowering itself onto its haunches", "a sit"),
    ],
    "lie": [("lies down", "lying down", "a rest lying down")],
}
_TURN = [
    ("turns {d}", "turning {d}", "a turn to the {d}"),
    ("veers {d}", "veering {d}", "a turn to the {d}"),
    ("curves round to the {d}", "curving round to the {d}", "a curve to the {d}"),
    ("bears {d}", "bearing {d}", "a bend to the {d}"),
]
_UP = [
    ("breaks into {n}", "breaking into {n}"),
    ("picks up speed to {n}", "picking up speed to {n}"),
    ("speeds up into {n}", "speeding up into {n}"),
    ("moves up to {n}", "moving up to {n}"),
]
_DOWN = [
    ("slows to {n}", "slowing to {n}"),
    ("drops back to {n}", "dropping back to {n}"),
    ("eases down to {n}", "easing down to {n}"),
]
_START = [("sets off at {n}", "setting off at {n}"), ("moves off at {n}", "moving off at {n}")]
_ON = [("carries on at {n}", "carrying on at {n}"), ("goes on at {n}", "going on at {n}")]
_SPEED_WORD = {
    "slow": ["slow", "easy", "leisurely"],
    "moderate": ["steady", "even", "moderate"],
    "fast": ["fast", "brisk", "quick"],
}
_ADVERB = {
    "slow": ["slowly", "at an easy pace", "unhurriedly"],
    "moderate": ["steadily", "at a steady pace"],
    "fast": ["quickly", "at speed", "hard"],
}
_SHARP = {
    "gentle": ["gently", "gradually"],
    "steady": ["steadily"],
    "sharp": ["sharply", "tightly"],
}
_NUMBER = "zero one two three four five six seven eight nine ten".split()


def _speed_class(species: str, step: ChainStep) -> str | None:
    """``slow`` / ``moderate`` / ``fast`` in the species' band of the step's gait."""
    sp = load_species(species)
    gait = step.gait if step.gait in sp.gaits else None
    if step.action in ("turn_left", "turn_right", "walk_backward"):
        gait = "walk"
    if gait is None or step.action not in (*_ORDER, "turn_left", "turn_right"):
        return None
    lo, hi = sp.gaits[gait].froude
    u = (step.froude - lo) / max(hi - lo, 1e-9)
    return "slow" if u < 1 / 3 else ("moderate" if u < 2 / 3 else "fast")


def _with_article(word: str, noun: str) -> str:
    """ "a trot" + "brisk" → "a brisk trot"."""
    art, _, rest = noun.partition(" ")
    if art not in ("a", "an"):
        return noun
    new_art = "an" if word[:1] in "aeiou" else "a"
    return f"{new_art} {word} {rest}"


def _phrase(
    species: str,
    steps: tuple[ChainStep, ...],
    k: int,
    level: int,
    rng: np.random.Generator,
) -> tuple[str, str, str]:
    """(third person, gerund, noun) of step ``k``, true of that step."""
    st = steps[k]
    prev = steps[k - 1].action if k > 0 else None
    cls = _speed_class(species, st) if level >= 2 else None
    if st.action in ("turn_left", "turn_right"):
        d = st.action.split("_")[1]
        third, ger, noun = (s.format(d=d) for s in _TURN[int(rng.integers(len(_TURN)))])
        if level >= 2:
            rate = abs(np.radians(st.turn_deg)) / max(st.end_s - st.start_s, 1e-9)
            nd = rate * np.sqrt(load_species(species).hip_height / GRAVITY)
            sharp = "gentle" if nd < 0.15 else ("steady" if nd < 0.3 else "sharp")
            adv = str(rng.choice(_SHARP[sharp]))
            third, ger = f"{third} {adv}", f"{ger} {adv}"
        return third, ger, noun
    third, ger, noun = _PLAIN[st.action][int(rng.integers(len(_PLAIN[st.action])))]
    if st.action in _ORDER:
        gait_noun = _PLAIN[st.action][0][2]
        if cls is not None and rng.random() < 0.6:
            gait_noun = _with_article(str(rng.choice(_SPEED_WORD[cls])), gait_noun)
            noun = gait_noun
        change = None
        if prev in _ORDER:
            change = _UP if _ORDER.index(st.action) > _ORDER.index(prev) else _DOWN
        elif prev == "idle":
            change = _START
        elif prev in ("turn_left", "turn_right") and rng.random() < 0.7:
            change = _ON
        if change is not None:
            t3, g3 = change[int(rng.integers(len(change)))]
            return t3.format(n=gait_noun), g3.format(n=gait_noun), noun
        if cls is not None and rng.random() < 0.6:
            adv = str(rng.choice(_ADVERB[cls]))
            return f"{third} {adv}", f"{ger} {adv}", noun
    return third, ger, noun


def _seconds(step: ChainStep, rng: np.random.Generator) -> str:
    d = step.end_s - step.start_s
    n = int(round(d))
    if abs(d - n) < 0.25 and 1 <= n < len(_NUMBER) and rng.random() < 0.5:
        return f"for about {_NUMBER[n]} second{'s' if n > 1 else ''}"
    return f"for about {d:.1f} s"


def _join(parts: list[str], rng: np.random.Generator) -> tuple[str, str]:
    """Parts joined in order with a connective style; returns (text, style)."""
    style = str(rng.choice(["then", "and_then", "after", "finally"]))
    if len(parts) == 2:
        if style == "then":
            return f"{parts[0]}, then {parts[1]}", style
        if style == "and_then":
            return f"{parts[0]} and then {parts[1]}", style
        if style == "after":
            return f"{parts[0]}; after that it {parts[1]}", style
        return f"{parts[0]} and finally {parts[1]}", style
    head = ", ".join(parts[:-1])
    if style == "then":
        return ", then ".join(parts), style
    if style == "and_then":
        return f"{head} and then {parts[-1]}", style
    if style == "after":
        return f"{parts[0]}; after that it " + ", then ".join(parts[1:]), style
    return f"{head}, and finally {parts[-1]}", style


def chain_caption(
    facts: ClipFacts, subject: str, form: str, level: int, rng: np.random.Generator
) -> tuple[str, str]:
    """One caption of a chained clip and its template name (form and connective).

    Args:
        facts: the clip's facts, with at least two :attr:`~ClipFacts.chain` steps.
        subject: the animal as the caption names it ("a dog").
        form: one of :data:`~habitsim.captions.FORMS`.
        level: 1, 2 or 3.
        rng: the caption's random generator.
    """
    steps = facts.chain
    ph = [_phrase(facts.species, steps, k, level, rng) for k in range(len(steps))]
    thirds = [p[0] for p in ph]
    if level >= 3:
        thirds = [
            t if s.action == "stop" else f"{t} {_seconds(s, rng)}"
            for t, s in zip(thirds, steps, strict=True)
        ]
    cap = subject[:1].upper() + subject[1:]
    if form == "lead" and steps[0].action in _ORDER:
        noun = ph[0][2] if ph[0][2].startswith(("a ", "an ")) else _PLAIN[steps[0].action][0][2]
        head = str(rng.choice([f"Starting at {noun}", f"Setting out at {noun}"]))
        body, style = _join(thirds[1:], rng) if len(thirds) > 2 else (thirds[1], "single")
        return f"{head}, {subject} {body}.", f"lead/{style}"
    if form == "lead":
        head = str(rng.choice(["In this clip, ", "Here, "]))
        body, style = _join(thirds, rng)
        return f"{head}{subject} {body}.", f"lead/{style}"
    if form == "progressive":
        gers = [p[1] for p in ph]
        body = ", then ".join(gers[:-1]) + f" and then {gers[-1]}"
        return f"{cap} is {body}.", "progressive"
    if form == "noun":
        nouns = [p[2] for p in ph]
        body = ", then ".join(nouns[:-1]) + f" and finally {nouns[-1]}"
        return f"{body[:1].upper()}{body[1:]} by {subject}.", "noun"
    if form == "fragment":
        gers = [p[1] for p in ph]
        if len(gers) >= 2 and rng.random() < 0.5:
            first = ", then ".join(gers[:-1]) if len(gers) > 2 else gers[0]
            return f"{subject} {first} before {gers[-1]}", "fragment/before"
        return f"{subject} " + ", then ".join(gers), "fragment/then"
    if form == "prompt":
        return f"{subject} " + " then ".join(thirds), "prompt"
    body, style = _join(thirds, rng)
    if len(thirds) >= 2 and rng.random() < 0.3:
        first = ", then ".join(thirds[:-1]) if len(thirds) > 2 else thirds[0]
        body, style = f"{first} before {ph[-1][1]}", "before"
    return f"{cap} {body}.", f"sentence/{style}"
