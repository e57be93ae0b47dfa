"""``proprio_history``: the observation's last control steps of joint angles, velocities and actions."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import quad_uneven_env  # noqa: F401  (registers QuadUneven-v0)
from quad_uneven_env.history import HISTORY_SOURCES, MAX_HISTORY


def test_the_history_holds_the_previous_observations_values_oldest_first():
    """Rows are the earlier observations' values as observed (noise included: the hard preset's noise)."""
    env = gym.make("QuadUneven-v0", terrain="rough", randomization="hard", proprio_history=3)
    st = env.unwrapped.observation_structure
    obs, _ = env.reset(seed=4)
    for name in HISTORY_SOURCES:  # after a reset every row holds the reset's values
        np.testing.assert_array_equal(obs[st[f"{name}_history"]].reshape(3, -1), np.tile(obs[st[name]], (3, 1)))
    seen = [obs]
    rng = np.random.default_rng(0)
    for _ in range(5):
        obs, *_ = env.step(rng.uniform(-0.3, 0.3, 12).astype(np.float32))
        seen.append(obs)
    for name in HISTORY_SOURCES:
        rows = obs[st[f"{name}_history"]].reshape(3, -1)
        for k in range(3):  # row 2 is the previous observation, row 0 the one three steps back
            np.testing.assert_array_equal(rows[k], seen[-4 + k][st[name]])
    assert not np.allclose(seen[-2][st["joint_vel"]], seen[-3][st["joint_vel"]])  # not a constant history
    env.close()


def test_without_a_history_the_layout_is_unchanged_and_the_history_goes_last():
    plain = gym.make("QuadUneven-v0", terrain="flat", course_frame=True)
    with_history = gym.make("QuadUneven-v0", terrain="flat", course_frame=True, proprio_history=2)
    a, b = plain.unwrapped.observation_structure, with_history.unwrapped.observation_structure
    assert all(b[k] == v for k, v in a.items())
    n = plain.observation_space.shape[0]
    assert with_history.observation_space.shape == (n + 2 * 36,)
    assert b["joint_pos_history"].start == n
    o1, _ = plain.reset(seed=1)
    o2, _ = with_history.reset(seed=1)
    np.testing.assert_array_equal(o1, o2[:n])


def test_the_env_checkers_pass_with_a_history():
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = gym.make("QuadUneven-v0", terrain="flat", proprio_history=4, action_mode="joint_pd")
    check_env(env.unwrapped)
    sb3_check_env(env.unwrapped)


@pytest.mark.parametrize("value", [-1, MAX_HISTORY + 1, 2.5, True])
def test_a_bad_history_length_is_refused_naming_the_argument(value):
    with pytest.raises(ValueError, match="proprio_history"):
        gym.make("QuadUneven-v0", terrain="flat", proprio_history=value)
