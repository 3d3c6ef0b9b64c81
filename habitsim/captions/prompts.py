"""What a text-to-motion prompt names, read from its words (:func:`read_prompt`), and
whether a generated clip does it (:func:`action_agrees`, :func:`prompt_warnings`).

* **Species**: a catalog species is named by its name ("horse"), its common name ("red
  fox") or the head noun of it ("camel" of "Dromedary camel"), one of its catalog
  ``synonyms`` ("puppy", "bull"), or the plural of any of them ("horses", "wolves").
  :func:`prompt_species` settles the species of a request from the text and the caller's
  species: a typed :class:`~habitsim.errors.PromptError` when they disagree, when the text
  names several, or when neither names one (with the known species listed).
* **Actions**: the words of the caption lexicon (:mod:`habitsim.captions.phrasing`) and
  their usual inflections: "trots", "cantering", "walks backwards", "turns left", "sits",
  "stands still", "jumps"; "runs" / "sprints" name a fast gait (canter, gallop or bound:
  :data:`RUN`), "turns" without a side names either turn (:data:`TURN`). Actions are kept
  in the order the text names them ("walks, then trots").

A prompt that names no action habitsim makes ("a bear swims") is still answered: the
caller generates, measures the clip with :func:`habitsim.captions.clip_facts` and reports
what it shows (:func:`prompt_warnings`), never silently.
"""

from __future__ import annotations

import functools
import re
from dataclasses import dataclass

from ..errors import PromptError
from ..species import all_species, load_species, species_names
from .facts import ClipFacts

__all__ = [
    "PromptReading",
    "PromptWarning",
    "RUN",
    "TURN",
    "read_prompt",
    "prompt_species",
    "action_agrees",
    "prompt_warnings",
    "describe_facts",
    "species_words",
    "species_neutral",
    "TEXT_FORMS",
]

#: A prompt's "runs": any of the fast gaits.
RUN = "run"
#: A prompt's "turns" without a side: either turn.
TURN = "turn"
#: What a prompt's action accepts of a clip's measured action (the rest: itself).
_ACCEPTS = {
    RUN: ("canter", "gallop", "bound"),
    TURN: ("turn_left", "turn_right"),
}

#: Word → action (inflections of the caption lexicon's verbs and nouns).
_ACTION_WORDS: dict[str, str] = {
    **dict.fromkeys(
        "walk walks walking walked stroll strolls strolling strolled wander wanders "
        "wandering plod plods plodding".split(),
        "walk",
    ),
    **dict.fromkeys("trot trots trotting trotted jog jogs jogging jogged".split(), "trot"),
    **dict.fromkeys("paces pacing paced".split(), "pace"),
    **dict.fromkeys("amble ambles ambling ambled".split(), "amble"),
    **dict.fromkeys("canter canters cantering cantered lope lopes loping loped".split(), "canter"),
    **dict.fromkeys("gallop gallops galloping galloped".split(), "gallop"),
    **dict.fromkeys("bound bounds bounding bounded hop hops hopping hopped".split(), "bound"),
    **dict.fromkeys(
        "run runs running ran sprint sprints sprinting sprinted race races racing raced "
        "dash dashes dashing dashed".split(),
        RUN,
    ),
    **dict.fromkeys(
        "jump jumps jumping jumped leap leaps leaping leapt leaped pounce pounces "
        "pouncing pounced".split(),
        "jump",
    ),
    **dict.fromkeys("sit sits sitting sat".split(), "sit"),
    **dict.fromkeys("idle idles idling motionless stationary".split(), "idle"),
}
#: Phrases read before the single words (longest first), each → action.
_ACTION_PHRASES: tuple[tuple[str, str], ...] = (
    (
        r"\b(?:walks?|walking|walked|steps?|stepping|stepped|moves?|moving|moved) "
        r"(?:backwards?|in reverse)\b",
        "walk_backward",
    ),
    (r"\b(?:backs?|backing|backed) (?:up|away)\b", "walk_backward"),
    (r"\b(?:backwards?|in reverse)\b", "walk_backward"),
    (r"\b(?:stands?|standing|stood) (?:still|in place|quietly)\b", "idle"),
    (r"\b(?:stands?|standing|stood|waits?|waiting|rests?|resting)\b", "idle"),
    (r"\bat (?:a|an|the) (?:[a-z-]+ )?pace\b", ""),  # "at a steady pace": a speed, no gait
)
#: Verbs of turning; a side word after them (within a few words) makes the turn's side.
_TURN_RE = re.compile(
    r"\b(?:turns?|turning|turned|veers?|veering|veered|curves?|curving|curved|circles?|"
    r"circling|wheels?|wheeling|bearing)\b(?P<rest>(?: [a-z]+){0,4})"
)
_SIDE_RE = re.compile(r"\b(left|right)\b")
_WORD_RE = re.compile(r"[a-z]+(?:-[a-z]+)*")


