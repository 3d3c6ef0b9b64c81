"""Training windows from a synthetic data set (:mod:`habitsim.dataset`).

Clips are pre-processed once (:func:`~habitsim.models.features.clip_arrays`) and kept in
memory (the default data set is ~45 k training frames). A :class:`WindowSampler` draws
heading-canonical windows with a seeded :class:`numpy.random.Generator`, and for each
window, when the data set has one, the *paired* window of another training species:
the clip with the same ``pair_key`` (same action and generator draws) and the same
length, at the same frames.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from ..dataset import iter_clips, load_manifest
from ..motion import MIRROR_ACTIONS
from .errors import TrainingDataError
from .features import C_DIM, C_INDEX, FEAT_DIM, ClipArrays, canonical_window, clip_arrays

__all__ = ["ClipSet", "Batch", "WindowSampler", "load_clip_set", "feature_stats", "fixed_windows"]


@dataclass
class ClipSet:
    """Pre-processed clips of one split.

    Attributes:
        clips: the clips.
        pair_keys: data set pair key of each clip (None if unknown).
        actions: action of each clip.
        fps: common frame rate [Hz].
    """

    clips: list[ClipArrays]
    pair_keys: list[str | None]
    actions: list[str]
    fps: float

    @property
    def species(self) -> list[str]:
        return sorted({c.species for c in self.clips})

    def of_species(self, names: Iterable[str]) -> ClipSet:
        """Only the clips of these species."""
        keep = set(names)
        idx = [i for i, c in enumerate(self.clips) if c.species in keep]
        return ClipSet(
            [self.clips[i] for i in idx],
            [self.pair_keys[i] for i in idx],
            [self.actions[i] for i in idx],
            self.fps,
        )

    def __add__(self, other: ClipSet) -> ClipSet:
        """Both sets' clips in one (same frame rate; pair keys are kept as they are)."""
        if other.fps != self.fps:
            raise TrainingDataError(
                f"cannot mix clips at {self.fps:g} fps with clips at {other.fps:g} fps"
            )
        return ClipSet(
            self.clips + other.clips,
            self.pair_keys + other.pair_keys,
            self.actions + other.actions,
            self.fps,
        )

    def partners(self) -> list[list[int]]:
        """For each clip, the clips of *other* species with its pair key and length."""
        by_key: dict[str, list[int]] = {}
        for i, k in enumerate(self.pair_keys):
            if k is not None:
                by_key.setdefault(k, []).append(i)
        out: list[list[int]] = []
        for i, k in enumerate(self.pair_keys):
            if k is None:
                out.append([])
                continue
            c = self.clips[i]
            out.append(
                [
                    j
                    for j in by_key[k]
                    if self.clips[j].species != c.species
                    and self.clips[j].num_frames == c.num_frames
                ]
            )
        return out


def load_clip_set(
    data_dir: str | Path,
    split: str,
    species: Iterable[str] | None = None,
    progress: bool = False,
    mirror: bool = False,
    speeds: Sequence[float] = (),
) -> ClipSet:
    """Read and pre-process every clip of ``split`` (optionally only some species).

    With ``mirror``, each clip's sagittal reflection (:meth:`~habitsim.motion.Motion.mirrored`)
    follows it, with the pair key ``KEY~mirror`` (so it pairs with its partners'
    reflections) and the reflected action.

    ``speeds`` adds, for each factor s ≠ 1, the clip (and its reflection) played s times
    faster (:func:`speed_variant`; cadence and speed both scale by s, stance labels
    follow), paired with its partners' variants of the same factor (``KEY~xS``).

    Raises:
        TrainingDataError: no clips, or clips of different frame rates.
        DatasetError: an unreadable data set (see :func:`habitsim.dataset.load_manifest`).
    """
    man = load_manifest(data_dir, check_files=False)
    sel = list(species) if species is not None else None
    entries = man.select(split=split, species=sel)
    it = iter_clips(man, split=split, species=sel)
    if progress:
        from tqdm import tqdm

        it = tqdm(it, total=len(entries), desc=f"loading {split}", unit="clip", leave=False)
    clips: list[ClipArrays] = []
    keys: list[str | None] = []
    actions: list[str] = []
    factors = [float(f) for f in speeds if abs(float(f) - 1.0) > 1e-9]
    for entry, m in it:
        versions = [(m, entry.pair_key, entry.action)]
        if mirror:
            versions.append(
                (
                    m.mirrored(),
                    None if entry.pair_key is None else f"{entry.pair_key}~mirror",
                    MIRROR_ACTIONS.get(entry.action, entry.action),
                )
            )
        for f in factors:
            versions += [
                (speed_variant(v, f), None if k is None else f"{k}~x{f:g}", a)
                for v, k, a in versions[: 1 + int(mirror)]
            ]
        for v, k, a in versions:
            clips.append(clip_arrays(v))
            keys.append(k)
            actions.append(a)
    if not clips:
        raise TrainingDataError(f"{data_dir}: no {split} clips" + (f" of {sel}" if sel else ""))
    fps = {c.fps for c in clips}
    if len(fps) != 1:
        raise TrainingDataError(f"{data_dir}: {split} clips have several frame rates {sorted(fps)}")
    return ClipSet(clips, keys, actions, fps.pop())


