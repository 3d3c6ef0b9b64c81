"""A habit latent z_c found from reference clips of a species (issue 49).

:func:`habitsim.models.transfer.habit_from_clips` turns one or several clips of one
species (K-shot) into a :class:`HabitLatent`, in one of two ways (:attr:`HabitFitOptions.method`):

* ``encoder``: the mean of the habit posterior's means μ_φ(m) over every window of the
  clips. The posterior encoders are per species; the one used is the clips' species' own
  when the checkpoint was trained on it, else the retrieval neighbour's (the same rule as
  :func:`habitsim.models.transfer.habit_species_for`). Any encoder takes any motion's
  windows: the features are the same for every species.
* ``fit`` (test-time fitting): z is optimised by Adam, the network frozen, to minimise
  the reconstruction error of every window of the clips through encode → quantize →
  decode with that z (the codes do not depend on z, so they are found once). It starts
  from the centre F(0) of the habit species' flow prior (``init="prior"``: the image of
  the base Gaussian's mean) or from the encoder mean (``init="encoder"``), and keeps the
  z of the lowest objective seen (the error, plus ``prior_weight`` times the prior's
  negative log-likelihood per dimension). No random draw: same clips and options ⇒ same z
  (on one CPU thread, :func:`habitsim.threads.one_thread`).

The latent then drives a transfer: ``transfer(motion, to, habit_from=[clip, ...])``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from ..errors import HabitReferenceError
from ..threads import one_thread
from .checkpoint import LoadedCheckpoint

__all__ = ["HabitFitOptions", "HabitLatent", "fit_latent"]

_METHODS = ("encoder", "fit")
_INITS = ("encoder", "prior")
_OBJECTIVES = ("frames", "stats")


@dataclass(frozen=True)
class HabitFitOptions:
    """How :func:`~habitsim.models.transfer.habit_from_clips` finds the habit latent.

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
        prior_weight: weight (≥ 0) of −log p_c(z) / z_dim, the habit species' flow
            prior, added to the fit's error: it keeps z among the habits seen in
            training (0: reconstruction only; 0.1 by the figures of docs/transfer.md).
        objective: what the fit's error compares: ``frames`` (every feature of every
            frame of the decoded windows against the clips') or ``stats`` (each
            feature's mean and standard deviation over all the clips' frames: the
            habit's statistics, not the clip's particular frames).
    """

    method: str = "fit"
    init: str = "prior"
    steps: int = 200
    lr: float = 0.05
    habit_species: str | None = None
    prior_weight: float = 0.1
    objective: str = "frames"

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
        if self.objective not in _OBJECTIVES:
            raise HabitReferenceError(
                "options",
                f"habit fit objective {self.objective!r}; valid: {', '.join(_OBJECTIVES)}",
            )
        if not np.isfinite(self.prior_weight) or self.prior_weight < 0:
            raise HabitReferenceError(
                "options", f"habit fit prior_weight={self.prior_weight}: must be ≥ 0"
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


def _recon_loss(
    ck: LoadedCheckpoint,
    x: torch.Tensor,
    codes: torch.Tensor,
    path: torch.Tensor | None,
    species: str,
    z: torch.Tensor,
    text: torch.Tensor | None,
    objective: str = "frames",
) -> torch.Tensor:
    """Mean squared error [σ²] of windows x (B, T, F) decoded from their codes with the
    one latent z (z_dim,): frame by frame (``frames``), or of each feature's mean and
    standard deviation over every frame (``stats``); ``text``: the species' raw text
    embeddings (B, text_dim) when the model does not store them (else None)."""
    model = ck.model
    b = x.shape[0]
    cond = model.condition([species] * b, z[None].expand(b, -1), text)
    y = model.decode(codes, cond, path)
    if objective == "stats":
        ys = (y / model.feat_std).flatten(0, 1)
        xs = (x / model.feat_std).flatten(0, 1)
        return ((ys.mean(0) - xs.mean(0)) ** 2).mean() + ((ys.std(0) - xs.std(0)) ** 2).mean()
    return (((y - x) / model.feat_std) ** 2).mean()


def fit_latent(
    ck: LoadedCheckpoint,
    x: torch.Tensor,
    species: str,
    habit_species: str,
    options: HabitFitOptions,
    text: torch.Tensor | None = None,
) -> tuple[np.ndarray, float, float]:
    """The habit latent of raw windows of one species (what
    :func:`habitsim.models.transfer.habit_from_clips` computes).

    Args:
        ck: the loaded checkpoint (a variant with z_c).
        x: every window of the reference clips (B, T, F), each in its heading frame.
        species: the clips' species (its text embedding conditions the decoder).
        habit_species: the training species whose posterior encoder / prior serve.
        options: how.
        text: ``species``' raw text embeddings (B, text_dim) when the checkpoint does not
            store them (None: it does, or the variant uses no text).

    Returns:
        (z (z_dim,), reconstruction error with the start latent, with z) [σ²].
    """
    model = ck.model
    with one_thread():
        with torch.no_grad():
            codes = model.quantize(model.encode(x), sample=False, update=False).quantized
            path = model.path(x)
            if options.method == "encoder" or options.init == "encoder":
                z0 = model.posterior(x, [habit_species] * x.shape[0])[0].mean(0)
            else:
                prior = model.priors[habit_species]
                z0 = prior(torch.zeros(1, model.cfg.habit.z_dim))[0][0]
            start = float(_recon_loss(ck, x, codes, path, species, z0, text, options.objective))
        best, best_loss = z0.clone(), start
        if options.method == "fit":
            z = z0.clone().requires_grad_(True)
            opt = torch.optim.Adam([z], lr=options.lr)
            best_obj = float("inf")
            for step in range(options.steps + 1):
                recon = _recon_loss(ck, x, codes, path, species, z, text, options.objective)
                obj = recon
                if options.prior_weight > 0:
                    nll = -model.prior_log_prob(z[None], [habit_species])[0] / z.shape[0]
                    obj = recon + options.prior_weight * nll
                if float(obj.detach()) < best_obj:  # keep the best z seen, the start's too
                    best, best_loss = z.detach().clone(), float(recon.detach())
                    best_obj = float(obj.detach())
                if step == options.steps:
                    break
                (grad,) = torch.autograd.grad(obj, z)  # the network's own grads untouched
                z.grad = grad
                opt.step()
    return best.numpy().astype(np.float32), start, best_loss
