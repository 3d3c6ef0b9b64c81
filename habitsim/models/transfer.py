"""Motion transfer to another species: the API, the method registry and the model cache.

``transfer(motion, to="cat", method="habit")`` re-expresses a motion on the target
species' skeleton. Registered methods (:data:`METHODS`, extendable with
:func:`register_method`):

==============  ================================================================
``habit``       VQ-VAE, EMA + code reset, decoder gets z_c (target's flow prior) and g_c
``habit_ema``   the same trained with an EMA codebook but no code reset
``no_habit``    VQ-VAE whose decoder gets neither z_c nor g_c (reconstruction model)
``habit_only``  decoder gets z_c only
``text_only``   decoder gets g_c only
``direct``      no network: copy the local rotations, scale the root by the hip-height ratio
==============  ================================================================

A network method needs a checkpoint of its variant: the ``checkpoint=`` argument, else
``$HABITSIM_MODELS_DIR/<variant>``, else the one shipped in
``habitsim/models/checkpoints/<variant>`` (only ``habit`` is shipped).

Long motions are cut into windows of the model's length overlapping by a quarter; each
window is encoded in its own heading frame, decoded with the target's condition, turned
back, and the windows are cross-faded. One z_c is drawn per call (``seed``) and used for
every window so that the habit stays the same along the clip. A motion at another frame
rate is resampled to the model's and back.

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
from collections.abc import Callable
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import torch

from ..errors import HabitsimError, InvalidMotionError
from ..motion import Motion, resample_motion
from ..species import FEET, load_species
from .checkpoint import CONFIG_FILE, LoadedCheckpoint, load_checkpoint
from .config import VARIANTS
from .errors import MethodNotAvailableError, TextEncoderError, UnknownMethodError
from .features import (
    NUM_JOINTS,
    Q_DIM,
    canonical_window,
    clip_arrays,
    decoded_contacts,
    features_to_motion,
    uncanonicalize,
)
from .text import Retrieval, retrieve_neighbour

if TYPE_CHECKING:
    from ..planting import PlantReport

__all__ = [
    "TransferMethod",
    "METHODS",
    "available_methods",
    "register_method",
    "transfer",
    "reconstruct",
    "direct_transfer",
    "transfer_contacts",
    "walking_stance",
    "WALK_MIN_DUTY",
    "WALK_MIN_FEET",
    "resolve_checkpoint",
    "load_model",
    "shipped_checkpoint",
    "habit_species_for",
]

_LOG = logging.getLogger("habitsim.models")

#: Environment variable naming a folder of ``<variant>/`` checkpoint folders.
MODELS_DIR_ENV = "HABITSIM_MODELS_DIR"


@dataclass(frozen=True)
class TransferMethod:
    """A registered transfer method.

    Attributes:
        name: registry key (``method=`` of :func:`transfer`).
        description: one line for listings.
        variant: model variant whose checkpoint it needs (None: no network).
        fn: ``fn(motion, to, *, seed, checkpoint, temperature) -> Motion``.
    """

    name: str
    description: str
    variant: str | None
    fn: Callable[..., Motion]


METHODS: dict[str, TransferMethod] = {}


def register_method(
    name: str,
    fn: Callable[..., Motion],
    *,
    description: str,
    variant: str | None = None,
    overwrite: bool = False,
) -> TransferMethod:
    """Add a transfer method to :data:`METHODS` (plug-in point for evaluation).

    :func:`transfer` calls ``fn(motion, to, seed=…, checkpoint=…, temperature=…,
    plant=…)``; a method takes ``**kwargs`` for the options it has no use for.

    Raises:
        ValueError: the name is taken (unless ``overwrite``).
    """
    if name in METHODS and not overwrite:
        raise ValueError(f"transfer method {name!r} is already registered")
    m = TransferMethod(name, description, variant, fn)
    METHODS[name] = m
    return m


def available_methods() -> list[str]:
    """Names of the registered methods (registration order)."""
    return list(METHODS)


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


def _embeddings(ck: LoadedCheckpoint, names: list[str]) -> dict[str, np.ndarray]:
    table = ck.model.text_table.detach().numpy()
    out = {n: table[i] for i, n in enumerate(ck.model.text_names)}
    missing = [n for n in names if n not in out]
    if missing:
        from .text import species_embeddings

        try:
            out.update(species_embeddings(missing, ck.config.model.text.model))
        except TextEncoderError as e:
            raise TextEncoderError(
                f"the checkpoint has no text embedding of {', '.join(missing)} and {e}"
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


@torch.no_grad()
def _run_network(
    ck: LoadedCheckpoint,
    motion: Motion,
    to: str,
    *,
    seed: int | None,
    temperature: float,
    reconstruct: bool = False,
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
    if model.cfg.use_z:
        habit_sp, retrieval = habit_species_for(ck, to)
        if reconstruct:
            z = model.posterior(x, [habit_sp] * k)[0]
        else:
            z = _prior_draw(ck, habit_sp, seed, temperature).expand(k, -1)
    cond = model.condition([to] * k, z, _text_rows(ck, to, k) if model.cfg.use_g else None)
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
    return out, info


def _gait_duty(target: str, source: Motion) -> tuple[str, float] | None:
    """(gait, duty factor) the target species uses for the source's action: the middle of
    the target's duty-factor range for that gait (the source species' range when the
    target lacks the gait, e.g. a trot sent to a camel); None for non-cyclic actions or
    a source without a known action."""
    from ..gaits import action_gait
    from ..gaits.actions import ACTIONS

    action = source.metadata.get("action")
    if action not in ACTIONS:
        return None
    for sp in (target, source.species):
        try:
            gait = action_gait(sp, str(action))
        except HabitsimError:
            continue
        habit = load_species(sp).gaits.get(gait)
        if habit is not None:
            return gait, float(np.mean(habit.duty_factor))
    return None


#: A decoded foot whose stance labels match the source's footfall schedule with an F1
#: below this takes the source's schedule instead (the action's footfalls survive).
#: The F1 alone lets a foot that is labelled in stance almost all the time through
#: (stance share 0.9 against the source's 0.4 still scores 0.6), hence also
#: :data:`MAX_DUTY_GAP`. Measured with the feature version 3 model: median decoded F1
#: 0.83 on synthetic test transfers, 0.70 on transfers of real dog clips.
MIN_SOURCE_AGREEMENT = 0.8

#: ... and a decoded foot whose stance share differs from the source's by more than this
#: takes the source's schedule too. On a real trot sent to the tiger the decoded feet
#: stood 82–91 % of the time against the source's 38–42 %; planted, that clip fell after
#: 0.3 s, with the source's schedule it was tracked to the end.
MAX_DUTY_GAP = 0.1


def transfer_contacts(
    out: Motion, source: Motion, decoded: np.ndarray | None = None
) -> tuple[np.ndarray, dict[str, Any]]:
    """Foot-contact labels of a transferred motion, and how they were found.

    In this order:

    1. ``decoded``: the network's own contact outputs (feature version 3), cleaned of
       runs shorter than 2 frames (:func:`habitsim.contacts.drop_short_runs`). When the
       source carries stance labels they are checked against its footfall schedule
       (carried over in normalised time, :func:`habitsim.contacts.warp_contacts`): the
       per-foot F1 and stance shares go into the report, and a foot that agrees less
       than :data:`MIN_SOURCE_AGREEMENT` or whose stance share is more than
       :data:`MAX_DUTY_GAP` from the source's takes the source's schedule.
    2. ``source``: no decoded contacts (``direct``), and the source carries stance labels
       (a synthetic clip's planned stance, an import's labels found on the source
       skeleton): the transferred motion keeps the source's footfall schedule.
    3. ``detected``: neither: contacts detected on the output's resting feet
       (:func:`habitsim.contacts.detect_contacts`).
    4. ``duty``: a gait whose stance feet still slide may hold no resting frame at all,
       and a refinement given no stance plants no foot; so a foot whose detected stance
       share is under half its gait's duty factor is labelled by
       :func:`habitsim.contacts.contacts_by_duty` instead (the target's duty factor for
       the source's gait) — the last resort, reported.

    Returns:
        ``(labels, info)``: (T, 4) bool labels of ``out`` and ``info["method"]`` (one of
        ``decoded``, ``source``, ``detected``, ``duty``) with the details of that method.
    """
    from ..contacts import contacts_by_duty, contacts_from_feet, drop_short_runs, warp_contacts
    from ..planting import contact_f1

    src = None
    if source.contacts is not None:
        src = drop_short_runs(warp_contacts(np.asarray(source.contacts, bool), out.num_frames), 2)
    if decoded is not None:
        labels = drop_short_runs(np.asarray(decoded, dtype=bool), 2)
        info: dict[str, Any] = {"method": "decoded"}
        if src is not None:
            f1 = contact_f1(labels, src)
            duty, duty_src = labels.mean(axis=0), src.mean(axis=0)
            info["source_f1"] = [round(float(v), 3) for v in f1]
            info["duty"] = [round(float(v), 3) for v in duty]
            info["source_duty"] = [round(float(v), 3) for v in duty_src]
            low = (f1 < MIN_SOURCE_AGREEMENT) | (np.abs(duty - duty_src) > MAX_DUTY_GAP)
            if low.any():
                labels[:, low] = src[:, low]
                info["feet_from_source"] = [n for n, lo in zip(FEET, low, strict=True) if lo]
            return labels, info
    elif src is not None:
        info = {
            "method": "source",
            "source_frames": int(np.asarray(source.contacts).shape[0]),
            "time_warped": bool(np.asarray(source.contacts).shape[0] != out.num_frames),
        }
        return src, info
    feet = out.foot_positions()  # one forward-kinematics pass for both labellings
    leg = out.species_info.leg_length
    detected = labels if decoded is not None else contacts_from_feet(feet, out.fps, leg)
    why = "the source has no stance labels"
    info = {"method": "decoded" if decoded is not None else "detected", "reason": why}
    gd = _gait_duty(out.species, source)
    if gd is None or out.num_frames < 5:
        return detected, info
    gait, duty = gd
    low = detected.mean(axis=0) < 0.5 * duty
    if not low.any():
        return detected, info
    by_duty = contacts_by_duty(feet, out.fps, leg, duty)
    labels = np.where(low[None, :], by_duty, detected)
    info = {
        "method": "duty",
        "reason": why,
        "gait": gait,
        "duty_factor": round(duty, 3),
        "feet_by_duty": [n for n, lo in zip(FEET, low, strict=True) if lo],
    }
    return labels, info


#: A gait whose duty factor is below one half has an aerial phase (docs/biomechanics.md, footfall
#: table); a target species that walks at the transfer's speed has none, so a transfer
#: below the top of the target's walking Froude band has every foot in stance at least
#: this share of the clip (:func:`walking_stance`). Measured with ``habitsim bench real``:
#: a real Labrador's fast lateral-sequence walk (duty factor 0.31–0.50, Froude 0.28–0.54)
#: sent to the cat kept its single-foot frames, which need a residual root force of
#: 0.28 m·g against 0.09 with two feet down (README, "Real motion").
WALK_MIN_DUTY = 0.5
#: ... and at least this many feet down on every frame (:func:`habitsim.contacts.
#: fill_support`; 0 switches it off): a duty factor of one half with the uneven footfall
#: spacing of a real walk, or a clip that speeds up at its end, still left single-foot
#: supports (a cat transfer of a Labrador walk that speeds up stood on one foot for the
#: last 0.3 s and fell there). With it the habit references of ``habitsim bench real``
#: need a median residual root force of 0.078 m·g instead of 0.108 (the cat's three
#: walking windows 0.07–0.08 instead of 0.10–0.12).
WALK_MIN_FEET = 2


def walking_stance(
    out: Motion, contacts: np.ndarray, source: Motion
) -> tuple[np.ndarray, dict[str, Any] | None]:
    """The stance labels of a transfer to a species that walks at the transfer's speed.

    When the transferred motion moves at a Froude number within the target's walking
    band (at most the top of ``gaits.walk.froude`` in its species file), every foot
    standing less than :data:`WALK_MIN_DUTY` of the clip has its stance runs lengthened
    at both ends (:func:`habitsim.contacts.lengthen_stance`), then every frame with
    fewer than :data:`WALK_MIN_FEET` feet down takes the stance run nearest in time
    (:func:`habitsim.contacts.fill_support`): the source's footfall phases stay, the
    aerial phases and single-foot supports of a faster source go. Kept
    as they are: labels of a gait that is not cyclic (a foot with fewer than two
    touchdowns: a jump, a stand), of a source whose action the target performs in
    another gait than its walk, and of a target species without a walk.

    Returns:
        ``(labels, info)``: the labels (the input when nothing changed) and None, or the
        lengthened labels with what was done (``froude``, ``walk_froude_max``,
        ``duty_before``, ``duty_after``).
    """
    from ..contacts import fill_support, lengthen_stance, touchdown_frames
    from ..gait_stats import gait_statistics
    from ..gaits import action_gait
    from ..gaits.actions import ACTIONS

    walk = load_species(out.species).gaits.get("walk")
    c = np.asarray(contacts, dtype=bool)
    if walk is None or c.ndim != 2:
        return c, None
    duty = c.mean(axis=0)
    if duty.min() >= WALK_MIN_DUTY:
        return c, None
    action = source.metadata.get("action")
    if action in ACTIONS:
        try:
            if action_gait(out.species, str(action)) != "walk":
                return c, None
        except HabitsimError:  # an action the target lacks
            return c, None
    if any(td.size < 2 for td in touchdown_frames(c)):
        return c, None
    froude = gait_statistics(out, c).froude
    if not froude <= walk.froude[1]:
        return c, None
    longer = lengthen_stance(c, WALK_MIN_DUTY)
    if WALK_MIN_FEET:
        longer = fill_support(longer, WALK_MIN_FEET)
    return longer, {
        "froude": round(float(froude), 3),
        "walk_froude_max": float(walk.froude[1]),
        "duty_before": [round(float(v), 3) for v in duty],
        "duty_after": [round(float(v), 3) for v in longer.mean(axis=0)],
    }


#: Planting is kept only when every planted toe reaches its target within this share of
#: leg length ...
PLANT_MAX_REACH_PER_LEG = 0.05
#: ... every swing toe between two stance runs comes within this share of its path (a
#: swing that cannot follow the straight line between footholds is a leg that cannot
#: step there: on real dog trots sent to the tiger and cat, plantings that missed their
#: swings by 0.13–0.36 leg lengths fell after 1.2 s where the carried root survived) ...
PLANT_MAX_SWING_REACH_PER_LEG = 0.1
#: ... and the pelvis is lowered by at most this share of leg length to reach them.
#: Beyond, a stance run sweeps further than the leg reaches: the decoded feet slide in
#: stance, so a foothold held for the whole run lies behind the hip at its end (and a
#: large source's stride sent to a small target keeps its cadence at the target's
#: Froude speed, so the small animal's strides are longer in leg lengths).
PLANT_MAX_DROP_PER_LEG = 0.1
#: When the legs do not reach, the body is moved only as far as its stance legs carry it
#: (:func:`habitsim.planting.stance_driven_root`) and planted again, provided it keeps
#: at least this share of its decoded speed; below, the action itself would change (a
#: trot slowed to a shuffle) and the decoded feet are kept. Measured on the default
#: evaluation (33 synthetic pairs, ``habitsim eval``): carrying down to 40 % of the speed
#: raised habit survival from 0.710 to 0.774 but dropped action accuracy from 0.636 to
#: 0.545 and multiplied the paired MPJPE by 5 (the synthetic transfers' legs carry a
#: median 36 % of the decoded travel); the transfers of real dog clips whose planting
#: missed kept 77-119 % of their speed (one 47 %). 0.6 against 0.7 on the default
#: evaluation's sources to cat, horse, camel and bear (44 habit pairs): survival 0.896
#: against 0.873, but paired MPJPE 1070 against 336 mm, action accuracy 0.727 against
#: 0.750 and sim MPJPE 118 against 89 mm.
PLANT_MIN_SPEED_RATIO = 0.7
#: How each root path is planted, in order: each stance run's foothold at the median of
#: its decoded toe path, then half-way along the shoulder's / hip's travel over the run
#: (:func:`habitsim.planting.plant_motion` with ``centre``: a sliding toe's median can
#: lie so far ahead of or behind the joint that the leg misses it at one end). The first
#: that reaches is kept; a rule whose footholds lie beyond the stretched legs even with
#: the pelvis lowered to the limit is not solved at all
#: (:func:`habitsim.planting.stance_reach_shortfall`). Measured with ``habitsim bench
#: model --real`` (median rule alone → both rules): stance toes at rest on 58.7 → 68.5 %
#: of the synthetic transfers' stance frames with the shipped model (42.9 → 60.3 % with
#: a ``large`` one), the real ones unchanged (62.4 %, 50.9 %); evaluator action accuracy
#: 0.704 → 0.726 (0.830 → 0.868); latency of a 64-frame transfer whose planting misses
#: 13.5 → 8.2 ms (the unsolvable rules are not solved).
FOOTHOLD_RULES: tuple[bool, ...] = (False, True)


def _summary(
    report: PlantReport, contacts: np.ndarray, leg: float, free: np.ndarray | None = None
) -> dict[str, Any]:
    """A planting report for the metadata: :meth:`PlantReport.to_dict` with the largest
    reach error over the held stance frames (not the ``free`` runs), over the swings
    between two stance runs, and apart over each foot's swing before its first or after
    its last stance run (with no foothold to head for at the clip's end, the IK may leave
    a toe behind there; that does not decide whether a planting is kept)."""
    d = report.to_dict(leg)
    c = np.asarray(contacts, dtype=bool)
    idx = np.arange(c.shape[0])[:, None]
    first = np.where(c.any(axis=0), c.argmax(axis=0), c.shape[0])
    last = np.where(c.any(axis=0), c.shape[0] - 1 - c[::-1].argmax(axis=0), -1)
    edge = ~c & ((idx < first[None, :]) | (idx > last[None, :]))
    held = c if free is None else c & ~np.asarray(free, dtype=bool)
    err = report.reach_error

    def worst(mask: np.ndarray) -> float:
        return round(float(np.where(mask, err, 0.0).max()) / leg, 5)

    d["max_reach_error_per_leg"] = worst(held)
    d["max_swing_reach_error_per_leg"] = worst(~c & ~edge)
    d["max_edge_reach_error_per_leg"] = worst(edge)
    return d


def _reaches(report: dict[str, Any]) -> bool:
    return (
        report["max_reach_error_per_leg"] <= PLANT_MAX_REACH_PER_LEG
        and report.get("max_swing_reach_error_per_leg", 0.0) <= PLANT_MAX_SWING_REACH_PER_LEG
        and report["max_pelvis_drop_per_leg"] <= PLANT_MAX_DROP_PER_LEG
    )


#: Lift every planted swing to the species' habitual swing height (:func:`_swing_lift`).
#: The decoder's swing toes stay near the ground (its feet rest in stance, but a swing
#: shuffles forward just above it), so a planting without a lift left swing feet moving
#: below docs/metrics.md's contact height. Measured with the lift: ``habitsim bench
#: model`` (182 synthetic transfers) action accuracy 0.714 → 0.802 (the frozen evaluator
#: reads a shuffling walk as another action), stance toes at rest unchanged (95.7 %);
#: ``habitsim bench real`` habit transfers' skate before refinement 42.5 → 0.0 mm/frame
#: (median).
SWING_LIFT = True


def _swing_lift(out: Motion, labels: np.ndarray) -> np.ndarray | None:
    """The lowest toe height [m] of each swing frame of a planting (T, 4; NaN in stance):
    a half-sine over the swing run peaking at the species' habitual swing height
    (``habits.swing_height`` of its species file, share of leg length), so a decoded
    foot that shuffles along the ground in swing is lifted; a toe already higher keeps
    its height. None when :data:`SWING_LIFT` is off."""
    from ..contacts import contact_segments

    if not SWING_LIFT:
        return None
    lift = np.full(labels.shape, np.nan)
    height = out.species_info.habits.swing_height * out.species_info.leg_length
    for f, runs in enumerate(contact_segments(~np.asarray(labels, dtype=bool))):
        for a, b in runs:
            lift[a:b, f] = height * np.sin(np.pi * (np.arange(b - a) + 0.5) / (b - a))
    return lift


def _plant(
    out: Motion, contacts: np.ndarray, glob: np.ndarray | None = None
) -> tuple[Motion, dict[str, Any]]:
    """Plant ``out``'s feet on ``contacts``; fall back to the legs' own travel (module
    constants above). Returns the motion to keep and the report of what was done
    (``glob``: ``out``'s global joint positions, if already at hand)."""
    from ..planting import plant_motion, stance_driven_root, stance_reach_shortfall

    leg = out.species_info.leg_length

    def attempt(motion: Motion, glob: np.ndarray) -> tuple[Motion, dict[str, Any], dict[str, Any]]:
        """(planted motion, its report, the first rule's report): the first foothold
        rule whose legs reach, else the last rule's result (``glob``: the motion's
        global joint positions)."""
        first: dict[str, Any] | None = None
        moved = motion
        for centre in FOOTHOLD_RULES:
            rule = "centred" if centre else "median"
            short = stance_reach_shortfall(
                motion, contacts, centre, PLANT_MAX_DROP_PER_LEG * leg, glob
            )
            if short > PLANT_MAX_REACH_PER_LEG * leg:  # no IK can hold these footholds
                rep = {
                    "max_reach_error_per_leg": round(short / leg, 5),
                    "max_pelvis_drop_per_leg": PLANT_MAX_DROP_PER_LEG,
                    "footholds": rule,
                    "solved": False,
                }
                moved = motion
            else:
                moved, report = plant_motion(
                    motion, contacts, _swing_lift(motion, contacts), centre=centre, glob=glob
                )
                rep = {**_summary(report, contacts, leg), "footholds": rule, "solved": True}
            first = rep if first is None else first
            if _reaches(rep):
                break
        assert first is not None  # FOOTHOLD_RULES is not empty
        return moved, rep, first

    if glob is None:
        glob = out.global_positions()  # one forward-kinematics pass for every reach test
    moved, rep, first = attempt(out, glob)
    if _reaches(rep):
        return moved, {**rep, "kept": True, "root": "decoded"}
    missed = (
        f"the legs do not reach the footholds (toe {first['max_reach_error_per_leg']:.2f} "
        f"leg lengths off in stance, {first.get('max_swing_reach_error_per_leg', 0.0):.2f} "
        f"in swing, pelvis lowered {first['max_pelvis_drop_per_leg']:.2f}; limits "
        f"{PLANT_MAX_REACH_PER_LEG}, {PLANT_MAX_SWING_REACH_PER_LEG}, {PLANT_MAX_DROP_PER_LEG})"
    )
    carried, ratio = stance_driven_root(out, contacts, glob)
    if ratio >= PLANT_MIN_SPEED_RATIO:
        # the carried body only translates: its joints move with its root
        shift = (carried.root_positions - out.root_positions)[:, None, :]
        moved, second, _ = attempt(carried, glob + shift)
        if _reaches(second):
            return moved, {
                **second,
                "kept": True,
                "root": "carried",
                "speed_ratio": round(ratio, 3),
                "reason": f"{missed} with the decoded root path; the body moved as far "
                f"as its stance legs carry it ({100 * ratio:.0f} % of its decoded speed)",
            }
        why = "not even with the body carried by its stance legs"
    else:
        why = (
            f"the stance legs carry the body only {100 * ratio:.0f} % of its decoded "
            f"speed (< {100 * PLANT_MIN_SPEED_RATIO:.0f} %)"
        )
    restep = _restep(out, contacts, glob)
    tried: dict[str, Any] = {}
    if restep is not None:
        moved, rep = restep
        tried = {
            "restep": {
                **rep["restep"],
                "max_reach_error_per_leg": rep["max_reach_error_per_leg"],
                "max_pelvis_drop_per_leg": rep["max_pelvis_drop_per_leg"],
            }
        }
        if _reaches(rep):
            return moved, {
                **rep,
                "kept": True,
                "root": "decoded",
                "reason": f"{missed}, {why}: the legs step faster "
                f"(stride {rep['restep']['period_s'][0]:.2f} s → "
                f"{rep['restep']['period_s'][1]:.2f} s)",
            }
    if tried:
        why += ", not even stepping faster"
    partly = None
    if restep is not None and PARTLY_ON_RESTEP:
        # the quickened labels ask the legs for the shorter sweeps: hold what they reach
        assert restep[0].contacts is not None  # plant_motion labels its output
        partly = _plant_partly(out, restep[0].contacts, glob, trim=TRIM_TO_REACH)
        if partly is not None:
            why += " in every stance run; on the faster steps"
    if partly is None:
        partly = _plant_partly(out, contacts, glob, trim=TRIM_TO_REACH)
    if partly is not None:
        moved, rep = partly
        trimmed = rep.get("trimmed")
        cut = (
            ""
            if trimmed is None
            else f"{trimmed['runs']} stance runs shortened to the legs' reach "
            f"({trimmed['frames']} frames), "
        )
        return moved, {
            **rep,
            **tried,
            "kept": True,
            "root": "decoded",
            "reason": f"{missed}, {why}: {cut}the stance runs out of reach keep the decoded "
            f"feet ({rep['free_runs'][0]} of {rep['free_runs'][1]} runs, "
            f"{100 * rep['free_share']:.0f} % of the stance frames)",
        }
    return out, {
        **first,
        **tried,
        "kept": False,
        "speed_ratio": round(ratio, 3),
        "reason": f"{missed}, {why}: the decoded feet are kept",
    }


#: When the legs stepping faster (:func:`_restep`) still miss some footholds, the partial
#: planting (:func:`_plant_partly`) holds the runs they reach on the faster steps, not on
#: the slower decoded ones, whose longer sweeps leave more runs to free or shorten.
PARTLY_ON_RESTEP = True
#: Partial planting (:func:`_plant_partly`) finds the runs to leave free in at most this
#: many IK passes.
PARTIAL_PASSES = 4


def _run_mask(contacts: np.ndarray, hit: np.ndarray) -> np.ndarray:
    """(T, 4) bool: the whole stance runs of ``contacts`` that have a frame in ``hit``."""
    from ..contacts import contact_segments

    out = np.zeros_like(contacts, dtype=bool)
    for k, segs in enumerate(contact_segments(contacts)):
        for a, b in segs:
            if hit[a:b, k].any():
                out[a:b, k] = True
    return out


#: Trimming (:func:`_trim_to_reach`): a stance run is shortened at both ends, a frame a
#: step, until its centred foothold is within the legs' reach, but not below this many
#: seconds (at least 2 frames); a run that still misses stays whole and is left free by
#: :func:`_plant_partly`.
TRIM_MIN_RUN_S = 0.1
#: Shorten the stance runs the partial planting leaves free and plant again
#: (:func:`_plant_partly` with ``trim``, called by :func:`_plant`).
TRIM_TO_REACH = True
#: A trimmed run's centred foothold must lie within the stretched leg with the pelvis
#: this share of leg length *higher* than it is. The cheap reach test counts the leg's
#: segments straight; the IK's legs, within their joint ranges, reach less far. Without
#: the margin the real back-walk sent to the cat was trimmed, the IK still had to lower
#: the pelvis beyond :data:`PLANT_MAX_DROP_PER_LEG`, and the trimmed labels held no more
#: stance (72 % of the stance frames free either way); with 0.1, 24 % are free; with 0.2
#: no run could be trimmed far enough.
TRIM_MARGIN_PER_LEG = 0.1


def _trim_to_reach(
    out: Motion,
    contacts: np.ndarray,
    glob: np.ndarray | None = None,
    only: np.ndarray | None = None,
) -> tuple[np.ndarray, dict[str, Any] | None]:
    """``contacts`` with every stance run whose centred foothold lies beyond the legs'
    reach shortened at both ends until it does not, and what was changed (``None``:
    nothing). ``only``: (T, 4) bool, the runs to consider (those with a frame in it;
    default every run).

    A decoded body that moves faster than its legs sweep in a long stance (a real dog's
    walk sent to the cat: duty factor 0.88 at 1.6 leg lengths per second, the legs
    carrying 44 % of that travel) asks each foot to stand where the shoulder or hip has
    already left. Such a run cannot be a foot at rest for its whole length. Its middle
    can: the foot touches down later and lifts earlier, at the same foothold, and the
    frames taken off are swing (lifted like the others). The run's centre, and with it
    the footfall phase, stays; the duty factor falls by what the legs cannot hold. A run
    that misses even at :data:`TRIM_MIN_RUN_S` is left as it was (the partial planting
    frees it). The reach test is :func:`habitsim.planting.stance_run_shortfall` of the
    centred foothold with the pelvis raised by :data:`TRIM_MARGIN_PER_LEG`.

    Measured with ``habitsim bench model --real`` (the Labrador clips sent to four
    targets): stance toes at rest on 88.8 % of the transfers' stance frames without
    trimming, 96.6 % with it; the back-walk sent to the cat 33 → 78 %.
    """
    from ..contacts import contact_segments
    from ..planting import stance_run_shortfall

    before = np.asarray(contacts, dtype=bool)  # read only
    c = before.copy()
    margin = TRIM_MARGIN_PER_LEG * out.species_info.leg_length
    glob = out.global_positions() if glob is None else glob
    shortest = max(2, int(round(TRIM_MIN_RUN_S * out.fps)))
    short = stance_run_shortfall(out, c, True, -margin, glob=glob)
    # (foot, start, stop) of the runs to trim, by their original extent
    active = [
        (k, a, b)
        for k, segs in enumerate(contact_segments(c))
        for a, b in segs
        if short[a:b, k].max() > 0.0 and (only is None or only[a:b, k].any())
    ]
    if not active:
        return c, None
    span = {run: (run[1], run[2]) for run in active}  # the run's current extent
    failed: set[tuple[int, int, int]] = set()
    t = len(c)
    while active:
        short = stance_run_shortfall(out, c, True, -margin, glob=glob)
        still = []
        for run in active:
            k, a, b = run
            lo, hi = span[run]
            if short[lo:hi, k].max() <= 0.0:
                continue  # within reach
            # a run cut by the clip's start or end is trimmed on its inner side only
            lo2 = lo if a == 0 else lo + 1
            hi2 = hi if b == t else hi - 1
            if hi2 - lo2 < shortest or (lo2, hi2) == (lo, hi):
                failed.add(run)
                continue
            c[lo:hi, k] = False
            c[lo2:hi2, k] = True
            span[run] = (lo2, hi2)
            still.append(run)
        active = still
    for k, a, b in failed:  # the runs no trimming brings within reach stay whole
        c[a:b, k] = before[a:b, k]
    trimmed = [run for run in span if run not in failed and span[run] != run[1:]]
    if not trimmed:
        return before, None
    return c, {
        "runs": len(trimmed),
        "frames": int((before & ~c).sum()),
        "duty_before": [round(float(v), 3) for v in before.mean(axis=0)],
        "duty_after": [round(float(v), 3) for v in c.mean(axis=0)],
    }


def _plant_partly(
    out: Motion, contacts: np.ndarray, glob: np.ndarray | None = None, trim: bool = False
) -> tuple[Motion, dict[str, Any]] | None:
    """The decoded motion planted on every stance run its legs reach, the other runs
    keeping the decoded feet; ``None`` when no run can be held (or the runs to free are
    not settled within :data:`PARTIAL_PASSES` passes).

    A long clip whose speed changes (a real walk that breaks into a run, a standing
    start the decoder already walks through) can have a few stance runs that sweep
    further than the legs reach while the rest are fine; all-or-nothing planting would
    leave every foot sliding. Runs are released where their centred foothold is beyond
    the stretched leg with the pelvis at its lowest (:func:`~habitsim.planting.
    stance_run_shortfall`), then, pass by pass, where the IK misses the foothold or the
    pelvis would come down further than :data:`PLANT_MAX_DROP_PER_LEG` (the runs whose
    legs are short there). The released runs stay stance (the foot is on the ground);
    the swings around them start and end where they do. Each run held is a foot at
    rest, however many others are free: there is no share of free runs beyond which the
    held ones are given up. ``glob``: the motion's global joint positions, if already
    at hand. With ``trim``, the runs left free are then shortened to the legs' reach
    (:func:`_trim_to_reach`) and planted again; the result that holds more stance frames
    at rest is kept, the trimming reported as ``trimmed`` (the output's labels are the
    trimmed ones).
    """
    from ..contacts import contact_segments
    from ..planting import plant_motion, stance_run_shortfall

    c = np.asarray(contacts, dtype=bool)
    stance = int(c.sum())
    if stance == 0:
        return None
    leg = out.species_info.leg_length
    reach, low = PLANT_MAX_REACH_PER_LEG * leg, PLANT_MAX_DROP_PER_LEG * leg
    glob = out.global_positions() if glob is None else glob
    free = _run_mask(c, stance_run_shortfall(out, c, True, low, glob=glob) > reach)
    hang = stance_run_shortfall(out, c, True, 0.0, glob=glob) > 0.0
    width = max(1, int(round(0.1 * out.fps)))
    lift = _swing_lift(out, c)
    for _ in range(PARTIAL_PASSES):
        if free.sum() >= stance:  # no run left to hold
            return None
        moved, report = plant_motion(out, c, lift, centre=True, free=free, glob=glob)
        held = c & ~free
        miss = held & (report.reach_error > reach)
        deep = report.pelvis_drop > low
        if deep.any():
            near = np.convolve(deep.astype(float), np.ones(2 * width + 1), "same") > 0
            cand = held & near[:, None]
            miss |= cand & hang if (cand & hang).any() else cand
        if not miss.any():
            break
        free |= _run_mask(c, miss)
    else:
        return None
    n_free = int(free.sum())  # checked before the last pass, which freed nothing more
    runs = sum(len(s) for s in contact_segments(c))
    loose = sum(len(s) for s in contact_segments(free))
    summary = _summary(report, c, leg, free)
    result = (
        moved,
        {
            **summary,
            "footholds": "centred",
            "solved": True,
            "free_runs": [loose, runs],
            "free_share": round(n_free / stance, 3),
        },
    )
    if trim and n_free:
        labels, trimmed = _trim_to_reach(out, c, glob, only=free)
        again = None if trimmed is None else _plant_partly(out, labels, glob)
        if again is not None:
            held = (1.0 - again[1]["free_share"]) * labels.sum()
            if held > stance - n_free:
                return again[0], {**again[1], "trimmed": trimmed}
    return result


#: Restepping (:func:`_restep`): a leg stretched to this share of its length sets the
#: longest stance sweep (:func:`habitsim.planting.stance_sweep_limit`) ...
RESTEP_REACH_SHARE = 0.92
#: ... and no stride gets shorter than this many frames.
RESTEP_MIN_PERIOD = 4.0


def _restep(
    out: Motion, contacts: np.ndarray, glob: np.ndarray | None = None
) -> tuple[Motion, dict[str, Any]] | None:
    """The decoded motion with its legs stepping fast enough for its body, or ``None``
    when its labels do not step or already fit.

    A decoder that gives a small target the source's slow cadence and the target's own
    speed (a camel's walk sent to the cat: strides of 1.4 s at 2.4 leg lengths per
    second) asks each stance foot to hold while the body travels further than the legs
    sweep. The stance labels are played faster (:func:`habitsim.contacts.quicken_contacts`,
    one rate for the clip: the body's mean travel over one stance ÷ the longest sweep),
    which keeps the duty factor and the feet's phase offsets; the legs are solved by IK
    onto footholds centred under each shoulder / hip sweep
    (:func:`habitsim.planting.plant_motion` with ``centre``), lifted in swing
    (:func:`_swing_lift`). The trunk, neck and tail and the root path stay the
    decoder's.

    Returns:
        ``(planted motion with the new labels, planting report with a ``restep`` entry)``.
    """
    from ..contacts import quicken_contacts, stride_period
    from ..planting import plant_motion, stance_sweep_limit

    period = stride_period(contacts)
    t = out.num_frames
    if period is None or t < 2 or period > t:
        return None
    sweep = stance_sweep_limit(out, RESTEP_REACH_SHARE, glob)
    speed = np.linalg.norm(np.diff(out.root_positions[:, :2], axis=0), axis=1).mean() * out.fps
    stance_s = float(contacts.mean()) * period / out.fps
    k = min(speed * stance_s / max(sweep, 1e-9), period / RESTEP_MIN_PERIOD)
    if k <= 1.0:
        return None
    # one rate for the whole clip: a rate that follows the speed frame by frame makes the
    # stances of a short stride uneven by a frame or two, enough for a leg to miss
    rate = np.full(t, k)
    labels = quicken_contacts(contacts, rate, period)
    leg = out.species_info.leg_length
    lift = _swing_lift(out, labels)
    moved, report = plant_motion(out, labels, lift, centre=True, glob=glob)
    new_period = stride_period(labels)
    return moved, {
        **_summary(report, labels, leg),
        "footholds": "centred",
        "solved": True,
        "restep": {
            "period_s": [round(period / out.fps, 3), round((new_period or period) / out.fps, 3)],
            "rate": round(float(rate[0]), 3),
            "sweep_limit_per_leg": round(sweep / leg, 3),
        },
    }


#: The decoded body's horizontal speed is kept within this factor of the source's speed
#: at the same Froude number (:func:`_bound_speed`) ...
SPEED_BAND = 1.5
#: ... both speeds smoothed with a Gaussian of this standard deviation [s] (about half a
#: stride of a walk), so the band bounds the pace, not the bob within a stride.
SPEED_SMOOTH_S = 0.25


def _bound_speed(out: Motion, source: Motion) -> tuple[Motion, dict[str, Any] | None]:
    """The decoded motion with its horizontal root speed within :data:`SPEED_BAND` of the
    source's, and what was changed (``None``: nothing).

    The decoder reads a window of about two seconds; a source that stands and then walks
    off (a real clip's first seconds, a pause between runs) can decode as a target that
    walks the whole time, and legs planted on the source's footfalls (all four feet down
    while it stands) cannot carry a body that travels. Dynamic similarity gives the speed
    the target would have at the source's gait (equal Froude numbers v²/(g·L): v_target
    = v_source·√(L_target / L_source), L the leg length); each frame's decoded velocity
    is scaled so its smoothed speed lies within a factor :data:`SPEED_BAND` of that
    (below for a standing source, a zero speed). The direction of travel, the height and
    every joint stay the decoder's.
    """
    from scipy.ndimage import gaussian_filter1d

    t = out.num_frames
    if t < 3 or source.num_frames != t:
        return out, None
    sigma = max(1.0, SPEED_SMOOTH_S * out.fps)
    step = np.diff(out.root_positions[:, :2], axis=0)
    src_step = np.diff(source.root_positions[:, :2], axis=0) * (out.fps / source.fps)
    ratio = float(np.sqrt(out.species_info.leg_length / source.species_info.leg_length))
    v_dec = gaussian_filter1d(np.linalg.norm(step, axis=1), sigma, mode="nearest")
    v_eq = gaussian_filter1d(np.linalg.norm(src_step, axis=1), sigma, mode="nearest") * ratio
    bounded = np.clip(v_dec, v_eq / SPEED_BAND, v_eq * SPEED_BAND)
    scale = np.where(v_dec > 1e-9, bounded / np.maximum(v_dec, 1e-9), 1.0)
    changed = np.abs(scale - 1.0) > 1e-3
    if not changed.any():
        return out, None
    root = np.array(out.root_positions, dtype=np.float64)
    root[1:, :2] = root[0, :2] + np.cumsum(step * scale[:, None], axis=0)
    moved = Motion(out.species, out.fps, root, out.rotations, out.contacts, dict(out.metadata))
    fps, leg = out.fps, out.species_info.leg_length
    return moved, {
        "frames": int(changed.sum()),
        "speed_per_leg": [
            round(float(v_dec.mean() * fps / leg), 3),
            round(float(bounded.mean() * fps / leg), 3),
        ],
    }


#: Pitch the decoded trunk so the fore and hind stance feet stand alike above the ground
#: (:func:`_level_trunk`) before the planting ...
LEVEL_TRUNK = True
#: ... where their heights differ by more than this share of leg length (the part beyond
#: it is levelled: a training species' decoded trunk is left as it is) ...
LEVEL_TOLERANCE_PER_LEG = 0.02
#: ... by at most this pitch [rad].
LEVEL_MAX_PITCH = 0.5


def _level_trunk(
    out: Motion, contacts: np.ndarray, glob: np.ndarray | None = None
) -> tuple[Motion, dict[str, Any] | None]:
    """The decoded motion pitched about its pelvis so that its fore and hind stance toes
    stand alike above the ground, and what was changed (``None``: nothing).

    The decoder poses a target's legs and trunk from what it learned of the training
    species; on a skeleton whose fore and hind legs differ from theirs (a giraffe, a
    moose or a zebra borrowing a camel's or a deer's habit latent) the decoded trunk can
    slope so that the fore toes stand a tenth of a leg under the ground and the hind
    toes as far above it. Planting each foot by leg IK then bends the fore legs and
    stretches the hind legs, a crouch the animal does not have (the frozen evaluator
    reads a standing giraffe so posed as the start of a jump). Over the frames where
    both girdles have a foot in stance, the median height difference ``dz`` of their
    stance toes and the median fore-to-hind stance distance ``d`` along the heading give
    one pitch for the whole clip, asin((|dz| − tol)·sign(dz) / d) with tol =
    :data:`LEVEL_TOLERANCE_PER_LEG` × L (none within it; at most
    :data:`LEVEL_MAX_PITCH`); the body turns by it about its pelvis and the legs keep
    their decoded angles. The planting then brings both pairs of feet down together
    (its slow pelvis carriage) instead of folding one pair. ``glob``: the motion's global
    joint positions, if already at hand.
    """
    from ..rotations import quat_from_axis_angle, quat_mul
    from .features import heading_yaw

    c = np.asarray(contacts, dtype=bool)
    both = c[:, :2].any(axis=1) & c[:, 2:].any(axis=1)
    if both.sum() < 2:
        return out, None
    glob = out.global_positions() if glob is None else glob
    feet = glob[:, out.skeleton.foot_indices]

    def centre(k: list[int]) -> np.ndarray:
        w = c[:, k].astype(np.float64)
        return (feet[:, k] * w[..., None]).sum(axis=1) / np.maximum(w.sum(axis=1), 1.0)[:, None]

    fore, hind = centre([0, 1]), centre([2, 3])
    yaw = heading_yaw(out.rotations[:, 0])
    ahead = np.stack([np.cos(yaw), np.sin(yaw), np.zeros_like(yaw)], axis=-1)
    span = float(np.median(np.einsum("ti,ti->t", fore - hind, ahead)[both]))
    if span <= 0.0:
        return out, None  # the feet are not where a quadruped's are: leave the pose
    dz = float(np.median((fore[:, 2] - hind[:, 2])[both]))
    leg = out.species_info.leg_length
    excess = float(np.sign(dz)) * max(abs(dz) - LEVEL_TOLERANCE_PER_LEG * leg, 0.0)
    if excess == 0.0:
        return out, None
    pitch = float(
        np.clip(np.arcsin(np.clip(excess / span, -1.0, 1.0)), -LEVEL_MAX_PITCH, LEVEL_MAX_PITCH)
    )
    left = np.stack([-np.sin(yaw), np.cos(yaw), np.zeros_like(yaw)], axis=-1)
    rot = np.array(out.rotations, dtype=np.float64, copy=True)
    rot[:, 0] = quat_mul(quat_from_axis_angle(left, np.full(len(yaw), pitch)), rot[:, 0])
    moved = Motion(out.species, out.fps, out.root_positions, rot, out.contacts, dict(out.metadata))
    return moved, {
        "pitch_deg": round(float(np.degrees(pitch)), 2),
        "fore_minus_hind_per_leg": round(dz / leg, 4),
    }


#: The decoded root height's deviation from its median is kept within this factor of the
#: source's (both in leg lengths, :func:`_bound_height`) ...
HEIGHT_BAND = 1.5
#: ... or within this share of leg length, whichever is larger (the decoder's own bob).
HEIGHT_FLOOR_PER_LEG = 0.01
#: Half-width [s] of the window the deviations' envelopes are taken over.
HEIGHT_WINDOW_S = 0.5


def _bound_height(out: Motion, source: Motion) -> tuple[Motion, dict[str, Any] | None]:
    """The decoded motion with its root height's excursions within :data:`HEIGHT_BAND`
    of the source's, and what was changed (``None``: nothing).

    A decoded root height drifts over a clip (one window decodes lower than the next):
    a standing source whose pelvis moves by a few millimetres can come out as a target
    that rises from a crouch, which reads as the start of a jump. Each frame's deviation
    from the clip's median height, in leg lengths, is scaled down where its envelope
    (the largest deviation within :data:`HEIGHT_WINDOW_S`) exceeds the source's envelope
    times :data:`HEIGHT_BAND` (at least :data:`HEIGHT_FLOOR_PER_LEG`). A gait's bob, a
    sit or a jump keep their size: the source has it too.
    """
    from scipy.ndimage import gaussian_filter1d, maximum_filter1d

    t = out.num_frames
    if t < 3 or source.num_frames != t:
        return out, None
    leg, src_leg = out.species_info.leg_length, source.species_info.leg_length
    z = out.root_positions[:, 2]
    mid = float(np.median(z))
    dev = (z - mid) / leg
    src_z = source.root_positions[:, 2]
    src_dev = (src_z - float(np.median(src_z))) / src_leg
    size = 2 * max(1, int(round(HEIGHT_WINDOW_S * out.fps))) + 1
    sigma = max(1.0, 0.5 * HEIGHT_WINDOW_S * out.fps)

    def envelope(x: np.ndarray) -> np.ndarray:
        return gaussian_filter1d(maximum_filter1d(np.abs(x), size, mode="nearest"), sigma)

    env, allowed = envelope(dev), np.maximum(HEIGHT_BAND * envelope(src_dev), HEIGHT_FLOOR_PER_LEG)
    scale = np.minimum(1.0, allowed / np.maximum(env, 1e-12))
    changed = scale < 1.0 - 1e-3
    if not changed.any():
        return out, None
    root = np.array(out.root_positions, dtype=np.float64)
    root[:, 2] = mid + dev * scale * leg
    moved = Motion(out.species, out.fps, root, out.rotations, out.contacts, dict(out.metadata))
    return moved, {
        "frames": int(changed.sum()),
        "range_per_leg": [round(float(np.ptp(dev)), 4), round(float(np.ptp(dev * scale)), 4)],
    }


#: The decoded heading may turn away from the source's at most this fast [rad/s] (the
#: rate of the difference of the two pelvis headings, :func:`_bound_heading`) ...
HEADING_MAX_RATE = 3.0
#: ... beyond, the difference is low-passed by a Gaussian of this standard deviation [s] ...
HEADING_SMOOTH_S = 0.25
#: ... and it never swings further than this angle [rad] (45°) from its own slow trend,
#: the departure low-passed by :data:`HEADING_TREND_S` (a target that turns at its own
#: rate departs steadily from the source's heading through a turn; that is kept).
HEADING_BAND = np.pi / 4
HEADING_TREND_S = 1.0


def _bound_heading(out: Motion, source: Motion) -> tuple[Motion, dict[str, Any] | None]:
    """The decoded motion with its heading's departures from the source's slowed to
    :data:`HEADING_MAX_RATE` and held within :data:`HEADING_BAND`, and what was changed
    (``None``: nothing).

    A transfer keeps the source's action, turns included: where the decoded pelvis
    heading swings away from the source's faster than any trunk turns (a decoder off
    its training data can wag the whole body by ±90° a few times a second, or spin it
    round, on a backward walk), the heading difference is replaced by its low-pass
    (:data:`HEADING_SMOOTH_S`), blended in where the swing exceeds the bound, and its
    swing about its own slow trend is clipped to the band. The body turns about the
    pelvis; the root path is kept. A decoded heading that departs slowly (a habitual
    drift, or a turn at the target's own rate) stays as decoded.
    """
    from scipy.ndimage import gaussian_filter1d, maximum_filter1d

    from ..rotations import quat_from_axis_angle, quat_mul
    from .features import heading_yaw

    t = out.num_frames
    if t < 3 or source.num_frames != t:
        return out, None
    sigma = max(1.0, HEADING_SMOOTH_S * out.fps)
    # against the source's heading low-passed alike (a mocap pelvis jitters in yaw)
    src = gaussian_filter1d(np.unwrap(heading_yaw(source.rotations[:, 0])), sigma, mode="nearest")
    dev = np.unwrap(heading_yaw(out.rotations[:, 0])) - src
    rate = np.abs(np.gradient(dev)) * out.fps
    new = dev
    if rate.max() > HEADING_MAX_RATE:
        size = 2 * int(round(sigma)) + 1
        env = gaussian_filter1d(maximum_filter1d(rate, size, mode="nearest"), sigma)
        w = np.clip(env / HEADING_MAX_RATE - 1.0, 0.0, 1.0)
        new = dev + w * (gaussian_filter1d(dev, sigma, mode="nearest") - dev)
    trend = gaussian_filter1d(dev, max(1.0, HEADING_TREND_S * out.fps), mode="nearest")
    new = trend + np.clip(new - trend, -HEADING_BAND, HEADING_BAND)
    turn = new - dev
    changed = np.abs(turn) > 1e-6
    if not changed.any():
        return out, None
    rot = np.array(out.rotations, dtype=np.float64, copy=True)
    axis = np.broadcast_to(np.array([0.0, 0.0, 1.0]), (t, 3))
    rot[:, 0] = quat_mul(quat_from_axis_angle(axis, turn), rot[:, 0])
    moved = Motion(out.species, out.fps, out.root_positions, rot, out.contacts, dict(out.metadata))
    after = np.abs(np.gradient(new)) * out.fps
    return moved, {
        "frames": int(changed.sum()),
        "max_rate": [round(float(rate.max()), 2), round(float(after.max()), 2)],
        "max_departure_deg": [
            round(float(np.degrees(np.abs(dev).max())), 1),
            round(float(np.degrees(np.abs(new).max())), 1),
        ],
    }


def _finish(out: Motion, source: Motion, info: dict[str, Any], plant: bool = False) -> Motion:
    """The decoded motion at the source's frame rate with its stance labels
    (:func:`transfer_contacts`; without aerial phases at a speed the target walks,
    :func:`walking_stance`) and, with ``plant``, its feet planted on them by leg IK
    (:func:`habitsim.planting.plant_motion`: each stance run held at one foothold on the
    ground, swing blended in between; footholds by the rules of :data:`FOOTHOLD_RULES`;
    a trunk whose fore and hind stance feet stand at different heights pitched level
    first, :func:`_level_trunk`, recorded as ``metadata["transfer"]["levelled"]``),
    kept when the legs reach (:data:`PLANT_MAX_REACH_PER_LEG`,
    :data:`PLANT_MAX_DROP_PER_LEG`); where they do not, the body is moved as far as its
    stance legs carry it and planted again (:data:`PLANT_MIN_SPEED_RATIO`).
    ``metadata["transfer"]["planted"]`` says what the planting did: ``False`` when it was
    off or no foot is in stance, else its report with ``kept``, ``root`` (``decoded`` or
    ``carried``), ``footholds`` (``median`` or ``centred``), ``solved`` (``False`` when
    the footholds were out of reach without IK), ``trimmed`` where stance runs were
    shortened to the legs' reach (the labels returned are then the trimmed ones,
    :func:`_trim_to_reach`) and ``reason`` where the first try missed."""
    # frame for frame with the source (a round trip through the model's rate can add or
    # drop a frame at the end)
    out = resample_motion(out, source.fps, source.num_frames)
    out, bounded = _bound_speed(out, source)
    if bounded is not None:
        info = {**info, "speed_bounded": bounded}
    out, lowered = _bound_height(out, source)
    if lowered is not None:
        info = {**info, "height_bounded": lowered}
    out, turned = _bound_heading(out, source)
    if turned is not None:
        info = {**info, "heading_bounded": turned}
    meta = {k: v for k, v in source.metadata.items() if k in ("action", "gait", "pair_key", "seed")}
    contacts, how = transfer_contacts(out, source, out.contacts)
    contacts, walking = walking_stance(out, contacts, source)
    if walking is not None:
        how = {**how, "walking_stance": walking}
    planted: Any = False
    if plant and contacts.any():
        glob: np.ndarray | None = out.global_positions()
        if LEVEL_TRUNK:
            out, levelled = _level_trunk(out, contacts, glob)
            if levelled is not None:
                info = {**info, "levelled": levelled}
                glob = None  # the body turned
        out, planted = _plant(out, contacts, glob)
        if ("restep" in planted or "trimmed" in planted) and planted["kept"]:
            assert out.contacts is not None  # plant_motion labels its output
            contacts = out.contacts  # the labels the legs now step on
    meta["transfer"] = {**info, "contacts": how, "planted": planted}
    return Motion(out.species, out.fps, out.root_positions, out.rotations, contacts, meta)


# ---------------------------------------------------------------------------- methods


def direct_transfer(motion: Motion, to: str, **_: Any) -> Motion:
    """The ``direct`` baseline: the source's local rotations on the target skeleton, the
    root path scaled by the hip-height ratio h_target / h_source; stance labels by
    :func:`transfer_contacts` (the source's, frame for frame, when it has them)."""
    tgt = load_species(to).name
    ratio = load_species(tgt).hip_height / load_species(motion.species).hip_height
    info = {
        "method": "direct",
        "from": motion.species,
        "to": tgt,
        "hip_height_ratio": round(ratio, 4),
    }
    meta = {k: v for k, v in motion.metadata.items() if k in ("action", "gait", "pair_key", "seed")}
    out = Motion(tgt, motion.fps, motion.root_positions * ratio, motion.rotations.copy())
    contacts, how = transfer_contacts(out, motion)
    meta["transfer"] = {**info, "contacts": how}
    return Motion(out.species, out.fps, out.root_positions, out.rotations, contacts, meta)


def _network_method(variant: str) -> Callable[..., Motion]:
    def run(
        motion: Motion,
        to: str,
        *,
        seed: int | None = 0,
        checkpoint: str | Path | None = None,
        temperature: float = 1.0,
        plant: bool = True,
        **_: Any,
    ) -> Motion:
        ck = load_model(checkpoint, variant)
        if ck.config.model.variant != variant:
            raise MethodNotAvailableError(
                f"method {variant!r} needs a {variant!r} checkpoint; {ck.path} is a "
                f"{ck.config.model.variant!r} one"
            )
        out, info = _run_network(
            ck, motion, load_species(to).name, seed=seed, temperature=temperature
        )
        info = {"method": variant, "from": motion.species, "to": out.species, "seed": seed, **info}
        return _finish(out, motion, info, plant=plant)

    run.__name__ = f"transfer_{variant}"
    return run


_DESCRIPTIONS = {
    "habit": "VQ-VAE (EMA + code reset) with habit latent z_c and text embedding g_c",
    "habit_ema": "VQ-VAE (EMA, no code reset) with z_c and g_c",
    "no_habit": "VQ-VAE without z_c and g_c (reconstruction model)",
    "habit_only": "VQ-VAE with the habit latent z_c only",
    "text_only": "VQ-VAE with the text embedding g_c only",
}
for _v in VARIANTS:
    register_method(_v, _network_method(_v), description=_DESCRIPTIONS[_v], variant=_v)
register_method(
    "direct", direct_transfer, description="copy local rotations, scale the root by hip height"
)


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
) -> Motion:
    """Transfer a motion onto another species, keeping the target's habits.

    Args:
        motion: the source motion (any catalog species, any frame rate).
        to: target species name.
        method: a name of :data:`METHODS` (default ``habit``).
        source: treat the motion as this species' (relabel) instead of ``motion.species``.
        seed: seed of the habit latent z_c drawn from the target's prior (same seed ⇒
            same output).
        checkpoint: checkpoint folder to use instead of the default of the method.
        temperature: scale of the flow's base Gaussian when drawing z_c (1 = the prior).
        plant: the network methods plant the decoded feet on the output's stance labels
            by leg IK (``False``: the decoder's raw kinematics; ``direct`` keeps the
            source's planted feet either way).

    Returns:
        A :class:`~habitsim.motion.Motion` on ``to``'s skeleton at the source's frame
        rate, with foot contacts (:func:`transfer_contacts`) and ``metadata["transfer"]``
        (method, habit species, retrieval explanation for held-out targets, how the
        contacts were found, what the planting did).

    Raises:
        UnknownMethodError: the method is not registered (lists the valid ones).
        UnknownSpeciesError: unknown target / source species.
        MethodNotAvailableError: no checkpoint for the method's variant.
        CheckpointError: the checkpoint cannot be loaded.
    """
    if method not in METHODS:
        raise UnknownMethodError(f"unknown transfer method {method!r}; valid: {', '.join(METHODS)}")
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
    return METHODS[method].fn(
        motion, tgt, seed=seed, checkpoint=checkpoint, temperature=temperature, plant=plant
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
