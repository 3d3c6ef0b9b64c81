"""Actions of the synthetic gait generator and which gait each one uses per species."""

from __future__ import annotations

from ..errors import GaitError
from ..species import Species, load_species

__all__ = [
    "ACTIONS",
    "LOCOMOTION_ACTIONS",
    "ASYMMETRIC_GAITS",
    "action_gait",
    "available_actions",
    "has_aerial_gait",
]

#: Every action the generator knows, in a fixed order.
ACTIONS: tuple[str, ...] = (
    "walk",
    "trot",
    "pace",
    "amble",
    "canter",
    "gallop",
    "bound",
    "turn_left",
    "turn_right",
    "walk_backward",
    "idle",
    "sit",
    "jump",
)
#: Actions made of cyclic steps (a gait with a footfall table).
LOCOMOTION_ACTIONS: tuple[str, ...] = ACTIONS[:10]
#: Gaits whose left and right feet are not half a stride apart.
ASYMMETRIC_GAITS: frozenset[str] = frozenset(
    {"canter", "transverse_gallop", "rotary_gallop", "half_bound", "bound"}
)
#: Duty factors at or above this never leave the ground (used for ``jump``).
_AERIAL_DUTY = 0.4


def has_aerial_gait(sp: Species) -> bool:
    """True if some gait of the species has a duty-factor minimum below 0.4.

    Species whose every gait keeps at least 40 % stance (the elephant) never have an
    aerial phase and get no ``jump``.
    """
    return any(g.duty_factor[0] < _AERIAL_DUTY for g in sp.gaits.values())


def _gait_for(sp: Species, action: str) -> str | None:
    """The species gait an action uses ("" = a non-cyclic action; None = unavailable)."""
    if action in ("walk", "turn_left", "turn_right", "walk_backward"):
        return "walk"
    if action in ("trot", "pace", "amble", "canter"):
        return action if action in sp.gaits else None
    if action == "gallop":
        return sp.gallop
    if action == "bound":
        for g in ("bound", "half_bound"):
            if g in sp.gaits:
                return g
        return None
    if action in ("idle", "sit"):
        return ""
    if action == "jump":
        return "" if has_aerial_gait(sp) else None
    return None


def available_actions(species: str | Species) -> list[str]:
    """Actions the species can perform, in the order of :data:`ACTIONS`.

    Raises:
        UnknownSpeciesError: unknown species name.
    """
    sp = load_species(species)
    return [a for a in ACTIONS if _gait_for(sp, a) is not None]


def action_gait(species: str | Species, action: str) -> str:
    """The gait name an action uses for a species (``stand``, ``sit``, ``jump`` for the
    non-cyclic actions).

    Raises:
        GaitError: unknown action, or an action the species does not have (the message
            lists the species' available actions).
    """
    sp = load_species(species)
    if action not in ACTIONS:
        raise GaitError(f"unknown action {action!r}; valid: {', '.join(ACTIONS)}")
    g = _gait_for(sp, action)
    if g is None:
        raise GaitError(
            f"species {sp.name!r} has no action {action!r}; available: "
            f"{', '.join(available_actions(sp))}"
        )
    if g == "":
        return {"idle": "stand", "sit": "sit", "jump": "jump"}[action]
    return g
