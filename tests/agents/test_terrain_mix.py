"""The terrain mix of training: a terrain per episode, seeded, the same spaces, the config's list form."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import quad_uneven_env  # noqa: F401  (registers QuadUneven-v0)
from agents.rl.config import TrainConfig, TrainConfigError, load_train_config, validate
from agents.rl.terrain_mix import TerrainMixEnv
from agents.rl.vec_env import make_train_env


def _mix(**kwargs) -> TerrainMixEnv:
    kinds = ("flat", "stairs", "rough")
    return TerrainMixEnv(
        [lambda k=k: gym.make("QuadUneven-v0", terrain=k, action_mode="joint_pd") for k in kinds],
        names=kinds,
        **kwargs,
    )


def test_each_episode_on_a_drawn_terrain_and_seeded():
    mix = _mix()
    kinds = []
    obs, info = mix.reset(seed=7)
    for _ in range(12):
        kinds.append(info["terrain_index"])
        assert mix.env.unwrapped.terrain.kind == mix.terrain_names[info["terrain_index"]]
        assert mix.observation_space.contains(obs)
        obs, _, _, _, step_info = mix.step(np.zeros(12, dtype=np.float32))
        assert step_info["terrain_index"] == info["terrain_index"]
        obs, info = mix.reset()
    assert set(kinds) == {0, 1, 2}  # 12 draws from 3 terrains: each one met (p = 1 - 3 (2/3)^12 > 0.97 per seed)
    again = _mix()
    _, info2 = again.reset(seed=7)
    kinds2 = [info2["terrain_index"]]
    for _ in range(11):
        _, info2 = again.reset()
        kinds2.append(info2["terrain_index"])
    assert kinds2 == kinds
    o1, _ = mix.reset(seed=3)
    o2, _ = again.reset(seed=3)
    np.testing.assert_array_equal(o1, o2)  # same terrain, same surface, same start


def test_weights_and_bad_mixes():
    mix = _mix(weights=[0.0, 1.0, 0.0])
    mix.reset(seed=0)
    assert {mix.reset()[1]["terrain_index"] for _ in range(5)} == {1}
    with pytest.raises(ValueError, match="terrain weights must be 3 non-negative"):
        _mix(weights=[1.0, -1.0, 1.0])
    with pytest.raises(ValueError, match="at least one terrain"):
        TerrainMixEnv([])
    other_scan = {"height_scan": {"size_x": 0.4, "size_y": 0.4, "resolution": 0.2}}
    with pytest.raises(ValueError, match="terrain 1 of the mix gives other spaces"):
        TerrainMixEnv(
            [
                lambda: gym.make("QuadUneven-v0", terrain="flat"),
                lambda: gym.make("QuadUneven-v0", terrain="flat", **other_scan),
            ]
        )


def test_training_env_of_a_terrain_list_with_randomization():
    from agents.rl.residual_env import ResidualConfig

    terrains = ["flat", {"kind": "stairs", "params": {"riser": 0.05}}]
    env = make_train_env(terrains, 5, {}, "mild", ResidualConfig(residual_scale=0.1))
    _, info = env.reset(seed=0)
    seen = set()
    for _ in range(6):
        seen.add(info["terrain_index"])
        assert info["randomization"]["friction"] != 1.0  # the mild preset is drawn
        for _ in range(5):
            _, _, terminated, truncated, info = env.step(np.zeros(12, dtype=np.float32))
            if terminated or truncated:
                break
        assert truncated and "ep_residual_torque" in info
        _, info = env.reset()
    assert seen == {0, 1}


def test_config_terrain_list_and_randomization_are_validated():
    cfg = validate(TrainConfig(terrain=["rough", {"kind": "stairs"}], randomization="hard"))
    assert cfg.terrain[1] == {"kind": "stairs"}
    with pytest.raises(TrainConfigError, match=r"^terrain\[1\]: terrain spec .lava. is neither a kind"):
        validate(TrainConfig(terrain=["rough", "lava"]))
    with pytest.raises(TrainConfigError, match="at least one terrain"):
        validate(TrainConfig(terrain=[]))
    with pytest.raises(TrainConfigError, match=r"^randomization"):
        validate(TrainConfig(randomization="stormy"))
    with pytest.raises(TrainConfigError, match="env_kwargs may not set"):
        validate(TrainConfig(env_kwargs={"randomization": "hard"}))
    shipped = load_train_config("configs/rl/ppo_residual_adaptive.yaml")
    assert len(shipped.terrain) == 6 and shipped.randomization == "extreme" and shipped.expert_features
