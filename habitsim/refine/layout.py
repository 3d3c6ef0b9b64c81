"""Names and sizes shared by the pieces of the refinement NLP: the feet, the global
parameters, the cost terms, the joints held above the floor, the friction-pyramid
edges."""

from __future__ import annotations

from ..skeleton import JOINT_NAMES

#: Feet in habitsim order; their geoms are ``<leg>_foot`` spheres, toes ``<leg>_toe`` sites.
FEET = ("lf", "rf", "lh", "rh")
#: Names of the global (per-window) parameters, in order.
GLOBAL_PARAMS = (
    "leg_length",
    "fps",
    "gravity",
    "mu",
    "w_track",
    "w_smooth",
    "w_jerk",
    "w_hinge_jerk",
    "w_reg",
    "w_root",
    "w_residual",
    "w_force",
)
#: Cost term names (stage A has the first five, stage B all seven).
COST_TERMS = (
    "track",
    "smooth",
    "jerk",
    "hinge_jerk",
    "regularisation",
    "residual",
    "force",
)
#: Number of cost terms of stage A (the first ones of :data:`COST_TERMS`).
STAGE_A_TERMS = 5
_TOES = tuple(f"{leg}_toe" for leg in FEET)
#: Name prefixes of the legs' hinges (the pre-filter treats them contact-aware).
LEG_PREFIXES = tuple(f"{leg}_" for leg in FEET)
_TOE_IDX = tuple(JOINT_NAMES.index(n) for n in _TOES)
#: Habitsim joints held at or above the floor by the ``ground`` rows (the toes are on
#: the foot spheres, held by the ``sole`` rows).
GROUND_JOINTS = tuple(i for i, n in enumerate(JOINT_NAMES) if n not in _TOES)
_N_EDGES = 4