@dataclass(frozen=True)
class PromptReading:
    """What a prompt names.

    Attributes:
        text: the prompt.
        species: the catalog species it names, in the order of first mention.
        actions: the actions it names in order: names of :data:`habitsim.gaits.ACTIONS`,
            or :data:`RUN` / :data:`TURN`.
    """

    text: str
    species: tuple[str, ...]
    actions: tuple[str, ...]


class PromptWarning(UserWarning):
    """A generated clip that does not show what its prompt asks (or a prompt that asks
    for an action habitsim does not make): the message says what the clip shows."""


def _plural(word: str) -> str:
    if word.endswith(("s", "x", "ch", "sh")):
        return word + "es"
    if word.endswith("f"):
        return word[:-1] + "ves"
    if word.endswith("y") and word[-2:-1] not in ("a", "e", "i", "o", "u"):
        return word[:-1] + "ies"
    return word + "s"


def species_words(include_user: bool = True) -> dict[str, str]:
    """Word or phrase (lower case) → catalog species: names, common names, their head
    nouns, synonyms and the plurals of each."""
    out: dict[str, str] = {}
    for sp in all_species(include_user=include_user):
        common = re.sub(r"\s*\(.*?\)", "", sp.common_name).strip().lower()
        words = {sp.name, common, common.split(" ")[-1], *sp.synonyms}
        for w in words:
            if not w:
                continue
            head, _, last = w.rpartition(" ")
            out.setdefault(w, sp.name)
            out.setdefault(f"{head} {_plural(last)}".strip(), sp.name)
    return out


#: How a text-to-motion model reads a prompt: ``as_written``, or ``species_neutral``
#: (:func:`species_neutral`: the species comes from the habit embedding, the words carry
#: the action).
TEXT_FORMS: tuple[str, ...] = ("as_written", "species_neutral")


@functools.lru_cache(maxsize=4)
def _species_pattern(names: tuple[str, ...]) -> re.Pattern[str]:
    return re.compile(r"\b(?:(a|an) )?(" + "|".join(map(re.escape, names)) + r")\b", re.I)


def species_neutral(text: str) -> str:
    """``text`` with every species word (:func:`species_words`) replaced by "animal"
    ("A red fox trots" → "An animal trots"): a sentence embedding then reads the action
    and manner instead of the animal, which the generator gets from its habit input."""
    words = species_words()
    pat = _species_pattern(tuple(sorted(words, key=lambda w: (-len(w), w))))

    def sub(m: re.Match[str]) -> str:
        art = m.group(1)
        if art is None:
            return "animal"
        return ("An" if art[0].isupper() else "an") + " animal"

    return pat.sub(sub, text)


