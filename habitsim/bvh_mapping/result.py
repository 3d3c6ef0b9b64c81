"""The mapping's result: which source joint drives each habitsim joint, the frame
conversion, and how confident the mapping of each leg is."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from ..skeleton import JOINT_NAMES
from .frame import FrameConversion

CONFIDENCE_CHECKS = (
    "names: the chain's joint names say fore / hind as the leg it was mapped to (0.5: no "
    "cue; 1 for a hand-made map)",
    "symmetry: its left/right partner has the same number of joints and a length within "
    "10 % (0.5: within 25 %)",
    "ground: the foot rests on the ground (floor within 10 % of leg length of the lowest "
    "foot's) and has stance frames",
)
#: Legs whose confidence is below this are reported as warnings.
CONFIDENCE_WARN = 0.67


@dataclass
class JointMapping:
    """Which source joint drives each habitsim joint, and how the file was converted.

    Attributes:
        joints: every habitsim joint name → source joint name, or None if unmapped
            (unmapped joints keep the species' standing pose).
        method: ``"auto"``, ``"map file <path>"``, ``"explicit"`` or ``"identity"``.
        frame: the file-to-habitsim frame conversion (None for the identity import).
        root_scale: factor applied to the source root translation (species hip height /
            source hip height) [-].
        notes: human-readable remarks (guesses made, fallbacks taken).
        confidence: per leg (``lf``, ``rf``, ``lh``, ``rh``) a score in [0, 1] that the
            chain mapped to it is that leg (:data:`CONFIDENCE_CHECKS`); empty until the
            motion has been retargeted.
        warnings: what a user should check by hand (a leg below
            :data:`CONFIDENCE_WARN`, legs that do not mirror each other).
    """

    joints: dict[str, str | None]
    method: str = "auto"
    frame: FrameConversion | None = None
    root_scale: float = 1.0
    notes: list[str] = field(default_factory=list)
    confidence: dict[str, float] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)

    def mapped(self) -> dict[str, str]:
        """Only the mapped habitsim joints: habitsim name → source name."""
        return {k: v for k, v in self.joints.items() if v is not None}

    def lines(self) -> list[str]:
        """One ``"habitsim joint <- source joint"`` line per habitsim joint."""
        w = max(len(n) for n in JOINT_NAMES)
        return [
            f"{n:<{w}} <- {self.joints.get(n) or '(unmapped: standing pose)'}" for n in JOINT_NAMES
        ]

    def __str__(self) -> str:
        head = [f"joint mapping ({self.method}):"]
        if self.frame is not None:
            head.append(f"  frame: {self.frame.describe()}; root scale {self.root_scale:.4g}")
        body = ["  " + s for s in self.lines()]
        if self.confidence:
            body.append(
                "  leg confidence: " + ", ".join(f"{k} {v:.2f}" for k, v in self.confidence.items())
            )
        tail = ["  note: " + n for n in self.notes]
        tail += ["  WARNING: " + w for w in self.warnings]
        return "\n".join(head + body + tail)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (stored in the imported motion's metadata)."""
        d: dict[str, Any] = {
            "method": self.method,
            "joints": self.mapped(),
            "root_scale": self.root_scale,
            "notes": list(self.notes),
            "confidence": dict(self.confidence),
            "warnings": list(self.warnings),
        }
        if self.frame is not None:
            d.update(
                units=self.frame.units,
                unit_scale=self.frame.scale,
                up=self.frame.up,
                forward=self.frame.forward,
            )
        return d
