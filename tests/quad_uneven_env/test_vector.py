"""Gymnasium's vector API: make_vec in every mode, fixed info shapes, a CleanRL-style loop with autoreset."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import quad_uneven_env  # noqa: F401

FIXED_ARRAYS = {
    "edge_moments": ((4,), np.float64),
    "contact_forces": ((4, 3), np.float64),
    "foot_contact": ((4,), np.bool_),
    "cog": ((3,), np.float64),
    "feet_pos": ((4, 3), np.float64),
}


def _check_single_info(info: dict) -> None:
    for key, (shape, dtype) in FIXED_ARRAYS.items():
        assert info[key].shape == shape and info[key].dtype == dtype, key


def test_info_shapes_are_fixed_through_contact_changes_and_falls():
    """Random full-range torques at frame_skip 1: stance sets of every size, falls, resets."""
    env = gym.make("QuadUneven-v0", terrain="rough", frame_skip=1, max_episode_steps=300)
    rng = np.random.default_rng(0)
    _, info = env.reset(seed=0)
    _check_single_info(info)
    seen_stance, ended = set(), 0
    for _ in range(700):
        _, _, term, trunc, info = env.step(rng.choice([-1.0, 1.0], 12).astype(np.float32))
        _check_single_info(info)
        n = int(info["foot_contact"].sum())
        seen_stance.add(n)
        em = info["edge_moments"]
        if n >= 3:
            assert np.isfinite(em[:n]).all() and np.isposinf(em[n:]).all()
            assert info["stability_index"] == pytest.approx(em.min())
        if term or trunc:
            ended += 1
            _, info = env.reset()
            _check_single_info(info)
    assert ended >= 1 and len(seen_stance) >= 3, (ended, seen_stance)


@pytest.mark.parametrize("mode", ["sync", None])  # None: the vector entry point (async subprocesses)
def test_make_vec_steps_through_autoresets(mode):
    envs = gym.make_vec("QuadUneven-v0", num_envs=2, vectorization_mode=mode, terrain="rough", max_episode_steps=15)
    try:
        obs, infos = envs.reset(seed=3)
        assert obs.shape == (2, *envs.single_observation_space.shape)
        rng = np.random.default_rng(1)
        dones = 0
        for _ in range(40):
            obs, rew, term, trunc, infos = envs.step(rng.uniform(-1, 1, (2, 12)).astype(np.float32))
            assert infos["edge_moments"].shape == (2, 4) and infos["contact_forces"].shape == (2, 4, 3)
            assert envs.single_observation_space.contains(obs[0]) and np.isfinite(rew).all()
            dones += int((term | trunc).sum())
        assert dones >= 4  # each copy truncated at least twice, then autoreset
    finally:
        envs.close()


def test_vector_entry_point_equals_single_envs():
    """Copy i of make_vec(seed=s) walks exactly as gym.make(...).reset(seed=s + i)."""
    envs = gym.make_vec("QuadUneven-v0", num_envs=2, vectorization="sync", terrain="flat")
    single = [gym.make("QuadUneven-v0", terrain="flat") for _ in range(2)]
    obs, _ = envs.reset(seed=7)
    for i, e in enumerate(single):
        np.testing.assert_array_equal(obs[i], e.reset(seed=7 + i)[0])
    rng = np.random.default_rng(2)
    alive = [True, True]
    compared = 0
    for _ in range(10):
        a = rng.uniform(-1, 1, (2, 12)).astype(np.float32)
        obs, *_ = envs.step(a)
        for i, e in enumerate(single):
            if alive[i]:  # up to and including the step that ends the episode (make_vec then autoresets)
                o, _, term, trunc, _ = e.step(a[i])
                np.testing.assert_array_equal(obs[i], o)
                alive[i] = not (term or trunc)
                compared += 1
    assert compared >= 10
    envs.close()
    with pytest.raises(ValueError, match="vectorization"):
        gym.make_vec("QuadUneven-v0", num_envs=2, vectorization="threads")


def test_cleanrl_style_loop_over_two_async_envs():
    """The loop of CleanRL's ppo_continuous_action.py: async envs, episode statistics, autoreset."""
    envs = gym.make_vec(
        "QuadUneven-v0",
        num_envs=2,
        vectorization_mode="async",
        terrain="rough",
        max_episode_steps=60,
        wrappers=[gym.wrappers.ClipAction],
    )
    envs = gym.wrappers.vector.RecordEpisodeStatistics(envs)
    try:
        obs, _ = envs.reset(seed=1)
        rng = np.random.default_rng(3)
        returns = []
        for _ in range(300):
            obs, _reward, _term, _trunc, infos = envs.step(rng.normal(0, 0.5, (2, 12)).astype(np.float32))
            assert np.isfinite(obs).all()
            if "episode" in infos:
                returns += list(infos["episode"]["r"][infos["_episode"]])
        assert len(returns) >= 6 and np.isfinite(returns).all()
    finally:
        envs.close()


@pytest.mark.parametrize("mode", ["sync", pytest.param("async", marks=pytest.mark.slow)])
def test_make_vec_residual_env(mode):
    import agents.rl  # noqa: F401  (registers QuadUnevenResidual-v0)

    envs = gym.make_vec(
        "QuadUnevenResidual-v0", num_envs=2, vectorization_mode=mode, terrain="flat", max_episode_steps=20
    )
    try:
        envs.reset(seed=0)
        for _ in range(45):
            _, _, term, _trunc, infos = envs.step(np.zeros((2, 12), np.float32))
            assert infos["residual_torque"].shape == (2,) and infos["edge_moments"].shape == (2, 4)
            assert not term.any()  # the expert walks: only truncations
    finally:
        envs.close()
