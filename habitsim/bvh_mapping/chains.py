"""The habitsim joint chains the mapping fills: legs, axial chain, tail, end points."""

from __future__ import annotations

from ..skeleton import JOINT_NAMES

_FORE_SEGS = ("scapula", "shoulder", "elbow", "wrist", "toe")
_HIND_SEGS = ("ilium", "hip", "knee", "hock", "toe")
_AXIAL = ("pelvis", "spine1", "spine2", "spine3", "neck", "head", "snout")
_TAIL = ("pelvis", "tail1", "tail2", "tail3")
#: The joints the pelvis's heading is read towards, first mapped one wins (import and export).
_HEADING = ("spine3", "spine2", "spine1", "neck", "head")
_LEG_CHAINS = {
    f"{s}{l}": tuple(f"{s}{l}_{seg}" for seg in (_FORE_SEGS if l == "f" else _HIND_SEGS))
    for s in ("l", "r")
    for l in ("f", "h")  # noqa: E741
}
_END_POINTS = ("snout", "tail3", "lf_toe", "rf_toe", "lh_toe", "rh_toe")
_IDX = {n: i for i, n in enumerate(JOINT_NAMES)}