def read_prompt(text: str) -> PromptReading:
    """The species and actions a prompt names (module docstring)."""
    low = " ".join(_WORD_RE.findall(text.lower()))
    found: list[tuple[int, str]] = []
    taken = [False] * (len(low) + 1)
    for phrase, sp in sorted(species_words().items(), key=lambda kv: -len(kv[0])):
        for m in re.finditer(rf"\b{re.escape(phrase)}\b", low):
            if not any(taken[m.start() : m.end()]):
                taken[m.start() : m.end()] = [True] * (m.end() - m.start())
                found.append((m.start(), sp))
    species = tuple(dict.fromkeys(sp for _, sp in sorted(found)))
    acts: list[tuple[int, str]] = []
    used = [False] * (len(low) + 1)

    def claim(start: int, end: int, action: str) -> None:
        if not any(used[start:end]):
            used[start:end] = [True] * (end - start)
            if action:
                acts.append((start, action))

    for m in _TURN_RE.finditer(low):
        side = _SIDE_RE.search(m.group("rest") or "")
        end = m.start("rest") + side.end() if side else m.start("rest")
        claim(m.start(), end, f"turn_{side.group(1)}" if side else TURN)
    for pattern, action in _ACTION_PHRASES:
        for m in re.finditer(pattern, low):
            claim(m.start(), m.end(), action)
    for m in _WORD_RE.finditer(low):
        if (a := _ACTION_WORDS.get(m.group())) is not None:
            claim(m.start(), m.end(), a)
    ordered = [a for _, a in sorted(acts)]
    # "walks in a curve to the left": the walk is the turn's
    if any(a.startswith("turn") for a in ordered):
        ordered = [a for a in ordered if a != "walk"]
    return PromptReading(text, species, tuple(dict.fromkeys(ordered)))


def prompt_species(reading: PromptReading, species: str | None = None) -> str:
    """The species of a request: the one the text names, else ``species``.

    Raises:
        PromptError: the text names several species, or another than ``species``, or
            neither names one (``code`` says which; the message lists the known ones).
        UnknownSpeciesError: ``species`` is not in the catalog (lists the known ones).
    """
    known = species_names(include_user=True)
    given = None if species is None else load_species(species).name
    named = reading.species
    if len(named) > 1:
        raise PromptError(
            "several_species",
            f"the prompt names several species ({', '.join(named)}); a clip shows one "
            "animal: name one",
            known,
        )
    if given is not None and named and named[0] != given:
        raise PromptError(
            "species_conflict",
            f"the prompt names a {named[0]} but the species asked for is {given}: "
            "make them agree or leave the species out",
            known,
        )
    if given is not None:
        return given
    if named:
        return named[0]
    raise PromptError(
        "no_species",
        "the prompt names no species habitsim knows; name one in the text or give the "
        f"species; known: {', '.join(known)}",
        known,
    )


def action_agrees(named: str, facts: ClipFacts) -> bool:
    """The measured clip shows the prompt's action ``named`` (a walk or trot that turns
    to the named side counts as that turn)."""
    accept = _ACCEPTS.get(named, (named,))
    if facts.action in accept:
        return True
    if named.startswith("turn") and facts.turning is not None:
        return f"turn_{facts.turning}" in accept and facts.action in ("walk", "trot")
    return False


def describe_facts(facts: ClipFacts | None) -> str:
    """What a measured clip shows, in a few words ("a trot turning left at 1.2 m/s")."""
    if facts is None or facts.action is None:
        return "none of habitsim's actions"
    what = facts.action.replace("_", " ")
    if facts.turning is not None and not facts.action.startswith("turn"):
        what += f" turning {facts.turning}"
    return f"a {what} at {facts.speed_mps:.2f} m/s"


def prompt_warnings(
    reading: PromptReading, facts: ClipFacts | None, known: tuple[str, ...]
) -> list[str]:
    """Why a generated clip may not be what its prompt asks: the prompt names no action
    of ``known`` (the actions habitsim makes), or the clip (``facts``, None when it could
    not be measured) shows none of the actions the prompt names."""
    shows = describe_facts(facts)
    if not reading.actions:
        return [
            f"the prompt names no action habitsim makes ({', '.join(known)}, or runs); "
            f"the generated clip shows {shows}"
        ]
    if facts is None or not any(action_agrees(a, facts) for a in reading.actions):
        asked = " then ".join(a.replace("_", " ") for a in reading.actions)
        return [f"the prompt asks for {asked}; the generated clip shows {shows}"]
    return []
