"""Captions written from what is measured on a clip (habitsim.captions)."""

from __future__ import annotations

import dataclasses
import json
from collections import Counter

import pytest

from habitsim.captions import CaptionOptions, captions, clip_facts, speed_class
from habitsim.captions.phrasing import _SPEED_ADVERBS, FORMS
from habitsim.captions.store import CAPTIONS_NAME, load_captions
from habitsim.cli import main
from habitsim.errors import CaptionError, MotionFileError
from habitsim.gaits import generate
from habitsim.species import load_species


def _unlabelled(m):
    """The clip as an import would give it: no generator metadata."""
    m.metadata = {}
    return m


@pytest.mark.parametrize(
    ("species", "action"),
    [
        ("dog", "walk"),
        ("horse", "trot"),
        ("cat", "turn_left"),
        ("dog", "turn_right"),
        ("dog", "walk_backward"),
        ("dog", "idle"),
        ("dog", "sit"),
    ],
)
def test_facts_are_measured_on_the_clip(species: str, action: str) -> None:
    m = generate(species, action, seed=4)
    f = clip_facts(m)
    assert f.action == action and f.source == "generator"
    assert f.duration_s == pytest.approx(m.num_frames / m.fps)
    if action in ("walk", "trot", "turn_left", "turn_right", "walk_backward"):
        assert f.speed_mps == pytest.approx(m.metadata["speed_mps"], rel=0.12)
    assert f.backward == (action == "walk_backward")
    assert f.turning == {"turn_left": "left", "turn_right": "right"}.get(action)
    if action == "sit":
        assert f.start == "standing" and f.end == "sitting"
    # without the generator's metadata the action is read from the timeline
    g = clip_facts(_unlabelled(m))
    assert g.source == "timeline"
    expect = {"trot": "trot", "sit": "sit"}.get(action, action)
    assert g.action == expect


def test_captions_say_only_what_is_true() -> None:
    left = clip_facts(generate("cat", "turn_left", seed=2))
    for c in captions(left, seed=0, options=CaptionOptions(per_clip=12)):
        assert "left" in c.text and "right" not in c.text, c.text
        assert "cat" in c.text.lower()
    slow = clip_facts(generate("dog", "walk", seed=1, froude=0.06))
    assert speed_class(slow) == "slow"
    fast = clip_facts(generate("dog", "walk", seed=1, froude=0.34))
    assert speed_class(fast) == "fast"
    for c in captions(slow, seed=3, options=CaptionOptions(per_clip=12)):
        assert not any(w in c.text for w in _SPEED_ADVERBS["fast"]), c.text
        assert "backwards" not in c.text
        if c.level == 3:
            assert "m/s" in c.text or "second" in c.text or " s" in c.text
    back = clip_facts(generate("dog", "walk_backward", seed=1))
    texts = [c.text for c in captions(back, seed=0, options=CaptionOptions(per_clip=8))]
    assert all("back" in t or "reverse" in t for t in texts), texts
    sit = clip_facts(generate("dog", "sit", seed=1))
    assert all("sit" in c.text or "haunches" in c.text for c in captions(sit, seed=0))


def test_captions_vary_and_are_seeded() -> None:
    f = clip_facts(generate("horse", "gallop", seed=5))
    a = captions(f, seed=7, options=CaptionOptions(per_clip=10))
    assert [c.text for c in a] == [c.text for c in captions(f, seed=7, options=CaptionOptions(10))]
    assert len({c.text.lower() for c in a}) == len(a) == 10
    assert {c.level for c in a} == {1, 2, 3}
    assert len({c.form for c in a}) >= 4
    assert [c.text for c in captions(f, seed=8)] != [c.text for c in a[:5]]


def test_no_caption_for_a_clip_without_an_action() -> None:
    f = clip_facts(generate("dog", "walk", seed=1))
    with pytest.raises(CaptionError, match="none of the generator's actions"):
        captions(dataclasses.replace(f, action=None))
    short = generate("dog", "walk", seed=1).slice(0, 10)
    with pytest.raises(CaptionError, match="too short"):
        clip_facts(short)
    with pytest.raises(CaptionError, match="per_clip"):
        CaptionOptions(per_clip=0)


def test_data_set_captions_file(tmp_path, capsys) -> None:
    from habitsim.dataset import build_dataset

    ds = tmp_path / "ds"
    build_dataset(ds, clips_per_species=13, species=["dog", "cat"], workers=1, progress=False)
    assert main(["data", "captions", str(ds), "--per-clip", "4", "--seed", "1"]) == 0
    out = capsys.readouterr().out
    assert "104 captions of 26 clips" in out
    cs = load_captions(ds)
    assert len(cs.clips) == 26 and cs.seed == 1 and not cs.skipped
    forms = Counter(c.form for v in cs.clips.values() for c in v)
    assert set(forms) == set(FORMS)
    assert max(forms.values()) <= 0.35 * sum(forms.values())  # no form is the language
    for name, caps in cs.clips.items():
        sp = load_species(name.split("/")[1])
        assert all(sp.name in c.text.lower() for c in caps)
        assert cs.facts[name]["species"] == sp.name
    bad = tmp_path / "bad.json"
    bad.write_text(
        json.dumps(
            {
                "kind": "habitsim.captions",
                "format": 1,
                "seed": 0,
                "clips": {"a": {"captions": [{"text": 3}]}},
            }
        )
    )
    with pytest.raises(MotionFileError, match="'captions' must be a list"):
        load_captions(bad)
    (tmp_path / "deep.json").write_text("[" * 100_000 + "]" * 100_000)
    with pytest.raises(MotionFileError, match="cannot read captions"):
        load_captions(tmp_path / "deep.json")
    assert (ds / CAPTIONS_NAME).is_file()
