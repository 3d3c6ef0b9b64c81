"""The code set of text-to-motion: every captioned clip of a data set as VQ-VAE codes.

:func:`build_code_set` encodes each clip of a synthetic data set (``habitsim data
synth``, captioned by ``habitsim data captions``) with a trained
:class:`~habitsim.models.model.HabitVQVAE` into what :mod:`habitsim.models.codegpt` is
trained on: per code step the code index of every residual level and the decoder's path
input, the clip's species, its captions and their sentence embeddings.

A whole clip is encoded as one heading-canonical sequence (its length cut to a multiple
of the model's temporal rate): the encoder and decoder are convolutional and take any
such length, and on synthetic clips the whole-clip reconstruction error matches that of
the 64-frame windows the model was trained on (docs/text_to_motion.md).

Layout of a code set folder::

    codes.json                       written LAST: clips, captions, VQ-VAE, text model
    clips/<split>/<species>/<name>.safetensors
                                     codes (T', L) int32, path (T', P) float32,
                                     text (N, E) float32 (one row per caption)

Every file is written atomically. A rebuild keeps each clip file whose recorded VQ-VAE,
text model and captions match (an interrupted build continues where it stopped).

**Held-out compositions.** The builder holds some species × action pairs out of training
(:class:`CompositionOptions`, :func:`held_out_compositions`): every train clip of such a
pair is recorded in the split ``compose`` instead of ``train``, so no caption of that
pair is ever trained on while the species (with other actions) and the action (with
other species) are. The pairs are chosen from the train clips alone, deterministically,
and listed in ``codes.json`` (``compositions``).
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..fileio import atomic_write, atomic_write_text, make_dirs
from ..jsonfile import load_json, loads_json
from .errors import CodeSetError

__all__ = [
    "COMPOSE_SPLIT",
    "CompositionOptions",
    "held_out_compositions",
    "CODES_NAME",
    "CODES_KIND",
    "CodeClip",
    "CodeSet",
    "Embedder",
    "build_code_set",
    "load_code_set",
    "clip_codes",
    "code_set_vq",
    "prompt_text",
]

#: File name of a code set's index.
CODES_NAME = "codes.json"
CODES_KIND = "habitsim.t2m.codes"
_FORMAT = 1

#: A sentence embedder: texts → (N, E) float32 (default: :func:`habitsim.models.text.embed_texts`).
Embedder = Callable[[Sequence[str]], np.ndarray]
#: The code set split of the train clips whose species × action pair is held out.
COMPOSE_SPLIT = "compose"


@dataclass(frozen=True)
class CompositionOptions:
    """Which species × action pairs of the train clips the code set holds out.

    Attributes:
        per_action: pairs held out per action (each of another species).
        min_species: an action is held out only for species beyond this many: it needs
            train clips of at least ``min_species`` species, and it stays in training
            with ``min_species - per_action`` of them at least.
        min_actions: a species keeps at least this many of its actions in training.
    """

    per_action: int = 1
    min_species: int = 3
    min_actions: int = 2


def held_out_compositions(
    pairs: Sequence[tuple[str, str]], options: CompositionOptions | None = None
) -> list[tuple[str, str]]:
    """The (species, action) pairs to hold out of ``pairs`` (those of the train clips):
    actions in name order, each taking the species with the fewest pairs held out so far
    (ties broken by a rotation with the action's index), within the limits of
    ``options``. The same pairs give the same choice."""
    opts = options or CompositionOptions()
    by_action: dict[str, list[str]] = {}
    actions_of: dict[str, set[str]] = {}
    for sp, act in sorted(set(pairs)):
        by_action.setdefault(act, []).append(sp)
        actions_of.setdefault(sp, set()).add(act)
    taken: dict[str, int] = {}
    out: list[tuple[str, str]] = []
    for i, act in enumerate(sorted(by_action)):
        have = by_action[act]
        if len(have) < max(opts.min_species, opts.per_action + 1):
            continue
        order = sorted(range(len(have)), key=lambda k: (taken.get(have[k], 0), (k - i) % len(have)))
        chosen = 0
        for k in order:
            sp = have[k]
            if chosen >= opts.per_action:
                break
            if len(actions_of[sp]) - taken.get(sp, 0) - 1 < opts.min_actions:
                continue
            taken[sp] = taken.get(sp, 0) + 1
            out.append((sp, act))
            chosen += 1
    return sorted(out)


@dataclass(frozen=True)
class CodeClip:
    """One encoded clip.

    Attributes:
        source: the clip's path in the data set's manifest.
        split: ``train``, ``val``, ``test`` or ``compose`` (a train clip of a held-out
            species × action pair).
        species: catalog species name.
        codes: (T', L) int code indices, one row per code step, one column per level.
        path: (T', P) float32, the decoder's path input per code step (P = 0 for a model
            without one).
        captions: the clip's caption texts.
        text: (N, E) float32 sentence embeddings of ``captions``.
    """

    source: str
    split: str
    species: str
    codes: np.ndarray
    path: np.ndarray
    captions: tuple[str, ...]
    text: np.ndarray

    @property
    def steps(self) -> int:
        return int(self.codes.shape[0])


@dataclass
class CodeSet:
    """A loaded code set (see the module docstring).

    Attributes:
        root: its folder.
        clips: the encoded clips.
        meta: the rest of ``codes.json`` (VQ-VAE, text model, fps, rate, levels, …).
    """

    root: Path
    clips: list[CodeClip]
    meta: dict[str, Any] = field(default_factory=dict)

    def split(self, name: str) -> list[CodeClip]:
        """The clips of one split."""
        return [c for c in self.clips if c.split == name]

    @property
    def species(self) -> list[str]:
        return sorted({c.species for c in self.clips})

    @property
    def levels(self) -> int:
        return int(self.meta["levels"])

    @property
    def num_codes(self) -> int:
        return int(self.meta["num_codes"])

    @property
    def path_dim(self) -> int:
        return int(self.meta["path_dim"])

    @property
    def text_dim(self) -> int:
        return int(self.meta["text_dim"])


def clip_codes(model: Any, motion: Any, fps: float) -> tuple[np.ndarray, np.ndarray]:
    """Encode a whole motion with a VQ-VAE into (codes (T', L) int32, path (T', P) float32).

    The motion is resampled to ``fps`` (the model's) and cut to a multiple of the
    model's rate; one heading-canonical sequence from its first frame.

    Raises:
        CodeSetError: the motion is shorter than one code step.
    """
    import torch

    from ..motion import resample_motion
    from ..threads import one_thread
    from .features import canonical_window, clip_arrays

    m = motion if abs(motion.fps - fps) < 1e-9 else resample_motion(motion, fps)
    arrays = clip_arrays(m)
    rate = model.cfg.rate
    n = arrays.num_frames // rate * rate
    if n < rate:
        raise CodeSetError(
            f"a {arrays.num_frames}-frame clip is shorter than one code step "
            f"({rate} frames at {fps:g} fps)"
        )
    x, _, _ = canonical_window(arrays, 0, n)
    with one_thread(), torch.no_grad():
        xt = torch.from_numpy(x)[None]
        out = model.quantize(model.encode(xt), sample=False, update=False)
        codes = out.level_indices[0].numpy().astype(np.int32)
        path = model.path(xt)
    p = (
        np.zeros((codes.shape[0], 0), np.float32)
        if path is None
        else path[0].T.numpy().astype(np.float32)
    )
    return codes, p


def _clip_file(root: Path, source: str) -> Path:
    return root / "clips" / Path(source).with_suffix(".safetensors")


def _read_clip(path: Path, source: str, split: str, species: str) -> CodeClip:
    from safetensors import SafetensorError, safe_open

    try:
        with safe_open(str(path), framework="numpy") as fh:
            meta = fh.metadata() or {}
            arrays = {k: fh.get_tensor(k) for k in ("codes", "path", "text")}
        captions = tuple(
            loads_json(meta.get("captions", "[]"), f"{path}: captions", error=CodeSetError)
        )
    except (SafetensorError, OSError, ValueError, KeyError, TypeError, CodeSetError) as e:
        raise CodeSetError(
            f"{path}: not a readable code clip ({type(e).__name__}); rebuild the code set "
            "with `build_code_set` (it re-encodes what is missing or broken)"
        ) from None
    if arrays["text"].shape[0] != len(captions) or arrays["codes"].ndim != 2:
        raise CodeSetError(f"{path}: its codes, captions and embeddings do not agree")
    return CodeClip(
        source,
        split,
        species,
        arrays["codes"].astype(np.int64),
        arrays["path"].astype(np.float32),
        captions,
        arrays["text"].astype(np.float32),
    )


def _clip_meta(path: Path) -> dict[str, str]:
    from safetensors import SafetensorError, safe_open

    try:
        with safe_open(str(path), framework="numpy") as fh:
            return dict(fh.metadata() or {})
    except (SafetensorError, OSError, ValueError):
        return {}


def build_code_set(
    dataset: str | Path,
    out_dir: str | Path,
    *,
    checkpoint: str | Path | None = None,
    embed: Embedder | None = None,
    text_model: str | None = None,
    splits: Sequence[str] = ("train", "val"),
    progress: Callable[[int, int], None] | None = None,
    compositions: CompositionOptions | None = None,
    text_form: str = "species_neutral",
) -> CodeSet:
    """Encode every captioned clip of a data set into a code set folder.

    Args:
        dataset: a data set folder with ``captions.json`` (``habitsim data captions``).
        out_dir: the code set folder (created; clips already encoded alike are kept).
        checkpoint: VQ-VAE checkpoint folder (default: the shipped ``habit`` one).
        embed: sentence embedder (default: :func:`habitsim.models.text.embed_texts` with
            the VQ-VAE's text model); a custom one needs ``text_model``.
        text_model: name recorded for the embedder (default: the VQ-VAE's text model;
            required with a custom ``embed``); a generator must embed prompts alike.
        splits: which splits of the data set to encode.
        progress: called with (clips done, clips in all).
        compositions: which species × action pairs of the train clips are held out into
            the split ``compose`` (module docstring; default :class:`CompositionOptions`).
        text_form: how captions are embedded (and prompts then read): ``species_neutral``
            (species words replaced by "animal",
            :func:`habitsim.captions.prompts.species_neutral`: the generator gets the
            species from its habit input) or ``as_written``.

    Returns:
        The code set, as :func:`load_code_set` reads it.

    Raises:
        CodeSetError: no captions, no captioned clip, a custom ``embed`` without
            ``text_model``, embeddings of the wrong shape.
        DatasetError: not a data set folder.
        CheckpointError / MethodNotAvailableError: the VQ-VAE cannot be loaded.
    """
    from ..captions.store import CAPTIONS_NAME, load_captions
    from ..dataset import iter_clips, load_manifest
    from ..errors import MotionFileError
    from ..gaits import ACTIONS
    from .checkpoint import MODEL_FILE
    from .transfer import load_model

    man = load_manifest(dataset, check_files=False)
    try:
        caps = load_captions(man.root)
    except MotionFileError as err:
        raise CodeSetError(
            f"{man.root}: no usable {CAPTIONS_NAME} ({err}); caption the data set first: "
            f"`habitsim data captions {man.root}`"
        ) from None
    if embed is not None and text_model is None:
        raise CodeSetError("a custom embed needs text_model: the name generation will embed with")
    from ..captions.prompts import TEXT_FORMS

    if text_form not in TEXT_FORMS:
        raise CodeSetError(f"unknown text_form {text_form!r}; valid: {', '.join(TEXT_FORMS)}")
    ck = load_model(checkpoint)
    model = ck.model
    tm = text_model or ck.config.model.text.model
    if embed is None:
        from .text import embed_texts

        def embed(texts: Sequence[str]) -> np.ndarray:
            return embed_texts(texts, tm)

    vq_sha = ck.meta["files"][MODEL_FILE]
    root = make_dirs(out_dir, "code set folder")
    entries = [e for e in man.clips if e.split in set(splits)]
    todo = [e for e in entries if caps.clips.get(e.path)]
    skipped = {e.path: "no caption" for e in entries if not caps.clips.get(e.path)}
    if not todo:
        raise CodeSetError(
            f"{man.root}: no captioned clip in the split(s) {', '.join(splits)}; valid "
            f"splits: train, val, test; caption with `habitsim data captions {man.root}`"
        )
    records: list[dict[str, Any]] = []
    done = 0
    keep: dict[str, bool] = {}
    for e in todo:
        texts = [c.text for c in caps.clips[e.path]]
        f = _clip_file(root, e.path)
        meta = _clip_meta(f) if f.is_file() else {}
        keep[e.path] = (
            meta.get("vq_sha256") == vq_sha
            and meta.get("text_model") == tm
            and meta.get("captions") == json.dumps(texts)
            and meta.get("text_form", "as_written") == text_form
        )
    missing = {e.path for e in todo if not keep[e.path]}
    motions = iter_clips(man) if missing else iter([])
    for entry, motion in motions:
        if entry.path not in missing:
            continue
        texts = [c.text for c in caps.clips[entry.path]]
        try:
            codes, path = clip_codes(model, motion, ck.fps)
        except CodeSetError as err:
            skipped[entry.path] = str(err)
            continue
        emb = np.asarray(embed(prompt_text(texts, text_form)), dtype=np.float32)
        if emb.ndim != 2 or emb.shape[0] != len(texts):
            raise CodeSetError(
                f"the embedder returned shape {emb.shape} for {len(texts)} captions; it must "
                "return one row per text, (N, E)"
            )
        _write_clip(_clip_file(root, entry.path), codes, path, emb, texts, vq_sha, tm, text_form)
        done += 1
        if progress is not None:
            progress(done, len(missing))
    text_dim = None
    held = held_out_compositions(
        [
            (e.species, e.action)
            for e in todo
            if e.split == "train" and e.path not in skipped and e.action in ACTIONS
        ],
        compositions,
    )
    for e in todo:
        if e.path in skipped:
            continue
        c = _read_clip(_clip_file(root, e.path), e.path, e.split, e.species)
        text_dim = c.text.shape[1] if text_dim is None else text_dim
        if c.text.shape[1] != text_dim:
            raise CodeSetError(
                f"{e.path}: embeddings of width {c.text.shape[1]}, others {text_dim}; "
                "one text model must embed every caption (rebuild into a new folder)"
            )
        held_out = e.split == "train" and (e.species, e.action) in held
        records.append(
            {
                "source": e.path,
                "split": COMPOSE_SPLIT if held_out else e.split,
                "species": e.species,
                "steps": c.steps,
                "captions": list(c.captions),
            }
        )
    if not records:
        raise CodeSetError(f"{man.root}: no clip could be encoded ({len(skipped)} skipped)")
    doc = {
        "kind": CODES_KIND,
        "format": _FORMAT,
        "dataset": str(man.root.resolve()),
        "vq": {
            "path": None if ck.path is None else str(Path(ck.path).resolve()),
            "sha256": vq_sha,
            "variant": ck.config.model.variant,
        },
        "text_model": tm,
        "text_form": text_form,
        "text_dim": int(text_dim or 0),
        "fps": ck.fps,
        "rate": model.cfg.rate,
        "levels": model.cfg.quantizer.levels,
        "num_codes": model.cfg.quantizer.num_codes,
        "path_dim": model.path_dim,
        "compositions": [list(p) for p in held],
        "clips": records,
        "skipped": skipped,
    }
    atomic_write_text(root / CODES_NAME, json.dumps(doc, indent=1) + "\n")
    return load_code_set(root)


def _write_clip(
    path: Path,
    codes: np.ndarray,
    p: np.ndarray,
    emb: np.ndarray,
    texts: list[str],
    vq_sha: str,
    text_model: str,
    text_form: str,
) -> None:
    from safetensors.numpy import save

    make_dirs(path.parent, "code set folder")
    blob = save(
        {
            "codes": np.ascontiguousarray(codes, dtype=np.int32),
            "path": np.ascontiguousarray(p, dtype=np.float32),
            "text": np.ascontiguousarray(emb, dtype=np.float32),
        },
        metadata={
            "vq_sha256": vq_sha,
            "text_model": text_model,
            "text_form": text_form,
            "captions": json.dumps(texts),
        },
    )
    with atomic_write(path) as fh:
        fh.write(blob)


def prompt_text(texts: Sequence[str], text_form: str) -> list[str]:
    """The texts as a model of ``text_form`` embeds them (``species_neutral``: species
    words replaced, :func:`habitsim.captions.prompts.species_neutral`)."""
    if text_form == "as_written":
        return list(texts)
    from ..captions.prompts import species_neutral

    return [species_neutral(t) for t in texts]


def load_code_set(path: str | Path) -> CodeSet:
    """Read a code set folder (or its ``codes.json``).

    Raises:
        CodeSetError: missing or unreadable index, a clip file missing or broken.
    """
    p = Path(path)
    root = p.parent if p.name == CODES_NAME else p
    idx = root / CODES_NAME
    try:
        doc = load_json(idx, "code set index", error=CodeSetError)
    except CodeSetError as e:
        raise CodeSetError(f"{e}; build one with `build_code_set(DATASET, OUT)`") from None
    need = ("fps", "rate", "levels", "num_codes", "path_dim", "text_dim", "text_model", "vq")
    if not isinstance(doc, dict) or doc.get("kind") != CODES_KIND or doc.get("format") != _FORMAT:
        raise CodeSetError(f"{idx}: not a habitsim code set (kind {CODES_KIND!r}, format 1)")
    missing = [k for k in need if k not in doc]
    if missing or not isinstance(doc.get("clips"), list):
        raise CodeSetError(f"{idx}: missing keys {missing or ['clips']}")
    clips = []
    for rec in doc["clips"]:
        try:
            src, split, sp = str(rec["source"]), str(rec["split"]), str(rec["species"])
        except (KeyError, TypeError):
            raise CodeSetError(f"{idx}: a clip record lacks source / split / species") from None
        clips.append(_read_clip(_clip_file(root, src), src, split, sp))
    meta = {k: v for k, v in doc.items() if k != "clips"}
    return CodeSet(root, clips, meta)


def code_set_vq(vq: dict[str, Any], checkpoint: str | Path | None = None) -> Any:
    """The VQ-VAE a code set (or a model trained on one) was encoded with: ``checkpoint``
    if given, else the recorded folder, else the shipped checkpoint of its variant; its
    ``model.safetensors`` must have the recorded SHA-256 (codes mean nothing under
    another codebook).

    Raises:
        CheckpointError: no such VQ-VAE, or another one than the codes were made with.
    """
    from .checkpoint import MODEL_FILE
    from .errors import CheckpointError
    from .transfer import load_model, shipped_checkpoint

    where = checkpoint
    if where is None and vq.get("path") and Path(vq["path"]).is_dir():
        where = vq["path"]
    if where is None:
        where = shipped_checkpoint(str(vq.get("variant", "habit")))
    if where is None:
        raise CheckpointError(
            f"the VQ-VAE {vq.get('path')!r} the codes were made with is gone; pass its "
            "folder as vq_checkpoint"
        )
    ck = load_model(where)
    sha = ck.meta["files"].get(MODEL_FILE)
    if sha != vq.get("sha256"):
        raise CheckpointError(
            f"{where}: VQ-VAE {str(sha)[:12]}… is not the one the codes were made with "
            f"({str(vq.get('sha256'))[:12]}…); pass that checkpoint as vq_checkpoint"
        )
    return ck
