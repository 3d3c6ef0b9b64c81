"""Checkpoints: a folder of safetensors tensors and a JSON config — nothing is unpickled.

Layout of a checkpoint folder::

    config.json              format, full Config, species, text model, fps, metrics,
                             training history and the SHA-256 of every tensor file
    model.safetensors        every parameter and buffer of HabitVQVAE (float32)
    train_state.safetensors  optimiser moments and the torch RNG state (resuming only)
    train_state.json         step, numpy RNG state, optimiser bookkeeping (resuming only)

Files are written atomically and ``config.json`` last: it records the hashes of the
tensor files, so an interrupted save or a damaged file is detected on load
(:class:`~habitsim.models.errors.CheckpointError`, naming the problem).
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch

from ..fileio import atomic_write, atomic_write_text, make_dirs, output_transaction
from ..jsonfile import load_json
from .config import Config
from .errors import CheckpointError, ConfigError
from .features import FEATURE_VERSION
from .model import HabitVQVAE

__all__ = [
    "CHECKPOINT_FORMAT",
    "CHECKPOINT_VERSION",
    "MODEL_FILE",
    "CONFIG_FILE",
    "LoadedCheckpoint",
    "save_checkpoint",
    "load_checkpoint",
    "read_checkpoint_config",
    "file_sha256",
    "export_checkpoint",
]

CHECKPOINT_FORMAT = "habitsim.models.checkpoint"
CHECKPOINT_VERSION = 1
MODEL_FILE = "model.safetensors"
CONFIG_FILE = "config.json"
STATE_FILE = "train_state.safetensors"
STATE_JSON = "train_state.json"


def file_sha256(path: str | Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


@dataclass
class LoadedCheckpoint:
    """A loaded checkpoint.

    Attributes:
        model: the model in eval mode.
        config: its configuration.
        meta: the rest of ``config.json`` (species, text, fps, metrics, training).
        path: the folder.
        prior_draws: habit latents already drawn from the flow prior, by (species, seed,
            temperature) (:func:`habitsim.models.transfer.transfer` draws one per call;
            the draw is deterministic, so a repeated transfer reuses it).
    """

    model: HabitVQVAE
    config: Config
    meta: dict[str, Any] = field(default_factory=dict)
    path: Path | None = None
    prior_draws: dict[tuple[str, int, float], torch.Tensor] = field(
        default_factory=dict, repr=False, compare=False
    )

    @property
    def fps(self) -> float:
        return float(self.meta["fps"])

    @property
    def metrics(self) -> dict[str, Any]:
        return dict(self.meta.get("metrics", {}))


def _state_bytes(tensors: dict[str, torch.Tensor]) -> bytes:
    from safetensors.torch import save

    return save({k: v.detach().contiguous().clone() for k, v in tensors.items()})


def save_checkpoint(
    out_dir: str | Path,
    model: HabitVQVAE,
    config: Config,
    meta: dict[str, Any],
    train_state: tuple[dict[str, torch.Tensor], dict[str, Any]] | None = None,
) -> Path:
    """Write a checkpoint folder (see the module docstring).

    Args:
        out_dir: the folder (created).
        model, config: what to save.
        meta: JSON-ready extra fields; must hold ``fps``; ``metrics`` / ``training`` optional.
        train_state: (tensors, json) of the optimiser / RNG state, to resume training.
    """
    out = make_dirs(out_dir, "checkpoint folder")  # OutputPathError, not a raw OSError
    blobs = {MODEL_FILE: _state_bytes(model.state_dict())}
    if train_state is not None:
        tensors, js = train_state
        blobs[STATE_FILE] = _state_bytes(tensors)
        blobs[STATE_JSON] = json.dumps(js).encode("utf-8")
    files = {name: hashlib.sha256(data).hexdigest() for name, data in blobs.items()}
    doc = {
        "format": CHECKPOINT_FORMAT,
        "format_version": CHECKPOINT_VERSION,
        "feature_version": FEATURE_VERSION,
        "config": config.to_dict(),
        "species": list(model.species),
        "text": {**meta.get("text", {}), "names": list(model.text_names), "dim": model.text_dim},
        **{k: v for k, v in meta.items() if k not in ("text", "files")},
        "files": files,
    }
    # all files or none: a failed write (a full disk) leaves the previous checkpoint whole,
    # so a resumed training continues from it
    with output_transaction():
        for name, data in blobs.items():
            with atomic_write(out / name) as fh:
                fh.write(data)
        atomic_write_text(out / CONFIG_FILE, json.dumps(doc, indent=2, sort_keys=False) + "\n")
    _readable(out, [MODEL_FILE, CONFIG_FILE, *([STATE_FILE, STATE_JSON] if train_state else [])])
    return out


def _readable(folder: Path, names: list[str]) -> None:
    """Give files the permissions of a normal new file (temporary files are 0600)."""
    import os

    umask = os.umask(0)
    os.umask(umask)
    for n in names:
        try:
            os.chmod(folder / n, 0o666 & ~umask)
        except OSError:
            pass


def read_checkpoint_config(path: str | Path) -> tuple[Config, dict[str, Any]]:
    """Parse and check ``config.json`` of a checkpoint folder.

    Raises:
        CheckpointError: missing folder / file, invalid JSON, wrong format or version,
            invalid configuration.
    """
    p = Path(path)
    if not p.is_dir():
        raise CheckpointError(f"{p}: no such checkpoint folder")
    cfg_path = p / CONFIG_FILE
    if not cfg_path.is_file():
        present = sorted(x.name for x in p.iterdir())
        raise CheckpointError(
            f"{p}: missing {CONFIG_FILE} (folder holds: {', '.join(present) or 'nothing'})"
        )
    doc = load_json(cfg_path, "checkpoint config", error=CheckpointError)
    if not isinstance(doc, dict) or doc.get("format") != CHECKPOINT_FORMAT:
        fmt = doc.get("format") if isinstance(doc, dict) else None
        raise CheckpointError(f"{cfg_path}: not a habitsim model checkpoint (format {fmt!r})")
    if doc.get("format_version") != CHECKPOINT_VERSION:
        raise CheckpointError(
            f"{cfg_path}: checkpoint format_version {doc.get('format_version')!r}; "
            f"this habitsim reads {CHECKPOINT_VERSION}"
        )
    fv = doc.get("feature_version", 1)
    if fv != FEATURE_VERSION:
        raise CheckpointError(
            f"{cfg_path}: trained on motion feature version {fv!r}; this habitsim encodes "
            f"motions with version {FEATURE_VERSION} (habitsim.models.features), so the "
            "network would read them wrongly: retrain it with `habitsim train`"
        )
    for key in ("config", "species", "text", "fps", "files"):
        if key not in doc:
            raise CheckpointError(f"{cfg_path}: missing key {key!r}")
    try:
        cfg = Config.from_dict(doc["config"])
    except ConfigError as e:
        raise CheckpointError(f"{cfg_path}: invalid config: {e}") from e
    text = doc["text"]
    if (
        not isinstance(text, dict)
        or not isinstance(text.get("names"), list)
        or not isinstance(text.get("dim"), int)
    ):
        raise CheckpointError(f"{cfg_path}: 'text' must hold 'names' (list) and 'dim' (int)")
    if not isinstance(doc["species"], list) or not all(isinstance(s, str) for s in doc["species"]):
        raise CheckpointError(f"{cfg_path}: 'species' must be a list of names")
    return cfg, doc


def _load_tensors(path: Path, expected_sha: str | None) -> dict[str, torch.Tensor]:
    from safetensors import SafetensorError
    from safetensors.torch import load_file

    if not path.is_file():
        raise CheckpointError(f"{path.parent}: missing {path.name}")
    if expected_sha is not None:
        got = file_sha256(path)
        if got != expected_sha:
            raise CheckpointError(
                f"{path}: corrupt or replaced file: SHA-256 {got[:12]}… does not match "
                f"{expected_sha[:12]}… recorded in {CONFIG_FILE}"
            )
    try:
        return load_file(str(path))
    except (SafetensorError, OSError, ValueError, RuntimeError) as e:
        raise CheckpointError(f"{path}: not a readable safetensors file ({e})") from e


def build_model(cfg: Config, doc: dict[str, Any]) -> HabitVQVAE:
    """An untrained model shaped like a checkpoint's config."""
    from ..errors import UnknownSpeciesError
    from ..species import load_species

    for s in doc["species"]:
        try:
            load_species(s)
        except UnknownSpeciesError as e:
            raise CheckpointError(f"checkpoint species {s!r} is not in the catalog ({e})") from e
    return HabitVQVAE(cfg.model, doc["species"], doc["text"]["names"], doc["text"]["dim"])


