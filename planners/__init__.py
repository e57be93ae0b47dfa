"""Planners: gait, footholds, COG path, swing legs, joint references (pure functions, no simulator).

Typical use::

    from planners import paper_scenario, plan_gait_cycle
    plan = plan_gait_cycle(paper_scenario())
    ref = plan.reference()          # planners.reference.Reference
    sample = ref.sample(1.234)      # planners.types.ReferenceSample for the controller
"""

from planners.cog import CogProblem, CogStats, plan_cog
from planners.cycle import GaitCyclePlan, plan_gait_cycle
from planners.footholds import FootholdLimits, choose_footholds
from planners.gait import PAPER_DURATIONS, SWING_ORDER, Phase, walk_cycle
from planners.reference import Reference
from planners.scenario import Scenario, paper_scenario
from planners.swing import SwingPath, plan_swing
from planners.types import PlanningError, ReferenceSample
from planners.wholebody import WholeBody

__all__ = [
    "PAPER_DURATIONS",
    "SWING_ORDER",
    "CogProblem",
    "CogStats",
    "FootholdLimits",
    "GaitCyclePlan",
    "Phase",
    "PlanningError",
    "Reference",
    "ReferenceSample",
    "Scenario",
    "SwingPath",
    "WholeBody",
    "choose_footholds",
    "paper_scenario",
    "plan_cog",
    "plan_gait_cycle",
    "plan_swing",
    "walk_cycle",
]
