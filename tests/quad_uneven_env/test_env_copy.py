"""copy.deepcopy and a pickle round trip give an env that steps exactly as the original from the copied state, and
shares nothing with it."""

from __future__ import annotations

import copy
import pickle

import gymnasium as gym
import numpy as np
import pytest

import agents.rl  # noqa: F401  (registers QuadUnevenResidual-v0)
import quad_uneven_env  # noqa: F401  (registers QuadUneven-v0)

CASES = {
    "plain": {},
    "randomized": {"randomization": "hard"},
    "command": {"command": {"ranges": {"vx": [-0.2, 0.2], "yaw_rate": [-0.3, 0.3]}, "resample_interval": 0.1}},
}
COPIES = {"deepcopy": copy.deepcopy, "pickle": lambda env: pickle.loads(pickle.dumps(env))}


def _roll(env: gym.Env, actions: np.ndarray) -> list:
    out = []
    for a in actions:
        obs, reward, terminated, truncated, info = env.step(a)
        out.append((obs.copy(), reward, terminated, truncated, info["stability_index"], info["cog"].copy()))
        if terminated or truncated:
            obs, _ = env.reset()
            out.append((obs.copy(),))
    return out


@pytest.mark.parametrize("how", sorted(COPIES))
@pytest.mark.parametrize("case", sorted(CASES))
def test_a_copy_steps_as_the_original(case, how):
    env = gym.make("QuadUneven-v0", max_episode_steps=12, **CASES[case])
    rng = np.random.default_rng(1)
    env.reset(seed=3)
    for a in rng.uniform(-0.3, 0.3, size=(5, 12)).astype(np.float32):
        env.step(a)
    twin = COPIES[how](env)
    actions = rng.uniform(-0.3, 0.3, size=(15, 12)).astype(np.float32)  # past the 12-step limit: a reset too
    ours, theirs = _roll(twin, actions), _roll(env, actions)
    assert len(ours) == len(theirs)
    for a, b in zip(ours, theirs, strict=True):
        for x, y in zip(a, b, strict=True):
            np.testing.assert_array_equal(x, y)
    assert twin.unwrapped.data is not env.unwrapped.data


@pytest.mark.parametrize("how", sorted(COPIES))
def test_a_copy_of_the_residual_env_steps_as_the_original(how):
    """The expert (planner, physics-rate hook, compiled control step) is copied with its env and drives the copy."""
    env = gym.make("QuadUnevenResidual-v0", max_episode_steps=20)
    rng = np.random.default_rng(2)
    env.reset(seed=5)
    for a in rng.uniform(-0.5, 0.5, size=(6, 12)).astype(np.float32):
        env.step(a)
    twin = COPIES[how](env)
    assert twin.unwrapped.data is not env.unwrapped.data
    actions = rng.uniform(-0.5, 0.5, size=(18, 12)).astype(np.float32)  # past the 20-step limit: a reset too
    ours, theirs = _roll(twin, actions), _roll(env, actions)
    assert len(ours) == len(theirs) == 19
    for a, b in zip(ours, theirs, strict=True):
        for x, y in zip(a, b, strict=True):
            np.testing.assert_array_equal(x, y)


def test_stepping_a_copy_leaves_the_original_alone():
    env = gym.make("QuadUneven-v0")
    env.reset(seed=0)
    before = env.unwrapped.data.qpos.copy()
    twin = copy.deepcopy(env)
    for _ in range(3):
        twin.step(np.full(12, 0.5, dtype=np.float32))
    np.testing.assert_array_equal(env.unwrapped.data.qpos, before)
    assert not np.array_equal(twin.unwrapped.data.qpos, before)
