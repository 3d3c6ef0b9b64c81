"""Name cues of source joint names: a joint's side, its side-free core, whether it
names a fore or a hind limb bone, and rig helpers that are never limbs."""

from __future__ import annotations

import re

_LEFT = {"l", "left", "lt", "lft"}
_RIGHT = {"r", "right", "rt", "rgt"}
#: Leg codes that name a side and a girdle at once, as robot and some animal rigs spell
#: them (``FL_thigh``, ``LH_SHANK``, ``Leg_RR_2``): code → (side, girdle word).
_QUADRANT = {
    **{
        f"{g}{s}": (s, w)
        for g, w in (("f", "front"), ("h", "hind"), ("r", "hind"), ("b", "hind"))
        for s in "lr"
    },
    **{f"{s}{g}": (s, w) for g, w in (("f", "front"), ("h", "hind"), ("b", "hind")) for s in "lr"},
}
_TOKEN_RE = re.compile(r"[A-Z]+(?![a-z])|[A-Z]?[a-z]+|\d+")
_FORE_WORDS = (
    "arm",
    "hand",
    "shoulder",
    "clavicle",
    "scapula",
    "collar",
    "front",
    "fore",
    "finger",
    "elbow",
    "wrist",
    "humerus",
    "carpal",
    "radius",
)
_HIND_WORDS = (
    "upleg",
    "thigh",
    "leg",
    "foot",
    "hind",
    "back",
    "knee",
    "hip",
    "ankle",
    "femur",
    "shin",
    "calf",
    "hock",
    "tibia",
    "toe",
)
#: Name tokens of rig helpers that are never part of a limb: tails, armour plates, 3ds Max
#: biped nubs and footstep trackers, IK poles and targets, twist and roll bones.
_HELPER_TOKENS = frozenset(
    {
        "tail",
        "armor",
        "armour",
        "nub",
        "footstep",
        "footsteps",
        "helper",
        "ik",
        "pole",
        "target",
        "twist",
        "roll",
        "dummy",
        "ctrl",
        "control",
        "prop",
        "weapon",
    }
)
_NOT_LIMB = (
    "ear",
    "eye",
    "jaw",
    "lip",
    "brow",
    "cheek",
    "whisker",
    "horn",
    "antler",
    "mouth",
    "tongue",
    "nostril",
    "wing",
)


def name_cues(name: str) -> tuple[str | None, str]:
    """Side and side-free core of a joint name.

    ``LeftUpLeg`` → ``("l", "upleg")``, ``R_Thigh`` → ``("r", "thigh")``,
    ``hand.L`` → ``("l", "hand")``, ``Spine1`` → ``(None, "spine1")``; a leg code
    (:data:`_QUADRANT`) gives the side and the girdle: ``FL_calf`` → ``("l", "frontcalf")``,
    ``RH_2`` → ``("r", "hind2")``, ``RR_thigh`` (rear right) → ``("r", "hindthigh")``.

    Args:
        name: a source joint name.

    Returns:
        ``("l" | "r" | None, core)``: the side cue and the lower-case name without it.
    """
    toks = _TOKEN_RE.findall(name)
    side: str | None = None
    rest: list[str] = []
    for t in toks:
        low = t.lower()
        if side is None and low in _LEFT:
            side = "l"
        elif side is None and low in _RIGHT:
            side = "r"
        elif side is None and low in _QUADRANT:
            side, girdle = _QUADRANT[low]
            rest.append(girdle)
        else:
            rest.append(low)
    return side, "".join(rest)


def is_helper_name(name: str) -> bool:
    """True if a joint name marks a rig helper that is never a limb bone.

    Tails, armour plates, biped nubs and footstep trackers, IK poles and targets, twist
    and roll bones (:data:`_HELPER_TOKENS`): ``Dog_LeftTail001``, ``Bip01_L_Toe0Nub``,
    ``Bip01_Footsteps``, ``LeftLegIKTarget``, ``forearm_twist.L``.
    """
    toks = [t.lower() for t in _TOKEN_RE.findall(name)]
    if any(t in _HELPER_TOKENS for t in toks):
        return True
    low = name.lower()
    return any(w in low for w in _HELPER_TOKENS if len(w) >= 5) or "tail" in low


def _fore_vote(core: str) -> int:
    if any(w in core for w in _FORE_WORDS):
        return 1
    if any(w in core for w in _HIND_WORDS):
        return -1
    return 0
