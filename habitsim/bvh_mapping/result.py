"""The mapping's result: which source joint drives each habitsim joint, the frame
conversion, and how confident the mapping of each leg is."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum
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


class MappingNote(StrEnum):
    """A remark of :attr:`JointMapping.notes` as a typed code (the note says the same in
    words, with the names and figures)."""

    #: the legs were found from symmetric unnamed chains; left/right decided by geometry
    GEOMETRIC_SIDES = "geometric_sides"
    #: fore/hind from the joint names contradicts the hierarchy; the names were used
    NAMES_OVER_HIERARCHY = "names_over_hierarchy"
    #: fore and hind legs hang from the same joint: no spine mapped
    NO_SPINE = "no_spine"
    #: no neck/head chain found beyond the chest
    NO_NECK = "no_neck"
    #: no tail chain found at the hips
    NO_TAIL = "no_tail"
    #: joints set by hand over the automatic mapping (a map file extending ``auto``)
    SET_BY_HAND = "set_by_hand"
    #: a habitsim-exported file: rotations and root translation copied
    COPIED = "copied"
    #: bone offsets differ from the species' skeleton: root translation scaled
    ROOT_SCALED = "root_scaled"
    #: stance labels detected on the file's own toes
    OWN_TOE_STANCE = "own_toe_stance"
    #: no spine/neck/head mapped: the pelvis keeps the standing orientation
    PELVIS_STANDING = "pelvis_standing"
    #: the source hip height is not measurable: root translation not scaled
    ROOT_UNSCALED = "root_unscaled"
    #: a leg has no mapped foot or upper joint: its feet not labelled or planted
    LEG_UNPLANTED = "leg_unplanted"
    #: a source leg has zero length: feet not planted
    ZERO_LEG = "zero_leg"
    #: the up axis found from the feet over the clip (what decided it, and the rest pose)
    UP_FROM_FEET = "up_from_feet"
    #: the up axis evidence was weak: a tie-breaker (rest pose, names) chose; check it
    UP_UNSURE = "up_unsure"
    #: a control-named chain (IK, pole, target, twist, MCH/ORG) is used as a leg: it is
    #: the one that animates
    CONTROL_LEG = "control_leg"
    #: a mapped leg does not animate while other legs do
    LEG_STATIC = "leg_static"
    #: fore/hind decided by the end of the trunk that carries the head (skull), over the
    #: names or the hierarchy
    FORE_FROM_HEAD = "fore_from_head"
    #: fore/hind decided by which way the body goes over the clip (the stance feet's sweep)
    FORE_FROM_TRAVEL = "fore_from_travel"
    #: the clip's direction of travel disagrees with the fore/hind chosen (a backward walk,
    #: or a wrong guess)
    TRAVEL_DISAGREES = "travel_disagrees"
    #: head or tail chain chosen by geometry over the names
    HEAD_TAIL_FROM_GEOMETRY = "head_tail_from_geometry"


@dataclass
class JointMapping:
    """Which source joint drives each habitsim joint, and how the file was converted.

    Attributes:
        joints: every habitsim joint name → source joint name, or None if unmapped
            (unmapped joints keep the species' standing pose).
        method: ``"auto"``, ``"map file <path>"``, ``"explicit"`` or ``"identity"``.
        frame: the file-to-habitsim frame conversion (None for the identity import).
        root_scale: factor applied to the source root translation (the species' hind-leg
            length / the source's, :func:`~habitsim.bvh_mapping.retargeting.leg_root_scale`;
            without feet to measure, species hip height / source hip height) [-].
        notes: human-readable remarks (guesses made, fallbacks taken).
        note_codes: each note as a typed code, in the same order (not written to the
            metadata).
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
    note_codes: list[MappingNote] = field(default_factory=list)

    def note(self, code: MappingNote, text: str) -> None:
        """Add a remark: its code to :attr:`note_codes`, its words to :attr:`notes`."""
        self.note_codes.append(code)
        self.notes.append(text)

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
