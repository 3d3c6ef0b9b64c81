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

from dataclasses import dataclass, field
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
            training (0: reconstruction only; 1 by the figures of docs/species.md).
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
    prior_weight: float = 1.0
    objective: str = "frames"
    fit_text: bool = False
    text_start_share: float = 0.9

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
        if not 0.0 < self.text_start_share < 1.0:
            raise HabitReferenceError(
                "options", f"text_start_share={self.text_start_share}: must be in (0, 1)"
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
        text: the fitted raw text embedding g_c (text_dim,) the decoder takes instead
            of the species' own (None: its own; ``fit_text``).
        text_weights: the mix of that embedding (species → weight; {} without).
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
    text: np.ndarray | None = None
    text_weights: dict[str, float] = field(default_factory=dict)

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
            **(
                {"text_weights": {k: round(v, 4) for k, v in self.text_weights.items()}}
                if self.text_weights
                else {}
            ),
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


def _text_candidates(
    ck: LoadedCheckpoint, species: str, text: torch.Tensor | None
) -> tuple[list[str], torch.Tensor]:
    """The species and its raw text embedding first, then every other training species'
    (names, (S, text_dim))."""
    model = ck.model
    own = text[0] if text is not None else model.text_embedding([species])[0]
    others = [s for s in model.species if s != species]
    return [species, *others], torch.cat([own[None], model.text_embedding(others)])


def fit_latent(
    ck: LoadedCheckpoint,
    x: torch.Tensor,
    species: str,
    habit_species: str,
    options: HabitFitOptions,
    text: torch.Tensor | None = None,
) -> tuple[np.ndarray, float, float, np.ndarray | None, dict[str, float]]:
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
        (z (z_dim,), reconstruction error with the start latent, with z [σ²], the fitted
        raw text embedding (None without ``fit_text``), its mix weights).
    """
    model = ck.model
    mix = options.fit_text and options.method == "fit" and model.cfg.use_g
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
            names, table = _text_candidates(ck, species, text) if mix else ([], torch.zeros(0))
            w0 = torch.zeros(len(names))
            if mix:  # the own embedding's share text_start_share, the others' equal
                share = options.text_start_share
                w0[0] = float(np.log(share * (len(names) - 1) / (1.0 - share)))
        best, best_loss, best_w = z0.clone(), start, w0.clone()
        if options.method == "fit":
            z = z0.clone().requires_grad_(True)
            w = w0.clone().requires_grad_(mix)
            params = [z, w] if mix else [z]
            opt = torch.optim.Adam(params, lr=options.lr)
            best_obj = float("inf")
            b = x.shape[0]
            for step in range(options.steps + 1):
                g = (w.softmax(0) @ table)[None].expand(b, -1) if mix else text
                recon = _recon_loss(ck, x, codes, path, species, z, g, options.objective)
                obj = recon
                if options.prior_weight > 0:
                    nll = -model.prior_log_prob(z[None], [habit_species])[0] / z.shape[0]
                    obj = recon + options.prior_weight * nll
                if float(obj.detach()) < best_obj:  # keep the best z seen, the start's too
                    best, best_loss = z.detach().clone(), float(recon.detach())
                    best_w = w.detach().clone()
                    best_obj = float(obj.detach())
                if step == options.steps:
                    break
                grads = torch.autograd.grad(obj, params)  # the network's own grads untouched
                for p, gr in zip(params, grads, strict=True):
                    p.grad = gr
                opt.step()
    if not mix:
        return best.numpy().astype(np.float32), start, best_loss, None, {}
    weights = best_w.softmax(0)
    g_fit = (weights @ table).numpy().astype(np.float32)
    return (
        best.numpy().astype(np.float32),
        start,
        best_loss,
        g_fit,
        {n: float(v) for n, v in zip(names, weights.tolist(), strict=True)},
    )
