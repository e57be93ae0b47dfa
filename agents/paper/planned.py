"""The paper's §6 scenario planned without a simulator: Figs. 4-6 and the plan's key numbers.

``quad-uneven plan-paper --out DIR`` (:func:`write_planned_outputs`) writes ``fig4_swing_paths.png``,
``fig5_cog.png``, ``fig6_stability.png`` and ``plan.json`` into DIR.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from planners.cycle import GaitCyclePlan, plan_gait_cycle
from planners.scenario import paper_scenario
from planners.terrain_query import sphere_clearance


def summary(plan: GaitCyclePlan) -> dict:
    """Key numbers of a plan (JSON-serialisable)."""
    t = np.linspace(0.0, plan.duration, 12001)
    clear = {}
    for leg, sw in plan.swing.items():
        ts = np.linspace(sw.spline.tau[1], sw.spline.tau[-2], 2000)
        clear[leg] = float(sphere_clearance(plan.terrain, sw.position(ts), plan.foot_radius).min())
    jumps = plan.cog.junction_jumps().max(axis=0)
    return {
        "duration_s": plan.duration,
        "min_stability_index_Nm": float(plan.stability(t).min()),
        "epsilon_Nm": plan.epsilon,
        "junction_jump_max": {
            "position_m": float(jumps[0]),
            "velocity_mps": float(jumps[1]),
            "acceleration_mps2": float(jumps[2]),
        },
        "swing_min_clearance_m": clear,
        "footholds_m": plan.footholds.tolist(),
        "cog_junction_m": plan.cog.position(plan.cog.t_knots).tolist(),
        "cog_solve_time_s": plan.stats["cog_solve_time"],
        "sqp_iterations": plan.stats["iterations"],
    }


def write_planned_outputs(out: Path) -> dict:
    """Plan the paper scenario; write Figs. 4-6 (PNG) and plan.json into ``out`` (created). :return: plan.json."""
    from agents.paper.figures import planned_fig4_swing_paths, planned_fig5_cog, planned_fig6_stability

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    plan = plan_gait_cycle(paper_scenario())
    planned_fig4_swing_paths(plan, out / "fig4_swing_paths.png")
    planned_fig5_cog(plan, out / "fig5_cog.png")
    planned_fig6_stability(plan, out / "fig6_stability.png")
    info = summary(plan)
    (out / "plan.json").write_text(json.dumps(info, indent=2))
    return info
