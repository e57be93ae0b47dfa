"""N copies of QuadUneven-v0 as one Gymnasium vector env: ``gym.make_vec("QuadUneven-v0", num_envs=N)``.

The registered ``vector_entry_point``. Each copy is ``gym.make("QuadUneven-v0", **env_kwargs)`` with the
env's own defaults (time limit 1000 control steps unless ``max_episode_steps`` is given), so the vector
env steps exactly the single envs; Gymnasium's autoreset (next-step mode) resets a copy after its episode
ends. ``reset(seed=s)`` seeds copy ``i`` with ``s + i``. Every ``info`` key has a fixed shape and dtype
(the contract is in :class:`quad_uneven_env.env.QuadUnevenEnv`'s docstring), which Gymnasium's stacking
of infos needs.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym

from quad_uneven_env.fields import Param, excerpt

VECTORIZATION = Param("vectorization", "async", "-", "how the copies run", kind="choice", choices=("async", "sync"))
"""``"async"``: one subprocess per copy (the physics is the cost; default), ``"sync"``: in this process."""


def make_vector_env(
    num_envs: int = 1, *, vectorization: str = "async", max_episode_steps: int = 1000, **env_kwargs: Any
) -> gym.vector.VectorEnv:
    """``num_envs`` QuadUneven-v0 envs stepped together.

    :param num_envs: number of copies (>= 1).
    :param vectorization: ``"async"`` (subprocesses; with ``num_envs == 1`` it runs in-process) or ``"sync"``.
    :param max_episode_steps: control steps per episode of each copy.
    :param env_kwargs: ``QuadUneven-v0`` arguments shared by every copy.
    :raises ValueError: on a bad ``num_envs`` or ``vectorization``.
    """
    if isinstance(num_envs, bool) or not isinstance(num_envs, int) or num_envs < 1:
        raise ValueError(f"num_envs must be an integer >= 1, got {excerpt(num_envs)}")
    mode = VECTORIZATION.check(vectorization, "")

    def make_one() -> gym.Env:
        return gym.make("QuadUneven-v0", max_episode_steps=max_episode_steps, **env_kwargs)

    fns = [make_one] * num_envs
    if mode == "async" and num_envs > 1:
        return gym.vector.AsyncVectorEnv(fns)
    return gym.vector.SyncVectorEnv(fns)


__all__ = ["VECTORIZATION", "make_vector_env"]
