"""The text–motion evaluator: a motion encoder and a text encoder in one embedding space.

It is what the text-to-motion protocol (:mod:`habitsim.evaluation.bench.t2m`) measures
with, and it is trained apart from the generator, on (caption, clip) pairs of a captioned
data set (``habitsim data captions DIR``), with a symmetric InfoNCE loss: in a batch of
B pairs each caption must pick its own clip among the B clips and each clip its own
caption.

* **Motion encoder**: the motion evaluator's network (:class:`~habitsim.evaluation.
  evaluator.MotionEvaluator`, its heads unused) over the same input
  (:func:`~habitsim.evaluation.evaluator.evaluator_input`: heading-canonical per-frame
  features at 30 Hz, standardised with the training clips' statistics), then a linear
  layer into the embedding.
* **Text encoder**: a two-layer MLP over the caption's sentence embedding (the text model
  named in the config, :func:`habitsim.models.text.embed_texts`; any embedder can be
  passed instead, as to :func:`habitsim.models.t2m.text_to_motion`).

Both embeddings have unit length, so Euclidean distances (R-precision, MM-Dist,
diversity) lie in [0, 2]. The checkpoint is ``model.safetensors`` + ``config.json``, both
written atomically and together.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from habitsim.fileio import atomic_write, atomic_write_text, make_dirs, output_transaction
from habitsim.jsonfile import load_json
from habitsim.motion import Motion
from habitsim.threads import one_thread

from .evaluator import EvaluatorConfig, EvaluatorError, MotionEvaluator, _batch, evaluator_input

__all__ = [
    "T2MEvaluatorConfig",
    "TextMotionEncoder",
    "T2MEvaluator",
    "T2MTrainReport",
    "Embedder",
    "captioned_clips",
    "train_t2m_evaluator",
    "load_t2m_evaluator",
    "r_precision",
    "matching_distance",
]

_WEIGHTS = "model.safetensors"
_CONFIG = "config.json"
_KIND = "habitsim.t2m_evaluator"
#: Version of ``config.json`` this module reads and writes (a format constant).
CONFIG_FORMAT_VERSION = 1

#: A sentence embedder: texts → (N, E) float32.
Embedder = Callable[[Sequence[str]], np.ndarray]


@dataclass(frozen=True)
class T2MEvaluatorConfig:
    """Sizes and training settings of the text–motion evaluator (stored in ``config.json``).

    Attributes:
        text_model: the sentence model captions are embedded with (recorded; an injected
            embedder must name its own).
        text_dim: width of its sentence embeddings (set from the data at training).
        fps: frame rate the motion encoder reads [Hz].
        d_model, n_heads, n_layers, ff_dim: motion transformer sizes.
        embed_dim: width of the shared embedding.
        text_hidden: hidden width of the text MLP.
        temperature: InfoNCE temperature (logits = cosine / temperature).
        steps: optimiser steps.
        batch_size: pairs per step (the InfoNCE negatives; capped at the clip count).
        lr, weight_decay: AdamW settings (cosine decay of lr).
        crop_s: longest training window [s] (a random window of each clip per step).
        seed: seed of every random draw of training.
    """

    text_model: str = "all-MiniLM-L6-v2"
    text_dim: int = 0
    fps: float = 30.0
    d_model: int = 64
    n_heads: int = 4
    n_layers: int = 2
    ff_dim: int = 128
    embed_dim: int = 32
    text_hidden: int = 128
    temperature: float = 0.1
    steps: int = 600
    batch_size: int = 32
    lr: float = 1e-3
    weight_decay: float = 1e-2
    crop_s: float = 4.0
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("d_model", "n_heads", "n_layers", "ff_dim", "embed_dim", "text_hidden"):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < 1:
                raise EvaluatorError(f"{name} must be a positive integer, got {v!r}")
        for name in ("steps", "batch_size"):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < 1:
                raise EvaluatorError(f"{name} must be a positive integer, got {v!r}")
        if self.batch_size < 2:
            raise EvaluatorError(
                f"batch_size must be ≥ 2 (negatives needed), got {self.batch_size}"
            )
        if self.d_model % self.n_heads:
            raise EvaluatorError(
                f"d_model {self.d_model} is not divisible by n_heads {self.n_heads}"
            )
        for name in ("fps", "temperature", "lr", "crop_s"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
                raise EvaluatorError(f"{name} must be a positive number, got {v!r}")

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> T2MEvaluatorConfig:
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(d) - known)
        if unknown:
            raise EvaluatorError(
                f"unknown text–motion evaluator config keys: {', '.join(unknown)}; "
                f"valid: {', '.join(sorted(known))}"
            )
        return cls(**d)


class TextMotionEncoder(nn.Module):
    """The two encoders (see the module docstring).

    Args:
        config: sizes; ``text_dim`` must be set.
    """

    def __init__(self, config: T2MEvaluatorConfig):
        super().__init__()
        if config.text_dim < 1:
            raise EvaluatorError(f"text_dim must be ≥ 1, got {config.text_dim}")
        self.config = config
        mcfg = EvaluatorConfig(
            species=("any",),
            actions=("any",),
            fps=config.fps,
            d_model=config.d_model,
            n_heads=config.n_heads,
            n_layers=config.n_layers,
            ff_dim=config.ff_dim,
            feature_dim=config.embed_dim,
            dropout=0.0,
        )
        self.motion = MotionEvaluator(mcfg)
        self.motion_out = nn.Linear(config.embed_dim, config.embed_dim)
        self.text = nn.Sequential(
            nn.Linear(config.text_dim, config.text_hidden),
            nn.GELU(),
            nn.Linear(config.text_hidden, config.embed_dim),
        )

    def encode_motion(self, x: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        """Unit embeddings (B, embed_dim) of evaluator inputs x (B, T, 210), mask (B, T)."""
        f = self.motion_out(self.motion.features(x, mask))
        return nn.functional.normalize(f, dim=-1)

    def encode_text(self, t: torch.Tensor) -> torch.Tensor:
        """Unit embeddings (B, embed_dim) of sentence embeddings t (B, text_dim)."""
        return nn.functional.normalize(self.text(t), dim=-1)


# ---------------------------------------------------------------------------- metrics


def r_precision(text: np.ndarray, motion: np.ndarray, top_k: int = 3) -> np.ndarray:
    """R-precision of one batch: share of texts whose own motion ranks within the top k.

    Text i's motion is row i of ``motion``; the others of the batch are its distractors
    (Guo et al. 2022 use batches of 32). Ranks by Euclidean distance; a distractor at
    exactly the same distance as the true motion does not push it down.

    Args:
        text: (B, D) text embeddings.
        motion: (B, D) motion embeddings, row i the motion of text i.
        top_k: the largest k reported.

    Returns:
        (top_k,) float: the share for k = 1 … top_k (non-decreasing).
    """
    t = np.asarray(text, np.float64)
    m = np.asarray(motion, np.float64)
    if t.ndim != 2 or t.shape != m.shape or t.shape[0] < 1:
        raise EvaluatorError(
            f"text {t.shape} and motion {m.shape} embeddings must both be (B, D), B ≥ 1"
        )
    d = np.linalg.norm(t[:, None, :] - m[None, :, :], axis=-1)
    rank = (d < np.diag(d)[:, None]).sum(1)  # distractors strictly closer than the truth
    return np.array([(rank < k).mean() for k in range(1, top_k + 1)])


def matching_distance(text: np.ndarray, motion: np.ndarray) -> float:
    """MM-Dist: mean Euclidean distance between each text and its motion ((N, D) each)."""
    t, m = np.asarray(text, np.float64), np.asarray(motion, np.float64)
    if t.shape != m.shape or t.ndim != 2:
        raise EvaluatorError(f"text {t.shape} and motion {m.shape} must both be (N, D)")
    return float(np.linalg.norm(t - m, axis=1).mean())


# ---------------------------------------------------------------------------- frozen wrapper


class T2MEvaluator:
    """A frozen text–motion evaluator (eval mode, CPU); build it with
    :func:`load_t2m_evaluator` or :func:`train_t2m_evaluator`."""

    def __init__(self, model: TextMotionEncoder, path: Path | None = None, info: Any = None):
        self.model = model.eval()
        self.config = model.config
        self.path = path
        self.info: dict[str, Any] = dict(info or {})

    def embed_motions(self, motions: Sequence[Motion], batch: int = 16) -> np.ndarray:
        """(N, embed_dim) unit embeddings of whole motions."""
        inputs = [evaluator_input(m, self.config.fps) for m in motions]
        out = []
        with torch.no_grad(), one_thread():
            for i in range(0, len(inputs), batch):
                x, mask = _batch(inputs[i : i + batch])
                out.append(self.model.encode_motion(x, mask).numpy())
        return np.concatenate(out) if out else np.zeros((0, self.config.embed_dim), np.float32)

    def embed_texts(self, texts: Sequence[str], embed: Embedder | None = None) -> np.ndarray:
        """(N, embed_dim) unit embeddings of captions.

        Args:
            texts: the captions.
            embed: sentence embedder (default: the config's text model).

        Raises:
            EvaluatorError: the sentence embeddings do not have the trained width.
        """
        vec = _sentences(texts, self.config.text_model, embed)
        if vec.shape != (len(texts), self.config.text_dim):
            raise EvaluatorError(
                f"sentence embeddings of shape {vec.shape}; this evaluator reads "
                f"({len(texts)}, {self.config.text_dim}) from {self.config.text_model!r}"
            )
        with torch.no_grad(), one_thread():
            return self.model.encode_text(torch.from_numpy(vec)).numpy()


def _sentences(texts: Sequence[str], model: str, embed: Embedder | None) -> np.ndarray:
    if embed is None:
        from habitsim.models.text import embed_texts

        return np.asarray(embed_texts(list(texts), model), np.float32)
    return np.asarray(embed(list(texts)), np.float32)


# ---------------------------------------------------------------------------- training


@dataclass(frozen=True)
class T2MTrainReport:
    """What a training run did.

    Attributes:
        out_dir: the checkpoint folder.
        pairs: training clips (each with its captions).
        steps: optimiser steps.
        final_loss: mean InfoNCE loss of the last 10 % of steps.
        retrieval: R-precision top-1/2/3 of each split's clips (first caption each, one
            seeded random batch of up to ``batch_size`` clips), e.g.
            ``{"train": [..], "val": [..]}``.
        wall_time_s: training time [s].
    """

    out_dir: Path
    pairs: int
    steps: int
    final_loss: float
    retrieval: dict[str, list[float]]
    wall_time_s: float


def captioned_clips(
    data: Path, split: str, only: set[str] | None = None
) -> tuple[list[Motion], list[list[str]]]:
    """The clips of a split that have captions, with their captions (``only``: just the
    clips of these manifest paths)."""
    from habitsim.captions.store import load_captions
    from habitsim.dataset import iter_clips
    from habitsim.errors import MotionFileError

    try:
        caps = load_captions(data).clips
    except MotionFileError as e:
        raise EvaluatorError(f"{data}: no readable captions ({e})") from None
    motions, texts = [], []
    for entry, m in iter_clips(data, split=split):
        if only is not None and entry.path not in only:
            continue
        c = [x.text for x in caps.get(entry.path, [])]
        if c:
            motions.append(m)
            texts.append(c)
    return motions, texts


def train_t2m_evaluator(
    data_dir: str | Path,
    out_dir: str | Path,
    config: T2MEvaluatorConfig | None = None,
    *,
    embed: Embedder | None = None,
    log: Callable[[str], None] | None = print,
) -> T2MTrainReport:
    """Train the text–motion evaluator on the ``train`` clips of a captioned data set and
    write it to ``out_dir`` (weights + config, together or not at all).

    Args:
        data_dir: a data set folder with ``captions.json``.
        out_dir: the checkpoint folder.
        config: sizes and settings (``text_dim`` is taken from the embeddings).
        embed: sentence embedder (default: ``config.text_model``); name it in
            ``config.text_model``.
        log: where progress lines go (None: silent).

    Raises:
        EvaluatorError: no captions, fewer than 2 captioned train clips.
        DatasetError: the data set cannot be read.
    """
    cfg = config or T2MEvaluatorConfig()
    data = Path(data_dir)
    motions, texts = captioned_clips(data, "train")
    if len(motions) < 2:
        raise EvaluatorError(
            f"{data}: {len(motions)} captioned train clip(s); training needs at least 2 "
            "(caption the data set with `habitsim data captions DIR`)"
        )
    flat = [t for c in texts for t in c]
    vec = _sentences(flat, cfg.text_model, embed)
    if vec.ndim != 2 or vec.shape[0] != len(flat):
        raise EvaluatorError(f"the embedder returned shape {vec.shape} for {len(flat)} captions")
    cfg = T2MEvaluatorConfig.from_dict({**cfg.to_dict(), "text_dim": int(vec.shape[1])})
    owner = np.repeat(np.arange(len(texts)), [len(c) for c in texts])
    first = np.concatenate([[0], np.cumsum([len(c) for c in texts])[:-1]])
    t0 = time.perf_counter()
    with one_thread():
        torch.manual_seed(cfg.seed)
        rng = np.random.default_rng(cfg.seed)
        model = TextMotionEncoder(cfg)
        inputs = [evaluator_input(m, cfg.fps) for m in motions]
        allx = np.concatenate(inputs)
        model.motion.feat_mean.copy_(torch.from_numpy(allx.mean(0)))
        model.motion.feat_std.copy_(torch.from_numpy(np.maximum(allx.std(0), 1e-3)))
        opt = torch.optim.AdamW(model.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
        sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, cfg.steps)
        tvec = torch.from_numpy(vec)
        window = max(2, int(round(cfg.crop_s * cfg.fps)))
        b = min(cfg.batch_size, len(inputs))
        losses = []
        model.train()
        for step in range(cfg.steps):
            idx = rng.choice(len(inputs), b, replace=False)
            crops = []
            for i in idx:
                a = inputs[i]
                s = int(rng.integers(0, max(1, a.shape[0] - window + 1)))
                crops.append(a[s : s + window])
            cap = [int(rng.choice(np.flatnonzero(owner == i))) for i in idx]
            x, mask = _batch(crops)
            zm = model.encode_motion(x, mask)
            zt = model.encode_text(tvec[cap])
            logits = zt @ zm.T / cfg.temperature
            target = torch.arange(b)
            loss = 0.5 * (
                nn.functional.cross_entropy(logits, target)
                + nn.functional.cross_entropy(logits.T, target)
            )
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            losses.append(float(loss.detach()))
            if log is not None and (step + 1) % max(1, cfg.steps // 10) == 0:
                log(f"step {step + 1}/{cfg.steps}: loss {np.mean(losses[-20:]):.3f}")
    ev = T2MEvaluator(model)
    retrieval = {"train": _retrieval(ev, motions, [vec[i] for i in first], cfg)}
    val_m, val_t = captioned_clips(data, "val")
    if len(val_m) >= 2:
        retrieval["val"] = _retrieval(
            ev, val_m, list(_sentences([c[0] for c in val_t], cfg.text_model, embed)), cfg
        )
    wall = time.perf_counter() - t0
    tail = losses[-max(1, cfg.steps // 10) :]
    info = {
        "trained_on": {"data": str(data), "split": "train", "clips": len(motions)},
        "retrieval": retrieval,
        "final_loss": round(float(np.mean(tail)), 4),
        "wall_time_s": round(wall, 1),
    }
    out = save_t2m_evaluator(model, out_dir, info)
    return T2MTrainReport(out, len(motions), cfg.steps, float(np.mean(tail)), retrieval, wall)


def _retrieval(
    ev: T2MEvaluator, motions: Sequence[Motion], vecs: Sequence[np.ndarray], cfg: T2MEvaluatorConfig
) -> list[float]:
    n = min(len(motions), cfg.batch_size)
    pick = np.random.default_rng(cfg.seed).permutation(len(motions))[:n]
    zm = ev.embed_motions([motions[i] for i in pick])
    tv = np.stack([vecs[i] for i in pick]).astype(np.float32)
    with torch.no_grad():
        zt = ev.model.encode_text(torch.from_numpy(tv)).numpy()
    return [round(float(v), 4) for v in r_precision(zt, zm)]


def save_t2m_evaluator(model: TextMotionEncoder, out_dir: str | Path, info: dict[str, Any]) -> Path:
    """Write ``model.safetensors`` + ``config.json`` to ``out_dir``: both or neither.

    Raises:
        OutputPathError: the folder cannot be written; OutputWriteError: a write failed.
    """
    from safetensors.torch import save

    import habitsim

    out = make_dirs(out_dir, "text–motion evaluator folder")
    state = {k: v.detach().contiguous() for k, v in model.state_dict().items()}
    blob = save(state, metadata={"format": "pt", "kind": _KIND})
    meta = {
        "kind": _KIND,
        "format_version": CONFIG_FORMAT_VERSION,
        "config": model.config.to_dict(),
        **info,
        "torch_version": torch.__version__,
        "habitsim_version": habitsim.__version__,
    }
    with output_transaction():
        with atomic_write(out / _WEIGHTS) as fh:
            fh.write(blob)
        atomic_write_text(out / _CONFIG, json.dumps(meta, indent=2, sort_keys=True) + "\n")
    return out


def load_t2m_evaluator(path: str | Path) -> T2MEvaluator:
    """Load a text–motion evaluator folder.

    Raises:
        EvaluatorError: missing files, another kind or format version, tensors that do not
            fit the config.
    """
    from safetensors import SafetensorError
    from safetensors.torch import load_file

    folder = Path(path)
    p = folder / _CONFIG
    if not p.is_file() or not (folder / _WEIGHTS).is_file():
        raise EvaluatorError(
            f"{folder}: not a text–motion evaluator folder (it holds {_WEIGHTS} + {_CONFIG}; "
            "train one with `habitsim t2m train-evaluator`)"
        )
    raw = load_json(p, "text–motion evaluator config", error=EvaluatorError)
    if not isinstance(raw, dict) or raw.get("kind") != _KIND:
        raise EvaluatorError(f"{p}: not a text–motion evaluator config (kind != {_KIND!r})")
    if raw.get("format_version") != CONFIG_FORMAT_VERSION:
        raise EvaluatorError(
            f"{p}: format_version {raw.get('format_version')!r}; this habitsim reads "
            f"{CONFIG_FORMAT_VERSION}"
        )
    if not isinstance(raw.get("config"), dict):
        raise EvaluatorError(f"{p}: 'config' must be an object of T2MEvaluatorConfig fields")
    try:
        cfg = T2MEvaluatorConfig.from_dict(raw["config"])
        model = TextMotionEncoder(cfg)
        state = load_file(str(folder / _WEIGHTS))
        model.load_state_dict(state, strict=True)
    except (TypeError, RuntimeError, SafetensorError) as e:
        raise EvaluatorError(f"{folder}: weights do not fit the config ({e})"[:400]) from None
    return T2MEvaluator(model, folder, raw)
