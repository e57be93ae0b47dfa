"""The env step's cheaper bookkeeping (compiled action clip, reward scratch buffers, the padded edge moments, the
measurement kernel's entry point) gives exactly the outputs of the plain numpy formulas it replaced."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from quad_uneven_env import constants as C
from quad_uneven_env.rewards import reward_terms


def _numpy_twin(env, action, cog_x_before: float, info: dict, fell: bool):
    """(clipped action, reward terms, edge moments) by the formulas ``step`` used before (numpy, allocating)."""
    a = np.minimum(np.maximum(np.asarray(action, dtype=np.float64), -1.0), 1.0)
    d, meas = env.data, env._meas
    diverged = info["diverged"]
    torque = d.actuator_force
    tau_frac = np.zeros(C.N_JOINTS) if diverged else torque / env.idx.torque_limit
    power = 0.0 if diverged else float(np.abs(torque * d.qvel[6:]).sum())
    cog_vel_x = 0.0 if diverged else (float(meas.cog[0]) - cog_x_before) / env.dt
    index_norm = info["stability_index_normalized"]
    terms = reward_terms(env.reward_weights, cog_vel_x, index_norm, tau_frac, power, env.total_mass * env._g, fell)
    moments = np.full(C.N_LEGS, np.inf)
    moments[: meas.moments.shape[0]] = meas.moments
    return a, terms, moments


@pytest.mark.parametrize("kwargs", [{}, {"randomization": "extreme"}, {"action_mode": "joint_pd"}])
def test_step_outputs_equal_the_numpy_formulas(kwargs):
    env = gym.make("QuadUneven-v0", terrain="rough", **kwargs).unwrapped
    env.reset(seed=4)
    rng = np.random.default_rng(1)
    checked = 0
    for i in range(150):
        action = rng.uniform(-1.6, 1.6, C.N_JOINTS)
        action[i % C.N_JOINTS] = -0.0
        if i % 3 == 0:
            action = action.astype(np.float32)
        elif i % 3 == 1:
            action = list(action)
        before = float(env._meas.cog[0])
        _, reward, fell, truncated, info = env.step(action)
        a, terms, moments = _numpy_twin(env, action, before, info, fell)
        np.testing.assert_array_equal(env._prev_action, a)
        assert np.signbit(env._prev_action).tolist() == np.signbit(a).tolist()
        assert info["reward_terms"] == terms
        assert reward == float(sum(terms.values()))
        np.testing.assert_array_equal(info["edge_moments"], moments)
        checked += 1
        if fell or truncated:
            env.reset(seed=i)
    assert checked == 150


def test_a_malformed_action_is_refused_as_before():
    env = gym.make("QuadUneven-v0", terrain="flat").unwrapped
    env.reset(seed=0)
    qpos = env.data.qpos.copy()
    bad = np.zeros(C.N_JOINTS)
    bad[[2, 7]] = (np.nan, -np.inf)
    with pytest.raises(ValueError, match=r"action must be finite, got NaN/Inf at indices \[2, 7\]"):
        env.step(bad)
    with pytest.raises(ValueError, match=r"action must have shape \(12,\), got \(11,\)"):
        env.step(np.zeros(11))
    np.testing.assert_array_equal(env.data.qpos, qpos)
    strided = np.linspace(-3.0, 3.0, 2 * C.N_JOINTS)[::2]  # a non-contiguous action
    env.step(strided)
    np.testing.assert_array_equal(env._prev_action, np.clip(strided, -1.0, 1.0))


def test_the_edge_moments_padding_is_never_shared():
    env = gym.make("QuadUneven-v0", terrain="flat").unwrapped
    _, first = env.reset(seed=0)
    _, _, _, _, second = env.step(np.zeros(C.N_JOINTS))
    first["edge_moments"][:] = -1.0
    np.testing.assert_array_equal(second["edge_moments"][np.isinf(second["edge_moments"])], np.inf)
    _, _, _, _, third = env.step(np.zeros(C.N_JOINTS))
    assert not np.any(third["edge_moments"] == -1.0)
