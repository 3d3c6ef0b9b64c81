"""Text to motion: a sentence and a species in, a :class:`~habitsim.motion.Motion` out.

``text_to_motion("a dog trots to the left", "dog", 4.0, seed=1, checkpoint=CKPT)``:

1. the sentence is embedded (the text model the code set was embedded with);
2. :class:`~habitsim.models.codegpt.CodeGPT` draws the code steps and the path,
   conditioned on the sentence, the species' habit embedding g_c and the length;
3. the VQ-VAE the codes belong to decodes them along that path, its decoder conditioned
   on the species exactly as in a transfer: z_c drawn from the species' flow prior with
   the seed, and its g_c;
4. the decoded features become a motion on the species' skeleton, with stance labels from
   the decoder's contact channels.

A species the transformer or the VQ-VAE was not trained on borrows the habit of its
nearest trained species by text retrieval (:func:`habitsim.models.text.retrieve_neighbour`);
``metadata["text_to_motion"]`` says which. The same arguments give the same motion
(one CPU thread, seeded draws).
"""

from __future__ import annotations

import functools
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from ..motion import Motion
from ..species import load_species
from ..threads import one_thread
from .checkpoint import CONFIG_FILE
from .codegpt import decoder_path
from .errors import GenerationRequestError, MethodNotAvailableError, TextEncoderError
from .t2m_data import Embedder, code_set_vq, prompt_text
from .t2m_train import LoadedCodeGPT, load_codegpt

__all__ = ["T2MOptions", "text_to_motion", "check_text", "load_t2m", "T2M_VARIANT"]

#: Folder name of a text-to-motion checkpoint under ``$HABITSIM_MODELS_DIR``.
T2M_VARIANT = "t2m"


@dataclass(frozen=True)
class T2MOptions:
    """Limits of a text-to-motion request.

    Attributes:
        max_text_chars: longest prompt [characters]; the bundled sentence model reads at
            most 256 word pieces and would silently drop the rest of a longer one.
    """

    max_text_chars: int = 512


def load_t2m(checkpoint: str | Path | None = None) -> LoadedCodeGPT:
    """A text-to-motion checkpoint: ``checkpoint``, else ``$HABITSIM_MODELS_DIR/t2m``
    (loaded once per folder and modification time).

    Raises:
        MethodNotAvailableError: none given and none in ``$HABITSIM_MODELS_DIR``.
        CheckpointError: it cannot be loaded.
    """
    from .transfer import MODELS_DIR_ENV

    if checkpoint is None:
        env = os.environ.get(MODELS_DIR_ENV)
        if env and (Path(env) / T2M_VARIANT / CONFIG_FILE).is_file():
            checkpoint = Path(env) / T2M_VARIANT
        else:
            raise MethodNotAvailableError(
                "no text-to-motion checkpoint ships with habitsim: build a code set and train "
                "one (docs/text_to_motion.md), then pass checkpoint=CKPT or put it in "
                f"${MODELS_DIR_ENV}/{T2M_VARIANT}"
            )
    p = Path(checkpoint).resolve()
    cfg = p / CONFIG_FILE
    return _cached(str(p), cfg.stat().st_mtime if cfg.is_file() else 0.0)


@functools.lru_cache(maxsize=4)
def _cached(path: str, mtime: float) -> LoadedCodeGPT:
    return load_codegpt(path)


def check_text(text: object, options: T2MOptions | None = None) -> str:
    """``text`` when it is a prompt the model can read.

    Raises:
        GenerationRequestError: empty (``empty_text``), longer than
            :attr:`T2MOptions.max_text_chars` (``text_too_long``) or not UTF-8 text
            (``bad_text``).
    """
    opts = options or T2MOptions()
    if not isinstance(text, str) or not text.strip():
        raise GenerationRequestError(
            "empty_text", "the prompt is empty: describe the motion in a sentence"
        )
    if len(text) > opts.max_text_chars:
        raise GenerationRequestError(
            "text_too_long",
            f"the prompt has {len(text)} characters; at most {opts.max_text_chars} are read",
        )
    try:
        text.encode("utf-8")
    except UnicodeEncodeError as e:
        raise GenerationRequestError(
            "bad_text",
            f"the prompt holds a character that is no text (U+{ord(text[e.start]):04X} at "
            f"position {e.start}, a lone surrogate); valid: a sentence in UTF-8",
        ) from None
    return text


