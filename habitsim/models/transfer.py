"""Motion transfer to another species: the API, the learned methods and the model cache.

``transfer(motion, to="cat", method="habit")`` re-expresses a motion on the target
species' skeleton with a method of the one registry,
:data:`habitsim.transfer_methods.METHODS` (re-exported here): the learned methods
(:func:`network_method` of each model variant)

==============  ================================================================
``habit``       VQ-VAE, EMA + code reset, decoder gets z_c (target's flow prior) and g_c
``habit_ema``   the same trained with an EMA codebook but no code reset
``no_habit``    VQ-VAE whose decoder gets neither z_c nor g_c (reconstruction model)
``habit_only``  decoder gets z_c only
``text_only``   decoder gets g_c only
==============  ================================================================

and the baselines ``direct`` (no network: copy the local rotations, scale the root by the
hip-height ratio, keep the source's labels and metadata), ``direct_relabelled`` (the same
motion, labelled by :func:`transfer_contacts`) and
``ground_truth``.

A network method needs a checkpoint of its variant: the ``checkpoint=`` argument, else
``$HABITSIM_MODELS_DIR/<variant>``, else the one shipped in
``habitsim/models/checkpoints/<variant>`` (only ``habit`` is shipped).

Long motions are cut into windows of the model's length overlapping by a quarter; each
window is encoded in its own heading frame, decoded with the target's condition, turned
back, and the windows are cross-faded. One z_c is drawn per call (``seed``) and used for
every window so that the habit stays the same along the clip. A motion at another frame
rate is resampled to the model's and back. The decoded motion is then conformed to its
source by the torch-free half (:func:`habitsim.stance.conform.conform`: bounds, stance
labels, levelling, planting), tuned by a :class:`~habitsim.stance.policy.ConformPolicy`
(``policy=``).

For a target species without a habit encoder (held out from training), z_c is drawn from
the prior of the nearest training species in text-embedding space (paper eq. 11,
:func:`habitsim.models.text.retrieve_neighbour`); the decoder still receives the target's
own text embedding g_c. The choice and its reason are stored in the result's
``metadata["transfer"]["retrieval"]``.
"""

from __future__ import annotations

import functools
import logging
import os
from collections.abc import Callable, Sequence
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import torch

from ..errors import HabitReferenceError, InvalidMotionError
from ..motion import Motion, resample_motion
from ..species import load_species
from ..stance.conform import ConformReport, conform
from ..stance.policy import ConformPolicy
from ..stance.schedule import transfer_contacts, walking_stance
from ..threads import one_thread
from ..transfer_methods import METHODS, TransferMethod, register_method, run_method
from ..transfer_methods import method_names as available_methods
from .checkpoint import CONFIG_FILE, LoadedCheckpoint, load_checkpoint
from .config import VARIANTS
from .errors import MethodNotAvailableError, TextEncoderError
from .features import (
    NUM_JOINTS,
    Q_DIM,
    canonical_window,
    clip_arrays,
    decoded_contacts,
    features_to_motion,
    uncanonicalize,
)
from .habit_fit import HabitFitOptions, HabitLatent, fit_latent
from .text import Retrieval, retrieve_neighbour

__all__ = [
    "TransferMethod",
    "METHODS",
    "available_methods",
    "register_method",
    "transfer",
    "reconstruct",
    "network_method",
    "network_transfer",
    "transfer_contacts",
    "walking_stance",
    "resolve_checkpoint",
    "load_model",
    "shipped_checkpoint",
    "habit_species_for",
    "habit_from_clips",
    "unseen_neighbour",
    "prior_latent",
]

_LOG = logging.getLogger("habitsim.models")

#: Environment variable naming a folder of ``<variant>/`` checkpoint folders.
MODELS_DIR_ENV = "HABITSIM_MODELS_DIR"


# ---------------------------------------------------------------------------- checkpoints


def shipped_checkpoint(variant: str = "habit") -> Path | None:
    """Folder of the checkpoint shipped in the package for ``variant`` (None if absent)."""
    root = Path(str(resources.files("habitsim.models") / "checkpoints" / variant))
    return root if (root / CONFIG_FILE).is_file() else None


