"""``habitsim data captions``: write captions for every clip of a data set
(:mod:`habitsim.captions`)."""

from __future__ import annotations

import argparse
from collections import Counter

from ..captions import CaptionOptions
from ..captions.store import caption_dataset


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``captions`` to the ``data`` command group."""
    p = sub.add_parser(
        "captions",
        help="caption every clip of a data set from what is measured on it",
        description=(
            "Measure what is true of every clip of DIR (species, action, speed and Froude "
            "number, turning, direction, duration, start and end pose) and write N varied "
            "captions per clip to DIR/captions.json; prints a few of them."
        ),
    )
    p.add_argument("dataset", metavar="DIR", help="data set folder (data synth / import-bvh)")
    p.add_argument(
        "--per-clip", type=int, default=5, metavar="N", help="captions per clip (default 5)"
    )
    p.add_argument("--seed", type=int, default=0, metavar="S", help="phrasing seed (default 0)")
    p.set_defaults(func=_captions)


def _captions(ns: argparse.Namespace) -> int:
    path, cs = caption_dataset(ns.dataset, seed=ns.seed, options=CaptionOptions(ns.per_clip))
    n = sum(len(c) for c in cs.clips.values())
    levels = Counter(c.level for v in cs.clips.values() for c in v)
    forms = Counter(c.form for v in cs.clips.values() for c in v)
    distinct = len({c.text.lower() for v in cs.clips.values() for c in v})
    print(f"{path}: {n} captions of {len(cs.clips)} clips ({distinct} distinct)")
    print("  levels: " + ", ".join(f"{k}: {levels[k]}" for k in sorted(levels)))
    print("  forms: " + ", ".join(f"{k} {v}" for k, v in forms.most_common()))
    if cs.skipped:
        print(
            f"  not captioned: {len(cs.skipped)} clip(s), e.g. " + next(iter(cs.skipped.items()))[0]
        )
    for name, caps in list(cs.clips.items())[:3]:
        print(f"  {name}:")
        for c in caps[:3]:
            print(f"    [{c.level}] {c.text}")
    return 0
