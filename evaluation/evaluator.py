"""The frozen motion evaluator: a small temporal transformer over motion features.

docs/metrics.md's distribution metrics (``fid``, ``intra_fid``, ``downstream_fid``,
``diversity``, ``one_nna``) are computed on its penultimate-layer features and its two
classification heads give ``habit_accuracy`` (species head) and ``action_accuracy``
(action head). It is trained once on the training split of the synthetic data set
(``habitsim train-evaluator --data DIR --out DIR``) and shipped frozen inside the
package as ``evaluator/model.safetensors`` + ``evaluator/config.json`` (nothing is ever
unpickled), with its accuracies in ``evaluator/README.md``.

Input (:func:`evaluator_input`): the paper's per-frame features
(:meth:`habitsim.motion.Motion.features`, local quaternions + global joint velocities,
J·7 = 210 numbers per frame) of the motion *turned to a canonical heading* (the pelvis'
first-frame heading along +x, so a clip walking north and one walking east read the same)
and resampled to the evaluator's frame rate (30 Hz), each quaternion track starting in
the w ≥ 0 hemisphere. Features are standardised with the training set's mean and
standard deviation (stored in the checkpoint).

Network (:class:`MotionEvaluator`): linear embedding → temporal convolution (kernel 5)
→ sinusoidal time encoding → ``n_layers`` pre-norm transformer encoder layers → masked
mean over time → LayerNorm → Linear → GELU = the **feature** (``feature_dim``, default 32;
small on purpose: the Gaussian fits of FID are estimated from tens of clips) → two linear
heads (species, action).

Species the evaluator was not trained on (the held-out species) still get features; their
species prediction is the nearest training species, so ``habit_accuracy`` is undefined
for them (see :func:`habitsim.evaluation.runner`).
"""

from __future__ import annotations

import functools
import json
import math
import os
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from habitsim.errors import HabitsimError
from habitsim.fileio import atomic_write, atomic_write_text, make_dirs, output_transaction
from habitsim.jsonfile import load_json
from habitsim.motion import FEATURE_DIM, Motion
from habitsim.rotations import quat_fix_continuity, quat_mul, quat_slerp
from habitsim.threads import one_thread

__all__ = [
    "EvaluatorConfig",
    "EvaluatorError",
    "MotionEvaluator",
    "Evaluator",
    "TrainReport",
    "DEFAULT_EVALUATOR_DIR",
    "evaluator_input",
    "resample_motion",
    "canonical_heading",
    "load_evaluator",
    "train_evaluator",
]

#: Folder of the shipped, frozen evaluator (inside the installed package).
DEFAULT_EVALUATOR_DIR = Path(__file__).resolve().parent / "evaluator"
_WEIGHTS = "model.safetensors"
_CONFIG = "config.json"
_README = "README.md"
#: Format version of the evaluator's ``config.json``.
CONFIG_FORMAT_VERSION = 1


class EvaluatorError(HabitsimError, ValueError):
    """A missing, corrupt or mismatched evaluator checkpoint, or bad training input."""


@dataclass(frozen=True)
class EvaluatorConfig:
    """Architecture and training settings of the evaluator (stored as ``config.json``).

    Attributes:
        species: class names of the species head (the training species).
        actions: class names of the action head.
        fps: frame rate the evaluator reads [Hz]; other rates are resampled.
        d_model, n_heads, n_layers, ff_dim: transformer sizes.
        feature_dim: size of the penultimate feature (the FID space).
        dropout: dropout in training.
        epochs, batch_size, lr, weight_decay: optimiser settings (AdamW, cosine decay).
        crops_per_clip: random sub-clips drawn per training clip (augmentation).
        min_crop_s: shortest training crop [s].
        feature_noise: std of Gaussian noise added to standardised training features.
        seed: seed of every random step of training.
    """

    species: tuple[str, ...] = ()
    actions: tuple[str, ...] = ()
    fps: float = 30.0
    d_model: int = 64
    n_heads: int = 4
    n_layers: int = 2
    ff_dim: int = 128
    feature_dim: int = 32
    dropout: float = 0.1
    epochs: int = 12
    batch_size: int = 64
    lr: float = 2e-3
    weight_decay: float = 1e-2
    crops_per_clip: int = 6
    min_crop_s: float = 1.5
    feature_noise: float = 0.05
    seed: int = 0

    def __post_init__(self) -> None:
        for name in (
            "d_model",
            "n_heads",
            "n_layers",
            "ff_dim",
            "feature_dim",
            "epochs",
            "batch_size",
            "crops_per_clip",
        ):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < 1:
                raise EvaluatorError(f"{name} must be a positive integer, got {v!r}")
        if self.d_model % self.n_heads:
            raise EvaluatorError(
                f"d_model {self.d_model} is not divisible by n_heads {self.n_heads}"
            )
        if not (self.fps > 0 and math.isfinite(self.fps)):
            raise EvaluatorError(f"fps must be positive, got {self.fps}")
        object.__setattr__(self, "species", tuple(self.species))
        object.__setattr__(self, "actions", tuple(self.actions))

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["species"] = list(self.species)
        d["actions"] = list(self.actions)
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> EvaluatorConfig:
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(d) - known)
        if unknown:
            raise EvaluatorError(f"unknown evaluator config keys: {', '.join(unknown)}")
        return cls(**d)


