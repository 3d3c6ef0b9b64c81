"""Training of the text-to-motion transformer (:class:`~habitsim.models.codegpt.CodeGPT`)
on a code set (:mod:`habitsim.models.t2m_data`), and its checkpoints.

Each step draws ``batch_size`` training clips (uniformly), one caption of each, a crop of
at most ``max_steps`` code steps, and for each with probability ``text_dropout`` the null
text token; the loss is the cross-entropy of every level's code plus ``path_weight`` ×
the mean squared error of the normalised path features. AdamW, a linear warm-up and a
cosine decay to ``lr_final``.

Everything random is seeded from ``T2MTrainConfig.seed`` inside
:func:`torch.random.fork_rng` (the caller's global RNG is untouched): the weights, the
dropout (torch's global RNG) and the batch sampler (a :class:`numpy.random.Generator`).
A checkpoint written during training holds all of them with the optimiser's moments, so a
resumed run gives the same weights as an uninterrupted one.

Checkpoint folder (like :mod:`habitsim.models.checkpoint`: safetensors + JSON, nothing
unpickled, ``config.json`` written last with the SHA-256 of every tensor file)::

    config.json              format, T2MConfig, species, shapes, the VQ-VAE it decodes
                             with (path and SHA-256), text model, fps, training history
    model.safetensors        every parameter and buffer of CodeGPT
    train_state.safetensors  optimiser moments and RNG states (resuming only)
    train_state.json
    best/                    config.json + model.safetensors of the step with the lowest
                             validation code cross-entropy (when the code set has val clips)
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from ..fileio import atomic_write, atomic_write_text, make_dirs
from ..jsonfile import load_json
from .checkpoint import (
    CONFIG_FILE,
    MODEL_FILE,
    STATE_FILE,
    STATE_JSON,
    _load_tensors,
    _readable,
    _state_bytes,
    file_sha256,
    load_train_state,
)
from .codegpt import CodeGPT, path_features
from .errors import CheckpointError, ConfigError, TrainingDataError
from .resume import _optimizer_state, _restore_optimizer
from .t2m_config import T2M_PRESETS, T2MConfig, T2MTrainConfig, t2m_preset
from .t2m_data import CodeClip, CodeSet, load_code_set
from .train import warmup_cosine

__all__ = [
    "T2M_FORMAT",
    "BEST_DIR",
    "T2M_PRESETS",
    "T2MTrainConfig",
    "T2MConfig",
    "T2MTrainResult",
    "LoadedCodeGPT",
    "t2m_preset",
    "train_codegpt",
    "save_codegpt",
    "load_codegpt",
]

T2M_FORMAT = "habitsim.models.codegpt"
#: Sub-folder of a training run's checkpoint that holds the weights of its lowest
#: validation code cross-entropy so far (only with val clips; no training state).
BEST_DIR = "best"
_VERSION = 1


# ---------------------------------------------------------------------------- checkpoints


@dataclass
class LoadedCodeGPT:
    """A loaded text-to-motion checkpoint (model in eval mode, its config and metadata)."""

    model: CodeGPT
    config: T2MConfig
    meta: dict[str, Any]
    path: Path

    @property
    def fps(self) -> float:
        return float(self.meta["fps"])

    @property
    def rate(self) -> int:
        return int(self.meta["rate"])


def _build(cfg: T2MConfig, shape: dict[str, Any], species: list[str]) -> CodeGPT:
    return CodeGPT(
        cfg.model,
        levels=int(shape["levels"]),
        num_codes=int(shape["num_codes"]),
        path_dim=int(shape["path_dim"]),
        text_dim=int(shape["text_dim"]),
        habit_dim=int(shape["habit_dim"]),
        species=species,
    )


def save_codegpt(
    out_dir: str | Path,
    model: CodeGPT,
    config: T2MConfig,
    meta: dict[str, Any],
    train_state: tuple[dict[str, torch.Tensor], dict[str, Any]] | None = None,
) -> Path:
    """Write a checkpoint folder (module docstring); ``meta`` holds fps, rate, vq, …"""
    out = make_dirs(out_dir, "checkpoint folder")
    files: dict[str, str] = {}
    with atomic_write(out / MODEL_FILE) as fh:
        fh.write(_state_bytes(model.state_dict()))
    files[MODEL_FILE] = file_sha256(out / MODEL_FILE)
    names = [MODEL_FILE, CONFIG_FILE]
    if train_state is not None:
        with atomic_write(out / STATE_FILE) as fh:
            fh.write(_state_bytes(train_state[0]))
        atomic_write_text(out / STATE_JSON, json.dumps(train_state[1]))
        files[STATE_FILE] = file_sha256(out / STATE_FILE)
        files[STATE_JSON] = file_sha256(out / STATE_JSON)
        names += [STATE_FILE, STATE_JSON]
    doc = {
        "format": T2M_FORMAT,
        "format_version": _VERSION,
        "config": config.to_dict(),
        "species": list(model.species),
        "shape": {
            "levels": model.levels,
            "num_codes": model.num_codes,
            "path_dim": model.path_dim,
            "text_dim": model.text_dim,
            "habit_dim": model.habit_dim,
        },
        **{k: v for k, v in meta.items() if k != "files"},
        "files": files,
    }
    atomic_write_text(out / CONFIG_FILE, json.dumps(doc, indent=1) + "\n")
    _readable(out, names)
    return out


def _read_doc(p: Path) -> tuple[T2MConfig, dict[str, Any]]:
    cfg_path = p / CONFIG_FILE
    try:
        doc = load_json(cfg_path, "text-to-motion checkpoint config", error=CheckpointError)
    except CheckpointError as e:
        raise CheckpointError(f"{e}; train one with `train_codegpt`") from None
    if not isinstance(doc, dict) or doc.get("format") != T2M_FORMAT:
        fmt = doc.get("format") if isinstance(doc, dict) else None
        raise CheckpointError(
            f"{cfg_path}: format {fmt!r} is not a text-to-motion checkpoint ({T2M_FORMAT!r})"
        )
    if doc.get("format_version") != _VERSION:
        raise CheckpointError(f"{cfg_path}: format_version {doc.get('format_version')!r}; reads 1")
    for key in ("config", "species", "shape", "vq", "fps", "rate", "text_model", "files"):
        if key not in doc:
            raise CheckpointError(f"{cfg_path}: missing key {key!r}")
    try:
        cfg = T2MConfig.from_dict(doc["config"])
    except ConfigError as e:
        raise CheckpointError(f"{cfg_path}: invalid config: {e}") from None
    return cfg, doc


def load_codegpt(path: str | Path) -> LoadedCodeGPT:
    """Load a text-to-motion checkpoint folder (CPU, eval mode).

    Raises:
        CheckpointError: missing, unreadable, corrupt (SHA-256) or not matching its config.
    """
    p = Path(path)
    cfg, doc = _read_doc(p)
    tensors = _load_tensors(p / MODEL_FILE, doc["files"].get(MODEL_FILE))
    model = _build(cfg, doc["shape"], list(doc["species"]))
    try:
        model.load_state_dict(tensors, strict=True)
    except RuntimeError as e:
        raise CheckpointError(f"{p / MODEL_FILE} does not match {CONFIG_FILE}: {e}") from None
    model.eval()
    return LoadedCodeGPT(model, cfg, {k: v for k, v in doc.items() if k != "config"}, p)


# ---------------------------------------------------------------------------- training


@dataclass
class T2MTrainResult:
    """Outcome of :func:`train_codegpt`: folder, steps done in all, this run's wall time
    [s] and steps per second, the last validation record and every record."""

    out_dir: Path
    steps: int
    wall_time_s: float
    steps_per_s: float
    metrics: dict[str, float]
    history: list[dict[str, Any]] = field(default_factory=list)


def lr_at(step: int, t: T2MTrainConfig) -> float:
    """Learning rate of optimiser step ``step`` (0-based): warm-up, then cosine."""
    return warmup_cosine(step, t.steps, t.warmup_steps, t.lr, t.lr_final)


class _Batches:
    """Padded training batches of clips: (text, keep, habit, codes, path, steps, valid)."""

    def __init__(self, clips: list[CodeClip], model: CodeGPT, habit: dict[str, np.ndarray]):
        self.clips = clips
        self.model = model
        self.habit = habit
        self.pf = [path_features(c.path) for c in clips]

    def make(
        self, idx: list[int], starts: list[int], caps: list[int], keep: list[bool], n: list[int]
    ) -> tuple[torch.Tensor, ...]:
        t = max(n)
        lv, pd = self.model.levels, self.model.pf_dim
        codes = np.zeros((len(idx), t, lv), np.int64)
        path = np.zeros((len(idx), t, pd), np.float32)
        valid = np.zeros((len(idx), t), bool)
        text, habit = [], []
        for b, (i, s, k, m) in enumerate(zip(idx, starts, caps, n, strict=True)):
            c = self.clips[i]
            codes[b, :m] = c.codes[s : s + m]
            path[b, :m] = self.pf[i][s : s + m]
            valid[b, :m] = True
            text.append(c.text[k])
            habit.append(self.habit[c.species])
        pt = self.model.normalize_path(torch.from_numpy(path)) * torch.from_numpy(valid)[..., None]
        return (
            torch.from_numpy(np.stack(text)),
            torch.as_tensor(keep),
            torch.from_numpy(np.stack(habit)),
            torch.from_numpy(codes),
            pt,
            torch.as_tensor(n, dtype=torch.long),
            torch.from_numpy(valid),
        )

    def sample(self, rng: np.random.Generator, size: int, max_steps: int, drop: float):
        idx = [int(i) for i in rng.integers(len(self.clips), size=size)]
        n = [min(self.clips[i].steps, max_steps) for i in idx]
        starts = [
            int(rng.integers(self.clips[i].steps - m + 1)) for i, m in zip(idx, n, strict=True)
        ]
        caps = [int(rng.integers(len(self.clips[i].captions))) for i in idx]
        keep = [bool(rng.random() >= drop) for _ in idx]
        return self.make(idx, starts, caps, keep, n)

    def fixed(self, max_steps: int) -> list[tuple[torch.Tensor, ...]]:
        """Every clip once, from its start, with its first caption (validation)."""
        out = []
        for lo in range(0, len(self.clips), 32):
            idx = list(range(lo, min(lo + 32, len(self.clips))))
            n = [min(self.clips[i].steps, max_steps) for i in idx]
            out.append(self.make(idx, [0] * len(idx), [0] * len(idx), [True] * len(idx), n))
        return out


def batch_losses(
    model: CodeGPT, batch: tuple[torch.Tensor, ...]
) -> tuple[torch.Tensor, dict[str, float]]:
    """(loss, logs) of a batch: mean code cross-entropy over levels and valid steps, plus
    ``path_weight`` × the path features' mean squared error; logs also the level-1 top-1
    accuracy."""
    text, keep, habit, codes, path, steps, valid = batch
    logits, pred = model(text, keep, habit, codes, path, steps)
    v = valid.float()
    nv = v.sum().clamp_min(1.0)
    ce = sum(
        (torch.nn.functional.cross_entropy(lg.transpose(1, 2), codes[..., k], reduction="none") * v)
        .sum()
        .div(nv)
        for k, lg in enumerate(logits)
    )
    assert isinstance(ce, torch.Tensor)
    ce = ce / len(logits)
    loss = ce
    logs = {"ce": float(ce.detach())}
    if pred is not None:
        mse = (((pred - path) ** 2).mean(-1) * v).sum() / nv
        loss = loss + model.cfg.path_weight * mse
        logs["path_mse"] = float(mse.detach())
    acc = ((logits[0].argmax(-1) == codes[..., 0]).float() * v).sum() / nv
    logs["acc1"] = float(acc)
    logs["loss"] = float(loss.detach())
    return loss, logs


def _habit_table(cs: CodeSet, species: list[str], vq_checkpoint: str | Path | None):
    from .t2m_data import code_set_vq
    from .transfer import _embeddings

    ck = code_set_vq(cs.meta["vq"], vq_checkpoint)
    emb = _embeddings(ck, species)
    return {s: np.asarray(emb[s], np.float32) for s in species}


def train_codegpt(
    codes: str | Path | CodeSet,
    out_dir: str | Path,
    config: T2MConfig,
    *,
    resume: bool = False,
    overwrite: bool = False,
    stop_at: int | None = None,
    vq_checkpoint: str | Path | None = None,
    log: Callable[[str], None] = print,
) -> T2MTrainResult:
    """Train a :class:`~habitsim.models.codegpt.CodeGPT` on a code set's ``train`` clips
    (``val`` clips, if any, for the validation records) and write a checkpoint folder.

    Args:
        codes: a code set folder (:func:`~habitsim.models.t2m_data.build_code_set`) or one
            already loaded.
        out_dir: the checkpoint folder.
        config: :func:`t2m_preset` or a variant of one.
        resume: continue from the training state in ``out_dir`` (the config may differ
            only in ``train.steps``, ``checkpoint_every`` and ``val_every``).
        overwrite: replace a checkpoint already in ``out_dir``.
        stop_at: stop after this step (checkpointed there), e.g. to time-box a session;
            the schedule stays that of ``config.train.steps``, and ``resume`` continues.
        vq_checkpoint: the VQ-VAE folder if it moved since the code set was built (its
            SHA-256 must match).
        log: where one-line messages go.

    Raises:
        TrainingDataError: no training clips.
        CheckpointError: ``out_dir`` holds a checkpoint (without ``resume`` /
            ``overwrite``) or one that this config cannot resume.
    """
    cfg = config.validate()
    t, mc = cfg.train, cfg.model
    cs = codes if isinstance(codes, CodeSet) else load_code_set(codes)
    tr = cs.split("train")
    if not tr:
        raise TrainingDataError(f"{cs.root}: the code set has no train clip (splits: train, val)")
    val = cs.split("val")
    species = sorted({c.species for c in tr})
    habit = _habit_table(cs, species, vq_checkpoint)
    out = Path(out_dir)
    existing = (out / CONFIG_FILE).is_file()
    if existing and not resume and not overwrite:
        raise CheckpointError(f"{out} already holds a checkpoint; pass resume or overwrite")
    old_threads = torch.get_num_threads()
    if t.threads is not None:
        torch.set_num_threads(t.threads)
    t0 = time.perf_counter()
    try:
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(t.seed)
            shape = {
                "levels": cs.levels,
                "num_codes": cs.num_codes,
                "path_dim": cs.path_dim,
                "text_dim": cs.text_dim,
                "habit_dim": int(next(iter(habit.values())).shape[0]),
            }
            model = _build(cfg, shape, species)
            batches = _Batches(tr, model, habit)
            with torch.no_grad():
                model.habit_table.copy_(torch.from_numpy(np.stack([habit[s] for s in species])))
                if model.pf_dim:
                    allp = np.concatenate(batches.pf).astype(np.float64)
                    model.path_mean.copy_(torch.from_numpy(allp.mean(0)))
                    model.path_std.copy_(torch.from_numpy(np.maximum(allp.std(0), 1e-6)))
            val_batches = _Batches(val, model, _habit_extra(habit, val, cs, vq_checkpoint))
            opt = torch.optim.AdamW(
                model.parameters(), lr=t.lr, betas=(0.9, 0.99), weight_decay=t.weight_decay
            )
            rng = np.random.default_rng(t.seed)
            start, prev_wall = 0, 0.0
            history: list[dict[str, Any]] = []
            if resume and existing:
                start, history, prev_wall = _resume(out, cfg, model, opt, rng, species)
                log(f"resuming {out} at step {start}/{t.steps}")
            n_params = sum(p.numel() for p in model.parameters())
            log(
                f"training t2m {cfg.name}: {len(tr)} clips of {len(species)} species, "
                f"{n_params / 1e6:.2f} M parameters, {t.steps} steps × {t.batch_size} clips, "
                f"{torch.get_num_threads()} thread(s)"
            )

            def meta(step: int) -> dict[str, Any]:
                return {
                    "vq": cs.meta["vq"],
                    "text_model": cs.meta["text_model"],
                    "text_form": cs.meta.get("text_form", "as_written"),
                    "fps": cs.meta["fps"],
                    "rate": cs.meta["rate"],
                    "codes": {"dir": str(cs.root.resolve()), "train_clips": len(tr)},
                    "parameters": n_params,
                    "training": {
                        "step": step,
                        "wall_time_s": round(prev_wall + time.perf_counter() - t0, 2),
                        "history": history,
                    },
                    "versions": {"torch": torch.__version__},
                }

            end = t.steps if stop_at is None else max(start, min(int(stop_at), t.steps))
            best = min((h["val_ce"] for h in history if "val_ce" in h), default=math.inf)
            model.train()
            run: dict[str, float] = {}
            n_run, t_run = 0, time.perf_counter()
            metrics: dict[str, float] = {}
            for step in range(start, end):
                for g in opt.param_groups:
                    g["lr"] = lr_at(step, t)
                batch = batches.sample(rng, t.batch_size, mc.max_steps, mc.text_dropout)
                loss, logs = batch_losses(model, batch)
                if not torch.isfinite(loss):
                    raise TrainingDataError(f"non-finite loss at step {step}: {logs}")
                opt.zero_grad(set_to_none=True)
                loss.backward()
                opt.step()
                for k, v in logs.items():
                    run[k] = run.get(k, 0.0) + v
                n_run += 1
                done = step + 1
                if done % t.val_every == 0 or done == t.steps:
                    rec: dict[str, Any] = {
                        "step": done,
                        "steps_per_s": round(n_run / max(time.perf_counter() - t_run, 1e-9), 3),
                    }
                    rec.update({f"train_{k}": round(v / n_run, 5) for k, v in run.items()})
                    rec.update(_validate(model, val_batches, mc.max_steps))
                    history.append(rec)
                    metrics = {k: v for k, v in rec.items() if k.startswith("val_")}
                    log(" ".join(f"{k}={v}" for k, v in rec.items()))
                    if rec.get("val_ce", math.inf) < best:
                        best = rec["val_ce"]
                        save_codegpt(out / BEST_DIR, model, cfg, meta(done))
                    run, n_run, t_run = {}, 0, time.perf_counter()
                if done % t.checkpoint_every == 0 or done in (t.steps, end):
                    tensors, opt_js = _optimizer_state(opt)
                    tensors["rng.torch"] = torch.get_rng_state()
                    js = {"step": done, "numpy_rng": rng.bit_generator.state, "optimizer": opt_js}
                    save_codegpt(out, model, cfg, meta(done), (tensors, js))
            wall = time.perf_counter() - t0
            return T2MTrainResult(
                out, max(start, end), wall, (end - start) / max(wall, 1e-9), metrics, history
            )
    finally:
        torch.set_num_threads(old_threads)


def _habit_extra(
    habit: dict[str, np.ndarray], clips: list[CodeClip], cs: CodeSet, vq: str | Path | None
) -> dict[str, np.ndarray]:
    more = sorted({c.species for c in clips} - set(habit))
    return {**habit, **(_habit_table(cs, more, vq) if more else {})}


@torch.no_grad()
def _validate(model: CodeGPT, val: _Batches, max_steps: int) -> dict[str, float]:
    if not val.clips:
        return {}
    was = model.training
    model.eval()
    acc: dict[str, float] = {}
    n = 0.0
    for b in val.fixed(max_steps):
        _, logs = batch_losses(model, b)
        w = float(b[-1].sum())
        for k, v in logs.items():
            acc[k] = acc.get(k, 0.0) + v * w
        n += w
    model.train(was)
    return {f"val_{k}": round(v / n, 5) for k, v in acc.items()}


def _resume(
    out: Path,
    cfg: T2MConfig,
    model: CodeGPT,
    opt: torch.optim.Optimizer,
    rng: np.random.Generator,
    species: list[str],
) -> tuple[int, list[dict[str, Any]], float]:
    old, doc = _read_doc(out)
    a, b = old.to_dict(), cfg.to_dict()
    for d in (a, b):
        for k in ("steps", "checkpoint_every", "val_every", "threads"):
            d["train"].pop(k)
    if a != b:
        raise CheckpointError(
            f"{out}: cannot resume: its config differs from this one in more than "
            "train.steps / checkpoint_every / val_every (train to a new folder instead)"
        )
    if list(doc["species"]) != species:
        raise CheckpointError(
            f"{out}: cannot resume: trained on species {doc['species']}, the code set has {species}"
        )
    ck = load_codegpt(out)
    tensors, js = load_train_state(out, doc)
    model.load_state_dict(ck.model.state_dict())
    _restore_optimizer(opt, tensors, js["optimizer"])
    rng.bit_generator.state = js["numpy_rng"]
    torch.set_rng_state(tensors["rng.torch"])
    tr = doc.get("training", {})
    return int(js["step"]), list(tr.get("history", [])), float(tr.get("wall_time_s", 0.0))