def speed_variant(motion, factor: float):
    """The motion played ``factor`` times faster, at its own frame rate (a training
    augmentation: real clips come at cadences and speeds the generator does not draw)."""
    from ..motion import Motion, resample_motion

    fast = Motion(
        motion.species,
        motion.fps * factor,
        motion.root_positions,
        motion.rotations,
        motion.contacts,
        dict(motion.metadata),
    )
    return resample_motion(fast, motion.fps)


@dataclass
class Batch:
    """A batch of raw heading-canonical windows.

    Attributes:
        x: (B, T, F) features; valid: (B, T) real (not padded) frames; species: B names.
        pair_x, pair_valid, pair_species: the paired windows of other species (P of them).
        pair_src: (P,) index into the batch of each paired window's source window.
    """

    x: torch.Tensor
    valid: torch.Tensor
    species: list[str]
    pair_x: torch.Tensor
    pair_valid: torch.Tensor
    pair_species: list[str]
    pair_src: torch.Tensor


class WindowSampler:
    """Random clip (uniform, or by ``weights``), uniform random start; paired window when
    one exists."""

    def __init__(
        self,
        data: ClipSet,
        window: int,
        rng: np.random.Generator,
        paired: bool = True,
        weights: np.ndarray | None = None,
    ):
        self.data = data
        self.window = int(window)
        self.rng = rng
        self.paired = paired
        self.partners = data.partners() if paired else [[] for _ in data.clips]
        self.p = None if weights is None else np.asarray(weights, float) / np.sum(weights)

    def sample(self, batch_size: int) -> Batch:
        xs, vs, sp = [], [], []
        pxs, pvs, psp, psrc = [], [], [], []
        w = self.window
        for b in range(batch_size):
            n = len(self.data.clips)
            i = int(self.rng.integers(n) if self.p is None else self.rng.choice(n, p=self.p))
            c = self.data.clips[i]
            start = int(self.rng.integers(max(1, c.num_frames - w + 1)))
            f, v, _ = canonical_window(c, start, w)
            xs.append(f)
            vs.append(v)
            sp.append(c.species)
            part = self.partners[i]
            if part:
                j = part[int(self.rng.integers(len(part)))]
                pf, pv, _ = canonical_window(self.data.clips[j], start, w)
                pxs.append(pf)
                pvs.append(pv)
                psp.append(self.data.clips[j].species)
                psrc.append(b)
        empty = np.zeros((0, w, FEAT_DIM), np.float32)
        return Batch(
            x=torch.from_numpy(np.stack(xs)),
            valid=torch.from_numpy(np.stack(vs)),
            species=sp,
            pair_x=torch.from_numpy(np.stack(pxs) if pxs else empty),
            pair_valid=torch.from_numpy(np.stack(pvs) if pvs else np.zeros((0, w), bool)),
            pair_species=psp,
            pair_src=torch.as_tensor(psrc, dtype=torch.long),
        )


def fixed_windows(data: ClipSet, window: int, per_clip: int = 1) -> list[tuple[int, int]]:
    """Deterministic (clip index, start) pairs: ``per_clip`` evenly spaced starts per clip."""
    out = []
    for i, c in enumerate(data.clips):
        last = max(0, c.num_frames - window)
        starts = sorted({int(round(s)) for s in np.linspace(0, last, per_clip)})
        out += [(i, s) for s in starts]
    return out


def feature_stats(data: ClipSet, window: int, floor: float = 1e-2) -> tuple[np.ndarray, np.ndarray]:
    """Per-dimension mean and std (floored) of canonical windows over the whole set
    (0 and 1 on the contact channels, whose decoded values are logits).

    Every clip contributes windows starting every ``window // 2`` frames.
    """
    acc = []
    for c in data.clips:
        for s in range(0, max(1, c.num_frames - window + 1), max(1, window // 2)):
            f, v, _ = canonical_window(c, s, window)
            acc.append(f[v])
    allf = np.concatenate(acc).astype(np.float64)
    mean, std = allf.mean(0), np.maximum(allf.std(0), floor)
    mean[C_INDEX : C_INDEX + C_DIM] = 0.0  # the decoder's contact outputs are logits
    std[C_INDEX : C_INDEX + C_DIM] = 1.0
    return mean.astype(np.float32), std.astype(np.float32)


def stack_windows(
    data: ClipSet, windows: Sequence[tuple[int, int]], window: int
) -> tuple[torch.Tensor, torch.Tensor, list[str], list[int]]:
    """(x (N, T, F), valid (N, T), species, clip indices) of fixed windows."""
    xs, vs, sp, ci = [], [], [], []
    for i, s in windows:
        f, v, _ = canonical_window(data.clips[i], s, window)
        xs.append(f)
        vs.append(v)
        sp.append(data.clips[i].species)
        ci.append(i)
    return torch.from_numpy(np.stack(xs)), torch.from_numpy(np.stack(vs)), sp, ci
