"""Typed configuration of text to motion: the transformer's shape
(:class:`CodeGPTConfig`), its training schedule (:class:`T2MTrainConfig`) and the presets.

Torch-free, like :mod:`habitsim.models.config`, so the command line lists the presets
without loading the learning core. A configuration round-trips through JSON
(:meth:`T2MConfig.to_dict` / :meth:`T2MConfig.from_dict`, which rejects unknown keys and
bad values with :class:`~habitsim.models.errors.ConfigError`); every checkpoint stores
the one it was trained with.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from .config import _from_dict
from .errors import ConfigError

__all__ = [
    "CodeGPTConfig",
    "T2MTrainConfig",
    "T2MConfig",
    "T2M_PRESETS",
    "t2m_preset",
]


@dataclass(frozen=True)
class CodeGPTConfig:
    """Shape and training-time regularisation of :class:`CodeGPT`.

    Attributes:
        d_model: width of every token [channels].
        layers: transformer blocks.
        heads: attention heads per block (must divide ``d_model``).
        ff: hidden width of each block's feed-forward layer.
        dropout: dropout inside the blocks while training.
        max_steps: most code steps the model makes (its position table); at 30 fps and
            rate 4, 64 steps = 8.5 s.
        text_dropout: probability that a training sequence sees the null text token
            (classifier-free guidance's condition dropout), in [0, 1).
        path_weight: weight of the path regression loss beside the code cross-entropy.
    """

    d_model: int = 192
    layers: int = 3
    heads: int = 4
    ff: int = 768
    dropout: float = 0.1
    max_steps: int = 64
    text_dropout: float = 0.1
    path_weight: float = 1.0

    def validate(self) -> CodeGPTConfig:
        """Self, or :class:`~habitsim.models.errors.ConfigError` naming the bad field."""
        checks = [
            (self.d_model >= 8, f"d_model must be ≥ 8, got {self.d_model}"),
            (self.layers >= 1, f"layers must be ≥ 1, got {self.layers}"),
            (
                self.heads >= 1 and self.d_model % self.heads == 0,
                f"heads must divide d_model {self.d_model}, got {self.heads}",
            ),
            (self.ff >= 1, f"ff must be ≥ 1, got {self.ff}"),
            (0.0 <= self.dropout < 1.0, f"dropout must be in [0, 1), got {self.dropout}"),
            (self.max_steps >= 1, f"max_steps must be ≥ 1, got {self.max_steps}"),
            (
                0.0 <= self.text_dropout < 1.0,
                f"text_dropout must be in [0, 1), got {self.text_dropout}",
            ),
            (self.path_weight >= 0.0, f"path_weight must be ≥ 0, got {self.path_weight}"),
        ]
        for ok, msg in checks:
            if not ok:
                raise ConfigError(f"codegpt: {msg}")
        return self

    def to_dict(self) -> dict[str, float | int]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: object) -> CodeGPTConfig:
        """Parse a dict (unknown keys and bad values: ConfigError)."""
        if not isinstance(d, dict):
            raise ConfigError(f"codegpt config must be an object, got {type(d).__name__}")
        names = {f.name for f in dataclasses.fields(cls)}
        bad = sorted(set(d) - names)
        if bad:
            raise ConfigError(f"codegpt: unknown keys {bad}; valid: {', '.join(sorted(names))}")
        try:
            return cls(**d).validate()
        except TypeError as e:
            raise ConfigError(f"codegpt: {e}") from None


@dataclass(frozen=True)
class T2MTrainConfig:
    """Schedule of :func:`train_codegpt`.

    Attributes:
        steps: optimiser steps in all.
        batch_size: clips per step.
        lr: peak learning rate; lr_final: the cosine's end value.
        warmup_steps: linear warm-up from lr / warmup_steps.
        weight_decay: AdamW's decoupled weight decay.
        checkpoint_every: steps between resumable checkpoints (and at the end).
        val_every: steps between validation records (and at the end).
        seed: seed of the weights, the dropout and the batch sampler.
        threads: torch CPU threads while training (None: leave torch's setting). One by
            default: on a model this small a second thread cost more than it gained
            (docs/text_to_motion.md).
    """

    steps: int = 4000
    batch_size: int = 32
    lr: float = 3e-4
    lr_final: float = 3e-5
    warmup_steps: int = 200
    weight_decay: float = 0.01
    checkpoint_every: int = 500
    val_every: int = 500
    seed: int = 0
    threads: int | None = 1

    def validate(self) -> T2MTrainConfig:
        checks = [
            (self.steps >= 1, f"steps must be ≥ 1, got {self.steps}"),
            (self.batch_size >= 1, f"batch_size must be ≥ 1, got {self.batch_size}"),
            (self.lr > 0 and self.lr_final >= 0, "lr must be > 0 and lr_final ≥ 0"),
            (self.warmup_steps >= 0, f"warmup_steps must be ≥ 0, got {self.warmup_steps}"),
            (self.weight_decay >= 0, f"weight_decay must be ≥ 0, got {self.weight_decay}"),
            (self.checkpoint_every >= 1, "checkpoint_every must be ≥ 1"),
            (self.val_every >= 1, "val_every must be ≥ 1"),
            (self.seed >= 0, f"seed must be ≥ 0, got {self.seed}"),
            (self.threads is None or self.threads >= 1, "threads must be ≥ 1 or None"),
        ]
        for ok, msg in checks:
            if not ok:
                raise ConfigError(f"t2m train: {msg}")
        return self


@dataclass(frozen=True)
class T2MConfig:
    """A text-to-motion configuration: preset name, model shape, schedule."""

    name: str = "default"
    model: CodeGPTConfig = field(default_factory=CodeGPTConfig)
    train: T2MTrainConfig = field(default_factory=T2MTrainConfig)

    def validate(self) -> T2MConfig:
        self.model.validate()
        self.train.validate()
        return self

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: Any) -> T2MConfig:
        """Parse :meth:`to_dict`'s output (ConfigError on unknown keys or bad values)."""
        return _from_dict(cls, d, "t2m config").validate()

    def replace(self, **changes: Any) -> T2MConfig:
        """A copy with dotted keys replaced: ``cfg.replace(**{"train.steps": 10})``."""
        d = self.to_dict()
        for key, value in changes.items():
            node = d
            *parents, last = key.split(".")
            for p in parents:
                if not isinstance(node.get(p), dict):
                    raise ConfigError(f"unknown t2m config key {key!r}")
                node = node[p]
            if last not in node:
                raise ConfigError(f"unknown t2m config key {key!r}; valid here: {', '.join(node)}")
            node[last] = value
        return T2MConfig.from_dict(d)


def _tiny() -> T2MConfig:
    """Seconds on one core: tests and smoke runs."""
    return T2MConfig(
        "tiny",
        CodeGPTConfig(d_model=32, layers=1, heads=2, ff=64, dropout=0.1, max_steps=48),
        T2MTrainConfig(steps=20, batch_size=4, warmup_steps=2, checkpoint_every=10, val_every=10),
    )


def _default() -> T2MConfig:
    """Well inside 2.5 h on 2 CPU cores: 22 to 27 min on one thread measured
    (docs/text_to_motion.md)."""
    return T2MConfig("default")


#: Preset name → factory.
T2M_PRESETS: dict[str, Callable[[], T2MConfig]] = {"tiny": _tiny, "default": _default}


def t2m_preset(name: str) -> T2MConfig:
    """The configuration of a preset (ConfigError listing the valid names)."""
    if name not in T2M_PRESETS:
        raise ConfigError(f"unknown t2m preset {name!r}; valid: {', '.join(T2M_PRESETS)}")
    return T2M_PRESETS[name]().validate()
