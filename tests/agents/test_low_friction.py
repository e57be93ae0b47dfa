"""The expert on slippery floors: its force QP keeps every stance force inside the cone it assumes (0.25 by
default), which a floor of 0.35 holds; cones of 0.5 let the same walk's feet slide (docs/robustness.md)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import quad_uneven_env  # noqa: F401
from agents.expert import ExpertConfig, attach_expert


def walk_flat(floor: float, seconds: float, **config) -> tuple[float, bool, float]:
    """The expert on flat ground of friction ``floor`` for ``seconds`` (or 1.5 m): distance (m), fell, and the
    largest tangential over normal ratio of the stance forces its QP commanded (-)."""
    env = gym.make("QuadUneven-v0", terrain="flat", randomization={"friction": [floor, floor]}, max_episode_steps=10**6)
    expert = attach_expert(env, ExpertConfig(**config))
    _, info = env.reset(seed=0)
    fell, ratio = False, 0.0
    for _ in range(round(seconds / env.unwrapped.dt)):
        _, _, terminated, _, info = env.step(expert.predict(None)[0])
        last = expert.controller.last
        if last is not None:
            f = np.asarray(last.contact_forces)
            loaded = f[:, 2] > 20.0  # N: a stance foot that carries load
            if loaded.any():
                ratio = max(ratio, float(np.max(np.hypot(f[loaded, 0], f[loaded, 1]) / f[loaded, 2])))
        if terminated:
            fell = True
            break
        if info["distance"] >= 1.5:
            break
    env.close()
    return float(info["distance"]), fell, ratio


@pytest.mark.slow
def test_the_default_expert_walks_flat_ground_of_friction_035_where_cones_of_05_slip():
    distance, fell, ratio = walk_flat(0.35, 20.0)
    assert not fell and distance >= 1.5
    assert ratio <= ExpertConfig().friction + 1e-6 < 0.35
    wide_distance, wide_fell, wide_ratio = walk_flat(0.35, 20.0, friction=0.5)
    assert wide_fell or wide_distance < 1.5
    assert wide_ratio > 0.35  # the QP asked more of the floor than it holds