def resolve_checkpoint(variant: str, checkpoint: str | Path | None = None) -> Path:
    """The checkpoint folder to use for a variant (see the module docstring).

    Raises:
        MethodNotAvailableError: no checkpoint of that variant anywhere.
    """
    if checkpoint is not None:
        return Path(checkpoint)
    env = os.environ.get(MODELS_DIR_ENV)
    if env and (Path(env) / variant / CONFIG_FILE).is_file():
        return Path(env) / variant
    shipped = shipped_checkpoint(variant)
    if shipped is not None:
        return shipped
    raise MethodNotAvailableError(
        f"no trained {variant!r} checkpoint: only {', '.join(_shipped_variants()) or 'none'} "
        f"ship(s) with habitsim; train one with `habitsim train --data DIR --variant {variant} "
        f"--out CKPT` and pass checkpoint=CKPT (or put it in ${MODELS_DIR_ENV}/{variant})"
    )


def _shipped_variants() -> list[str]:
    return [v for v in VARIANTS if shipped_checkpoint(v) is not None]


@functools.lru_cache(maxsize=8)
def _load_cached(path: str, mtime: float) -> LoadedCheckpoint:
    return load_checkpoint(path)


def load_model(checkpoint: str | Path | None = None, variant: str = "habit") -> LoadedCheckpoint:
    """Load (and cache) a checkpoint: a folder, or the default one of ``variant``.

    Raises:
        CheckpointError / MethodNotAvailableError.
    """
    p = resolve_checkpoint(variant, checkpoint).resolve()
    cfg = p / CONFIG_FILE
    mtime = cfg.stat().st_mtime if cfg.is_file() else 0.0
    return _load_cached(str(p), mtime)


# ---------------------------------------------------------------------------- helpers


def _resample(motion: Motion, fps: float) -> Motion:
    """The motion at another frame rate (:func:`habitsim.motion.resample_motion`)."""
    return resample_motion(motion, fps)


