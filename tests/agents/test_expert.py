"""The scripted expert walks: planner + inverse dynamics in the loop."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import quad_uneven_env  # noqa: F401
from agents import expert as expert_mod
from agents.expert import ExpertConfig, attach_expert
from planners import PlanningError
from quad_uneven_env import constants as C


def walk(terrain, seconds, seed=0, config=None, on_step=None):
    env = gym.make("QuadUneven-v0", terrain=terrain, max_episode_steps=10**6)
    policy = attach_expert(env, config)
    obs, info = env.reset(seed=seed)
    x0 = info["cog"][0]
    indices = []
    for _ in range(int(seconds / env.unwrapped.dt)):
        action, _ = policy.predict(obs)
        obs, _, terminated, _, info = env.step(action)
        indices.append(info["stability_index"])
        assert not terminated, info["termination_reason"]
        if on_step is not None:
            on_step(env.unwrapped)
    return policy, info["cog"][0] - x0, np.array(indices), info


def leg_links_on_terrain(env) -> list[str]:
    """Names of the thigh and shank geoms touching the terrain (feet and trunk excluded)."""
    m, d = env.model, env.data
    terrain = m.geom(C.TERRAIN_GEOM).id
    links = {m.geom(f"{leg}_{part}_geom").id for leg in C.LEG_NAMES for part in ("thigh", "shank")}
    touching = set()
    for g1, g2 in d.contact.geom[: d.ncon]:
        other = g2 if g1 == terrain else g1 if g2 == terrain else None
        if other in links:
            touching.add(m.geom(int(other)).name)
    return sorted(touching)


@pytest.mark.parametrize("terrain", ["flat", {"kind": "rough", "amplitude": 0.04}])
def test_expert_walks_forward_without_falling(terrain):
    policy, distance, index, info = walk(terrain, 9.3)  # three gait cycles
    assert distance > 0.7  # 3 x 0.33 m planned; the last cycle's end is not yet reached
    assert abs(info["cog"][1]) < 0.1  # keeps heading +x
    # The measured stability index stays positive nearly all the time.
    assert np.mean(index > 0) > 0.99
    assert len(policy.planner_times_ms) >= 3 and policy.failure_log == []


def test_predict_follows_sb3_protocol():
    env = gym.make("QuadUneven-v0", terrain="flat")
    policy = attach_expert(env)
    obs, _ = env.reset(seed=0)
    action, state = policy.predict(obs, state="s", episode_start=np.ones(1, bool), deterministic=True)
    assert action.shape == env.action_space.shape and action.dtype == env.action_space.dtype
    assert state == "s" and env.action_space.contains(action)


def test_planning_failure_degrades_to_standing(monkeypatch):
    def always_fail(scenario):
        raise PlanningError("forced failure for the test")

    monkeypatch.setattr(expert_mod, "plan_gait_cycle", always_fail)
    env = gym.make("QuadUneven-v0", terrain="flat")
    policy = attach_expert(env)
    obs, info = env.reset(seed=0)
    x0 = info["cog"].copy()
    for _ in range(100):
        obs, _, terminated, _, info = env.step(policy.predict(obs)[0])
        assert not terminated
    assert any("forced failure" in line for line in policy.failure_log)
    assert any("standing still" in line for line in policy.failure_log)
    np.testing.assert_allclose(info["cog"][:2], x0[:2], atol=0.01)


def test_bad_config_is_rejected():
    env = gym.make("QuadUneven-v0", terrain="flat")
    with pytest.raises(ValueError, match="distribution"):
        attach_expert(env, ExpertConfig(distribution="magic"))
    with pytest.raises(ValueError, match="body_pitch"):
        attach_expert(env, ExpertConfig(body_pitch="magic"))


def test_stance_shanks_stay_off_the_stair_nosings():
    """Regression: 8 cm stairs down, seed 3. With a level body the plan lowered the COG for the
    front feet (a step lower) while the left hind foot still stood 2.5 cm behind the top nosing;
    the hind leg folded until its forward knee was below the foot and at t = 10.6 s the shank
    rested on the nosing, lifting the foot (index < 0 for 1.6 % of the episode)."""
    touched = []

    def check(env):
        touched.extend((round(env.data.time, 2), name) for name in leg_links_on_terrain(env))

    terrain = {"kind": "stairs", "direction": "down", "riser": 0.08, "tread": 0.3, "n_steps": 5}
    policy, distance, index, _ = walk(terrain, 12.0, seed=3, on_step=check)
    assert touched == []
    assert np.all(index >= 0.0)
    assert distance > 1.0 and policy.failure_log == []


@pytest.mark.slow
@pytest.mark.parametrize(
    "terrain",
    [
        {"kind": "stairs", "direction": "pyramid", "riser": 0.08},
        "stepping_stones",
        {"kind": "slope", "angle_deg": 10},
        "paper",
    ],
)
def test_expert_crosses_hard_terrain(terrain):
    _, distance, index, _ = walk(terrain, 31.0)
    assert distance > 2.5
    assert np.mean(index > 0) > 0.99
