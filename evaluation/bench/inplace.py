"""``habitsim bench inplace``: in-place clips, their travel recovered from the feet.

Two parts:

* **Recovery** (``dev_dir``, and always a synthetic walk of habitsim's own): every walk or
  run clip (file name containing ``walk`` or ``run``) is made in place by holding its
  root's horizontal position channels at their first frame (every joint loses the root's
  travel; :func:`make_in_place`), imported, and compared with the import of the clip as it
  was: the recovered root path's largest horizontal distance from the original's (both
  from their first frame) as a share of the distance travelled, the heading of the net
  displacement, and the pooled stance-label F1 against the original import's labels
  (:func:`habitsim.stance.labels.pooled_stance_f1`).
* **Game loops** (``gltf`` files' ``Walk`` and ``Run`` animations, and a synthetic in-place
  walk loop): the stance share of each foot of a walk, and the highest reference toe
  during labelled stance as a share of the leg length.

:func:`evaluate_targets` checks the issue's targets: root path within 5 % of the distance
travelled, heading within 10°, stance F1 ≥ 0.9, a walk's stance share 0.5–0.8 (every
foot), no stance toe above :data:`habitsim.physics_constants.CONTACT_HEIGHT_PER_LEG`.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from habitsim.errors import HabitsimError
from habitsim.physics_constants import CONTACT_HEIGHT_PER_LEG

from .targets import TargetCheck, verdict

if TYPE_CHECKING:  # pragma: no cover
    from habitsim.motion import Motion

__all__ = [
    "BenchInPlaceError",
    "InPlaceBenchOptions",
    "RecoveryRow",
    "LoopRow",
    "InPlaceBenchResult",
    "make_in_place",
    "synthetic_walk",
    "recovery_row",
    "loop_row",
    "run_inplace",
    "evaluate_targets",
]

#: Recovered root path: largest distance from the original's [share of the distance travelled].
PATH_SHARE = 0.05
#: Heading of the recovered net displacement against the original's [deg].
HEADING_DEG = 10.0
#: Pooled stance-label F1 against the original clip's import.
STANCE_F1 = 0.9
#: A walk's stance share, every foot [0–1].
WALK_STANCE = (0.5, 0.8)


class BenchInPlaceError(HabitsimError, ValueError):
    """Bad input to ``bench inplace``: a folder without walk or run clips, a missing file."""


@dataclass(frozen=True)
class InPlaceBenchOptions:
    """What ``bench inplace`` runs.

    Attributes:
        dev_dir: folder of clips to make in place (None: only the synthetic walk).
        gltf: glTF/GLB files whose ``Walk`` and ``Run`` animations are game loops.
        species: the skeleton clips are imported onto.
        seed: the synthetic walk's seed.
    """

    dev_dir: Path | None = None
    gltf: tuple[Path, ...] = ()
    species: str = "dog"
    seed: int = 3


@dataclass(frozen=True)
class RecoveryRow:
    """One clip made in place and recovered.

    Attributes:
        clip: its name.
        detected: the import found the in-place clip.
        distance_m: the original import's root path length [m].
        path_share: the recovered root path's largest distance from the original's, over
            ``distance_m``.
        heading_error_deg: the recovered net displacement's heading against the
            original's [deg].
        stance_f1: pooled stance F1 of the recovered import against the original's.
    """

    clip: str
    detected: bool
    distance_m: float
    path_share: float
    heading_error_deg: float
    stance_f1: float


@dataclass(frozen=True)
class LoopRow:
    """One game loop imported.

    Attributes:
        clip: its name (file:animation).
        gait: ``walk`` or ``run``.
        detected: the import found it in place.
        loop: the loop kind (``closed``, ``open``, ``no``).
        recovered_m: the recovered travel [m].
        stance_share: (4,) each foot's stance share.
        stance_toe_per_leg: the highest toe during labelled stance [leg lengths].
    """

    clip: str
    gait: str
    detected: bool
    loop: str
    recovered_m: float
    stance_share: tuple[float, ...]
    stance_toe_per_leg: float


@dataclass(frozen=True)
class InPlaceBenchResult:
    """The rows of a run and its target checks."""

    recovery: tuple[RecoveryRow, ...]
    loops: tuple[LoopRow, ...]
    checks: tuple[TargetCheck, ...]


def make_in_place(bvh: object, up: str) -> object:
    """A BVH clip with its root's horizontal position channels held at their first frame.

    Args:
        bvh: the :class:`~habitsim.bvh.BVHData`.
        up: its up axis (``"+y"``, ``"z"``, …; the import's ``mapping.frame.up``).
    """
    from habitsim.bvh import BVHData

    assert isinstance(bvh, BVHData)
    axis = up.strip("+-").upper()
    frames = bvh.frames.copy()
    start = bvh.channel_start[0]
    for i, ch in enumerate(bvh.channels[0]):
        if ch.endswith("position") and ch[0] != axis:
            frames[:, start + i] = frames[0, start + i]
    return dataclasses.replace(bvh, frames=frames)


def synthetic_walk(seed: int = 3, seconds: float = 3.0, in_place: bool = True) -> Motion:
    """A habitsim synthetic dog walk, an exact loop of whole strides (the frame rate is
    chosen so a stride is 24 frames), its root's horizontal travel removed when
    ``in_place``: a :class:`~habitsim.motion.Motion`."""
    from habitsim.gaits import generate

    probe = generate("dog", "walk", seed=seed, duration_s=seconds)
    fps = 24.0 * float(probe.metadata["stride_frequency_hz"])
    m = generate("dog", "walk", seed=seed, duration_s=seconds, fps=fps)
    n = 24 * int(m.num_frames // 24) + 1
    m = m.slice(0, n)
    return held_in_place(m) if in_place else m


def held_in_place(m: Motion) -> Motion:
    """``m`` with its root's horizontal travel removed (held at the first frame)."""
    from habitsim.motion import Motion

    root = m.root_positions.copy()
    root[:, :2] = root[0, :2]
    return Motion(m.species, m.fps, root, m.rotations, m.contacts, dict(m.metadata))


def _heading(xy: np.ndarray) -> float:
    d = xy[-1] - xy[0]
    return math.degrees(math.atan2(d[1], d[0]))


def recovery_row(name: str, original: object, in_place: object) -> RecoveryRow:
    """Compare the import of an in-place clip with the import of the clip it was made from
    (both :class:`~habitsim.motion.Motion`)."""
    from habitsim.bvh_mapping.report import ImportReport
    from habitsim.motion import Motion
    from habitsim.stance.labels import pooled_stance_f1

    assert isinstance(original, Motion) and isinstance(in_place, Motion)
    a = original.root_positions[:, :2] - original.root_positions[0, :2]
    b = in_place.root_positions[:, :2] - in_place.root_positions[0, :2]
    dist = float(np.linalg.norm(np.diff(a, axis=0), axis=-1).sum())
    err = float(np.linalg.norm(a - b, axis=-1).max())
    dh = (_heading(b) - _heading(a) + 180.0) % 360.0 - 180.0
    rep = ImportReport.from_metadata(in_place.metadata)
    detected = bool(rep is not None and rep.in_place is not None and rep.in_place.detected)
    f1 = (
        pooled_stance_f1(in_place.contacts, original.contacts)
        if in_place.contacts is not None and original.contacts is not None
        else 0.0
    )
    return RecoveryRow(name, detected, dist, err / max(dist, 1e-9), abs(dh), float(f1))


def loop_row(name: str, gait: str, motion: object) -> LoopRow:
    """The stance shares and stance toe heights of an imported game loop."""
    from habitsim.bvh_mapping.report import ImportReport
    from habitsim.motion import Motion

    assert isinstance(motion, Motion)
    c = motion.contacts if motion.contacts is not None else np.zeros((motion.num_frames, 4), bool)
    toes = motion.foot_positions()[..., 2] / motion.species_info.leg_length
    top = float(toes[c].max()) if c.any() else 0.0
    rep = ImportReport.from_metadata(motion.metadata)
    ip = None if rep is None else rep.in_place
    return LoopRow(
        name,
        gait,
        bool(ip is not None and ip.detected),
        "no" if ip is None else ip.loop,
        0.0 if ip is None else ip.recovered_m,
        tuple(float(v) for v in c.mean(axis=0)),
        top,
    )


def _dev_clips(folder: Path) -> list[Path]:
    if not folder.is_dir():
        raise BenchInPlaceError(f"{folder}: not a folder; give a folder of .bvh clips")
    clips = sorted(
        p
        for p in folder.iterdir()
        if p.suffix.lower() == ".bvh" and ("walk" in p.stem.lower() or "run" in p.stem.lower())
    )
    if not clips:
        raise BenchInPlaceError(
            f"{folder}: no walk or run clip (a .bvh file whose name contains walk or run)"
        )
    return clips


def run_inplace(options: InPlaceBenchOptions | None = None) -> InPlaceBenchResult:
    """Run the benchmark (see the module docstring)."""
    import tempfile

    from habitsim.bvh import write_bvh
    from habitsim.bvh_mapping import import_bvh, read_source

    opts = options or InPlaceBenchOptions()
    recovery: list[RecoveryRow] = []
    loops: list[LoopRow] = []
    with tempfile.TemporaryDirectory() as tmp:
        walk = synthetic_walk(opts.seed, in_place=False)
        still = held_in_place(walk)
        orig, _ = import_bvh(write_bvh(walk, Path(tmp) / "walk.bvh"), opts.species)
        inpl, _ = import_bvh(write_bvh(still, Path(tmp) / "walk_in_place.bvh"), opts.species)
    recovery.append(recovery_row("synthetic walk", orig, inpl))
    loops.append(loop_row("synthetic walk loop", "walk", inpl))
    if opts.dev_dir is not None:
        for p in _dev_clips(Path(opts.dev_dir)):
            bvh = read_source(p)
            o, mapping = import_bvh(bvh, opts.species)
            assert mapping.frame is not None
            i, _ = import_bvh(make_in_place(bvh, mapping.frame.up), opts.species)  # type: ignore[arg-type]
            recovery.append(recovery_row(p.name, o, i))
    for g in opts.gltf:
        if not Path(g).is_file():
            raise BenchInPlaceError(f"{g}: no such file; give a .glb or .gltf file")
        for anim, gait in (("Walk", "walk"), ("Run", "run")):
            m, _ = import_bvh(read_source(g, animation=anim), opts.species)
            loops.append(loop_row(f"{Path(g).name}:{anim}", gait, m))
    res = InPlaceBenchResult(tuple(recovery), tuple(loops), ())
    return dataclasses.replace(res, checks=tuple(evaluate_targets(res)))


def evaluate_targets(res: InPlaceBenchResult) -> list[TargetCheck]:
    """The issue's targets against a run: the worst clip of each figure."""
    out = []
    rec = res.recovery
    if rec:
        path = max(r.path_share for r in rec)
        head = max(r.heading_error_deg for r in rec)
        f1 = min(r.stance_f1 for r in rec)
        out += [
            TargetCheck(
                "recovered root path, worst clip [share of distance]",
                path,
                f"{100 * path:.1f} %",
                f"≤ {100 * PATH_SHARE:.0f} %",
                verdict(path <= PATH_SHARE),
            ),
            TargetCheck(
                "recovered heading, worst clip",
                head,
                f"{head:.1f}°",
                f"≤ {HEADING_DEG:.0f}°",
                verdict(head <= HEADING_DEG),
            ),
            TargetCheck(
                "stance F1 against the original, worst clip",
                f1,
                f"{f1:.3f}",
                f"≥ {STANCE_F1:g}",
                verdict(f1 >= STANCE_F1),
            ),
        ]
    walks = [r for r in res.loops if r.gait == "walk"]
    if walks:
        lo = min(min(r.stance_share) for r in walks)
        hi = max(max(r.stance_share) for r in walks)
        ok = lo >= WALK_STANCE[0] and hi <= WALK_STANCE[1]
        out.append(
            TargetCheck(
                "game-loop walk stance share, every foot",
                lo,
                f"{lo:.2f}–{hi:.2f}",
                f"{WALK_STANCE[0]:g}–{WALK_STANCE[1]:g}",
                verdict(ok),
            )
        )
    if res.loops:
        top = max(r.stance_toe_per_leg for r in res.loops)
        out.append(
            TargetCheck(
                "game-loop highest stance toe [leg lengths]",
                top,
                f"{100 * top:.2f} %",
                f"≤ {100 * CONTACT_HEIGHT_PER_LEG:.0f} %",
                verdict(top <= CONTACT_HEIGHT_PER_LEG + 1e-9),
            )
        )
    return out
