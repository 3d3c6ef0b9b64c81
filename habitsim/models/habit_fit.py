"""A habit latent z_c found from reference clips of a species (issue 49).

:func:`habit_from_clips` turns one or several clips of one species (K-shot) into a
:class:`HabitLatent`, in one of two ways (:attr:`HabitFitOptions.method`):

* ``encoder``: the mean of the habit posterior's means μ_φ(m) over every window of the
  clips. The posterior encoders are per species; the one used is the clips' species' own
  when the checkpoint was trained on it, else the retrieval neighbour's (the same rule as
  :func:`habitsim.models.transfer.habit_species_for`). Any encoder takes any motion's
  windows: the features are the same for every species.
* ``fit`` (test-time fitting): z is optimised by Adam, the network frozen, to minimise
  the reconstruction error of every window of the clips through encode → quantize →
  decode with that z (the codes do not depend on z, so they are found once). It starts
  from the encoder mean (``init="encoder"``) or from the centre F(0) of the habit
  species' flow prior (``init="prior"``: the image of the base Gaussian's mean), and
  keeps the z of the lowest error seen. No random draw: same clips and options ⇒ same z
  (on one CPU thread, :func:`habitsim.threads.one_thread`).

The latent then drives a transfer: ``transfer(motion, to, habit_from=[clip, ...])``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from ..errors import HabitReferenceError
from ..motion import Motion
from ..species import load_species
from ..threads import one_thread
from .checkpoint import LoadedCheckpoint
from .features import canonical_window, clip_arrays

__all__ = ["HabitFitOptions", "HabitLatent", "habit_from_clips", "fit_latent"]

_METHODS = ("encoder", "fit")
_INITS = ("encoder", "prior")


@dataclass(frozen=True)
class HabitFitOptions:
    """How :func:`habit_from_clips` finds the habit latent.

    Attributes:
        method: ``fit`` (test-time fitting through the frozen decoder) or ``encoder``
            (the habit posterior's mean over the clips' windows).
        init: where fitting starts: ``encoder`` (the posterior mean) or ``prior`` (the
            centre F(0) of the habit species' flow prior).
        steps: Adam steps of the fit (≥ 0).
        lr: Adam's learning rate (> 0) [latent units per step].
        habit_species: the training species whose posterior encoder and prior serve
            (None: the clips' species if the checkpoint knows it, else its retrieval
            neighbour). Setting it treats a training species as if it were unseen.
    """

    method: str = "fit"
    init: str = "encoder"
    steps: int = 200
    lr: float = 0.05
    habit_species: str | None = None

    def validate(self) -> None:
        """Raises:
        HabitReferenceError: (code ``options``) a field out of range, naming the valid ones.
        """
        if self.method not in _METHODS:
            raise HabitReferenceError(
                "options", f"habit method {self.method!r}; valid: {', '.join(_METHODS)}"
            )
        if self.init not in _INITS:
            raise HabitReferenceError(
                "options", f"habit fit init {self.init!r}; valid: {', '.join(_INITS)}"
            )
        if self.steps < 0 or not np.isfinite(self.lr) or self.lr <= 0:
            raise HabitReferenceError(
                "options",
                f"habit fit steps={self.steps}, lr={self.lr}: steps must be ≥ 0 and lr > 0",
            )


@dataclass(frozen=True)
class HabitLatent:
    """A habit latent found from reference clips, and how.

    Attributes:
        z: the latent z_c, shape (z_dim,).
        species: the clips' species (the skeleton the latent describes).
        habit_species: the training species whose encoder / prior served.
        method: ``encoder`` or ``fit``.
        init: where the fit started (``encoder`` / ``prior``; ``-`` for ``encoder``).
        clips: names of the reference clips (K = their number).
        windows: model windows of all the clips.
        loss_start: reconstruction error of the clips' windows with the start latent
            (mean squared error in training-σ units).
        loss: the same with :attr:`z`.
    """

    z: np.ndarray
    species: str
    habit_species: str
    method: str
    init: str
    clips: tuple[str, ...]
    windows: int
    loss_start: float
    loss: float

    def to_metadata(self) -> dict[str, Any]:
        """The JSON entry a transfer writes as ``metadata["transfer"]["habit_from"]``."""
        return {
            "clips": list(self.clips),
            "k": len(self.clips),
            "method": self.method,
            "init": self.init,
            "habit_species": self.habit_species,
            "windows": self.windows,
            "fit_loss_start": round(self.loss_start, 6),
            "fit_loss": round(self.loss, 6),
        }


def _windows(ck: LoadedCheckpoint, motions: Sequence[Motion]) -> torch.Tensor:
    """Every model window (B, T, F) of every clip, each in its own heading frame."""
    from .transfer import _resample, _window_starts

    window = ck.config.model.window
    out = []
    for m in motions:
        arrays = clip_arrays(_resample(m, ck.fps))
        out += [
            canonical_window(arrays, s, window)[0]
            for s in _window_starts(arrays.num_frames, window)
        ]
    return torch.from_numpy(np.stack(out))


def _recon_loss(
    ck: LoadedCheckpoint,
    x: torch.Tensor,
    codes: torch.Tensor,
    path: torch.Tensor | None,
    species: str,
    z: torch.Tensor,
) -> torch.Tensor:
    """Mean squared reconstruction error [σ²] of windows x (B, T, F) decoded from their
    codes with the one latent z (z_dim,)."""
    from .transfer import _text_rows

    model = ck.model
    b = x.shape[0]
    text = _text_rows(ck, species, b) if model.cfg.use_g else None
    cond = model.condition([species] * b, z[None].expand(b, -1), text)
    y = model.decode(codes, cond, path)
    return (((y - x) / model.feat_std) ** 2).mean()


def fit_latent(
    ck: LoadedCheckpoint,
    motions: Sequence[Motion],
    habit_species: str,
    options: HabitFitOptions,
) -> tuple[np.ndarray, float, float, int]:
    """The latent of ``motions`` with a loaded checkpoint (what :func:`habit_from_clips`
    computes): (z (z_dim,), start loss, loss, windows)."""
    model = ck.model
    species = motions[0].species
    x = _windows(ck, motions)
    with one_thread():
        with torch.no_grad():
            codes = model.quantize(model.encode(x), sample=False, update=False).quantized
            path = model.path(x)
            if options.method == "encoder" or options.init == "encoder":
                z0 = model.posterior(x, [habit_species] * x.shape[0])[0].mean(0)
            else:
                prior = model.priors[habit_species]
                z0 = prior(torch.zeros(1, model.cfg.habit.z_dim))[0][0]
            start = float(_recon_loss(ck, x, codes, path, species, z0))
        best, best_loss = z0.clone(), start
        if options.method == "fit":
            z = z0.clone().requires_grad_(True)
            opt = torch.optim.Adam([z], lr=options.lr)
            for _ in range(options.steps):
                loss = _recon_loss(ck, x, codes, path, species, z)
                if float(loss.detach()) < best_loss:
                    best, best_loss = z.detach().clone(), float(loss.detach())
                (grad,) = torch.autograd.grad(loss, z)  # the network's own grads untouched
                z.grad = grad
                opt.step()
            with torch.no_grad():
                last = float(_recon_loss(ck, x, codes, path, species, z))
            if last < best_loss:
                best, best_loss = z.detach().clone(), last
    return best.numpy().astype(np.float32), start, best_loss, int(x.shape[0])


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
        options: how (None: :class:`HabitFitOptions` defaults: fitted from the encoder
            mean).
        names: a name per clip for the record (None: ``clip 1`` …).

    Returns:
        The :class:`HabitLatent` (z and how it was found).

    Raises:
        HabitReferenceError: no clip (``empty``), clips of several species (``species``),
            options out of range (``options``), or a model without a habit latent
            (``method``).
        UnknownSpeciesError: ``options.habit_species`` is no training species.
    """
    from .transfer import habit_species_for, load_model

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
    z, start, loss, windows = fit_latent(ck, list(motions), hs, opts)
    return HabitLatent(
        z=z,
        species=species,
        habit_species=hs,
        method=opts.method,
        init=opts.init if opts.method == "fit" else "-",
        clips=clip_names,
        windows=windows,
        loss_start=start,
        loss=loss,
    )
