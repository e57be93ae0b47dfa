"""The policy protocol shared by the expert, learned agents and the evaluation; the zero policy."""

from __future__ import annotations

from typing import Any, Protocol

import gymnasium as gym
import numpy as np


class Policy(Protocol):
    """SB3's predict protocol: the scripted expert and learned agents both follow it."""

    def predict(
        self,
        observation: np.ndarray,
        state: Any = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = True,
    ) -> tuple[np.ndarray, Any]: ...


class ZeroActionPolicy:
    """Always the zero action: in ``joint_pd`` mode the robot holds its standing pose."""

    def __init__(self, action_space: gym.spaces.Box) -> None:
        self._zero = np.zeros(action_space.shape, dtype=action_space.dtype)

    def predict(self, observation, state=None, episode_start=None, deterministic=True):
        """:return: the zero action and the unchanged state."""
        return self._zero.copy(), state