def _check_request(
    text: str,
    seconds: float,
    temperature: float,
    top_k: int | None,
    guidance: float,
    gpt: LoadedCodeGPT,
    opts: T2MOptions,
) -> int:
    """The number of code steps of a valid request (GenerationRequestError otherwise)."""
    check_text(text, opts)
    per_step = gpt.rate / gpt.fps
    most = gpt.config.model.max_steps
    ok = isinstance(seconds, int | float) and not isinstance(seconds, bool)
    steps = int(round(seconds / per_step)) if ok and math.isfinite(seconds) else 0
    if not 1 <= steps <= most:
        raise GenerationRequestError(
            "length_out_of_range",
            f"cannot make a clip of {seconds!r} s: this model makes {per_step:.3g} s to "
            f"{most * per_step:.3g} s ({most} code steps of {gpt.rate} frames at "
            f"{gpt.fps:g} fps)",
        )
    if not (math.isfinite(temperature) and temperature >= 0):
        raise GenerationRequestError(
            "bad_sampling", f"temperature must be ≥ 0 (0: most likely codes), got {temperature}"
        )
    if not (math.isfinite(guidance) and guidance >= 0):
        raise GenerationRequestError(
            "bad_sampling", f"guidance must be ≥ 0 (1: no guidance), got {guidance}"
        )
    if top_k is not None and not (isinstance(top_k, int) and 1 <= top_k <= gpt.model.num_codes):
        raise GenerationRequestError(
            "bad_sampling", f"top_k must be None or in 1…{gpt.model.num_codes}, got {top_k!r}"
        )
    return steps


def _embed(text: str, gpt: LoadedCodeGPT, embed: Embedder | None) -> torch.Tensor:
    """The prompt's sentence embedding, read as the checkpoint's code set read captions
    (its ``text_form``)."""
    read = prompt_text([text], str(gpt.meta.get("text_form", "as_written")))
    if embed is None:
        from .text import embed_texts

        vec = embed_texts(read, str(gpt.meta["text_model"]))
    else:
        vec = np.asarray(embed(read), dtype=np.float32)
    if vec.shape != (1, gpt.model.text_dim):
        raise TextEncoderError(
            f"the prompt's embedding has shape {vec.shape}; this model reads (1, "
            f"{gpt.model.text_dim}) from {gpt.meta['text_model']!r}: embed with that model"
        )
    return torch.from_numpy(np.asarray(vec[0], dtype=np.float32))


def _code_species(gpt: LoadedCodeGPT, ck: Any, species: str) -> tuple[str, Any]:
    """The transformer's species for ``species`` (itself, or the nearest it knows)."""
    from .text import retrieve_neighbour
    from .transfer import _embeddings

    known = list(gpt.model.species)
    if species in known:
        return species, None
    emb = _embeddings(ck, [species, *known])
    r = retrieve_neighbour(species, known, emb, ck.config.model.text.morphology_weight)
    return r.neighbour, r


def _retrieval_info(r: Any) -> dict[str, Any] | None:
    if r is None:
        return None
    return {
        "neighbour": r.neighbour,
        "text_distance": round(r.text_distance, 4),
        "explanation": r.explain(),
    }


