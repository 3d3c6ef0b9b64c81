"""``habitsim bench export``: a motion onto a user's rig and back.

For each rig file and each motion (the species' synthetic walk and trot, and the rig's own
clip imported without planting), :func:`habitsim.bvh_mapping.export_to_rig` writes the
motion onto the rig and :func:`habitsim.bvh_mapping.round_trip` imports it back: the
distance of every joint the rig maps from the motion's, as it comes back and with the
import's constant root-height offset removed (the pose), in millimetres.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .targets import TargetCheck, verdict

__all__ = [
    "ExportCase",
    "ExportResult",
    "run_export",
    "export_checks",
    "rig_stance_slide",
    "TARGET_POSE_MM",
]

#: import(export(m, rig)) equals m within this on every joint the rig maps [mm].
TARGET_POSE_MM = 1.0
#: The label of a rig's own clip among the motions.
OWN = "own clip"
#: The synthetic motions exported onto every rig.
DEFAULT_ACTIONS = ("walk", "trot")


@dataclass(frozen=True)
class ExportCase:
    """One rig and motion: where it came from and what came back (:meth:`RoundTrip.summary
    <habitsim.bvh_mapping.RoundTrip.summary>` figures, the import's root scale, seconds)."""

    rig: str
    motion: str
    joints: int
    figures: dict[str, float]
    root_scale: float
    seconds: float
    slide_mm: float
    slide_feet_mm: float

    def to_dict(self) -> dict[str, Any]:
        return {
            "rig": self.rig,
            "motion": self.motion,
            "joints": self.joints,
            **self.figures,
            "root_scale": self.root_scale,
            "seconds": self.seconds,
            "slide_mm": self.slide_mm,
            "slide_feet_mm": self.slide_feet_mm,
        }


def rig_stance_slide(export: Any, motion: Any) -> float:
    """Median horizontal travel [mm] of the rig's feet (each leg's lowest mapped joint)
    over the motion's stance runs of at least 3 frames; NaN without such runs."""
    import numpy as np

    from habitsim.bvh_mapping.chains import _LEG_CHAINS
    from habitsim.stance.labels import stance_runs

    j2s = export.mapping.mapped()
    feet = [
        export.bvh.index(next(j2s[n] for n in reversed(_LEG_CHAINS[p]) if n in j2s))
        for p in ("lf", "rf", "lh", "rh")
    ]
    pos = export.mapping.frame.apply(export.bvh.fk()[:, feet])
    contacts = motion.contacts if motion.contacts is not None else motion.detect_contacts()
    moved = [
        float(np.linalg.norm(pos[b - 1, k, :2] - pos[a, k, :2]))
        for k, runs in enumerate(stance_runs(contacts))
        for a, b in runs
        if b - a >= 3
    ]
    return float(np.median(moved)) * 1e3 if moved else float("nan")


@dataclass(frozen=True)
class ExportResult:
    cases: tuple[ExportCase, ...]


def run_export(
    rigs: list[Path],
    species: str = "dog",
    duration_s: float = 4.0,
    seed: int = 0,
    own_seconds: float | None = 20.0,
) -> ExportResult:
    """Export the species' synthetic walk and trot and each rig's own clip (its first
    ``own_seconds``, cut from the rig's file and imported without planting) onto each rig
    and back."""
    from habitsim.bvh_mapping import export_to_rig, import_bvh, read_source, round_trip
    from habitsim.bvh_mapping.export import RigExportOptions
    from habitsim.gaits import generate

    cases = []
    made = {a: generate(species, a, seed=seed, duration_s=duration_s) for a in DEFAULT_ACTIONS}
    for path in rigs:
        rig = read_source(path)
        if own_seconds is not None:  # the rig's clip cut first: its own import is of it
            keep = max(2, int(round(own_seconds * rig.fps)))
            rig = dataclasses.replace(rig, frames=rig.frames[:keep])
        own, _ = import_bvh(rig, species, plant=False)
        for label, motion in [*made.items(), (OWN, own)]:
            t0 = time.perf_counter()
            ex = export_to_rig(motion, rig)
            rt = round_trip(ex, motion)
            seconds = time.perf_counter() - t0
            feet = export_to_rig(motion, rig, export=RigExportOptions(travel="feet"))
            cases.append(
                ExportCase(
                    path.name,
                    label,
                    len(rt.joints),
                    rt.summary(),
                    ex.root_scale,
                    seconds,
                    rig_stance_slide(ex, motion),
                    rig_stance_slide(feet, motion),
                )
            )
    return ExportResult(tuple(cases))


def export_checks(res: ExportResult) -> list[TargetCheck]:
    """The targets: import(export(m, rig)) equals m within :data:`TARGET_POSE_MM` on every
    joint the rig maps, for each rig's own clip (imported without planting) and for the
    other motions (the species' synthetic walk and trot), the worst case of each."""
    out = []
    for name, cases in (
        ("each rig's own clip", [c for c in res.cases if c.motion == OWN]),
        ("the synthetic motions", [c for c in res.cases if c.motion != OWN]),
    ):
        worst = max((c.figures["max_mm"] for c in cases), default=None)
        out.append(
            TargetCheck(
                f"round trip of {name}, max error over the joints the rig maps [mm]",
                worst,
                "-" if worst is None else f"{worst:.3f}",
                f"≤ {TARGET_POSE_MM:g}",
                verdict(None if worst is None else worst <= TARGET_POSE_MM),
            )
        )
    return out
