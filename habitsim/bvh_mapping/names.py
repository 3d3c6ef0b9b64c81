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
#: biped nubs and footstep trackers, props.
_HELPER_TOKENS = frozenset(
    {
        "tail",
        "armor",
        "armour",
        "nub",
        "footstep",
        "footsteps",
        "helper",
        "dummy",
        "prop",
        "weapon",
    }
)
#: Name tokens of a rig's control layer: IK chains, poles and targets, controls, twist and
#: roll bones, and Blender's mechanism (``MCH-``) and original (``ORG-``) layers. Such a
#: chain is a leg only where it is the one that animates (:mod:`.limbs`): a name alone
#: never drops a chain whose joints move.
_CONTROL_TOKENS = frozenset(
    {
        "ik",
        "pole",
        "target",
        "twist",
        "roll",
        "ctrl",
        "control",
        "mch",
        "org",
    }
)
#: Control tokens of bones that lie along a limb bone (a twist or roll segment in series
#: with the thigh): a leg chain spans them.
_SEGMENT_TOKENS = frozenset({"twist", "roll"})
#: Blender's layer prefixes (``DEF-thigh.L``, ``MCH-shin_ik.L``, ``ORG-foot.L``): not part of
#: the bone's name core.
_LAYER_TOKENS = frozenset({"def", "mch", "org"})
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
        elif low in _LAYER_TOKENS and t.isupper():
            continue
        else:
            rest.append(low)
    return side, "".join(rest)


def _tokens(name: str) -> list[str]:
    return [t.lower() for t in _TOKEN_RE.findall(name)]


def is_helper_name(name: str) -> bool:
    """True if a joint name marks a rig helper or a control bone.

    Helpers that are never a limb (:data:`_HELPER_TOKENS`: ``Dog_LeftTail001``,
    ``Bip01_L_Toe0Nub``, ``Bip01_Footsteps``) and control bones (:func:`is_control_name`:
    ``LeftLegIKTarget``, ``forearm_twist.L``).
    """
    return is_never_limb_name(name) or is_control_name(name)


def is_never_limb_name(name: str) -> bool:
    """True if a joint name marks a helper that is never part of a limb: tails, armour
    plates, biped nubs and footstep trackers, props (:data:`_HELPER_TOKENS`)."""
    toks = _tokens(name)
    if any(t in _HELPER_TOKENS for t in toks):
        return True
    low = name.lower()
    return any(w in low for w in _HELPER_TOKENS if len(w) >= 5) or "tail" in low


def is_control_name(name: str) -> bool:
    """True if a joint name marks a bone of a rig's control layer: IK chains, poles and
    targets, controls, twist and roll bones, Blender's ``MCH-`` and ``ORG-`` layers
    (:data:`_CONTROL_TOKENS`): ``L_legIK_knee``, ``thigh_twist_01_l``, ``MCH-shin_ik.L``.

    Such a bone is not dropped for its name: the mapping takes a control chain as a leg
    when it is the chain that animates (see ``docs/import.md``, helper rigs).
    """
    toks = _tokens(name)
    low = name.lower()
    return any(t in _CONTROL_TOKENS for t in toks) or any(
        w in low for w in ("twist", "target", "control")
    )


def is_segment_name(name: str) -> bool:
    """True for a twist or roll bone, which lies along a limb bone (:data:`_SEGMENT_TOKENS`)."""
    low = name.lower()
    return any(t in _SEGMENT_TOKENS for t in _tokens(name)) or "twist" in low


def _fore_vote(core: str) -> int:
    if any(w in core for w in _FORE_WORDS):
        return 1
    if any(w in core for w in _HIND_WORDS):
        return -1
    return 0
