"""Gait-cycle planning end to end: the paper's §6 scenario, API contract, input validation."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import planners
from planners.terrain_query import BlockTerrain, sphere_clearance
from quad_uneven_env.stability import stability_index


@pytest.fixture(scope="module")
def paper_plan():
    return planners.plan_gait_cycle(planners.paper_scenario())


def test_paper_plan_stable_continuous_and_clear(paper_plan):
    plan, sc = paper_plan, planners.paper_scenario()
    assert [p.swing_leg for p in plan.phases] == [None, "RH", "RF", None, "LH", "LF", None]
    # Stability on a dense grid, recomputed here from the stance feet with the environment's index.
    t = np.linspace(0.0, plan.duration, 12201)
    pos, acc = plan.cog.position(t), plan.cog.acceleration(t)
    assert pos.shape == (t.size, 3)
    for ph in plan.phases:
        sel = (t >= ph.t_start) & (t <= ph.t_end)
        feet = np.where(np.asarray(ph.moved)[:, None], plan.footholds, plan.feet_start)[np.asarray(ph.stance)]
        idx, _ = stability_index(pos[sel], acc[sel], feet, 50.0)
        assert idx.min() >= sc.epsilon, ph.name()
    # C² at the junctions, from both sides.
    for ph in plan.phases[:-1]:
        te = ph.t_end
        for f in (plan.cog.position, plan.cog.velocity, plan.cog.acceleration):
            left, right = f(np.array([te - 1e-12]))[0], f(np.array([te]))[0]
            assert np.abs(left - right).max() <= 1e-9
    # Boundary conditions.
    np.testing.assert_allclose(plan.cog.position(np.array([0.0]))[0], [0.01, 0.0, 0.544], atol=1e-12)
    np.testing.assert_allclose(plan.cog.position(np.array([6.1]))[0], [0.21, 0.0, 0.5743], atol=1e-12)
    np.testing.assert_allclose(plan.cog.velocity(np.array([0.0, 6.1])), 0.0, atol=1e-9)
    # Body height follows the terrain: it rises with the footholds.
    assert plan.cog.position(np.array([5.0]))[0, 2] > plan.cog.position(np.array([1.0]))[0, 2] + 0.01
    # Swing paths: end on the footholds' sites, clear the terrain between the intermediate points.
    assert set(plan.swing) == {"LF", "RF", "LH", "RH"}
    for i, leg in enumerate(("LF", "RF", "LH", "RH")):
        sw = plan.swing[leg]
        np.testing.assert_allclose(sw.position(np.array([sw.t_end]))[0], plan.footholds[i] + [0, 0, 0.02], atol=1e-12)
        ts = np.linspace(sw.spline.tau[1], sw.spline.tau[-2], 801)
        assert sphere_clearance(plan.terrain, sw.position(ts), 0.02).min() >= sc.clearance - 1e-3
    assert plan.stats["min_clearance"] >= sc.clearance
    assert plan.stats["min_stability"] >= sc.epsilon
    for key in ("cog_solve_time", "iterations", "min_stability", "min_clearance"):
        assert key in plan.stats


def test_automatic_footholds_on_paper_terrain_pick_the_blocks():
    sc = dataclasses.replace(planners.paper_scenario(), footholds=None, cog_goal=None)
    plan = planners.plan_gait_cycle(sc)
    from quad_uneven_env.terrain import PAPER_BLOCKS

    # The target blocks are the only flat, reachable spots near the nominal footholds... within a block.
    assert np.abs(plan.footholds[:, :2] - PAPER_BLOCKS["target"][:, :2]).max() <= 0.05
    np.testing.assert_allclose(plan.footholds[:, 2], PAPER_BLOCKS["target"][:, 2], atol=1e-9)


def test_scenario_accepts_height_map_and_validates_fields():
    flat = BlockTerrain(0.0)
    feet = np.array([[0.25, 0.185, 0], [0.25, -0.185, 0], [-0.25, 0.185, 0], [-0.25, -0.185, 0]])
    sc = planners.Scenario(terrain=flat, feet_start=feet, cog_start={"pos": (0, 0, 0.36)})
    plan = planners.plan_gait_cycle(sc)
    assert plan.cog.position(np.array([plan.duration]))[0, 0] == pytest.approx(0.2, abs=0.02)
    with pytest.raises(ValueError, match="feet_start"):
        planners.Scenario(terrain=flat, feet_start=feet[:3], cog_start={"pos": (0, 0, 0.36)})
    with pytest.raises(ValueError, match="durations"):
        planners.Scenario(terrain=flat, feet_start=feet, cog_start={"pos": (0, 0, 0.36)}, durations=(1, 1))
    with pytest.raises(ValueError, match="cog_start"):
        planners.Scenario(terrain=flat, feet_start=feet, cog_start={"position": (0, 0, 0.36)})


def test_unreachable_goal_raises_planning_error():
    flat = BlockTerrain(0.0)
    feet = np.array([[0.25, 0.185, 0], [0.25, -0.185, 0], [-0.25, 0.185, 0], [-0.25, -0.185, 0]])
    sc = planners.Scenario(
        terrain=flat, feet_start=feet, footholds=feet + np.array([0.2, 0, 0]),
        cog_start={"pos": (0, 0, 0.36)}, cog_goal={"pos": (0.2, 0.0, 0.36)}, epsilon=150.0,
    )  # fmt: skip
    with pytest.raises(planners.PlanningError, match=r"phase \d"):
        planners.plan_gait_cycle(sc)


def test_a_measured_start_beyond_the_reach_cap_is_planned_from(paper_robot):
    # The start COG stands high above the feet: every stance leg already reaches past REACH_MARGIN of
    # the stretched leg (a measured state can: the planner's nominal hips are not the robot's). The
    # cycle is planned from it instead of failing on "the given start state itself" at every replan.
    from planners.cycle import REACH_MARGIN
    from planners.wholebody import WholeBody

    feet = np.column_stack([paper_robot.hip_positions_B[:, :2], np.zeros(4)])
    wb = WholeBody(paper_robot)
    com_to_base = -wb.com_offset(paper_robot.two_link.standing_joints(0.33).reshape(4, 3))
    site_z = paper_robot.foot_radius
    # COG height at which the hip-to-site distance is 0.995 of the leg (the hips straight above the sites).
    z = site_z + 0.995 * paper_robot.leg_length - (wb.hips[0, 2] + com_to_base[2])
    sc = planners.Scenario(
        terrain=BlockTerrain(0.0), feet_start=feet, cog_start={"pos": [0.0, 0.0, z]}, footholds=feet,
        epsilon=0.1, cog_height=0.33, robot=paper_robot,
    )  # fmt: skip
    hip = np.array([0.0, 0.0, z]) + wb.hips[0] + com_to_base
    assert np.linalg.norm(hip - [feet[0, 0], feet[0, 1], site_z]) > REACH_MARGIN * paper_robot.leg_length
    plan = planners.plan_gait_cycle(sc)
    assert plan.cog.position(np.array([plan.duration]))[0, 2] < z - 0.01  # and it comes down
