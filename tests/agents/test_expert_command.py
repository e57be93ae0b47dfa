"""The expert follows the env's commanded (vx, vy): stride = command x cycle duration, backwards and sideways."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import quad_uneven_env  # noqa: F401
from agents.expert import ExpertConfig, attach_expert

PERIOD = float(sum(ExpertConfig().durations))  # s, 3.1


def first_plan(command, terrain="flat"):
    """The expert's first plan in an env with ``command``."""
    env = gym.make("QuadUneven-v0", terrain=terrain, command=command)
    expert = attach_expert(env)
    env.reset(seed=0)
    assert expert.failure_log == []
    return expert.plans[0][1]


def first_plan_advance(command):
    """(2,) m: the first cycle's planned COG displacement (start to end) on flat ground."""
    plan = first_plan(command)
    return plan.cog.position(np.array([plan.duration]))[0, :2] - plan.cog.position(np.array([0.0]))[0, :2]


@pytest.mark.parametrize(
    ("command", "expected"),
    [
        (None, (ExpertConfig().stride, 0.0)),
        ({"vx": 0.1}, (0.1 * PERIOD, 0.0)),
        ({"vx": -0.08}, (-0.08 * PERIOD, 0.0)),
        ({"vy": 0.05}, (0.0, 0.05 * PERIOD)),
        ({"vx": 0.06, "vy": -0.04}, (0.06 * PERIOD, -0.04 * PERIOD)),
        ({"vy": 0.1}, (0.0, 0.1 * PERIOD)),  # 0.31 m to the left: only with the left legs first
        ({"vy": -0.1}, (0.0, -0.1 * PERIOD)),
    ],
)
def test_planned_advance_is_the_commanded_velocity_times_the_cycle(command, expected):
    """On flat ground the footholds are the nominal ones, so the planned COG moves by exactly the stride."""
    np.testing.assert_allclose(first_plan_advance(command), expected, atol=0.01)


@pytest.mark.parametrize(("vy", "first"), [(0.05, "LH"), (0.0, "RH"), (-0.05, "RH"), (None, "RH")])
def test_the_legs_on_the_side_moved_to_swing_first(vy, first):
    plan = first_plan(None if vy is None else {"vx": 0.05, "vy": vy})
    assert plan.phases[1].swing_leg == first


@pytest.mark.parametrize(("vx", "vy"), [(-0.1, 0.0), (0.0, 0.1), (0.0, -0.1)])
def test_expert_walks_backwards_and_sideways_on_rough_terrain(vx, vy):
    """Three cycles on rough 5 cm terrain: no fall, the index >= 0 almost always, the whole-cycle velocity
    within 0.02 m/s of the command."""
    env = gym.make(
        "QuadUneven-v0",
        terrain={"kind": "rough", "amplitude": 0.05},
        command={"vx": vx, "vy": vy},
        max_episode_steps=10**6,
    )
    expert = attach_expert(env)
    _, info = env.reset(seed=1)
    dt = env.unwrapped.dt
    per_cycle = round(PERIOD / dt)
    cogs, index = [info["cog"][:2].copy()], []
    for _ in range(3 * per_cycle):
        _, _, terminated, _, info = env.step(expert.predict(None)[0])
        assert not terminated, info["termination_reason"]
        cogs.append(info["cog"][:2].copy())
        index.append(info["stability_index"])
    v = (cogs[3 * per_cycle] - cogs[per_cycle]) / (2 * PERIOD)  # the two cycles after the first (from rest)
    np.testing.assert_allclose(v, [vx, vy], atol=0.02)
    assert np.mean(np.array(index) >= 0.0) > 0.99
