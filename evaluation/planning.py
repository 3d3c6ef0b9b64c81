"""Planning a benchmark run: its data set (built when none is given) and every
(method, source clip, target species) task, in a fixed order."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from .config import EvalConfig, EvalError, PairTask

__all__ = ["DEFAULT_DATA_CLIPS_PER_SPECIES", "clip_key", "default_data", "plan_tasks"]

#: Clips per species of the data set ``habitsim eval`` builds when given no ``--data``
#: (every species; 1–3 validation clips per training species, the first a trot for 8 of
#: the 12, and 16–18 train clips as the set metrics' real references).
DEFAULT_DATA_CLIPS_PER_SPECIES = 20


def default_data(
    out: str | Path,
    *,
    workers: int | None = None,
    progress: bool = True,
    log: Callable[[str], None] | None = None,
    clips_per_species: int = DEFAULT_DATA_CLIPS_PER_SPECIES,
) -> Path:
    """The synthetic data set of a run given no data: ``OUT/data``, every species,
    ``clips_per_species`` clips each (default :data:`DEFAULT_DATA_CLIPS_PER_SPECIES`),
    seed 0; built on the first run and reused after (a folder holding another
    configuration is rebuilt).

    Raises:
        DatasetError: ``OUT/data`` cannot be written.
    """
    from habitsim.dataset import build_dataset, check_resumable
    from habitsim.errors import DatasetError

    folder = Path(out) / "data"
    try:
        check_resumable(folder, seed=0)
        overwrite = False
    except DatasetError:
        overwrite = True  # another configuration (or not a data set): rebuild it
    if log:
        log(
            f"eval: no --data given: the default synthetic data set in {folder} "
            f"({clips_per_species} clips per species, seed 0)"
        )
    build_dataset(
        folder,
        clips_per_species=clips_per_species,
        seed=0,
        workers=workers,
        progress=progress,
        overwrite=overwrite,
    )
    return folder


def _manifest(cfg: EvalConfig):
    from habitsim.dataset import load_manifest

    return load_manifest(cfg.data, check_files=False, follow_symlinks=cfg.follow_symlinks)


def _targets(cfg: EvalConfig, man) -> list[str]:
    from habitsim.species import load_species

    if cfg.targets is None:
        return [s["name"] for s in man.species if not s["held_out"]]
    return [load_species(t).name for t in cfg.targets]


def plan_tasks(cfg: EvalConfig) -> list[PairTask]:
    """Every (source clip, target, method) task of a run, in a fixed order.

    Raises:
        EvalError: unknown methods, no clips in the split, no targets.
    """
    from habitsim.transfer_methods import get_method

    folders = dict(cfg.outputs)
    for m in cfg.methods:
        if m not in folders:
            get_method(m)  # raises UnknownMethodError listing the registered ones
    man = _manifest(cfg)
    clips = man.select(split=cfg.split, species=cfg.sources)
    if cfg.clips_per_source is not None:
        seen: dict[str, int] = {}
        kept = []
        for c in clips:
            seen[c.species] = seen.get(c.species, 0) + 1
            if seen[c.species] <= cfg.clips_per_source:
                kept.append(c)
        clips = kept
    if cfg.max_clips is not None:
        clips = clips[: cfg.max_clips]
    if not clips:
        raise EvalError(
            f"the data set at {cfg.data} has no {cfg.split!r} clips"
            + (f" of {', '.join(cfg.sources)}" if cfg.sources else "")
        )
    targets = _targets(cfg, man)
    if not targets:
        raise EvalError("no target species")
    held = {s["name"]: bool(s["held_out"]) for s in man.species}
    from habitsim.species import load_species

    trace_pairs = _report_pairs(clips, targets, cfg.report_pairs, cfg.include_self)
    tasks = []
    owner: dict[str, str] = {}
    for c in clips:
        clip_id = clip_key(c.path)
        if owner.setdefault(clip_id, c.path) != c.path:
            raise EvalError(
                f"the data set at {cfg.data} has clips {owner[clip_id]!r} and {c.path!r} "
                "whose row keys would be the same; rename one"
            )
        for t in targets:
            if t == c.species and not cfg.include_self:
                continue
            for m in cfg.methods:
                tasks.append(
                    PairTask(
                        key=f"{m}__{clip_id}__{t}",
                        method=m,
                        clip=c.path,
                        clip_path=str(Path(cfg.data) / c.path),
                        source=c.species,
                        target=t,
                        target_held_out=held.get(t, load_species(t).held_out),
                        action=c.action,
                        gait=c.gait,
                        pair_key=c.pair_key,
                        refine=cfg.refine,
                        controller=cfg.controller,
                        assist=cfg.assist,
                        track=cfg.track,
                        dynamic=cfg.dynamic,
                        seed=cfg.seed,
                        evaluator=cfg.evaluator,
                        out=cfg.out,
                        trace=(c.path, t) in trace_pairs,
                        videos=cfg.videos,
                        outputs=folders.get(m),
                        method_timeout_s=cfg.method_timeout_s,
                    )
                )
    return tasks


def clip_key(path: str) -> str:
    """A clip's part of a row key: its path relative to the data set folder without the
    suffix, ``/`` written ``~`` (``val/cat/cat_walk_0003.npz`` → ``val~cat~cat_walk_0003``),
    so two clips of the same file name in two folders get two rows."""
    return Path(path).with_suffix("").as_posix().replace("/", "~")


def _report_pairs(clips, targets: list[str], n: int, include_self: bool) -> set[tuple[str, str]]:
    """Up to n (clip, target) pairs for the report: locomotion clips of distinct actions,
    each to a different target."""
    from habitsim.gaits import LOCOMOTION_ACTIONS

    out: set[tuple[str, str]] = set()
    seen: set[str] = set()
    ti = 0
    pool = [c for c in clips if c.action in LOCOMOTION_ACTIONS] or list(clips)
    for c in pool:
        if len(out) >= n:
            break
        if c.action in seen and len({x.action for x in pool}) > len(seen):
            continue
        for _ in range(len(targets)):
            t = targets[ti % len(targets)]
            ti += 1
            if t != c.species or include_self:
                out.add((c.path, t))
                seen.add(c.action)
                break
    return out
