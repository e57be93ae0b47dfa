"""The expert follows a commanded yaw rate: it turns in place and walks arcs, planning in a yawing body frame."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

import quad_uneven_env  # noqa: F401
from agents.expert import ExpertConfig, attach_expert

PERIOD = float(sum(ExpertConfig().durations))  # s, 3.1


def base_yaw(env) -> float:
    """rad: the trunk's measured heading (z-y-x yaw of its orientation)."""
    w, x, y, z = env.unwrapped.data.qpos[3:7]
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def walk(command: dict, cycles: int, terrain="flat", seed: int = 0):
    """The expert for ``cycles`` gait cycles: unwrapped yaw change (rad), start yaw, COG path, index, the expert."""
    env = gym.make("QuadUneven-v0", terrain=terrain, command=command, max_episode_steps=10**6)
    expert = attach_expert(env)
    _, info = env.reset(seed=seed)
    yaw0 = prev = base_yaw(env)
    turned, cogs, index = 0.0, [info["cog"][:2].copy()], []
    for _ in range(round(cycles * PERIOD / env.unwrapped.dt)):
        _, _, terminated, _, info = env.step(expert.predict(None)[0])
        assert not terminated, info["termination_reason"]
        y = base_yaw(env)
        turned += (y - prev + math.pi) % (2.0 * math.pi) - math.pi
        prev = y
        cogs.append(info["cog"][:2].copy())
        index.append(info["stability_index"])
    env.close()
    return turned, yaw0, np.array(cogs), np.array(index), expert


@pytest.mark.parametrize("yaw_rate", [0.2, -0.3])
def test_expert_turns_in_place_by_the_commanded_angle(yaw_rate):
    """Two cycles on flat ground: the heading changes by yaw_rate x 2 cycles within 0.03 rad, the COG stays
    within 2 cm of where it started, the index is >= 0 at every step and no plan fails."""
    turned, _, cogs, index, expert = walk({"yaw_rate": yaw_rate}, cycles=2)
    assert turned == pytest.approx(yaw_rate * 2 * PERIOD, abs=0.03)
    assert np.linalg.norm(cogs[-1] - cogs[0]) < 0.02
    assert index.min() >= 0.0
    assert expert.failure_log == []
    assert all(plan.pitch.yawed for _, plan in expert.plans[1:])


def test_expert_walks_an_arc_on_rough_terrain():
    """Forward at 0.1 m/s turning at 0.2 rad/s, three cycles on rough 5 cm terrain: the heading follows within
    0.05 rad, and the last two cycles' COG chord is the commanded arc's (chord of a circle of radius v / w) to
    within 0.01 m/s of mean velocity (the first swing leg's foothold, limited by its reach at touch-down, makes
    each cycle about 2 cm short) and within 0.1 rad of its direction."""
    vx, wz = 0.1, 0.2
    rough = {"kind": "rough", "amplitude": 0.05}
    turned, yaw0, cogs, index, _ = walk({"vx": vx, "yaw_rate": wz}, cycles=3, terrain=rough, seed=1)
    assert turned == pytest.approx(wz * 3 * PERIOD, abs=0.05)
    per_cycle = (len(cogs) - 1) // 3
    chord = cogs[-1] - cogs[per_cycle]
    angle = wz * 2 * PERIOD
    expected = 2.0 * vx / wz * math.sin(0.5 * angle)
    assert abs(np.linalg.norm(chord) - expected) / (2 * PERIOD) < 0.01
    heading = math.atan2(chord[1], chord[0])
    assert heading == pytest.approx(yaw0 + wz * PERIOD * 2, abs=0.1)  # the chord points along the middle heading
    assert np.mean(index >= 0.0) > 0.99


def test_expert_turns_to_a_commanded_heading_and_holds_it():
    """Heading mode, 0.5 rad (left) then hold: the first cycle turns the whole error (deadbeat, within the
    cycle's cap), the second walks straight on; after two cycles the heading is within 0.03 rad of it, the
    index >= 0 at every step and no plan fails."""
    turned, yaw0, _, index, expert = walk({"vx": 0.05, "heading": 0.5}, cycles=2)
    assert yaw0 + turned == pytest.approx(0.5, abs=0.03)
    assert index.min() >= 0.0
    assert expert.failure_log == []
    turns = [plan.pitch.yaw_end - plan.pitch.yaw_start for _, plan in expert.plans[:2]]
    assert turns[0] == pytest.approx(0.5 - yaw0, abs=1e-9) and abs(turns[1]) < 0.05
