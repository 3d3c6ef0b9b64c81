"""One row builder for every benchmark that runs a clip through the pipeline.

:func:`run_row` flattens a :class:`habitsim.pipeline.ClipRun` once into a :class:`RunRow`:
the stages' statuses and metrics, how the transfer found and planted its stance labels,
the refinement check, the wall time per stage and the dynamic plausibility of the tracked
reference. Each benchmark picks its columns from it: ``habitsim eval``
(:func:`habitsim.evaluation.pairs.evaluate_pair`, :meth:`RunRow.pair_columns`) and
``habitsim bench real`` (:func:`habitsim.evaluation.bench.real.run_window`,
:meth:`RunRow.real_columns`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from habitsim.errors import HabitsimError

if TYPE_CHECKING:  # pragma: no cover
    from habitsim.pipeline import ClipRun, Metrics

__all__ = ["RunRow", "run_row", "finite_or_none"]


def finite_or_none(v: Any) -> float | None:
    """``v`` as a float, or None when it is no finite number."""
    try:
        f = float(v)
    except (TypeError, ValueError):
        return None
    return f if math.isfinite(f) else None


@dataclass(frozen=True)
class RunRow:
    """The figures of one :class:`~habitsim.pipeline.ClipRun`, flat.

    Attributes:
        contacts_method: how the transfer found its stance labels
            (:attr:`habitsim.pipeline.Stage.contacts_method`).
        walking_stance: what the walking-stance rule did to the labels, the JSON form of
            :class:`habitsim.stance.report.WalkingRecord` (None: not applied).
        planted: how the transfer planted its feet (``decoded``, ``carried``, ``no``, ``-``:
            :attr:`habitsim.stance.report.TransferRecord.planted_how`).
        refine_status, track_status: the refine and track stages' statuses.
        refine_check: the refinement check (:attr:`habitsim.pipeline.ClipRun.refine_verdict`).
        refine_note: one line saying what the check rests on.
        transfer_metrics, refine_metrics: the transferred and refined motions' metrics
            (docs/metrics.md kinematic keys, ``skate_labelled_mm`` [mm/frame],
            ``stance_toe_height_per_leg`` [leg lengths]).
        track_metrics: the kept tracking run's simulated metrics ({} untracked).
        tracked: a tracking run was kept (``track_result`` is not None).
        times: wall time per stage [s]: ``transfer``, ``refine``, ``track``.
        reference_dynamics: docs/metrics.md's dynamic plausibility of the tracked
            reference under its stance labels ({} when not measured).
    """

    contacts_method: str
    walking_stance: dict[str, Any] | None
    planted: str
    refine_status: str
    track_status: str
    refine_check: str
    refine_note: str
    transfer_metrics: Metrics
    refine_metrics: Metrics
    track_metrics: Metrics
    tracked: bool
    times: Mapping[str, float]
    reference_dynamics: Mapping[str, float] = field(default_factory=dict)

    def real_columns(self) -> dict[str, Any]:
        """The columns ``bench real`` takes from the run, non-finite numbers as None
        (``survival_runs``, ``whole_runs`` and the repeats' time are its own)."""
        a, b, tm = self.transfer_metrics, self.refine_metrics, self.track_metrics
        n = finite_or_none
        return {
            "contacts_method": self.contacts_method,
            "walking_stance": self.walking_stance,
            "planted": self.planted,
            "stance_toe_height_transfer": n(a.get("stance_toe_height_per_leg")),
            "stance_toe_height_refined": n(b.get("stance_toe_height_per_leg")),
            "skate_mm_before": n(a.get("skate_mm")),
            "skate_mm_after": n(b.get("skate_mm")),
            "skate_labelled_mm_before": n(a.get("skate_labelled_mm")),
            "skate_labelled_mm_after": n(b.get("skate_labelled_mm")),
            "jerk_before": n(a.get("jerk")),
            "jerk_after": n(b.get("jerk")),
            "penetration_mm_before": n(a.get("penetration_mm")),
            "penetration_mm_after": n(b.get("penetration_mm")),
            "refine_status": self.refine_status,
            "refine_check": self.refine_check,
            "refine_note": self.refine_note,
            "track_status": self.track_status,
            "survival": n(tm.get("survival")),
        }

    def real_tail_columns(self) -> dict[str, Any]:
        """``bench real``'s columns after its repeats: the reference's dynamics, the sim
        error and contact F1, the wall time per stage [s]."""
        dyn, tm = self.reference_dynamics, self.track_metrics
        return {
            "reference_residual_mg": finite_or_none(dyn.get("root_residual_mg")),
            "reference_torque_saturation": finite_or_none(dyn.get("torque_saturation")),
            "sim_mpjpe_per_leg": finite_or_none(tm.get("sim_mpjpe_per_leg")),
            "contact_f1_sim": finite_or_none(tm.get("contact_f1")),
            **{f"time_{k}_s": v for k, v in self.times.items()},
        }

    def refine_columns(self, keys: tuple[str, ...]) -> dict[str, Any]:
        """The refined motion's metrics ``keys``, as they are (``eval``'s columns)."""
        return {k: self.refine_metrics[k] for k in keys}

    def track_columns(self) -> dict[str, Any]:
        """Every simulated metric of the kept tracking run, numbers as floats ({}
        untracked; ``eval``'s columns)."""
        if not self.tracked:
            return {}
        return {
            k: (float(v) if isinstance(v, bool | int | float) else v)
            for k, v in self.track_metrics.items()
        }


def reference_dynamics(run: ClipRun, *, strict: bool) -> dict[str, float]:
    """docs/metrics.md's dynamic plausibility of the tracked reference under its stance
    labels (``root_residual_mg``, ``torque_saturation``, …): how far from what the
    animal's ground forces and motors can do the clip is.

    Args:
        run: the pipeline's run.
        strict: raise the measurement's typed error (else: {} when it cannot be measured).
    """
    from habitsim.metrics.dynamic import dynamic_metrics

    try:
        return dynamic_metrics(run.reference, run.model, run.reference_contacts)
    except HabitsimError:
        if strict:
            raise
        return {}


def run_row(run: ClipRun, *, dynamics: bool = False, strict: bool = False) -> RunRow:
    """Flatten one pipeline run into its :class:`RunRow`.

    Args:
        run: :func:`habitsim.pipeline.run_clip`'s result.
        dynamics: measure the tracked reference's dynamic plausibility (inverse dynamics
            over the whole clip).
        strict: a dynamics measurement that fails raises (else it is left out).
    """
    record = run.transferred.transfer
    schedule = None if record is None else record.contacts
    walking = None if schedule is None else schedule.walking_stance
    return RunRow(
        contacts_method=run.transferred.contacts_method,
        walking_stance=None if walking is None else walking.to_dict(),
        planted="-" if record is None else record.planted_how,
        refine_status=run.refined.status,
        track_status=run.tracked.status,
        refine_check=run.refine_verdict,
        refine_note=run.refine_note,
        transfer_metrics=run.transferred.metrics,
        refine_metrics=run.refined.metrics,
        track_metrics=run.tracked.metrics,
        tracked=run.track_result is not None,
        times=run.times,
        reference_dynamics=reference_dynamics(run, strict=strict) if dynamics else {},
    )