def _window_starts(n: int, window: int) -> list[int]:
    if n <= window:
        return [0]
    hop = max(1, window - window // 4)
    starts = list(range(0, n - window + 1, hop))
    if starts[-1] != n - window:
        starts.append(n - window)
    return starts


def _blend(windows: list[np.ndarray], starts: list[int], n: int, window: int) -> np.ndarray:
    """Cross-fade world-frame window features into one (n, F) sequence."""
    f = windows[0].shape[1]
    acc = np.zeros((n, f))
    wsum = np.zeros(n)
    ov = max(1, window // 4)
    for k, (w, s) in enumerate(zip(windows, starts, strict=True)):
        length = min(window, n - s)
        w = w[:length].copy()
        ramp = np.ones(length)
        if k > 0:
            ramp = np.minimum(ramp, (np.arange(length) + 1) / (ov + 1))
        if k < len(starts) - 1:
            ramp = np.minimum(ramp, (length - np.arange(length)) / (ov + 1))
        if k > 0:  # put each joint's quaternions in the hemisphere of what is there already
            q = w[:, :Q_DIM].reshape(length, NUM_JOINTS, 4)
            prev = acc[s : s + length, :Q_DIM].reshape(length, NUM_JOINTS, 4)
            have = wsum[s : s + length] > 0
            if have.any():
                dots = np.sum(q[have] * prev[have], axis=-1).sum(0)
                q[:, dots < 0] *= -1.0
                w[:, :Q_DIM] = q.reshape(length, -1)
        acc[s : s + length] += w * ramp[:, None]
        wsum[s : s + length] += ramp
    return acc / np.maximum(wsum, 1e-9)[:, None]


def habit_species_for(ck: LoadedCheckpoint, target: str) -> tuple[str, Retrieval | None]:
    """Species whose habit encoder / prior serves ``target``, and the retrieval if any."""
    model = ck.model
    if target in model.species:
        return target, None
    emb = _embeddings(ck, [target, *model.species])
    r = retrieve_neighbour(target, list(model.species), emb, ck.config.model.text.morphology_weight)
    _LOG.info(r.explain())
    return r.neighbour, r


def unseen_neighbour(ck: LoadedCheckpoint, target: str) -> Retrieval:
    """The retrieval neighbour of ``target`` among the checkpoint's training species other
    than ``target`` itself: what a held-out target gets, also for a training species
    treated as unseen (the benchmark of one-shot habits, ``habitsim bench oneshot``)."""
    others = [s for s in ck.model.species if s != target]
    emb = _embeddings(ck, [target, *others])
    return retrieve_neighbour(target, others, emb, ck.config.model.text.morphology_weight)


def prior_latent(
    ck: LoadedCheckpoint, species: str, habit_species: str, seed: int | None = 0
) -> HabitLatent:
    """The habit latent a transfer to ``species`` draws from ``habit_species``' flow prior
    with ``seed`` (temperature 1), as a :class:`HabitLatent` (method ``prior``) that
    :func:`network_method`'s ``habit=`` takes: the retrieval (a neighbour's prior) and
    the oracle (the species' own) of ``habitsim bench oneshot``."""
    ck.model._check_species([habit_species])
    z = _prior_draw(ck, habit_species, seed, 1.0)[0].numpy().astype(np.float32)
    nan = float("nan")
    return HabitLatent(z, species, habit_species, "prior", "-", (), 0, nan, nan)


def _embeddings(ck: LoadedCheckpoint, names: list[str]) -> dict[str, np.ndarray]:
    table = ck.model.text_table.detach().numpy()
    out = {n: table[i] for i, n in enumerate(ck.model.text_names)}
    missing = [n for n in names if n not in out]
    if missing:
        from .text import species_embeddings

        try:
            out.update(species_embeddings(missing, ck.config.model.text.model))
        except TextEncoderError as e:
            # a species made from a clip without the text model: its cousin's embedding
            for name in missing:
                cousin = load_species(name).cousin
                if cousin in out:
                    _LOG.info("%s: no text model here; using its cousin %s's", name, cousin)
                    out[name] = out[cousin]
            left = [n for n in missing if n not in out]
            if left:
                raise TextEncoderError(
                    f"the checkpoint has no text embedding of {', '.join(left)} and {e}; "
                    "install the text extra (pip install 'habitsim[text]') to embed its "
                    "description, or give the species a catalog neighbour (habitsim species "
                    "from-clip --like SPECIES)"
                ) from e
    return out


def _text_rows(ck: LoadedCheckpoint, species: str, n: int) -> torch.Tensor | None:
    if species in ck.model.text_names:
        return None  # the model looks it up itself
    g = _embeddings(ck, [species])[species]
    return torch.from_numpy(np.repeat(g[None], n, axis=0))


#: Most prior draws a loaded checkpoint keeps (:attr:`LoadedCheckpoint.prior_draws`).
PRIOR_DRAWS_KEPT = 256


@torch.no_grad()
def _prior_draw(
    ck: LoadedCheckpoint, species: str, seed: int | None, temperature: float
) -> torch.Tensor:
    """One habit latent (1, z_dim) from ``species``' flow prior with the generator seeded
    by ``seed`` (``None``: 0): the same draw every time, kept on the checkpoint."""
    key = (species, 0 if seed is None else int(seed), float(temperature))
    z = ck.prior_draws.get(key)
    if z is None:
        gen = torch.Generator().manual_seed(key[1])
        z = ck.model.sample_prior(species, 1, gen, temperature)
        if len(ck.prior_draws) >= PRIOR_DRAWS_KEPT:
            ck.prior_draws.pop(next(iter(ck.prior_draws)))
        ck.prior_draws[key] = z
    return z


@one_thread()  # the same output on every machine (habitsim.threads)
@torch.no_grad()
def _run_network(
    ck: LoadedCheckpoint,
    motion: Motion,
    to: str,
    *,
    seed: int | None,
    temperature: float,
    reconstruct: bool = False,
    habit: HabitLatent | None = None,
) -> tuple[Motion, dict[str, Any]]:
    model = ck.model
    window = ck.config.model.window
    src = _resample(motion, ck.fps)
    arrays = clip_arrays(src)
    n = arrays.num_frames
    starts = _window_starts(n, window)
    wins = [canonical_window(arrays, s, window) for s in starts]
    x = torch.from_numpy(np.stack([w[0] for w in wins]))
    k = x.shape[0]
    codes = model.quantize(model.encode(x), sample=False, update=False).quantized
    habit_sp: str | None = None
    retrieval: Retrieval | None = None
    z = None
    if model.cfg.use_z and habit is not None:  # found from reference clips
        habit_sp = habit.habit_species
        z = torch.from_numpy(habit.z)[None].expand(k, -1)
    elif model.cfg.use_z:
        habit_sp, retrieval = habit_species_for(ck, to)
        if reconstruct:
            z = model.posterior(x, [habit_sp] * k)[0]
        else:
            z = _prior_draw(ck, habit_sp, seed, temperature).expand(k, -1)
    text = _text_rows(ck, to, k) if model.cfg.use_g else None
    if habit is not None and habit.text is not None and model.cfg.use_g:  # fitted to clips
        text = torch.from_numpy(habit.text)[None].expand(k, -1)
    cond = model.condition([to] * k, z, text)
    y = model.decode(codes, cond, model.path(x)).numpy()
    world = [uncanonicalize(y[i], wins[i][2]) for i in range(k)]
    feats = _blend(world, starts, n, window)
    ratio = load_species(to).hip_height / load_species(src.species).hip_height
    out = features_to_motion(feats, to, ck.fps, src.root_positions[0, :2] * ratio)
    out = Motion(out.species, out.fps, out.root_positions, out.rotations, decoded_contacts(feats))
    info = {
        "habit_species": habit_sp,
        "retrieval": None
        if retrieval is None
        else {
            "neighbour": retrieval.neighbour,
            "text_distance": round(retrieval.text_distance, 4),
            "morphology_distance": round(retrieval.morphology_distance, 4),
            "explanation": retrieval.explain(),
        },
        "windows": k,
        "checkpoint": str(ck.path) if ck.path else None,
    }
    if habit is not None:
        info["habit_from"] = habit.to_metadata()
    return out, info


# ---------------------------------------------------------------------------- methods


def network_method(variant: str) -> Callable[..., Motion]:
    """The transfer function of the learned method ``variant`` (a name of
    :data:`habitsim.models.config.VARIANTS`): ``fn(motion, to, *, seed, checkpoint,
    temperature, plant)`` runs the network of that variant's checkpoint and conforms its
    output (:func:`_finish`).

    Raises:
        ConfigError: an unknown variant.
    """
    if variant not in VARIANTS:
        from .errors import ConfigError

        raise ConfigError(f"unknown model variant {variant!r}; valid: {', '.join(VARIANTS)}")

    def run(
        motion: Motion,
        to: str,
        *,
        seed: int | None = 0,
        checkpoint: str | Path | None = None,
        temperature: float = 1.0,
        plant: bool = True,
        policy: ConformPolicy | None = None,
        habit: HabitLatent | None = None,
        **_: Any,
    ) -> Motion:
        return network_transfer(
            variant,
            motion,
            to,
            seed=seed,
            checkpoint=checkpoint,
            temperature=temperature,
            plant=plant,
            policy=policy,
            habit=habit,
        )[0]

    run.__name__ = f"transfer_{variant}"
    return run


def network_transfer(
    variant: str,
    motion: Motion,
    to: str,
    *,
    seed: int | None = 0,
    checkpoint: str | Path | None = None,
    temperature: float = 1.0,
    plant: bool = True,
    policy: ConformPolicy | None = None,
    habit: HabitLatent | None = None,
) -> tuple[Motion, ConformReport]:
    """The learned method ``variant``'s transfer (what :func:`network_method` runs) with
    the typed :class:`~habitsim.stance.report.ConformReport` of its conform step (its
    planting's :attr:`~habitsim.stance.report.PlantOutcome.reason_codes`, …), which the
    motion's ``metadata["transfer"]`` holds only as text.

    Raises:
        MethodNotAvailableError: the checkpoint is of another variant.
    """
    ck = load_model(checkpoint, variant)
    if ck.config.model.variant != variant:
        raise MethodNotAvailableError(
            f"method {variant!r} needs a {variant!r} checkpoint; {ck.path} is a "
            f"{ck.config.model.variant!r} one"
        )
    out, info = _run_network(
        ck, motion, load_species(to).name, seed=seed, temperature=temperature, habit=habit
    )
    info = {"method": variant, "from": motion.species, "to": out.species, "seed": seed, **info}
    return conform(out, motion, info, plant, policy)


def transfer(
    motion: Motion,
    to: str,
    method: str = "habit",
    *,
    source: str | None = None,
    seed: int | None = 0,
    checkpoint: str | Path | None = None,
    temperature: float = 1.0,
    plant: bool = True,
    policy: ConformPolicy | None = None,
    habit_from: Sequence[Motion | str | Path] | None = None,
    habit_options: HabitFitOptions | None = None,
) -> Motion:
    """Transfer a motion onto another species, keeping the target's habits.

    Args:
        motion: the source motion (any catalog species, any frame rate).
        to: target species name.
        method: a name of the registry :data:`METHODS` (default ``habit``).
        source: treat the motion as this species' (relabel) instead of ``motion.species``.
        seed: seed of the habit latent z_c drawn from the target's prior (same seed ⇒
            same output).
        checkpoint: checkpoint folder to use instead of the default of the method.
        temperature: scale of the flow's base Gaussian when drawing z_c (1 = the prior).
        plant: the network methods plant the decoded feet on the output's stance labels
            by leg IK (``False``: the decoder's raw kinematics; the ``direct`` methods
            keep the source's planted feet either way).
        policy: the knobs and switches of conforming the decoded motion to its source
            (stance labels, bounds, levelling, planting; None: the defaults of
            :class:`~habitsim.stance.policy.ConformPolicy`).
        habit_from: reference clips (motions or ``.npz`` files) of the target species:
            the habit latent is found from them (:func:`habitsim.models.habit_fit.
            habit_from_clips`) instead of drawn from a prior; a learned method with z_c only.
        habit_options: how that latent is found (None: the defaults of
            :class:`~habitsim.models.habit_fit.HabitFitOptions`).

    Returns:
        A :class:`~habitsim.motion.Motion` on ``to``'s skeleton at the source's frame
        rate. The learned methods and ``direct_relabelled`` give it foot contacts
        (:func:`transfer_contacts`) and ``metadata["transfer"]`` (method, habit species,
        retrieval explanation for held-out targets, how the contacts were found, what
        the planting did); ``direct`` keeps the source's labels and metadata
        (:func:`habitsim.transfer_methods.direct_transfer`).

    Raises:
        UnknownMethodError: the method is not registered (lists the valid ones).
        UnknownSpeciesError: unknown target / source species.
        MethodNotAvailableError: no checkpoint for the method's variant.
        MethodUnavailable: the method cannot serve this pair (``ground_truth``).
        CheckpointError: the checkpoint cannot be loaded.
        HabitReferenceError: ``habit_from`` clips of another species than ``to`` (code
            ``species``, naming both), none, or a method without a habit latent.
    """
    entry = METHODS[method]  # UnknownMethodError listing the registered ones
    if not isinstance(motion, Motion):
        raise InvalidMotionError(f"transfer needs a habitsim Motion, got {type(motion).__name__}")
    tgt = load_species(to).name
    if source is not None:
        src_name = load_species(source).name
        if src_name != motion.species:
            motion = Motion(
                src_name,
                motion.fps,
                motion.root_positions,
                motion.rotations,
                motion.contacts,
                dict(motion.metadata),
            )
    options: dict[str, Any] = {} if policy is None else {"policy": policy}
    if habit_from is not None:
        options["habit"] = _habit_latent(entry, tgt, habit_from, checkpoint, habit_options)
    return run_method(
        entry,
        motion,
        tgt,
        seed=seed,
        checkpoint=checkpoint,
        temperature=temperature,
        plant=plant,
        **options,
    )


def _habit_latent(
    entry: TransferMethod,
    target: str,
    clips: Sequence[Motion | str | Path],
    checkpoint: str | Path | None,
    options: HabitFitOptions | None,
) -> HabitLatent:
    """The habit latent of ``transfer(habit_from=clips)`` (see :func:`transfer`)."""
    from ..motion import load_motion

    if entry.variant is None:
        raise HabitReferenceError(
            "method",
            f"method {entry.name!r} has no habit latent to take from a clip; use a learned "
            "one with z_c (habit, habit_ema, habit_only)",
        )
    if not clips:
        raise HabitReferenceError("empty", "habit_from needs at least one reference clip")
    motions = [c if isinstance(c, Motion) else load_motion(c) for c in clips]
    names = [
        f"clip {i + 1}" if isinstance(c, Motion) else Path(c).name for i, c in enumerate(clips)
    ]
    for name, m in zip(names, motions, strict=True):
        if load_species(m.species).name != target:
            raise HabitReferenceError(
                "species",
                f"habit reference {name} is a {m.species} motion but the target is {target}: "
                f"the reference clips must be on the {target}'s skeleton",
            )
    ck = resolve_checkpoint(entry.variant, checkpoint)
    return habit_from_clips(motions, ck, options, names)


def _clip_windows(ck: LoadedCheckpoint, motions: Sequence[Motion]) -> torch.Tensor:
    """Every model window (B, T, F) of every clip, each in its own heading frame."""
    window = ck.config.model.window
    out = []
    for m in motions:
        arrays = clip_arrays(_resample(m, ck.fps))
        out += [
            canonical_window(arrays, s, window)[0]
            for s in _window_starts(arrays.num_frames, window)
        ]
    return torch.from_numpy(np.stack(out))


def habit_from_clips(
    motions: Sequence[Motion],
    checkpoint: str | Path | None = None,
    options: HabitFitOptions | None = None,
    names: Sequence[str] | None = None,
) -> HabitLatent:
    """The habit latent shown by one or several clips of one species.

    Args:
        motions: K ≥ 1 reference clips, all of one species (any frame rate, any length;
            a clip shorter than a window is padded as in a transfer).
        checkpoint: checkpoint folder (None: the default ``habit`` one).
        options: how (None: :class:`HabitFitOptions` defaults: fitted from the
            prior's centre).
        names: a name per clip for the record (None: ``clip 1`` …).

    Returns:
        The :class:`HabitLatent` (z and how it was found).

    Raises:
        HabitReferenceError: no clip (``empty``), clips of several species (``species``),
            options out of range (``options``), or a model without a habit latent
            (``method``).
        UnknownSpeciesError: ``options.habit_species`` is no training species.
    """
    opts = options or HabitFitOptions()
    opts.validate()
    if not motions:
        raise HabitReferenceError("empty", "habit_from needs at least one reference clip")
    species = load_species(motions[0].species).name
    other = [m.species for m in motions if load_species(m.species).name != species]
    if other:
        raise HabitReferenceError(
            "species",
            f"reference clips of several species: {species} and {other[0]}; "
            "give clips of one species",
        )
    clip_names = (
        tuple(names) if names is not None else tuple(f"clip {i + 1}" for i in range(len(motions)))
    )
    ck = load_model(checkpoint)
    if not ck.model.cfg.use_z:
        raise HabitReferenceError(
            "method",
            f"the {ck.config.model.variant!r} checkpoint has no habit latent; use one of a "
            "variant with z_c (habit, habit_ema, habit_only)",
        )
    if opts.habit_species is not None:
        ck.model._check_species([opts.habit_species])
        hs = opts.habit_species
    else:
        hs = habit_species_for(ck, species)[0]
    x = _clip_windows(ck, motions)
    text = _text_rows(ck, species, x.shape[0]) if ck.model.cfg.use_g else None
    z, start, loss, g_fit, weights = fit_latent(ck, x, species, hs, opts, text)
    return HabitLatent(
        z=z,
        species=species,
        habit_species=hs,
        method=opts.method,
        init=opts.init if opts.method == "fit" else "-",
        clips=clip_names,
        windows=int(x.shape[0]),
        loss_start=start,
        loss=loss,
        text=g_fit,
        text_weights=weights,
    )


def reconstruct(
    motion: Motion, checkpoint: str | Path | None = None, variant: str = "habit"
) -> Motion:
    """Encode and decode a motion on its own species (codes: nearest; z_c: posterior mean
    of its species' habit encoder, or of the retrieved neighbour's for a held-out one).

    The reconstruction error of this function is the figure recorded in a checkpoint.
    """
    ck = load_model(checkpoint, variant)
    out, info = _run_network(
        ck, motion, motion.species, seed=None, temperature=1.0, reconstruct=True
    )
    info = {
        "method": f"reconstruct:{ck.config.model.variant}",
        "from": motion.species,
        "to": motion.species,
        **info,
    }
    out = _resample(out, motion.fps)
    return Motion(
        out.species, out.fps, out.root_positions, out.rotations, out.contacts, {"transfer": info}
    )
