"""What a text-to-motion prompt names (habitsim.captions.prompts): species, actions."""

from __future__ import annotations

import pytest

from habitsim.captions.facts import ClipFacts
from habitsim.captions.prompts import (
    action_agrees,
    prompt_species,
    prompt_warnings,
    read_prompt,
    species_words,
)
from habitsim.errors import PromptError, UnknownSpeciesError
from habitsim.gaits import ACTIONS


@pytest.mark.parametrize(
    ("text", "species", "actions"),
    [
        ("a horse trots", ("horse",), ("trot",)),
        ("Two wolves gallop across the field", ("wolf",), ("gallop",)),
        ("A red fox is cantering", ("fox",), ("canter",)),
        ("the puppy is trotting at a steady pace", ("dog",), ("trot",)),
        ("A camel paces slowly, then turns left", ("camel",), ("pace", "turn_left")),
        ("A dog walks in a curve to the right", ("dog",), ("turn_right",)),
        ("a husky walks backwards", ("dog",), ("walk_backward",)),
        ("A white-tailed deer backs up", ("deer",), ("walk_backward",)),
        ("the brown bear is standing still", ("bear",), ("idle",)),
        ("a bull leaps", ("cow",), ("jump",)),
        ("the kittens sit down", ("cat",), ("sit",)),
        ("a deer runs and then stops", ("deer",), ("run",)),
        ("A cat veering right while trotting", ("cat",), ("turn_right", "trot")),
        ("a bear swims across the river", ("bear",), ()),
        ("a unicorn trots", (), ("trot",)),
        ("a dog chases a cat", ("dog", "cat"), ()),
    ],
)
def test_read_prompt(text: str, species: tuple[str, ...], actions: tuple[str, ...]) -> None:
    r = read_prompt(text)
    assert r.species == species and r.actions == actions


def test_species_words_cover_names_plurals_and_synonyms() -> None:
    words = species_words()
    for w, sp in [
        ("horses", "horse"),
        ("wolves", "wolf"),
        ("foxes", "fox"),
        ("ponies", "horse"),
        ("dromedary camel", "camel"),
        ("bulls", "cow"),
    ]:
        assert words[w] == sp
    assert "unicorn" not in words


def test_prompt_species() -> None:
    assert prompt_species(read_prompt("a horse trots")) == "horse"
    assert prompt_species(read_prompt("a horse trots"), "horse") == "horse"
    assert prompt_species(read_prompt("something trots"), "goat") == "goat"
    for text, sp, code in [
        ("something trots", None, "no_species"),
        ("a horse trots", "dog", "species_conflict"),
        ("a horse and a dog walk", None, "several_species"),
    ]:
        with pytest.raises(PromptError) as e:
            prompt_species(read_prompt(text), sp)
        assert e.value.code == code and "zebra" in e.value.known
    with pytest.raises(UnknownSpeciesError) as u:
        prompt_species(read_prompt("a unicorn trots"), "unicorn")
    assert "horse" in u.value.known


def _facts(action: str | None, turning: str | None = None) -> ClipFacts:
    return ClipFacts(
        "dog",
        "Domestic dog",
        action,
        None,
        4.0,
        1.0,
        0.3,
        False,
        0.0,
        0.0,
        turning,
        "standing",
        "standing",
        (),
        None,
        "timeline",
    )


def test_agreement_and_warnings() -> None:
    assert action_agrees("trot", _facts("trot"))
    assert not action_agrees("trot", _facts("walk"))
    assert action_agrees("run", _facts("gallop")) and not action_agrees("run", _facts("trot"))
    assert action_agrees("turn", _facts("turn_right"))
    assert action_agrees("turn_left", _facts("walk", "left"))
    assert not action_agrees("turn_left", _facts("walk", "right"))
    r = read_prompt("a dog trots")
    assert prompt_warnings(r, _facts("trot"), ACTIONS) == []
    (w,) = prompt_warnings(r, _facts("walk", "left"), ACTIONS)
    assert "asks for trot" in w and "walk turning left at 1.00 m/s" in w
    (w,) = prompt_warnings(read_prompt("a dog swims"), _facts("walk"), ACTIONS)
    assert "names no action habitsim makes" in w and "shows a walk" in w
    (w,) = prompt_warnings(r, None, ACTIONS)
    assert "none of habitsim's actions" in w


def test_species_neutral_keeps_the_action_words() -> None:
    from habitsim.captions.prompts import species_neutral

    assert species_neutral("A red fox trots to the left.") == "An animal trots to the left."
    assert species_neutral("the puppy walks; a bull jumps") == "the animal walks; an animal jumps"
    assert species_neutral("a unicorn gallops") == "a unicorn gallops"
    assert read_prompt(species_neutral("Two horses canter")).actions == ("canter",)