def load_checkpoint(path: str | Path, verify: bool = True) -> LoadedCheckpoint:
    """Load a checkpoint folder into a model (eval mode, CPU).

    Args:
        path: the folder.
        verify: check the SHA-256 of ``model.safetensors`` against ``config.json``.

    Raises:
        CheckpointError: anything missing, corrupt or not matching the config: names the
            file and the first mismatching tensors.
    """
    p = Path(path)
    cfg, doc = read_checkpoint_config(p)
    sha = doc["files"].get(MODEL_FILE) if verify and isinstance(doc["files"], dict) else None
    if verify and sha is None:
        raise CheckpointError(f"{p / CONFIG_FILE}: no SHA-256 recorded for {MODEL_FILE}")
    tensors = _load_tensors(p / MODEL_FILE, sha)
    model = build_model(cfg, doc)
    expected = model.state_dict()
    missing = sorted(set(expected) - set(tensors))
    unexpected = sorted(set(tensors) - set(expected))
    shapes = [
        f"{k} {tuple(tensors[k].shape)} (config needs {tuple(v.shape)})"
        for k, v in expected.items()
        if k in tensors and tuple(tensors[k].shape) != tuple(v.shape)
    ]
    if missing or unexpected or shapes:
        parts = []
        if missing:
            parts.append(f"missing tensors {missing[:4]}{' …' if len(missing) > 4 else ''}")
        if unexpected:
            parts.append(
                f"unexpected tensors {unexpected[:4]}{' …' if len(unexpected) > 4 else ''}"
            )
        if shapes:
            parts.append(f"shape mismatch {shapes[:3]}{' …' if len(shapes) > 3 else ''}")
        raise CheckpointError(f"{p / MODEL_FILE} does not match {CONFIG_FILE}: " + "; ".join(parts))
    bad_dtype = [k for k, v in expected.items() if tensors[k].dtype != v.dtype]
    if bad_dtype:
        raise CheckpointError(f"{p / MODEL_FILE}: wrong dtype of {bad_dtype[:4]}")
    model.load_state_dict(tensors, strict=True)
    model.eval()
    meta = {k: v for k, v in doc.items() if k not in ("config",)}
    return LoadedCheckpoint(model, cfg, meta, p)