def text_to_motion(
    text: str,
    species: str,
    seconds: float,
    *,
    seed: int = 0,
    temperature: float = 1.0,
    guidance: float = 2.0,
    top_k: int | None = None,
    checkpoint: str | Path | None = None,
    vq_checkpoint: str | Path | None = None,
    embed: Embedder | None = None,
    options: T2MOptions | None = None,
) -> Motion:
    """Generate a motion of ``species`` that does what ``text`` says.

    Args:
        text: the prompt (a sentence like the captions: "a cat trots slowly to the left").
        species: a catalog species; one the models were not trained on borrows its
            nearest trained neighbour's habit (``metadata["text_to_motion"]``).
        seconds: clip length [s], rounded to whole code steps (rate / fps each).
        seed: seed of the code draws and of the habit latent z_c (same seed ⇒ same motion).
        temperature: divides the logits (0: the most likely code each step).
        guidance: classifier-free guidance scale s: logits l_u + s·(l_c − l_u)
            (1: conditional only, 0: the prompt ignored, > 1: follows it more closely).
        top_k: draw among the k most likely codes only (None: all).
        checkpoint: the transformer's checkpoint folder (default
            ``$HABITSIM_MODELS_DIR/t2m``).
        vq_checkpoint: the VQ-VAE folder if it moved since training (SHA-256 checked).
        embed: sentence embedder (default: the checkpoint's text model through
            :func:`habitsim.models.text.embed_texts`).
        options: request limits (:class:`T2MOptions`).

    Returns:
        A motion at the VQ-VAE's frame rate, ``steps × rate`` frames, with stance labels
        and ``metadata["text_to_motion"]`` (text, seed, sampling, habit species,
        retrieval, checkpoints).

    Raises:
        GenerationRequestError: empty or too long text, a length the model cannot make,
            sampling settings out of range (``code`` says which).
        UnknownSpeciesError: not a catalog species (lists the known ones).
        MethodNotAvailableError / CheckpointError: no usable checkpoint.
        TextEncoderError: the prompt cannot be embedded as the model needs.
    """
    opts = options or T2MOptions()
    gpt = load_t2m(checkpoint)
    steps = _check_request(text, seconds, temperature, top_k, guidance, gpt, opts)
    sp = load_species(species).name
    ck = code_set_vq(gpt.meta["vq"], vq_checkpoint)
    feats, info = _generate(
        gpt, ck, text, sp, steps, seed, temperature, top_k, guidance, _embed(text, gpt, embed)
    )
    from .features import decoded_contacts, features_to_motion

    out = features_to_motion(feats, sp, ck.fps)
    info = {
        "text": text,
        "species": sp,
        "seconds": round(steps * gpt.rate / gpt.fps, 4),
        "steps": steps,
        "seed": int(seed),
        "temperature": float(temperature),
        "guidance": float(guidance),
        "top_k": top_k,
        **info,
        "checkpoint": str(gpt.path),
        "vq_checkpoint": None if ck.path is None else str(ck.path),
    }
    return Motion(
        sp,
        out.fps,
        out.root_positions,
        out.rotations,
        decoded_contacts(feats),
        {"text_to_motion": info},
    )


@one_thread()  # the same output on every machine (habitsim.threads)
@torch.no_grad()
def _generate(
    gpt: LoadedCodeGPT,
    ck: Any,
    text: str,
    sp: str,
    steps: int,
    seed: int,
    temperature: float,
    top_k: int | None,
    guidance: float,
    emb: torch.Tensor,
) -> tuple[np.ndarray, dict[str, Any]]:
    from .transfer import _prior_draw, _text_rows, habit_species_for

    code_sp, code_r = _code_species(gpt, ck, sp)
    gen = torch.Generator().manual_seed(int(seed))
    codes, pathf = gpt.model.sample(
        emb,
        gpt.model.habit_rows([code_sp])[0],
        steps,
        generator=gen,
        temperature=temperature,
        top_k=top_k,
        guidance=guidance,
    )
    vq = ck.model
    books = [vq.quantizer, *(getattr(vq, "residual_quantizers", None) or [])]
    q = sum(b.dequantize(codes[None, :, k]) for k, b in enumerate(books))
    assert isinstance(q, torch.Tensor)
    path = decoder_path(pathf, vq.path_dim).T[None] if vq.path_dim else None
    habit_sp, habit_r = None, None
    z = None
    if vq.cfg.use_z:
        habit_sp, habit_r = habit_species_for(ck, sp)
        z = _prior_draw(ck, habit_sp, seed, 1.0)
    cond = vq.condition([sp], z, _text_rows(ck, sp, 1) if vq.cfg.use_g else None)
    feats = vq.decode(q, cond, path)[0].numpy().astype(np.float64)
    info = {
        "habit_species": habit_sp,
        "retrieval": _retrieval_info(habit_r),
        "code_species": code_sp,
        "code_retrieval": _retrieval_info(code_r),
    }
    return feats, info
