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


@pytest.mark.parametrize(
    ("command", "expected"),
    [
        ({"vx": 0.1}, ExpertConfig().durations),  # 0.31 m a cycle: the configured phases
        ({"vx": 0.145}, ExpertConfig().durations),  # 0.4495 m
        # 0.2 m/s: 0.45 m in a cycle of 2.25 s; the 0.1 s phase kept, the six others (2.25 - 0.1) / 6 s
        ({"vx": -0.2}, (2.15 / 6,) * 3 + (0.1,) + (2.15 / 6,) * 3),
        ({"vx": 0.12, "vy": 0.16}, (2.15 / 6,) * 3 + (0.1,) + (2.15 / 6,) * 3),  # |v| = 0.2 m/s
        ({"vx": 0.8}, (0.3,) * 3 + (0.1,) + (0.3,) * 3),  # never below 0.3 s
    ],
)
def test_a_faster_command_shortens_the_phases_not_the_stride(command, expected):
    env = gym.make("QuadUneven-v0", terrain="flat", command=command)
    expert = attach_expert(env)
    env.reset(seed=0)
    np.testing.assert_allclose(expert.planner.durations, expected, rtol=0, atol=1e-12)
    plan = expert.plans[0][1]
    assert plan.duration == pytest.approx(sum(expected), abs=1e-12)


@pytest.mark.parametrize(("vx", "vy"), [(-0.1, 0.0), (0.0, 0.1), (0.0, -0.1), (0.2, 0.0), (-0.2, 0.0)])
def test_expert_walks_backwards_and_sideways_on_rough_terrain(vx, vy):
    """Three cycles on rough 5 cm terrain: no fall, the index >= 0 almost always, the whole-cycle velocity
    within 0.02 m/s of the command (at 0.2 m/s with the phases the command shortens)."""
    centred = {"kind": "rough", "amplitude": 0.05, "x_start": -5.0, "length": 10.0, "width": 5.0, "spawn_radius": 0.4}
    env = gym.make(
        "QuadUneven-v0",
        terrain=centred,  # room to walk backwards
        command={"vx": vx, "vy": vy},
        max_episode_steps=10**6,
    )
    expert = attach_expert(env)
    _, info = env.reset(seed=1)
    dt = env.unwrapped.dt
    period = float(sum(expert.planner.durations))
    per_cycle = round(period / dt)
    cogs, index = [info["cog"][:2].copy()], []
    for _ in range(3 * per_cycle):
        _, _, terminated, _, info = env.step(expert.predict(None)[0])
        assert not terminated, info["termination_reason"]
        cogs.append(info["cog"][:2].copy())
        index.append(info["stability_index"])
    v = (cogs[3 * per_cycle] - cogs[per_cycle]) / (2 * per_cycle * dt)  # the two cycles after the first (from rest)
    np.testing.assert_allclose(v, [vx, vy], atol=0.02)
    assert np.mean(np.array(index) >= 0.0) > 0.99