# ---------------------------------------------------------------------------- input


def resample_motion(motion: Motion, fps: float) -> Motion:
    """The motion at another frame rate (root: linear, rotations: slerp), same duration.

    Returns the motion itself when the rate already matches.
    """
    if abs(motion.fps - fps) < 1e-9:
        return motion
    t_old = np.arange(motion.num_frames) / motion.fps
    n_new = max(1, int(round((motion.num_frames - 1) * fps / motion.fps)) + 1)
    t_new = np.minimum(np.arange(n_new) / fps, t_old[-1])
    root = np.stack([np.interp(t_new, t_old, motion.root_positions[:, k]) for k in range(3)], 1)
    pos = t_new * motion.fps
    i0 = np.minimum(np.floor(pos).astype(int), motion.num_frames - 1)
    i1 = np.minimum(i0 + 1, motion.num_frames - 1)
    a = (pos - i0)[:, None]
    q = quat_slerp(
        motion.rotations[i0],
        motion.rotations[i1],
        np.broadcast_to(a, i0.shape + (motion.rotations.shape[1],)),
    )
    return Motion(motion.species, fps, root, q, None, dict(motion.metadata))


def canonical_heading(motion: Motion) -> Motion:
    """The motion turned about the vertical so the pelvis' first-frame heading is +x.

    The root path is turned about its first-frame position; the horizontal start is
    moved to the origin (features use velocities, so this changes nothing but
    readability).
    """
    q0 = motion.rotations[0, 0]
    w, x, y, z = q0
    # heading of the pelvis' +x axis in the world, projected on the ground plane
    fx = 1.0 - 2.0 * (y * y + z * z)
    fy = 2.0 * (x * y + w * z)
    yaw = math.atan2(fy, fx)
    half = -0.5 * yaw
    qz = np.array([math.cos(half), 0.0, 0.0, math.sin(half)])
    c, s = math.cos(-yaw), math.sin(-yaw)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    root = motion.root_positions.copy()
    root[:, :2] -= root[0, :2]
    root = root @ rot.T
    q = motion.rotations.copy()
    q[:, 0] = quat_mul(np.broadcast_to(qz, q[:, 0].shape), q[:, 0])
    return Motion(motion.species, motion.fps, root, q, motion.contacts, dict(motion.metadata))


def evaluator_input(motion: Motion, fps: float = 30.0) -> np.ndarray:
    """(T', 210) float32 evaluator input of a motion (see the module docstring).

    Args:
        motion: any motion on a habitsim skeleton.
        fps: the evaluator's frame rate [Hz].
    """
    m = canonical_heading(resample_motion(motion, fps))
    q = m.rotations.copy()
    q[0] = np.where(q[0, :, :1] < 0.0, -q[0], q[0])
    m.rotations = quat_fix_continuity(q, axis=0)
    return m.features()


# ---------------------------------------------------------------------------- network


def _sinusoid(t: int, d: int, device: torch.device) -> torch.Tensor:
    pos = torch.arange(t, dtype=torch.float32, device=device)[:, None]
    div = torch.exp(
        torch.arange(0, d, 2, dtype=torch.float32, device=device) * (-math.log(1e4) / d)
    )
    pe = torch.zeros(t, d, device=device)
    pe[:, 0::2] = torch.sin(pos * div)
    pe[:, 1::2] = torch.cos(pos * div)
    return pe


