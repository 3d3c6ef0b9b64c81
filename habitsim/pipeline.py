"""One clip through the whole pipeline: source → transfer → refine → track → metrics.

:func:`run_clip` is the one place where the stages are chained; the demo
(``habitsim demo``), the evaluation (``habitsim eval``, :mod:`habitsim.evaluation.runner`)
and the benchmarks (``habitsim bench real``) all call it per clip. It returns a
:class:`ClipRun` holding, per stage, the motion, its qpos on the target's MuJoCo model,
its stance labels and how they were found, the wall time and the stage's metrics.

Stance labels travel, they are never found twice:

* **transfer** labels its output (:func:`habitsim.stance.schedule.transfer_contacts`:
  the source's footfalls when the source has labels, else detected on resting feet, else
  the duty-factor guess; a method that returns labels of its own keeps them);
* **refine** plants exactly those labels (``refine(..., contacts=...)``) and returns them;
* **track** gets the refined labels as its reference contact schedule (the ``balance`` /
  ``mpc`` controllers' plan and the reference of ``contact_f1``:
  ``track(..., contacts=...)``).

The target species' model is the shared compiled one (:func:`habitsim.qpos.species_model`),
handed to refinement and used by tracking, so a species is compiled once per process.

Refinement never makes a clip worse unnoticed: with ``guard=True`` (default) and a
successful refinement, the unrefined transfer is tracked too; when the refined clip
tracks worse (lower survival, or equal survival and a sim MPJPE more than
:attr:`GuardOptions.mpjpe_ratio` × the input's plus
:attr:`GuardOptions.mpjpe_margin_per_leg`), the
pipeline keeps the unrefined clip as the tracked reference, says so in
:attr:`ClipRun.refine_verdict` (``reverted``) and :attr:`ClipRun.refine_note`, and keeps
both results.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .errors import HabitsimError, unknown_choice
from .motion import Motion
from .species import load_species
from .stance.labels import EditReason, StanceLabels, StanceSource
from .stance.report import TransferRecord

if TYPE_CHECKING:  # pragma: no cover
    import mujoco

    from .captions.facts import ClipFacts
    from .captions.prompts import PromptReading
    from .refine import RefineOptions, RefineResult
    from .sim import TrackResult
    from .transfer_methods import TransferMethod

__all__ = [
    "PipelineError",
    "REFINE_MODES",
    "REFINE_ALIASES",
    "GuardOptions",
    "Metrics",
    "Stage",
    "ClipRun",
    "run_clip",
    "TextRun",
    "run_text",
    "track_reference",
    "stance_toe_height",
    "refine_mode",
]

#: Refinement modes of :func:`run_clip`: none, stage A (kinematic), stage B (dynamics).
REFINE_MODES = ("none", "A", "B")
#: Other names accepted for the modes (the evaluation's ``--refine`` values).
REFINE_ALIASES = {"kinematic": "A", "dynamics": "B", "dynamic": "B", "a": "A", "b": "B"}


@dataclass(frozen=True)
class GuardOptions:
    """The thresholds of the refinement guard (``guard`` of :func:`run_clip`): at equal
    survival the refined clip "tracks clearly worse" when its sim MPJPE exceeds the
    input's × ``mpjpe_ratio`` + ``mpjpe_margin_per_leg``.

    Attributes:
        mpjpe_ratio: factor on the unrefined clip's sim MPJPE [unitless].
        mpjpe_margin_per_leg: margin added to it [share of the hind-leg length].
    """

    mpjpe_ratio: float = 1.10
    mpjpe_margin_per_leg: float = 0.005


#: A stage's metrics: name → value (numbers; the simulated ``fell`` is a bool).
Metrics = dict[str, float | bool]


class PipelineError(HabitsimError, ValueError):
    """Bad pipeline options: an unknown refinement mode, a source that is no Motion."""


def refine_mode(mode: str) -> str:
    """The canonical refinement mode (``none``, ``A`` or ``B``) of a name or alias.

    Raises:
        PipelineError: an unknown mode (the message lists the valid ones).
    """
    m = REFINE_ALIASES.get(str(mode), str(mode))
    if m not in REFINE_MODES:
        raise PipelineError(unknown_choice("refine mode", mode, (*REFINE_MODES, *REFINE_ALIASES)))
    return m


#: :attr:`Stage.contacts_method` of labels by their source (the others: their code).
_METHOD_OF_SOURCE = {StanceSource.INPUT: "labels"}


@dataclass
class Stage:
    """One stage's output.

    Attributes:
        name: ``source``, ``transfer``, ``refine`` or ``track``.
        motion: the stage's motion (tracking: the simulated frames; None when the stage
            did not run).
        labels: its (T, 4) stance labels (feet LF, RF, LH, RH), where they came from and
            the edits made to them (tracking: the simulated foot contacts); None when
            the stage has none.
        wall_time_s: the stage's wall time [s] (0 for the source).
        metrics: the stage's metrics (kinematic plausibility and stance toe height for
            motions; the simulated metrics for tracking).
        status: ``ok``, or what happened (refinement's IPOPT status, ``fell``,
            ``error: …``, ``off``).
        species: the species of the motion.
        transfer: the transferred motion's ``metadata["transfer"]``, typed (the
            transfer and refine stages of a method that writes it; else None).
    """

    name: str
    motion: Motion | None
    labels: StanceLabels | None
    wall_time_s: float = 0.0
    metrics: Metrics = field(default_factory=dict)
    status: str = "ok"
    species: str = ""
    transfer: TransferRecord | None = None
    _qpos: np.ndarray | None = field(default=None, repr=False)

    @property
    def contacts(self) -> np.ndarray | None:
        """(T, 4) bool stance labels (read-only; None when the stage has none)."""
        return None if self.labels is None else self.labels.array

    @property
    def contacts_method(self) -> str:
        """How the labels were found: ``source`` (the source's footfalls), ``decoded``,
        ``detected``, ``duty`` (a foot labelled by its gait's duty factor), ``method``
        (the transfer method's own labels), ``labels`` (the source motion's own),
        ``simulated``, or ``none`` (the code written to reports and rows)."""
        lab = self.labels
        if lab is None:
            return "none"
        if any(e.reason == EditReason.DUTY_FOOT for e in lab.edits):
            return "duty"
        return _METHOD_OF_SOURCE.get(lab.source, lab.source.value)

    @property
    def qpos(self) -> np.ndarray | None:
        """(T, nq) the motion's qpos on its species' shipped model (computed once)."""
        if self._qpos is None and self.motion is not None:
            from .qpos import motion_to_qpos, species_model

            self._qpos = motion_to_qpos(self.motion, species_model(self.motion.species)).qpos
        return self._qpos


@dataclass
class ClipRun:
    """One clip through :func:`run_clip`.

    Attributes:
        target: target species; method: transfer method; refine: ``none``/``A``/``B``;
        controller: tracking controller; assist: root assistance; seed: the seed.
        model: the target species' compiled MuJoCo model (the shared instance of
            :func:`habitsim.qpos.species_model`; do not modify).
        source, transferred, refined, tracked: the stages (:class:`Stage`). ``refined``
            is the transferred stage's motion again when ``refine == "none"``;
            ``tracked`` is the run of the kept reference (see ``refine_verdict``).
        refine_result: :func:`habitsim.refine.refine`'s result (None without refinement).
        track_result: the kept :class:`~habitsim.sim.TrackResult` (None untracked).
        input_track_result: the tracking of the unrefined transfer, when the refinement
            was checked (``guard``).
        refine_verdict: ``kept`` (refined clip tracked no worse), ``reverted`` (it
            tracked worse: the unrefined transfer is the tracked reference), ``fallback``
            (refinement failed and returned its input), ``unchecked`` (not compared:
            no tracking or ``guard=False``), ``none`` (no refinement).
        refine_note: one line for reports saying what the verdict rests on.
    """

    target: str
    method: str
    refine: str
    controller: str
    assist: bool | str
    seed: int
    model: mujoco.MjModel
    source: Stage
    transferred: Stage
    refined: Stage
    tracked: Stage
    refine_result: RefineResult | None = None
    track_result: TrackResult | None = None
    input_track_result: TrackResult | None = None
    refine_verdict: str = "none"
    refine_note: str = ""

    @property
    def stages(self) -> dict[str, Stage]:
        """Stage name → stage, in pipeline order."""
        return {s.name: s for s in (self.source, self.transferred, self.refined, self.tracked)}

    @property
    def times(self) -> dict[str, float]:
        """Wall time per stage [s] (``track`` includes the check's second run)."""
        return {k: s.wall_time_s for k, s in self.stages.items() if k != "source"}

    @property
    def metrics(self) -> dict[str, Metrics]:
        """Metrics per stage."""
        return {k: s.metrics for k, s in self.stages.items()}

    @property
    def reference(self) -> Motion:
        """The motion that was (or would be) tracked: the refined one unless reverted."""
        if self.refine_verdict == "reverted":
            assert self.transferred.motion is not None
            return self.transferred.motion
        assert self.refined.motion is not None
        return self.refined.motion

    @property
    def reference_contacts(self) -> np.ndarray | None:
        """The stance labels of :attr:`reference` (the tracking's contact schedule)."""
        if self.refine_verdict == "reverted":
            return self.transferred.contacts
        return self.refined.contacts


# ---------------------------------------------------------------------------- metrics


def stance_toe_height(motion: Motion, contacts: np.ndarray | None) -> float:
    """Median height of the toes the labels put in stance / leg length (NaN without any)."""
    if contacts is None:
        return math.nan
    c = np.asarray(contacts, dtype=bool)
    if not c.any():
        return math.nan
    z = motion.foot_positions()[..., 2]
    return float(np.median(z[c]) / motion.species_info.leg_length)


def _motion_metrics(motion: Motion, contacts: np.ndarray | None) -> Metrics:
    """docs/metrics.md kinematic metrics (literal contact definition), the skating under the
    stage's own labels, and the stance toe height."""
    from .metrics.kinematic import kinematic_metrics, skate_mm

    out: Metrics = dict(kinematic_metrics(motion))
    out["stance_toe_height_per_leg"] = stance_toe_height(motion, contacts)
    out["skate_labelled_mm"] = (
        math.nan if contacts is None else float(skate_mm(motion, np.asarray(contacts, bool)))
    )
    return out


def _method_labels(contacts: np.ndarray, record: TransferRecord | None) -> StanceLabels:
    """A transfer method's own labels: their source is the schedule's method its
    ``metadata["transfer"]`` names (``decoded``, ``source``, ``detected``, ``duty``,
    ``planned``, …), :attr:`StanceSource.METHOD` when it names none or a code of its own.
    The edits the method made are recorded in its own report
    (:attr:`habitsim.stance.report.ConformReport.labels`), not in the motion."""
    code = None if record is None or record.contacts is None else record.contacts.method
    known = {s.value for s in StanceSource}
    return StanceLabels(contacts, StanceSource(code) if code in known else StanceSource.METHOD)


# ---------------------------------------------------------------------------- stages


def _transfer(
    source: Motion, target: str, method: str | TransferMethod, seed: int, clip_id: str | None
) -> Stage:
    from .transfer_methods import run_method

    t0 = time.perf_counter()
    out = run_method(method, source, target, seed=seed, clip_id=clip_id)
    record = TransferRecord.from_metadata(out.metadata)
    if out.contacts is not None:
        labels = _method_labels(np.asarray(out.contacts, dtype=bool), record)
    else:  # the method gave no labels: the transfer stage finds them, once
        from .stance.schedule import transfer_contacts

        labels, _ = transfer_contacts(out, source)
    wall = time.perf_counter() - t0
    return Stage(
        "transfer",
        out,
        labels,
        wall,
        _motion_metrics(out, labels.array),
        species=out.species,
        transfer=record,
    )


def _refine(
    stage: Stage, mode: str, model: mujoco.MjModel, options: RefineOptions | None
) -> tuple[Stage, RefineResult | None]:
    if mode == "none":
        return (
            Stage(
                "refine",
                stage.motion,
                stage.labels,
                0.0,
                dict(stage.metrics),
                "none",
                stage.species,
                stage.transfer,
                stage._qpos,
            ),
            None,
        )
    from dataclasses import replace

    from .refine import RefineOptions, refine

    opts = options or RefineOptions(metrics=False)
    opts = replace(opts, dynamics=mode == "B", fallback=True)
    assert stage.motion is not None  # the transfer stage always has a motion
    t0 = time.perf_counter()
    res = refine(stage.motion, opts, contacts=np.array(stage.contacts), model=model)
    wall = time.perf_counter() - t0
    labels = _refined_labels(stage.labels, res)
    st = Stage(
        "refine",
        res.motion,
        labels,
        wall,
        _motion_metrics(res.motion, labels.array),
        str(res.status),
        stage.species,
        stage.transfer,
        np.asarray(res.qpos),
    )
    return st, res


def _refined_labels(given: StanceLabels | None, res: RefineResult) -> StanceLabels:
    """The labels a refinement planted: the transfer's, their source kept, with the
    refinement's edits (its cleaning) appended."""
    contacts = np.asarray(res.contacts, dtype=bool)
    done = () if res.labels is None else res.labels.edits
    if given is None:
        return StanceLabels(contacts, StanceSource.GIVEN, done)
    return StanceLabels(contacts, given.source, (*given.edits, *done))


def _run_track(
    motion: Motion, contacts: np.ndarray | None, controller: str, assist: bool | str, seed: int
) -> tuple[TrackResult | None, str, float]:
    """(result, status, wall time); a tracking failure is a status, not an exception."""
    from .sim import track

    t0 = time.perf_counter()
    try:
        res = track(motion, controller=controller, assist=assist, seed=seed, contacts=contacts)
    except HabitsimError as e:
        return None, f"error: {e}", time.perf_counter() - t0
    except Exception as e:  # noqa: BLE001 - a tracker bug is recorded, the caller goes on
        return None, f"error: {type(e).__name__}: {e}", time.perf_counter() - t0
    return res, ("fell" if res.failed else "ok"), time.perf_counter() - t0


def _writable(stage: Stage) -> np.ndarray | None:
    """A stage's (T, 4) labels as a fresh array (what tracking takes)."""
    return None if stage.contacts is None else np.array(stage.contacts)


def _worse(
    refined: TrackResult, plain: TrackResult, options: GuardOptions = GuardOptions()
) -> str | None:
    """Why the refined clip tracks worse than its input, or None."""
    sr, sp = float(refined.survival), float(plain.survival)
    if sr < sp - 1e-9:
        return f"survival {sr:.2f} < {sp:.2f} unrefined"
    er = float(refined.metrics.get("sim_mpjpe_per_leg", math.nan))
    ep = float(plain.metrics.get("sim_mpjpe_per_leg", math.nan))
    if abs(sr - sp) <= 1e-9 and math.isfinite(er) and math.isfinite(ep):
        if er > ep * options.mpjpe_ratio + options.mpjpe_margin_per_leg:
            return f"equal survival {sr:.2f}, sim MPJPE {er:.3f} > {ep:.3f} leg lengths unrefined"
    return None


def _sim_stage(res: TrackResult | None, status: str, wall: float, species: str) -> Stage:
    if res is None:
        return Stage("track", None, None, wall, {}, status, species)
    st = Stage(
        "track",
        res.motion(),
        StanceLabels(np.asarray(res.contacts, bool), StanceSource.SIMULATED),
        wall,
        dict(res.metrics),
        status,
        species,
        _qpos=np.asarray(res.qpos),
    )
    return st


# ---------------------------------------------------------------------------- entry point


def run_clip(
    source: Motion,
    target: str,
    *,
    method: str | TransferMethod = "habit",
    refine: str = "A",
    controller: str = "mpc",
    assist: bool | str = False,
    seed: int = 0,
    track: bool = True,
    guard: bool = True,
    refine_options: RefineOptions | None = None,
    guard_options: GuardOptions = GuardOptions(),
    clip_id: str | None = None,
) -> ClipRun:
    """Run one clip through transfer → refine → track, with the metrics of every stage.

    Args:
        source: the source motion (its ``contacts`` are the source's stance labels).
        target: target species.
        method: transfer method, a name of the registry
            :data:`habitsim.transfer_methods.METHODS` (``habit``, ``direct``,
            ``ground_truth``, …) or an unregistered
            :class:`~habitsim.transfer_methods.TransferMethod`.
        refine: ``none``, ``A`` (kinematic) or ``B`` (dynamics); ``kinematic`` and
            ``dynamics`` are accepted too. A failed solve keeps its input (fallback) and
            says so in ``refined.status``.
        controller: tracking controller (:data:`habitsim.sim.CONTROLLERS`).
        assist: root assistance while tracking (``False``, ``"root"``/``True``).
        seed: seed of the transfer (and the tracking's, which is deterministic).
        track: run the MuJoCo tracking (``tracked.status == "off"`` when not).
        guard: check that refinement does not make the clip track worse (module
            docstring); costs a second tracking run after a successful refinement.
        refine_options: :class:`~habitsim.refine.RefineOptions` (default: its defaults
            without its own before/after metrics; ``dynamics`` and ``fallback`` are set
            here).
        guard_options: the guard's thresholds (:class:`GuardOptions`).
        clip_id: the source clip's id, passed to a method that takes ``clip_id``
            (:func:`habitsim.transfer_methods.run_method`).

    Returns:
        The :class:`ClipRun`.

    Raises:
        PipelineError: bad options. UnknownSpeciesError: unknown target.
        UnknownMethodError / MethodUnavailable: the method is unknown / cannot serve the
        pair (from :mod:`habitsim.transfer_methods`). RefineInputError: a motion the
        refinement cannot take. Tracking failures are results (``tracked.status``).
    """
    from .qpos import species_model

    if not isinstance(source, Motion):
        raise PipelineError(f"run_clip needs a habitsim Motion, got {type(source).__name__}")
    mode = refine_mode(refine)
    tgt = load_species(target).name
    model = species_model(tgt)
    src_labels = (
        None
        if source.contacts is None
        else StanceLabels(np.asarray(source.contacts), StanceSource.INPUT)
    )
    src = Stage(
        "source",
        source,
        src_labels,
        0.0,
        _motion_metrics(source, source.contacts),
        species=source.species,
    )
    moved = _transfer(source, tgt, method, seed, clip_id)
    refined, rres = _refine(moved, mode, model, refine_options)
    run = ClipRun(
        tgt,
        method if isinstance(method, str) else method.name,
        mode,
        controller,
        assist,
        int(seed),
        model,
        src,
        moved,
        refined,
        Stage("track", None, None, 0.0, {}, "off", tgt),
        refine_result=rres,
    )
    if mode == "none":
        run.refine_verdict, run.refine_note = "none", "no refinement"
    elif rres is not None and not rres.success:
        run.refine_verdict = "fallback"
        run.refine_note = f"refinement failed ({rres.status}); the transfer goes on unrefined"
    else:
        run.refine_verdict = "unchecked"
        run.refine_note = "refinement not checked in simulation"
    if not track:
        return run
    assert refined.motion is not None
    res, status, wall = _run_track(refined.motion, _writable(refined), controller, assist, seed)
    run.track_result = res
    run.tracked = _sim_stage(res, status, wall, tgt)
    if guard and run.refine_verdict == "unchecked" and res is not None:
        assert moved.motion is not None
        plain, pstatus, pwall = _run_track(moved.motion, _writable(moved), controller, assist, seed)
        run.input_track_result = plain
        if plain is None:
            run.refine_verdict = "kept"
            run.refine_note = f"kept the refined clip (the unrefined one: {pstatus})"
            run.tracked.wall_time_s += pwall
        else:
            why = _worse(res, plain, guard_options)
            if why is None:
                run.refine_verdict = "kept"
                run.refine_note = (
                    f"refined clip tracks no worse (survival {res.survival:.2f} vs "
                    f"{plain.survival:.2f} unrefined)"
                )
                run.tracked.wall_time_s += pwall
            else:
                run.refine_verdict = "reverted"
                run.refine_note = (
                    f"refinement made the clip track worse ({why}): kept the unrefined transfer"
                )
                run.track_result = plain
                run.tracked = _sim_stage(plain, pstatus, wall + pwall, tgt)
    return run


def track_reference(
    run: ClipRun,
    *,
    controller: str,
    assist: bool | str = False,
    seed: int | None = None,
    init_noise: float = 0.0,
) -> TrackResult:
    """Track a run's kept reference again (another controller, with assistance, or from a
    perturbed initial state: ``init_noise`` of :func:`habitsim.sim.track`), with the same
    reference contact labels."""
    from .sim import track

    return track(
        run.reference,
        controller=controller,
        assist=assist,
        seed=run.seed if seed is None else seed,
        contacts=run.reference_contacts,
        init_noise=init_noise,
    )


# ---------------------------------------------------------------------------- from text


@dataclass
class TextRun:
    """A prompt through :func:`run_text`.

    Attributes:
        reading: what the prompt names (species, actions).
        species: the species the clip was made for.
        generated: the generated motion (the pipeline's source).
        facts: what the generated clip shows, measured by
            :func:`habitsim.captions.clip_facts` (None: it shows nothing measurable).
        warnings: why the clip may not be what the prompt asks (empty: it is).
        run: the generated clip through refinement and tracking (:class:`ClipRun`; its
            transfer stage is the identity on the species).
    """

    reading: PromptReading
    species: str
    generated: Motion
    facts: ClipFacts | None
    warnings: tuple[str, ...]
    run: ClipRun


def _as_generated(source: Motion, target: str, *, seed: int | None = 0, **_: object) -> Motion:
    """The transfer stage of a generated clip: the motion is already the species'."""
    from .transfer_methods import direct_transfer

    return direct_transfer(source, target, seed=seed)


def run_text(
    text: str,
    species: str | None = None,
    *,
    seconds: float = 4.0,
    seed: int = 0,
    temperature: float = 1.0,
    guidance: float = 2.0,
    top_k: int | None = None,
    checkpoint: str | Path | None = None,
    refine: str = "none",
    controller: str = "mpc",
    track: bool = False,
    guard: bool = True,
    refine_options: RefineOptions | None = None,
    embed: Callable[[Sequence[str]], np.ndarray] | None = None,
) -> TextRun:
    """Make a motion from a prompt, then refine and track it as :func:`run_clip` does.

    The species is the one the text names (name, common name, synonym or plural:
    :func:`habitsim.captions.prompts.read_prompt`), else ``species``. The generated clip
    is measured (:func:`habitsim.captions.clip_facts`); when the prompt names no action
    habitsim makes, or the clip shows none of the ones it names, the clip is still
    returned, with a :class:`~habitsim.captions.prompts.PromptWarning` (also in
    :attr:`TextRun.warnings`) saying what it shows.

    Args:
        text: the prompt ("a horse trots to the left").
        species: the species when the text names none (it must agree when it does).
        seconds, seed, temperature, guidance, top_k, checkpoint, embed: as
            :func:`habitsim.models.t2m.text_to_motion`.
        refine, controller, track, guard, refine_options: as :func:`run_clip`
            (``refine`` also takes ``kinematic`` / ``dynamic``).

    Raises:
        PromptError: the text names several species, another species than ``species``,
            or neither names one (checked before any model is loaded).
        UnknownSpeciesError: ``species`` is not in the catalog.
        GenerationRequestError, MethodNotAvailableError, CheckpointError: as
            :func:`~habitsim.models.t2m.text_to_motion`. PipelineError: a bad ``refine``.
    """
    import warnings as _warnings

    from .captions.prompts import PromptWarning, prompt_species, prompt_warnings, read_prompt
    from .errors import CaptionError
    from .gaits import ACTIONS
    from .models.t2m import check_text, text_to_motion
    from .transfer_methods import TransferMethod

    mode = refine_mode(refine)
    reading = read_prompt(check_text(text))
    sp = prompt_species(reading, species)
    motion = text_to_motion(
        text,
        sp,
        seconds,
        seed=seed,
        temperature=temperature,
        guidance=guidance,
        top_k=top_k,
        checkpoint=checkpoint,
        embed=embed,
    )
    try:
        from .captions import clip_facts

        facts = clip_facts(motion)
    except CaptionError:
        facts = None
    notes = tuple(prompt_warnings(reading, facts, ACTIONS))
    for note in notes:
        _warnings.warn(note, PromptWarning, stacklevel=2)
    method = TransferMethod("text_to_motion", "the generated clip as it is", _as_generated)
    run = run_clip(
        motion,
        motion.species,
        method=method,
        refine=mode,
        controller=controller,
        seed=seed,
        track=track,
        guard=guard,
        refine_options=refine_options,
    )
    return TextRun(reading, motion.species, motion, facts, notes, run)