def load_train_state(
    path: str | Path, doc: dict[str, Any]
) -> tuple[dict[str, torch.Tensor], dict[str, Any]]:
    """Optimiser / RNG state of a checkpoint written during training.

    Raises:
        CheckpointError: the folder has no (or a corrupt) training state.
    """
    p = Path(path)
    files = doc.get("files", {})
    if STATE_FILE not in files or not (p / STATE_JSON).is_file():
        raise CheckpointError(f"{p}: no training state to resume from (was it shipped / stripped?)")
    tensors = _load_tensors(p / STATE_FILE, files[STATE_FILE])
    js_path = p / STATE_JSON
    if file_sha256(js_path) != files.get(STATE_JSON):
        raise CheckpointError(f"{js_path}: corrupt or replaced (SHA-256 mismatch)")
    js = load_json(js_path, "training state", error=CheckpointError)
    return tensors, js


def export_checkpoint(src: str | Path, dst: str | Path, note: dict[str, Any] | None = None) -> Path:
    """Copy a checkpoint without its training state (how the shipped model is made).

    Args:
        src: trained checkpoint folder (verified on the way).
        dst: destination folder (created; its model / config files are replaced).
        note: extra top-level JSON fields to merge into the copy's ``config.json``.
    """
    import shutil

    src, dst = Path(src), Path(dst)
    load_checkpoint(src)  # refuse to export a broken checkpoint
    doc = load_json(src / CONFIG_FILE, "checkpoint config", error=CheckpointError)
    doc["files"] = {MODEL_FILE: doc["files"][MODEL_FILE]}
    doc.update(note or {})
    make_dirs(dst, "checkpoint folder")
    with atomic_write(dst / MODEL_FILE) as fh, open(src / MODEL_FILE, "rb") as fin:
        shutil.copyfileobj(fin, fh)
    for stale in (STATE_FILE, STATE_JSON):
        (dst / stale).unlink(missing_ok=True)
    atomic_write_text(dst / CONFIG_FILE, json.dumps(doc, indent=2) + "\n")
    _readable(dst, [MODEL_FILE, CONFIG_FILE])
    load_checkpoint(dst)
    return dst
