"""Synthetic quadruped gaits: :func:`generate` one clip of any species and action.

Actions (:data:`ACTIONS`): ``walk, trot, pace, amble, canter, gallop, bound, turn_left,
turn_right, walk_backward, idle, sit, jump``; which of them a species has follows its
gait table (:func:`available_actions`). See :mod:`habitsim.gaits.locomotion` for how a
cyclic clip is built, :mod:`habitsim.gaits.stationary` and :mod:`habitsim.gaits.jump`
for the others; :func:`generate_chain` (:mod:`habitsim.gaits.chain`) makes one continuous
clip through several actions (walk → trot → gallop, walk → turn_left → stop → sit).
"""

from __future__ import annotations

from .actions import ACTIONS, LOCOMOTION_ACTIONS, action_gait, available_actions
from .chain import (
    CHAIN_STEPS,
    allowed_transitions,
    chain_min_duration,
    draw_chain,
    generate_chain,
    speed_ladder,
)
from .generator import GENERATOR_VERSION, generate
from .options import GeneratorOptions

__all__ = [
    "ACTIONS",
    "CHAIN_STEPS",
    "LOCOMOTION_ACTIONS",
    "GENERATOR_VERSION",
    "GeneratorOptions",
    "action_gait",
    "allowed_transitions",
    "available_actions",
    "chain_min_duration",
    "draw_chain",
    "generate",
    "generate_chain",
    "speed_ladder",
]
