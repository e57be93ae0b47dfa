"""Every shipped robot walks a short course in the ``hard`` world at its own scale (``make test-slow``).

The course is ``robust_hard``'s rough entry magnified to the robot (as ``evaluate --robot NAME --scale-terrain``),
cut to one leg length x 2.5 of travel; three of its worlds (the suite's seeds 0-2: friction, payload, motors,
latency, pushes and noise drawn at the robot's scale). The expert must reach the goal in at least two of them.
"""

from __future__ import annotations

import dataclasses

import pytest

from agents.evaluation.episode import EvalConfig, run_task
from agents.evaluation.run import robot_scale, suite_episodes
from agents.evaluation.suites import load_suite

ROBOTS = ("paper", "go1", "solo12", "anymal_c", "hyq")
COURSE_LEG_LENGTHS = 2.5
"""Goal distance in leg lengths (1.05 m for the paper robot's 0.42 m legs)."""


@pytest.mark.slow
@pytest.mark.parametrize("robot", ROBOTS)
def test_the_expert_walks_a_short_hard_world_course_on_every_robot(robot):
    suite = load_suite("robust_hard")
    rough = dataclasses.replace(suite, terrains=suite.terrains[:1])
    scaled, tasks = suite_episodes(rough, {"robot": robot}, 3, 0)
    goal = COURSE_LEG_LENGTHS * 0.42 * robot_scale(robot)
    cfg = EvalConfig("expert", goal_distance=goal, time_limit=scaled.time_limit, env_kwargs={"robot": robot})
    records = [run_task(task, cfg).record for task in tasks]
    assert all(r["randomization"] for r in records)  # the hard world, not the nominal one
    walked = [r for r in records if r["success"]]
    assert len(walked) >= 2, [(r["seed"], r["end_reason"], round(r["distance"], 2)) for r in records]
