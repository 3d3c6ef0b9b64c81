"""What a benchmark run is: its configuration (:class:`EvalConfig`), its unit of work
(:class:`PairTask`), the defaults of ``habitsim eval`` and the run's typed error.

Light on purpose (no numpy work, no torch): the command line reads the defaults from here
to build its parser.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from habitsim.controllers import CONTROLLERS
from habitsim.errors import HabitsimError, unknown_choice

__all__ = [
    "EvalError",
    "EvalConfig",
    "PairTask",
    "REFINE_MODES",
    "DEFAULT_METHODS",
    "DEFAULT_CONTROLLER",
    "DEFAULT_TARGETS",
    "DEFAULT_CLIPS_PER_SOURCE",
    "RUN_FORMAT_VERSION",
]

REFINE_MODES = ("none", "kinematic", "dynamics")

#: What ``habitsim eval`` measures with no options: the product's own method beside the
#: baseline and the paired ground truth, refinement stage A (``kinematic``) and the
#: controller the README recommends, unassisted.
DEFAULT_METHODS = ("habit", "direct", "ground_truth")
DEFAULT_CONTROLLER = "mpc"
#: The default run's size, chosen to finish within 20 min on 2 cores: the first
#: validation clip of every training species (12 sources) to three targets of different
#: build (small digitigrade, large unguligrade, pacer): 33 pairs per method, 99 in all.
DEFAULT_TARGETS = ("cat", "horse", "camel")
DEFAULT_CLIPS_PER_SOURCE = 1
#: Format version of a run folder's files.
RUN_FORMAT_VERSION = 1


class EvalError(HabitsimError, ValueError):
    """Bad benchmark input: unknown method / refine mode / species, a data set without
    clips in the split, an output folder holding another run (without ``--resume``)."""


@dataclass(frozen=True)
class EvalConfig:
    """What a benchmark run does.

    Attributes:
        data: synthetic data set folder.
        out: output folder.
        methods: method names (:func:`habitsim.transfer_methods.method_names`).
        refine: ``none``, ``kinematic`` or ``dynamics``.
        controller: tracking controller (:data:`habitsim.controllers.CONTROLLERS`).
        assist: root assistance while tracking.
        track: run the MuJoCo tracking at all.
        dynamic: compute the dynamic plausibility (inverse dynamics) of the reference.
        split: split of the source clips.
        sources: only these source species (None: all of the split).
        targets: target species (None: the data set's training species).
        include_self: also transfer a clip to its own species.
        max_clips: only the first N source clips (manifest order) — for quick runs.
        clips_per_source: only the first N clips of each source species (manifest
            order; None: all), applied before ``max_clips``.
        reference_split: comma-separated splits of the real clips for the set metrics
            (only the summary depends on it; it may change on ``--resume``).
        evaluator: evaluator folder (None: the shipped one).
        seed: seed passed to the methods and used by the set metrics.
        report_pairs: pairs per method whose traces (gait diagrams, tracking error,
            videos) are kept for the report.
        videos: render videos of the report pairs when :mod:`habitsim.render` works.
        outputs: ``(name, folder)`` of methods whose transfers are files in a folder
            (:mod:`habitsim.evaluation.outputs`: ``DIR/<target>/<clip_id>.npz`` or
            ``.bvh``); each name is added to ``methods`` when it is not there.
        follow_symlinks: read clips through links in ``data`` that lead out of it (else
            they are refused).
        method_timeout_s: time limit of one call of a transfer method [s] (None: none);
            a call that runs longer is stopped in its worker and its row fails with the
            note ``method X exceeded N s`` (:mod:`habitsim.timelimit`).
        worker_retries: how many times a pair whose worker process died (killed, e.g.
            by the out-of-memory killer) is run again before its row fails
            (:class:`habitsim.evaluation.executors.ExecutorOptions`).
    """

    data: str
    out: str
    methods: tuple[str, ...] = DEFAULT_METHODS
    refine: str = "kinematic"
    controller: str = DEFAULT_CONTROLLER
    assist: bool = False
    track: bool = True
    dynamic: bool = True
    split: str = "val"
    sources: tuple[str, ...] | None = None
    targets: tuple[str, ...] | None = None
    include_self: bool = False
    max_clips: int | None = None
    clips_per_source: int | None = None
    reference_split: str = "train,val"
    evaluator: str | None = None
    seed: int = 0
    report_pairs: int = 3
    videos: bool = True
    outputs: tuple[tuple[str, str], ...] = ()
    follow_symlinks: bool = False
    method_timeout_s: float | None = None
    worker_retries: int = 2

    def __post_init__(self) -> None:
        object.__setattr__(self, "data", str(Path(self.data).resolve()))
        object.__setattr__(self, "out", str(Path(self.out).resolve()))
        outputs = tuple((str(n), str(Path(f).resolve())) for n, f in self.outputs)
        object.__setattr__(self, "outputs", outputs)
        names = [n for n, _ in outputs]
        if len(set(names)) != len(names):
            raise EvalError(f"outputs named twice: {', '.join(names)}")
        extra = tuple(n for n in names if n not in self.methods)
        object.__setattr__(self, "methods", tuple(self.methods) + extra)
        if self.sources is not None:
            object.__setattr__(self, "sources", tuple(self.sources))
        if self.targets is not None:
            object.__setattr__(self, "targets", tuple(self.targets))
        if self.evaluator is not None:
            object.__setattr__(self, "evaluator", str(Path(self.evaluator).resolve()))
        if not self.methods:
            raise EvalError("no methods given")
        if len(set(self.methods)) != len(self.methods):
            raise EvalError(f"methods listed twice: {', '.join(self.methods)}")
        from habitsim.dataset import SPLITS

        bad = [x for x in self.reference_split.split(",") if x.strip() not in SPLITS]
        if bad or not self.reference_split.strip():
            raise EvalError(
                f"reference_split {self.reference_split!r}: comma-separated splits of "
                f"{', '.join(SPLITS)}"
            )
        if self.refine not in REFINE_MODES:
            raise EvalError(unknown_choice("refine mode", self.refine, REFINE_MODES))
        if self.controller not in CONTROLLERS:
            raise EvalError(unknown_choice("controller", self.controller, CONTROLLERS))
        if self.max_clips is not None and self.max_clips < 1:
            raise EvalError(f"max_clips must be >= 1, got {self.max_clips}")
        if self.clips_per_source is not None and self.clips_per_source < 1:
            raise EvalError(f"clips_per_source must be >= 1, got {self.clips_per_source}")
        t = self.method_timeout_s
        if t is not None and (
            isinstance(t, bool) or not isinstance(t, int | float) or not 0 < t <= 1e6
        ):
            raise EvalError(f"method_timeout_s {t!r}; valid: a number of seconds in (0, 1e6]")
        r = self.worker_retries
        if isinstance(r, bool) or not isinstance(r, int) or not 0 <= r <= 100:
            raise EvalError(f"worker_retries {r!r}; valid: a whole number from 0 to 100")

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        for k in ("methods", "sources", "targets"):
            if d[k] is not None:
                d[k] = list(d[k])
        d["outputs"] = [list(o) for o in self.outputs]
        return d

    #: fields that must match for --resume (the others only select which pairs run)
    RESUME_KEYS = (
        "data",
        "refine",
        "controller",
        "assist",
        "track",
        "dynamic",
        "evaluator",
        "seed",
    )


@dataclass(frozen=True)
class PairTask:
    """One (method, source clip, target) unit of work; plain data, picklable."""

    key: str
    method: str
    clip: str
    clip_path: str
    source: str
    target: str
    target_held_out: bool
    action: str
    gait: str
    pair_key: str
    refine: str
    controller: str
    assist: bool
    track: bool
    dynamic: bool
    seed: int
    evaluator: str | None
    out: str
    trace: bool = False
    videos: bool = False
    #: the folder of the method's outputs (:mod:`habitsim.evaluation.outputs`; None: a
    #: registered method)
    outputs: str | None = None
    #: time limit of one call of the method [s] (None: none)
    method_timeout_s: float | None = None
