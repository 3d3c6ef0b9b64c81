"""A data set's captions, one JSON file beside its manifest (``captions.json``).

Layout::

    {"kind": "habitsim.captions", "format": 1, "seed": S, "per_clip": N,
     "clips": {"<clip path in the manifest>": {"facts": {...},
                                                "captions": [{"text", "level", "form"}]}}}

:func:`caption_dataset` writes it (whole or not at all: the file is written atomically);
:func:`load_captions` reads it back, checking every field's type.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import CaptionError, MotionFileError
from ..fileio import atomic_write_text
from ..jsonfile import load_json
from .facts import clip_facts
from .phrasing import Caption, CaptionOptions, captions

__all__ = ["CAPTIONS_NAME", "CaptionSet", "caption_dataset", "load_captions"]

#: File name of a data set's captions.
CAPTIONS_NAME = "captions.json"
_KIND = "habitsim.captions"
_FORMAT = 1


@dataclass(frozen=True)
class CaptionSet:
    """The captions of a data set.

    Attributes:
        clips: clip path (as in the manifest) → its captions.
        facts: clip path → the measured facts they were written from.
        skipped: clip path → why no caption was written (a clip that shows no action).
        seed: the seed they were drawn with.
    """

    clips: dict[str, list[Caption]]
    facts: dict[str, dict[str, Any]]
    skipped: dict[str, str]
    seed: int


def caption_dataset(
    dataset: str | Path,
    seed: int = 0,
    options: CaptionOptions | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> tuple[Path, CaptionSet]:
    """Caption every clip of a data set and write ``DIR/captions.json``.

    Args:
        dataset: a data set folder (``habitsim data synth`` or ``data import-bvh``).
        seed: seed of the phrasing; each clip draws from ``seed`` and its own position.
        options: how many captions and of which levels.
        progress: called with (clips done, clips in all).

    Raises:
        DatasetError: not a data set folder (see :func:`habitsim.dataset.load_manifest`).
        OutputPathError: the captions file cannot be written.
    """
    from ..dataset import iter_clips, load_manifest

    opts = options or CaptionOptions()
    man = load_manifest(dataset, check_files=False)
    clips: dict[str, list[Caption]] = {}
    facts: dict[str, dict[str, Any]] = {}
    skipped: dict[str, str] = {}
    total = len(man.clips)
    for k, (entry, motion) in enumerate(iter_clips(man)):
        try:
            f = clip_facts(motion)
            clips[entry.path] = captions(f, seed=seed * 1_000_003 + k, options=opts)
            facts[entry.path] = f.to_dict()
        except CaptionError as e:
            skipped[entry.path] = str(e)
        if progress is not None:
            progress(k + 1, total)
    out = man.root / CAPTIONS_NAME
    doc = {
        "kind": _KIND,
        "format": _FORMAT,
        "seed": int(seed),
        "per_clip": opts.per_clip,
        "clips": {
            p: {"facts": facts[p], "captions": [c.__dict__ for c in cs]} for p, cs in clips.items()
        },
        "skipped": skipped,
    }
    atomic_write_text(out, json.dumps(doc, indent=1, ensure_ascii=False) + "\n")
    return out, CaptionSet(clips, facts, skipped, int(seed))


def load_captions(path: str | Path) -> CaptionSet:
    """Read a ``captions.json`` (or the one in a data set folder).

    Raises:
        MotionFileError: missing, not JSON, or not a habitsim captions file (the message
            names the field that is wrong).
    """
    p = Path(path)
    if p.is_dir():
        p = p / CAPTIONS_NAME
    try:
        doc = load_json(p, "captions", error=MotionFileError)
    except MotionFileError as e:
        raise MotionFileError(f"{e}; write them with `habitsim data captions DIR`") from None
    if not isinstance(doc, dict) or doc.get("kind") != _KIND or doc.get("format") != _FORMAT:
        raise MotionFileError(f"{p}: not a habitsim captions file (kind {_KIND!r}, format 1)")
    raw, skipped, seed = doc.get("clips"), doc.get("skipped", {}), doc.get("seed")
    if not isinstance(raw, dict) or not isinstance(skipped, dict) or type(seed) is not int:
        raise MotionFileError(f"{p}: 'clips' and 'skipped' must be objects, 'seed' an integer")
    clips: dict[str, list[Caption]] = {}
    facts: dict[str, dict[str, Any]] = {}
    for name, item in raw.items():
        caps = item.get("captions") if isinstance(item, dict) else None
        if not isinstance(caps, list) or not all(
            isinstance(c, dict)
            and isinstance(c.get("text"), str)
            and type(c.get("level")) is int
            and isinstance(c.get("form"), str)
            for c in caps
        ):
            raise MotionFileError(
                f"{p}: clip {name[:80]!r}: 'captions' must be a list of "
                "{text: str, level: int, form: str}"
            )
        clips[name] = [Caption(c["text"], c["level"], c["form"]) for c in caps]
        f = item.get("facts")
        facts[name] = f if isinstance(f, dict) else {}
    return CaptionSet(clips, facts, {str(k): str(v) for k, v in skipped.items()}, seed)
