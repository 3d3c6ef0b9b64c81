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


# ---------------------------------------------------------------------------- chains


def _chained(species: str, steps: list[tuple[str, float]], seed: int = 3):
    from habitsim.gaits import chain_min_duration, generate_chain

    steps = [(a, max(d, chain_min_duration(species, a))) for a, d in steps]
    return generate_chain(species, steps, seed=seed)


@pytest.fixture(scope="module")
def chained() -> dict[str, object]:
    return {
        "up": _chained("horse", [("walk", 3.2), ("trot", 2.0), ("canter", 2.0), ("gallop", 2.0)]),
        "sit": _chained("dog", [("walk", 2.0), ("turn_left", 2.0), ("stop", 3.5), ("sit", 3.0)]),
        "right": _chained("cat", [("idle", 2.0), ("walk", 2.0), ("turn_right", 2.0)]),
        "down": _chained("dog", [("gallop", 2.0), ("trot", 2.0), ("walk", 2.0)]),
    }


def test_facts_of_a_chain_equal_the_generators_segments(chained) -> None:
    for m in chained.values():
        f = clip_facts(m)
        segs = m.metadata["chain"]["segments"]
        assert [c.action for c in f.chain] == [s["action"] for s in segs]
        assert [c.gait for c in f.chain] == [s["gait"] for s in segs]
        for c, s in zip(f.chain, segs, strict=True):
            assert c.start_s == pytest.approx(s["start_s"], abs=0.05)
            assert c.end_s == pytest.approx(s["end_s"], abs=0.05)
        assert f.source == "generator" and f.action is not None
        assert f.to_dict()["chain"][0][0] == segs[0]["action"]
    up = clip_facts(chained["up"]).chain
    assert [c.speed_mps for c in up] == sorted(c.speed_mps for c in up)
    assert clip_facts(chained["sit"]).chain[1].turn_deg > 20


_WORDS = {
    "walk": ("walk", "stroll", "stepping along", "steps along"),
    "trot": ("trot",),
    "canter": ("canter", "lope"),
    "gallop": ("gallop", "flat out"),
    "turn_left": ("left",),
    "turn_right": ("right",),
    "stop": ("stop", "halt", "pull"),
    "sit": ("sit", "haunches"),
    "idle": ("stand", "wait", "pause"),
}


def _positions(text: str, steps: list[str]) -> list[int]:
    """Where each step is first named, searching on from the one before."""
    out, at = [], 0
    low = text.lower()
    for s in steps:
        hits = [low.find(w, at) for w in _WORDS[s]]
        hits = [h for h in hits if h >= 0]
        out.append(min(hits) if hits else -1)
        at = out[-1] + 1 if hits else at
    return out


def test_chain_captions_name_the_steps_in_order(chained) -> None:
    for m in chained.values():
        f = clip_facts(m)
        steps = [c.action for c in f.chain]
        for cap in captions(f, seed=2, options=CaptionOptions(per_clip=12)):
            pos = _positions(cap.text, steps)
            assert -1 not in pos, (cap.text, steps)
            assert pos == sorted(pos), (cap.text, steps)


def test_chain_captions_make_no_false_claims(chained) -> None:
    right = clip_facts(chained["right"])
    down = clip_facts(chained["down"])
    for seed in range(20):
        for cap in captions(right, seed=seed):
            assert "left" not in cap.text.lower()
        for cap in captions(down, seed=seed):
            low = cap.text.lower()
            assert not any(w in low for w in ("breaks into", "picks up", "speeds up", "moves up"))


def test_chain_captions_vary_and_are_seeded(chained) -> None:
    from collections import Counter

    import numpy as np

    from habitsim.captions.sequences import chain_caption

    f = clip_facts(chained["sit"])
    rng = np.random.default_rng(0)
    templates = Counter(
        chain_caption(f, "a dog", str(rng.choice(FORMS)), int(rng.integers(1, 4)), rng)[1]
        for _ in range(400)
    )
    assert max(templates.values()) / 400 <= 0.35, templates
    assert captions(f, seed=4) == captions(f, seed=4)
    assert captions(f, seed=4) != captions(f, seed=5)


def test_chain_read_from_the_timeline_without_metadata(chained) -> None:
    m = chained["sit"]
    bare = type(m)(
        species=m.species,
        fps=m.fps,
        root_positions=m.root_positions,
        rotations=m.rotations,
        contacts=m.contacts,
        metadata={},
    )
    f = clip_facts(bare)
    assert f.source == "timeline"
    acts = [c.action for c in f.chain]
    assert acts[-1] == "sit" and acts[0] in ("walk", "turn_left")
    assert captions(f, seed=0)


def test_held_out_lexicon_never_meets_the_train_lexicon() -> None:
    from habitsim.captions import CaptionOptions, captions, clip_facts
    from habitsim.errors import CaptionError
    from habitsim.gaits import generate

    held_words = (
        "saunter",
        "moves at a trot",
        "at a canter",
        "charg",
        "reverses",
        "reversing",
        "motionless",
        "vault",
        "swing",
        "this clip shows",
        "watch ",
        "can be seen",
    )
    held = CaptionOptions(per_clip=4, lexicon="held_out")
    train = CaptionOptions(per_clip=8)
    for sp, action in [
        ("horse", "walk"),
        ("dog", "trot"),
        ("cat", "turn_left"),
        ("cow", "idle"),
        ("goat", "walk_backward"),
        ("horse", "gallop"),
    ]:
        facts = clip_facts(generate(sp, action, seed=1))
        para = [c.text.lower() for c in captions(facts, seed=0, options=held)]
        seen = [c.text.lower() for c in captions(facts, seed=0, options=train)]
        assert all(any(w in t for w in held_words) for t in para), para
        assert not any(w in t for w in held_words for t in seen), seen
        assert all(sp in t or facts.common_name.split()[-1].lower() in t for t in para)
    with pytest.raises(CaptionError):
        CaptionOptions(lexicon="poetry")