class MotionEvaluator(nn.Module):
    """Temporal transformer classifying species and action (see the module docstring).

    Args:
        config: the :class:`EvaluatorConfig` (class lists and sizes).
    """

    # Buffers (registered in ``__init__``), declared for the type checker.
    feat_mean: torch.Tensor
    feat_std: torch.Tensor

    def __init__(self, config: EvaluatorConfig):
        super().__init__()
        if not config.species or not config.actions:
            raise EvaluatorError("the evaluator config needs species and action class lists")
        self.config = config
        d = config.d_model
        self.embed = nn.Linear(FEATURE_DIM, d)
        self.conv = nn.Conv1d(d, d, kernel_size=5, padding=2)
        layer = nn.TransformerEncoderLayer(
            d,
            config.n_heads,
            config.ff_dim,
            config.dropout,
            activation="gelu",
            batch_first=True,
            norm_first=True,
        )
        self.encoder = nn.TransformerEncoder(layer, config.n_layers, enable_nested_tensor=False)
        self.norm = nn.LayerNorm(d)
        self.proj = nn.Linear(d, config.feature_dim)
        self.species_head = nn.Linear(config.feature_dim, len(config.species))
        self.action_head = nn.Linear(config.feature_dim, len(config.actions))
        self.register_buffer("feat_mean", torch.zeros(FEATURE_DIM))
        self.register_buffer("feat_std", torch.ones(FEATURE_DIM))

    def features(self, x: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        """Penultimate features (B, feature_dim) of raw inputs x (B, T, 210).

        Args:
            x: un-standardised evaluator inputs (:func:`evaluator_input`), zero-padded.
            mask: (B, T) bool, True on real frames.
        """
        m = mask[..., None].to(x.dtype)
        h = (x - self.feat_mean) / self.feat_std * m
        h = self.embed(h) * m
        h = torch.nn.functional.gelu(self.conv(h.transpose(1, 2)).transpose(1, 2)) * m
        h = h + _sinusoid(h.shape[1], h.shape[2], h.device)[None]
        h = self.encoder(h, src_key_padding_mask=~mask)
        pooled = (h * m).sum(1) / m.sum(1).clamp(min=1.0)
        return torch.nn.functional.gelu(self.proj(self.norm(pooled)))

    def forward(
        self, x: torch.Tensor, mask: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """(features, species logits, action logits)."""
        f = self.features(x, mask)
        return f, self.species_head(f), self.action_head(f)


def _batch(inputs: Sequence[np.ndarray]) -> tuple[torch.Tensor, torch.Tensor]:
    t = max(a.shape[0] for a in inputs)
    x = np.zeros((len(inputs), t, FEATURE_DIM), np.float32)
    mask = np.zeros((len(inputs), t), bool)
    for i, a in enumerate(inputs):
        x[i, : a.shape[0]] = a
        mask[i, : a.shape[0]] = True
    return torch.from_numpy(x), torch.from_numpy(mask)


# ---------------------------------------------------------------------------- frozen wrapper


@dataclass
class Predictions:
    """Evaluator outputs for N motions.

    Attributes:
        features: (N, feature_dim) penultimate features.
        species: predicted species names (N,).
        actions: predicted action names (N,).
        species_prob: (N, S) softmax over the species head.
        action_prob: (N, A) softmax over the action head.
    """

    features: np.ndarray
    species: list[str]
    actions: list[str]
    species_prob: np.ndarray
    action_prob: np.ndarray


class Evaluator:
    """A frozen evaluator network ready to score motions (eval mode, CPU, no gradients).

    Build it with :func:`load_evaluator`.
    """

    def __init__(self, model: MotionEvaluator, path: Path | None = None, info: dict | None = None):
        self.model = model.eval()
        self.config = model.config
        self.path = path
        self.info = info or {}

    @property
    def feature_dim(self) -> int:
        return self.config.feature_dim

    def inputs(self, motions: Iterable[Motion]) -> list[np.ndarray]:
        return [evaluator_input(m, self.config.fps) for m in motions]

    def predict_inputs(self, inputs: Sequence[np.ndarray], batch_size: int = 64) -> Predictions:
        """:class:`Predictions` of precomputed evaluator inputs.

        Inference runs on one CPU thread (restored afterwards), so features are bitwise
        identical in every process of a benchmark, whatever its thread settings.
        """
        with one_thread(), torch.no_grad():
            return self._predict(inputs, batch_size)

    def _predict(self, inputs: Sequence[np.ndarray], batch_size: int) -> Predictions:
        feats = []
        order = np.argsort([a.shape[0] for a in inputs], kind="stable")  # less padding
        for s in range(0, len(inputs), batch_size):
            idx = order[s : s + batch_size]
            x, mask = _batch([inputs[i] for i in idx])
            f, ls, la = self.model(x, mask)
            feats.append((idx, f.numpy(), ls.softmax(-1).numpy(), la.softmax(-1).numpy()))
        n = len(inputs)
        f_out = np.zeros((n, self.feature_dim), np.float64)
        ps = np.zeros((n, len(self.config.species)))
        pa = np.zeros((n, len(self.config.actions)))
        for idx, f, p1, p2 in feats:
            f_out[idx], ps[idx], pa[idx] = f, p1, p2
        sp = [self.config.species[i] for i in ps.argmax(1)] if n else []
        ac = [self.config.actions[i] for i in pa.argmax(1)] if n else []
        return Predictions(f_out, sp, ac, ps, pa)

    def predict(self, motions: Iterable[Motion], batch_size: int = 64) -> Predictions:
        """:class:`Predictions` (features, species and action) of motions."""
        return self.predict_inputs(self.inputs(motions), batch_size)

    def features(self, motions: Iterable[Motion]) -> np.ndarray:
        """(N, feature_dim) float64 penultimate features of motions."""
        return self.predict(motions).features


def _read_config(folder: Path) -> tuple[EvaluatorConfig, dict[str, Any]]:
    p = folder / _CONFIG
    if not p.is_file():
        raise EvaluatorError(
            f"{folder}: no {_CONFIG}; an evaluator folder holds {_WEIGHTS} + {_CONFIG}"
        )
    raw = load_json(p, "evaluator config", error=EvaluatorError)
    if not isinstance(raw, dict) or raw.get("kind") != "habitsim.evaluator":
        raise EvaluatorError(f"{p}: not a habitsim evaluator config (kind != 'habitsim.evaluator')")
    if raw.get("format_version") != CONFIG_FORMAT_VERSION:
        raise EvaluatorError(
            f"{p}: format_version {raw.get('format_version')!r}; "
            f"this habitsim reads {CONFIG_FORMAT_VERSION}"
        )
    try:
        cfg = EvaluatorConfig.from_dict(raw["config"])
    except (KeyError, TypeError) as e:
        raise EvaluatorError(f"{p}: bad evaluator config ({e})") from e
    return cfg, raw


def load_evaluator(path: str | Path | None = None) -> Evaluator:
    """Load a frozen evaluator (default: the one shipped inside the package).

    Loaded evaluators are cached per folder (one per process).

    Raises:
        EvaluatorError: missing files, wrong format version, tensors that do not fit the
            configuration (the message names them).
    """
    folder = DEFAULT_EVALUATOR_DIR if path is None else Path(path)
    return _load_cached(str(folder.resolve()))


@functools.lru_cache(maxsize=4)
def _load_cached(folder_s: str) -> Evaluator:
    from safetensors import SafetensorError
    from safetensors.torch import load_file

    folder = Path(folder_s)
    cfg, raw = _read_config(folder)
    w = folder / _WEIGHTS
    if not w.is_file():
        raise EvaluatorError(f"{folder}: no {_WEIGHTS}")
    try:
        state = load_file(str(w))
    except (SafetensorError, OSError, ValueError) as e:
        raise EvaluatorError(f"{w}: not a readable safetensors file ({e})") from e
    model = MotionEvaluator(cfg)
    expected = model.state_dict()
    missing = sorted(set(expected) - set(state))
    extra = sorted(set(state) - set(expected))
    bad = sorted(k for k in set(expected) & set(state) if expected[k].shape != state[k].shape)
    if missing or extra or bad:
        raise EvaluatorError(
            f"{w} does not fit its config: missing {missing[:5]}, unexpected {extra[:5]}, "
            f"wrong shape {bad[:5]}"
        )
    model.load_state_dict(state)
    return Evaluator(model, folder, raw)


# ---------------------------------------------------------------------------- training


@dataclass
class TrainReport:
    """What :func:`train_evaluator` measured.

    Attributes:
        accuracy: split → {"species": acc, "action": acc, "clips": n}; splits ``train``,
            ``val``, ``test`` over the training species and ``held_out`` over the
            held-out species (action accuracy; ``species`` there is the share classified
            as the species' catalog cousin).
        wall_time_s: training wall time [s].
        out_dir: where the checkpoint was written.
        losses: mean training loss per epoch.
    """

    accuracy: dict[str, dict[str, float]]
    wall_time_s: float
    out_dir: Path
    losses: list[float] = field(default_factory=list)


def _crops(m: Motion, rng: np.random.Generator, n: int, min_frames: int) -> list[Motion]:
    t = m.num_frames
    out = [m]
    if t <= min_frames:
        return out
    for _ in range(n):
        length = int(rng.integers(min_frames, t + 1))
        start = int(rng.integers(0, t - length + 1))
        out.append(m.slice(start, start + length))
    return out


def _accuracy(
    ev: Evaluator,
    inputs: list[np.ndarray],
    species: list[str],
    actions: list[str],
    cousins: dict[str, str | None] | None = None,
) -> dict[str, float]:
    if not inputs:
        return {"species": math.nan, "action": math.nan, "clips": 0}
    p = ev.predict_inputs(inputs)
    want = species if cousins is None else [cousins.get(s) or "" for s in species]
    return {
        "species": float(np.mean([a == b for a, b in zip(p.species, want, strict=True)])),
        "action": float(np.mean([a == b for a, b in zip(p.actions, actions, strict=True)])),
        "clips": len(inputs),
    }


def _load_split(
    data: Path, split: str, species: Iterable[str] | None = None
) -> tuple[list[Motion], list[str], list[str]]:
    from habitsim.dataset import iter_clips

    motions, sp, ac = [], [], []
    for entry, m in iter_clips(data, split=split, species=species):
        motions.append(m)
        sp.append(entry.species)
        ac.append(entry.action)
    return motions, sp, ac


def train_evaluator(
    data_dir: str | Path,
    out_dir: str | Path,
    config: EvaluatorConfig | None = None,
    *,
    progress: bool = True,
    log: Callable[[str], None] | None = print,
) -> TrainReport:
    """Train the evaluator on a data set's training split and write it to ``out_dir``.

    Writes ``model.safetensors``, ``config.json`` (config + standardisation + accuracies)
    and ``README.md`` (how it was trained, accuracies per split), each atomically.

    Args:
        data_dir: a synthetic data set (:func:`habitsim.dataset.build_dataset`).
        out_dir: output folder (created).
        config: training settings; class lists default to the data set's training
            species and :data:`habitsim.gaits.ACTIONS`.
        progress: show a tqdm bar over epochs.
        log: where to print one-line progress notes (None: silent).

    Raises:
        DatasetError: a folder without a manifest. EvaluatorError: no training clips.
        OutputPathError: ``out_dir`` cannot be written (checked before training).
    """
    from habitsim.dataset import load_manifest
    from habitsim.fileio import check_writable
    from habitsim.gaits import ACTIONS
    from habitsim.species import load_species

    t0 = time.perf_counter()
    for name in (_WEIGHTS, _CONFIG, _README):
        check_writable(Path(out_dir) / name, "evaluator folder")
    data = Path(data_dir)
    man = load_manifest(data, check_files=False)
    train_species = sorted({c.species for c in man.clips if c.split == "train"})
    if not train_species:
        raise EvaluatorError(f"{data}: the data set has no training clips")
    cfg = config or EvaluatorConfig()
    if not cfg.species:
        cfg = EvaluatorConfig.from_dict(
            {**cfg.to_dict(), "species": train_species, "actions": list(ACTIONS)}
        )
    s_index = {s: i for i, s in enumerate(cfg.species)}
    a_index = {a: i for i, a in enumerate(cfg.actions)}

    rng = np.random.default_rng(cfg.seed)
    torch.manual_seed(cfg.seed)
    motions, sp, ac = _load_split(data, "train")
    xs: list[np.ndarray] = []
    ys: list[tuple[int, int]] = []
    min_frames = max(8, int(round(cfg.min_crop_s * cfg.fps)))
    for m, s, a in zip(motions, sp, ac, strict=True):
        if s not in s_index or a not in a_index:
            continue
        for c in _crops(m, rng, cfg.crops_per_clip, min_frames):
            xs.append(evaluator_input(c, cfg.fps))
            ys.append((s_index[s], a_index[a]))
    if not xs:
        raise EvaluatorError(f"{data}: no training clips of the configured species/actions")
    if log:
        log(
            f"evaluator: {len(motions)} training clips → {len(xs)} samples "
            f"({len(cfg.species)} species, {len(cfg.actions)} actions)"
        )

    model = MotionEvaluator(cfg)
    allx = np.concatenate(xs, 0)
    model.feat_mean.copy_(torch.from_numpy(allx.mean(0)))
    model.feat_std.copy_(torch.from_numpy(np.maximum(allx.std(0), 1e-2)))
    y = torch.tensor(ys, dtype=torch.long)
    opt = torch.optim.AdamW(model.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    steps_per_epoch = math.ceil(len(xs) / cfg.batch_size)
    sched = torch.optim.lr_scheduler.OneCycleLR(
        opt, max_lr=cfg.lr, total_steps=cfg.epochs * steps_per_epoch, pct_start=0.1
    )
    order_len = np.array([a.shape[0] for a in xs])
    losses: list[float] = []
    epochs: Iterable[int] = range(cfg.epochs)
    bar = None
    if progress:
        from tqdm.auto import tqdm

        epochs = bar = tqdm(epochs, desc="train evaluator", unit="epoch")
    gen = torch.Generator().manual_seed(cfg.seed)
    for _epoch in epochs:
        model.train()
        perm = rng.permutation(len(xs))
        # bucket by length within chunks: less padding, still shuffled
        chunks = [perm[i : i + cfg.batch_size * 8] for i in range(0, len(perm), cfg.batch_size * 8)]
        batches = []
        for ch in chunks:
            ch = ch[np.argsort(order_len[ch], kind="stable")]
            batches += [ch[i : i + cfg.batch_size] for i in range(0, len(ch), cfg.batch_size)]
        rng.shuffle(batches)
        tot = 0.0
        for idx in batches:
            x, mask = _batch([xs[i] for i in idx])
            if cfg.feature_noise > 0:
                x = (
                    x
                    + torch.randn(x.shape, generator=gen)
                    * cfg.feature_noise
                    * model.feat_std
                    * mask[..., None]
                )
            _, ls, la = model(x, mask)
            yy = y[torch.from_numpy(idx)]
            loss = nn.functional.cross_entropy(ls, yy[:, 0]) + nn.functional.cross_entropy(
                la, yy[:, 1]
            )
            opt.zero_grad()
            loss.backward()
            nn.utils.clip_grad_norm_(model.parameters(), 1.0)
            opt.step()
            sched.step()
            tot += float(loss.detach()) * len(idx)
        losses.append(tot / len(xs))
        if bar is not None:
            bar.set_postfix(loss=f"{losses[-1]:.3f}")

    ev = Evaluator(model.eval())
    acc: dict[str, dict[str, float]] = {}
    for split in ("train", "val", "test"):
        ms, ss, aa = _load_split(
            data, split, species=[s for s in cfg.species if s in man.species_names]
        )
        acc[split] = _accuracy(ev, ev.inputs(ms), ss, aa)
    held = [s["name"] for s in man.species if s["held_out"]]
    if held:
        ms, ss, aa = _load_split(data, "test", species=held)
        cousins = {s: load_species(s).cousin for s in held}
        acc["held_out"] = _accuracy(ev, ev.inputs(ms), ss, aa, cousins)
    wall = time.perf_counter() - t0
    out = save_evaluator(
        model,
        out_dir,
        accuracy=acc,
        data_dir=data,
        seed=man.seed,
        clips_per_species=man.clips_per_species,
        wall_time_s=wall,
        final_loss=losses[-1],
    )
    if log:
        for k, v in acc.items():
            log(
                f"  {k:9s} species {v['species']:.3f}  action {v['action']:.3f}  "
                f"({v['clips']} clips)"
            )
        log(f"evaluator written to {out} in {wall:.1f} s")
    return TrainReport(acc, wall, out, losses)


def save_evaluator(
    model: MotionEvaluator,
    out_dir: str | Path,
    *,
    accuracy: dict[str, Any],
    data_dir: Path,
    seed: int,
    clips_per_species: int,
    wall_time_s: float,
    final_loss: float,
) -> Path:
    """Write weights (safetensors), ``config.json`` and ``README.md``: all three or none.

    Raises:
        OutputPathError: the folder cannot be written; OutputWriteError: a write failed
            (a full disk), the folder keeps what it held before.
    """
    from safetensors.torch import save

    out = make_dirs(out_dir, "evaluator folder")
    state = {k: v.detach().contiguous() for k, v in model.state_dict().items()}
    blob = save(state, metadata={"format": "pt", "kind": "habitsim.evaluator"})
    import habitsim

    meta = {
        "kind": "habitsim.evaluator",
        "format_version": CONFIG_FORMAT_VERSION,
        "config": model.config.to_dict(),
        "trained_on": {
            "data": str(data_dir),
            "seed": seed,
            "clips_per_species": clips_per_species,
            "split": "train",
            "command": f"habitsim data synth --out DIR --clips-per-species {clips_per_species} "
            f"--seed {seed} && habitsim train-evaluator --data DIR --out OUT",
        },
        "accuracy": {
            split: {
                k: (None if isinstance(v, float) and not math.isfinite(v) else v)
                for k, v in a.items()
            }
            for split, a in accuracy.items()
        },
        "final_loss": final_loss,
        "wall_time_s": round(wall_time_s, 1),
        "torch_version": torch.__version__,
        "habitsim_version": habitsim.__version__,
    }
    with output_transaction():  # the three files together or none (a full disk)
        with atomic_write(out / _WEIGHTS) as fh:
            fh.write(blob)
        atomic_write_text(out / _CONFIG, json.dumps(meta, indent=2, sort_keys=True) + "\n")
        atomic_write_text(out / _README, _readme(meta))
    for name in (_WEIGHTS, _CONFIG, _README):  # package data: readable by everyone
        os.chmod(out / name, 0o644)
    _load_cached.cache_clear()
    return out


def _readme(meta: dict[str, Any]) -> str:
    cfg = meta["config"]
    acc = meta["accuracy"]
    rows = []
    names = {
        "train": "train (seen)",
        "val": "val",
        "test": "test (held-out clips)",
        "held_out": "held-out species",
    }

    def fmt(v: float | None) -> str:
        return "—" if v is None or not math.isfinite(v) else f"{v:.3f}"

    for k in ("train", "val", "test", "held_out"):
        if k in acc:
            a = acc[k]
            sp = fmt(a["species"]) + (" (= its cousin)" if k == "held_out" else "")
            rows.append(f"| {names[k]} | {a['clips']} | {sp} | {fmt(a['action'])} |")
    return f"""# Frozen motion evaluator

The feature extractor and classifier behind habitsim's distribution metrics
(`fid`, `intra_fid`, `downstream_fid`, `diversity`, `one_nna`: penultimate features,
{cfg["feature_dim"]} numbers per clip) and `habit_accuracy` / `action_accuracy` (species and
action heads). See `habitsim/evaluation/evaluator.py` for the architecture.

* Files: `model.safetensors` (weights and the input standardisation), `config.json`
  (architecture, class lists, training settings, these accuracies).
* Architecture: temporal transformer, d_model {cfg["d_model"]}, {cfg["n_layers"]} layers,
  {cfg["n_heads"]} heads, feed-forward {cfg["ff_dim"]}, feature {cfg["feature_dim"]}; input = the
  paper's per-frame features (local quaternions + global joint velocities) at
  {cfg["fps"]:g} Hz after turning the clip to a canonical heading.
* Classes: {len(cfg["species"])} training species ({", ".join(cfg["species"])});
  {len(cfg["actions"])} actions ({", ".join(cfg["actions"])}).
* Trained on the `train` split of the default synthetic data set, reproduced by

  ```bash
  {meta["trained_on"]["command"]}
  ```

  ({cfg["epochs"]} epochs, AdamW, seed {cfg["seed"]}, torch {meta["torch_version"]}, CPU,
  {meta["wall_time_s"]} s).

## Accuracy

Whole clips, top-1. The held-out species are not classes of the species head; their row
gives the action accuracy and the share classified as the species' catalog cousin.

| split | clips | species | action |
|---|---:|---:|---:|
{chr(10).join(rows)}
"""
