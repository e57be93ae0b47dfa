"""A terrain mix: every episode on a terrain drawn from a list (one env per terrain, one active at a time).

A MuJoCo height field's grid is fixed when the model is compiled, and terrain kinds have grids of their
own, so a mix cannot regenerate one model's height field into another kind. :class:`TerrainMixEnv` holds
one env per terrain spec (built by a factory, each with its own expert) and, at every reset, draws which
one runs the episode from its ``np_random`` (uniformly, or with ``weights``), then resets that env with a
seed drawn from the same generator. A seeded reset therefore fixes the whole sequence of terrains and
worlds. The observation and action spaces must be the same for every terrain.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np

from quad_uneven_env.fields import excerpt


class TerrainMixEnv(gym.Env):
    """Episodes on terrains drawn from a list; ``info["terrain_index"]`` says which one runs.

    :param env_fns: one factory per terrain (called once here); all envs must share their spaces.
    :param weights: draw probabilities (normalised here; default uniform).
    :param names: a label per terrain, for ``terrain_names`` (default ``"0"``, ``"1"``, ...).
    :raises ValueError: on no factory, spaces that differ, or weights of the wrong length or sign.
    """

    def __init__(
        self,
        env_fns: Sequence[Callable[[], gym.Env]],
        weights: Sequence[float] | None = None,
        names: Sequence[str] | None = None,
    ) -> None:
        if not env_fns:
            raise ValueError("terrain: the terrain mix needs at least one terrain")
        self.envs = [fn() for fn in env_fns]
        first = self.envs[0]
        for i, env in enumerate(self.envs[1:], start=1):
            if env.observation_space != first.observation_space or env.action_space != first.action_space:
                self.close()
                raise ValueError(
                    f"terrain: terrain {i} of the mix gives other spaces than terrain 0 "
                    f"({env.observation_space} vs {first.observation_space}); use one height-scan config for all"
                )
        n = len(self.envs)
        w = np.ones(n) if weights is None else np.asarray(weights, dtype=float)
        if w.shape != (n,) or not np.all(np.isfinite(w)) or np.any(w < 0) or w.sum() <= 0:
            self.close()
            raise ValueError(
                f"terrain weights must be {n} non-negative numbers with a positive sum, got {excerpt(weights)}"
            )
        self.weights = w / w.sum()
        self.terrain_names = [str(i) for i in range(n)] if names is None else [str(x) for x in names]
        self.observation_space = first.observation_space
        self.action_space = first.action_space
        self.metadata = first.metadata
        self.render_mode = first.render_mode
        self.active = 0
        """index of the terrain running the current episode."""

    @property
    def env(self) -> gym.Env:
        """The env running the current episode."""
        return self.envs[self.active]

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Draw the episode's terrain and reset its env with a seed drawn from :attr:`np_random`."""
        super().reset(seed=seed)
        self.active = int(self.np_random.choice(len(self.envs), p=self.weights))
        child_seed = int(self.np_random.integers(2**31 - 1))
        obs, info = self.env.reset(seed=child_seed, options=options)
        info["terrain_index"] = self.active
        return obs, info

    def step(self, action: np.ndarray):
        """Step the current terrain's env."""
        obs, reward, terminated, truncated, info = self.env.step(action)
        info["terrain_index"] = self.active
        return obs, reward, terminated, truncated, info

    def render(self):
        """Render the current terrain's env."""
        return self.env.render()

    def close(self) -> None:
        """Close every terrain's env."""
        for env in getattr(self, "envs", ()):
            env.close()


__all__ = ["TerrainMixEnv"]
