"""Captions in varied English from a clip's facts (:func:`captions`).

A caption is put together from parts that are each true of the clip
(:class:`~habitsim.captions.facts.ClipFacts`): who (the species by its catalog name or
common name), what (a verb for the action, chosen among synonyms that fit the measured
speed: a slow walk may be a stroll, a fast one never), how fast (a word for where the
speed lies in the species' own Froude band of that gait, or the speed in m/s and its
Froude number), where to (left or right, gently or sharply, through how many degrees;
forwards or backwards), how long, and from what pose to what pose. Sentence forms vary
(a full sentence, a progressive, a noun phrase, a fragment, a clause that leads with the
duration), and so does the level of detail:

* level 1: the animal and the action (``A dog trots.``);
* level 2: plus the manner: speed in words, turning, direction, the pose it ends in;
* level 3: plus figures: duration, speed in m/s and Froude number, degrees turned.

:func:`captions` draws ``n`` distinct captions with a seeded generator, spread over the
levels and forms, so that no single template is the language of a data set.

**Held-out paraphrases.** ``CaptionOptions(lexicon="held_out")`` writes the same facts
with verbs and sentence frames the training captions never use ("A horse saunters
slowly.", "This clip shows a dog moving at a trot."): the benchmark's paraphrase split
(:mod:`habitsim.evaluation.bench.t2m`). Data sets are captioned with the ``train`` lexicon.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from ..errors import CaptionError
from ..species import load_species
from .facts import ClipFacts

__all__ = [
    "Caption",
    "CaptionOptions",
    "captions",
    "speed_class",
    "FORMS",
    "HELD_OUT_FORMS",
    "LEVELS",
    "LEXICONS",
]

#: Sentence forms (:attr:`Caption.form`).
FORMS: tuple[str, ...] = ("sentence", "progressive", "noun", "fragment", "lead", "prompt")
#: Levels of detail.
LEVELS: tuple[int, ...] = (1, 2, 3)
#: Sentence frames of the held-out lexicon only.
HELD_OUT_FORMS: tuple[str, ...] = ("shows", "watch", "seen")
#: The lexicons of :attr:`CaptionOptions.lexicon`.
LEXICONS: tuple[str, ...] = ("train", "held_out")

_NUMBER_WORDS = "zero one two three four five six seven eight nine ten eleven twelve".split()


@dataclass(frozen=True)
class CaptionOptions:
    """Knobs of :func:`captions`.

    Attributes:
        per_clip: captions per clip.
        level_weights: relative frequency of the detail levels 1, 2, 3.
        attempts: draws per caption before giving up on a new distinct one.
        lexicon: ``train`` (the data sets' captions) or ``held_out`` (verbs and
            sentence frames the train lexicon never uses: the paraphrase split).
    """

    per_clip: int = 5
    level_weights: tuple[float, float, float] = (0.25, 0.45, 0.30)
    attempts: int = 40
    lexicon: str = "train"

    def __post_init__(self) -> None:
        if self.lexicon not in LEXICONS:
            raise CaptionError(
                f"lexicon must be one of {', '.join(LEXICONS)}, got {self.lexicon!r}"
            )
        if not 1 <= self.per_clip <= 100:
            raise CaptionError(f"per_clip must be 1..100, got {self.per_clip}")
        w = self.level_weights
        if len(w) != 3 or min(w) < 0 or sum(w) <= 0:
            raise CaptionError(f"level_weights must be three weights >= 0, got {w}")


@dataclass(frozen=True)
class Caption:
    """One caption: its text, level of detail and sentence form."""

    text: str
    level: int
    form: str


# ----------------------------------------------------------------------------- lexicon
#: Per action: (third person, base form, gerund, noun) and the speed classes it fits.
_VERBS: dict[str, list[tuple[str, str, str, str, tuple[str, ...]]]] = {
    "walk": [
        ("walks", "walk", "walking", "walk", ("slow", "moderate", "fast")),
        ("strolls", "stroll", "strolling", "stroll", ("slow",)),
        ("steps along", "step along", "stepping along", "walk", ("slow", "moderate", "fast")),
        ("walks briskly along", "walk briskly along", "walking briskly", "brisk walk", ("fast",)),
    ],
    "trot": [
        ("trots", "trot", "trotting", "trot", ("slow", "moderate", "fast")),
        (
            "jogs along at a trot",
            "jog along at a trot",
            "jogging at a trot",
            "jogging trot",
            ("slow", "moderate"),
        ),
    ],
    "pace": [
        ("paces", "pace", "pacing", "pace", ("slow", "moderate", "fast")),
        (
            "moves at a lateral pace",
            "move at a lateral pace",
            "moving at a lateral pace",
            "lateral pace",
            ("slow", "moderate", "fast"),
        ),
    ],
    "amble": [
        ("ambles", "amble", "ambling", "amble", ("slow", "moderate", "fast")),
        (
            "moves at an amble",
            "move at an amble",
            "moving at an amble",
            "ambling gait",
            ("slow", "moderate", "fast"),
        ),
    ],
    "canter": [
        ("canters", "canter", "cantering", "canter", ("slow", "moderate", "fast")),
        ("lopes along", "lope along", "loping along", "lope", ("slow", "moderate")),
    ],
    "gallop": [
        ("gallops", "gallop", "galloping", "gallop", ("slow", "moderate", "fast")),
        (
            "runs at a gallop",
            "run at a gallop",
            "running at a gallop",
            "galloping run",
            ("slow", "moderate", "fast"),
        ),
        (
            "races along at full gallop",
            "race along at full gallop",
            "racing at full gallop",
            "full gallop",
            ("fast",),
        ),
    ],
    "bound": [
        ("bounds", "bound", "bounding", "bounding run", ("slow", "moderate", "fast")),
        (
            "bounds along",
            "bound along",
            "bounding along",
            "bounding gait",
            ("slow", "moderate", "fast"),
        ),
    ],
    "walk_backward": [
        (
            "walks backwards",
            "walk backwards",
            "walking backwards",
            "backward walk",
            ("slow", "moderate", "fast"),
        ),
        ("backs up", "back up", "backing up", "backward walk", ("slow", "moderate")),
        (
            "steps backwards",
            "step backwards",
            "stepping backwards",
            "walk in reverse",
            ("slow", "moderate", "fast"),
        ),
    ],
    "idle": [
        ("stands", "stand", "standing", "still stand", ("slow",)),
        ("stands still", "stand still", "standing still", "quiet stand", ("slow",)),
        ("stands in place", "stand in place", "standing in place", "stand in place", ("slow",)),
        (
            "waits on all fours",
            "wait on all fours",
            "waiting on all fours",
            "standing pause",
            ("slow",),
        ),
    ],
    "jump": [
        ("jumps", "jump", "jumping", "jump", ("slow", "moderate", "fast")),
        ("leaps", "leap", "leaping", "leap", ("slow", "moderate", "fast")),
        (
            "springs forward in a jump",
            "spring forward in a jump",
            "springing forward",
            "forward jump",
            ("slow", "moderate", "fast"),
        ),
    ],
}
#: The held-out lexicon's verbs per action (same layout as :data:`_VERBS`; an action
#: missing here keeps the train verbs, in the held-out frames).
_HELD_OUT_VERBS: dict[str, list[tuple[str, str, str, str, tuple[str, ...]]]] = {
    "walk": [
        ("saunters", "saunter", "sauntering", "saunter", ("slow", "moderate")),
        (
            "moves along at a walk",
            "move along at a walk",
            "moving at a walk",
            "walking gait",
            ("slow", "moderate", "fast"),
        ),
    ],
    "trot": [
        (
            "moves at a trot",
            "move at a trot",
            "moving at a trot",
            "trotting gait",
            ("slow", "moderate", "fast"),
        ),
    ],
    "canter": [
        (
            "goes at a canter",
            "go at a canter",
            "going at a canter",
            "cantering gait",
            ("slow", "moderate", "fast"),
        ),
    ],
    "gallop": [
        (
            "charges along at a gallop",
            "charge along at a gallop",
            "charging at a gallop",
            "galloping charge",
            ("slow", "moderate", "fast"),
        ),
    ],
    "walk_backward": [
        ("reverses", "reverse", "reversing", "reversing walk", ("slow", "moderate", "fast")),
    ],
    "idle": [
        (
            "remains motionless",
            "remain motionless",
            "remaining motionless",
            "motionless pause",
            ("slow",),
        ),
    ],
    "jump": [
        ("vaults", "vault", "vaulting", "vault", ("slow", "moderate", "fast")),
    ],
}
_HELD_OUT_TURN_VERBS = [
    (
        "swings round to the {dir}",
        "swing round to the {dir}",
        "swinging round to the {dir}",
        "swing round to the {dir}",
    ),
]
_TURN_VERBS = [
    ("turns {dir}", "turn {dir}", "turning {dir}", "turn to the {dir}"),
    (
        "walks in a curve to the {dir}",
        "walk in a curve to the {dir}",
        "walking in a curve to the {dir}",
        "curving walk to the {dir}",
    ),
    ("veers {dir}", "veer {dir}", "veering {dir}", "walk veering {dir}"),
    (
        "walks round to the {dir}",
        "walk round to the {dir}",
        "walking round to the {dir}",
        "walk round to the {dir}",
    ),
]
_SPEED_ADVERBS = {
    "slow": ["slowly", "at a leisurely pace", "unhurriedly", "at an easy pace"],
    "moderate": ["steadily", "at a moderate pace", "at a steady pace", "at an even pace"],
    "fast": ["quickly", "at a fast pace", "at speed", "rapidly"],
}
_SPEED_ADJECTIVES = {
    "slow": ["slow", "leisurely", "easy", "unhurried"],
    "moderate": ["steady", "moderate", "even-paced"],
    "fast": ["fast", "quick", "rapid", "hurried"],
}
_TURN_ADVERBS = {
    "gentle": ["gently", "gradually", "slightly"],
    "steady": ["steadily", "smoothly"],
    "sharp": ["sharply", "tightly", "hard"],
}
#: First words of common names that keep their capital (proper adjectives).
_PROPER = frozenset({"Asian", "African", "European", "American", "Arctic", "Bactrian"})
_POSE_NOUN = {"lying": "lying down", "sitting": "a sit", "standing": "a stand"}


def speed_class(facts: ClipFacts) -> str:
    """``slow``, ``moderate`` or ``fast``: where the clip's Froude number lies in the
    species' band of its gait (thirds), or, for a gait the species has no band for,
    against fixed Froude numbers (0.15 and 0.5 for walks, 0.8 and 1.8 for faster gaits)."""
    if facts.action in ("idle", "sit"):
        return "slow"
    sp = load_species(facts.species)
    gait = facts.gait if facts.gait in sp.gaits else None
    if gait is None and facts.action in ("turn_left", "turn_right", "walk_backward"):
        gait = "walk" if "walk" in sp.gaits else None
    if gait is not None:
        lo, hi = sp.gaits[gait].froude
        u = (facts.froude - lo) / max(hi - lo, 1e-9)
        return "slow" if u < 1 / 3 else ("moderate" if u < 2 / 3 else "fast")
    a, b = (0.15, 0.5) if facts.froude < 0.5 else (0.8, 1.8)
    return "slow" if facts.froude < a else ("moderate" if facts.froude < b else "fast")


def _turn_class(facts: ClipFacts) -> str:
    r = abs(facts.turn_rate_nd)
    return "gentle" if r < 0.15 else ("steady" if r < 0.3 else "sharp")


def _article(word: str) -> str:
    return "an" if word[:1].lower() in "aeiou" else "a"


def _animal_names(facts: ClipFacts) -> list[str]:
    common = re.sub(r"\s*\(.*?\)", "", facts.common_name).strip()
    names = [facts.species]
    if common and common.lower() != facts.species:
        first, _, rest = common.partition(" ")
        if first not in _PROPER:
            first = first.lower()
        names.append(f"{first} {rest}".strip())
    return names


def _number(x: float, rng: np.random.Generator) -> str:
    n = int(round(x))
    if abs(x - n) < 0.25 and 0 <= n < len(_NUMBER_WORDS) and rng.random() < 0.5:
        return _NUMBER_WORDS[n]
    return f"{x:.1f}" if x < 10 else f"{x:.0f}"


def _duration(facts: ClipFacts, rng: np.random.Generator) -> str:
    d = facts.duration_s
    n = _number(d, rng)
    unit = "second" if n in ("one", "1.0") else "seconds"
    return str(rng.choice([f"about {n} {unit}", f"roughly {n} {unit}", f"{d:.1f} s"]))


def _degrees(facts: ClipFacts, rng: np.random.Generator) -> str:
    deg = abs(facts.turn_deg)
    q = int(round(deg / 45.0)) * 45
    words = {90: "a quarter turn", 180: "a half turn", 360: "a full circle"}
    if q in words and abs(deg - q) < 12 and rng.random() < 0.5:
        return f"about {words[q]}"
    return f"through about {int(round(deg / 5.0)) * 5} degrees"


@dataclass(frozen=True)
class _Parts:
    subject: str  # "a dog"
    third: str  # "trots"
    base: str  # "trot"
    gerund: str  # "trotting"
    noun: str  # "trot"
    manner: str  # ", veering left" / " slowly" (with its leading space or comma)
    adjective: str  # "slow" (for the noun forms; "" if none)
    tail: str  # " and ends sitting" / ", then stops"
    lead: str  # "For about three seconds"
    figures: str  # " at about 1.2 m/s (Froude number 0.31)"


def _parts(
    facts: ClipFacts, level: int, rng: np.random.Generator, held_out: bool = False
) -> _Parts:
    names = _animal_names(facts)
    name = str(rng.choice(names))
    subject = f"{_article(name)} {name}" if rng.random() < 0.7 else f"the {name}"
    action = facts.action or "walk"
    cls = speed_class(facts)
    turning = facts.turning
    if action in ("turn_left", "turn_right"):
        direction = action.split("_")[1]
        turns = _HELD_OUT_TURN_VERBS if held_out else _TURN_VERBS
        third, base, gerund, noun = (
            s.format(dir=direction) for s in turns[rng.integers(len(turns))]
        )
    elif action == "sit":
        sits_then_stands = facts.end != "sitting"
        if sits_then_stands:
            third, base, gerund, noun = (
                "sits down and stands up again",
                "sit down and stand up again",
                "sitting down and standing up again",
                "brief sit",
            )
        else:
            third, base, gerund, noun = str(
                rng.choice(
                    [
                        "sits down|sit down|sitting down|sit",
                        "lowers itself into a sit|lower itself into a sit|settling into a sit|sit",
                        "settles onto its haunches|settle onto its haunches|"
                        "settling onto its haunches|sit",
                    ]
                )
            ).split("|")
    else:
        table = _VERBS
        if held_out and any(cls in v[4] for v in _HELD_OUT_VERBS.get(action, [])):
            table = _HELD_OUT_VERBS
        verbs = [v for v in table.get(action, _VERBS["walk"]) if cls in v[4]]
        third, base, gerund, noun, _ = verbs[rng.integers(len(verbs))]
    manner = adjective = tail = lead = figures = ""
    if level >= 2:
        is_turn = action in ("turn_left", "turn_right")
        if facts.travels and action != "jump" and not (is_turn and rng.random() < 0.6):
            if not any(w in third for w in ("briskly", "full gallop", "stroll")):
                words = [w for w in _SPEED_ADVERBS[cls] if "pace" not in w or action != "pace"]
                manner = " " + str(rng.choice(words))
                adjective = str(rng.choice(_SPEED_ADJECTIVES[cls]))
        if is_turn and not manner:
            adv = str(rng.choice(_TURN_ADVERBS[_turn_class(facts)]))
            third, base, gerund = (f"{v} {adv}" for v in (third, base, gerund))
        elif not is_turn and turning is not None and action not in ("idle", "sit"):
            manner += str(
                rng.choice(
                    [
                        f", veering {turning}",
                        f", bearing to the {turning}",
                        f" while turning {turning}",
                    ]
                )
            )
        if facts.start in _POSE_NOUN and facts.start != "standing" and action != "sit":
            third = f"gets up from {_POSE_NOUN[facts.start]} and {third}"
            base = f"get up from {_POSE_NOUN[facts.start]} and {base}"
            gerund = f"getting up from {_POSE_NOUN[facts.start]} and {gerund}"
        if facts.travels and facts.end == "standing":
            tail = str(
                rng.choice(
                    [", then stops", " and then comes to a halt", ", ending at a standstill"]
                )
            )
        elif facts.end in ("sitting", "lying") and action != "sit":
            tail = f" and ends {facts.end}"
    if level >= 3:
        lead = _duration(facts, rng)
        if facts.travels:
            figures = (
                f" at about {facts.speed_mps:.1f} m/s"
                if rng.random() < 0.5
                else f" at about {facts.speed_mps:.1f} m/s (Froude number {facts.froude:.2f})"
            )
        if action in ("turn_left", "turn_right") or (turning and action not in ("idle", "sit")):
            figures += ", " + _degrees(facts, rng)
        if action == "jump" and facts.jump_height_m is not None:
            figures += f", rising about {100 * facts.jump_height_m:.0f} cm"
    return _Parts(subject, third, base, gerund, noun, manner, adjective, tail, lead, figures)


def _cap(s: str) -> str:
    return s[:1].upper() + s[1:]


def _render(p: _Parts, form: str, rng: np.random.Generator) -> str:
    body = f"{p.manner}{p.figures}{p.tail}"
    if form == "sentence":
        s = f"{p.subject} {p.third}{body}"
        if p.lead:
            s += f", for {p.lead}" if rng.random() < 0.5 else f" over {p.lead}"
        return _cap(s) + "."
    if form == "progressive":
        s = f"{p.subject} is {p.gerund}{body}"
        if p.lead:
            s += f" for {p.lead}"
        return _cap(s) + "."
    if form == "noun":
        adj = f"{p.adjective} " if p.adjective else ""
        np_ = f"{_article(adj + p.noun)} {adj}{p.noun} by {p.subject}"
        s = np_ + f"{p.figures}{p.tail}"
        if p.lead:
            s += f", lasting {p.lead}"
        return _cap(s) + "."
    if form == "fragment":
        s = f"{p.subject} {p.gerund}{body}"
        if p.lead:
            s += f", {p.lead}"
        return s
    if form == "shows":
        s = f"this clip shows {p.subject} {p.gerund}{body}"
        return _cap(s) + (f", {p.lead}." if p.lead else ".")
    if form == "watch":
        s = f"watch {p.subject} as it {p.third.removesuffix(' again')}{body}"
        return _cap(s) + (f" over {p.lead}." if p.lead else ".")
    if form == "seen":
        s = f"{p.subject} can be seen {p.gerund}{body}"
        return _cap(s) + (f" for {p.lead}." if p.lead else ".")
    if form == "lead":
        head = f"For {p.lead}, " if p.lead else str(rng.choice(["Here, ", "In this clip, "]))
        return head + f"{p.subject} {p.third}{body}."
    # "prompt": as a user types a request, without a full stop
    s = f"{p.subject} {p.third}{body}"
    if p.lead:
        s += f" ({p.lead})"
    return s


def _chain_text(facts: ClipFacts, form: str, level: int, rng: np.random.Generator) -> str:
    """A caption of a clip that chains actions (:mod:`habitsim.captions.sequences`)."""
    from .sequences import chain_caption

    name = str(rng.choice(_animal_names(facts)))
    subject = f"{_article(name)} {name}" if rng.random() < 0.7 else f"the {name}"
    return chain_caption(facts, subject, form, level, rng)[0]


def captions(
    facts: ClipFacts, seed: int = 0, options: CaptionOptions | None = None
) -> list[Caption]:
    """``options.per_clip`` distinct captions of a clip, each true of ``facts``.

    A clip whose facts hold a chain of two or more steps gets captions that name the
    steps in order (:mod:`habitsim.captions.sequences`).

    Raises:
        CaptionError: the clip shows no action habitsim can name (``facts.action`` is
            None), or not enough distinct captions could be drawn.
    """
    if facts.action is None and len(facts.chain) < 2:
        raise CaptionError(
            f"no caption for a {facts.species} clip that shows none of the generator's "
            "actions (its timeline: "
            + ", ".join(f"{s.activity} {s.start_s:.1f}-{s.end_s:.1f} s" for s in facts.segments)
            + ")"
        )
    options = options or CaptionOptions()
    rng = np.random.default_rng(seed)
    w = np.asarray(options.level_weights, dtype=float)
    w = w / w.sum()
    out: list[Caption] = []
    seen: set[str] = set()
    for k in range(options.per_clip):
        for _ in range(options.attempts):
            # spread over the levels: the first three captions take one level each
            level = int(LEVELS[k]) if k < 3 and w[k] > 0 else int(rng.choice(LEVELS, p=w))
            held_out = options.lexicon == "held_out"
            form = str(rng.choice(HELD_OUT_FORMS if held_out else FORMS))
            if len(facts.chain) >= 2:
                if held_out:
                    raise CaptionError("the held-out lexicon has no captions of chained clips")
                text = _chain_text(facts, form, level, rng)
            else:
                text = _render(_parts(facts, level, rng, held_out), form, rng)
            text = re.sub(r"\s+", " ", text).strip()
            if text.lower() not in seen:
                seen.add(text.lower())
                out.append(Caption(text, level, form))
                break
        else:
            break
    if not out:
        raise CaptionError(f"no caption could be drawn for the {facts.species} clip")
    return out
