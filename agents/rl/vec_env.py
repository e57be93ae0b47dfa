"""Environments of a training run: the residual env with per-episode statistics, vectorised the SB3 way."""

from __future__ import annotations

import functools
import math
import signal
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecEnv, VecNormalize

from agents.rl.config import TrainConfig, terrain_label
from agents.rl.plan_config import PlanConfig
from agents.rl.plan_env import PLAN_ENV_ID
from agents.rl.residual_config import ResidualConfig
from agents.rl.residual_env import RESIDUAL_ENV_ID
from agents.rl.terrain_mix import TerrainMixEnv

SCRATCH_ENV_KWARGS: dict[str, Any] = {"action_mode": "joint_pd"}
"""QuadUneven-v0 arguments of a policy trained from scratch (``TrainConfig.residual = False``)."""

EPISODE_KEYS = ("ep_stability_mean", "ep_stability_min", "ep_distance", "ep_diverged", "ep_fell", "ep_residual_torque")
"""Keys :class:`EpisodeStats` puts in the last info of an episode (and Monitor writes to its CSV)."""

EVAL_SEED_OFFSET = 1000
"""The evaluation env is seeded with ``seed + EVAL_SEED_OFFSET`` (terrains unseen in training)."""


class EpisodeStats(gym.Wrapper):
    """Adds per-episode figures to the info of the step that ends an episode.

    ``ep_stability_mean`` and ``ep_stability_min`` (N m): mean and minimum of ``info["stability_index"]``
    over the steps with >= 3 feet in contact (NaN if none); ``ep_distance`` (m): COG x travelled;
    ``ep_diverged`` and ``ep_fell`` (0 or 1): the episode ended by numerical divergence / by a fall or
    divergence (not by the time limit); ``ep_residual_torque`` (N m): mean of ``info["residual_torque"]``
    (NaN without a residual).
    """

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self._sum, self._n, self._min = 0.0, 0, math.inf
        self._res_sum, self._res_n = 0.0, 0

    def reset(self, **kwargs: Any):
        """Reset the env and the episode statistics."""
        self._sum, self._n, self._min = 0.0, 0, math.inf
        self._res_sum, self._res_n = 0.0, 0
        return self.env.reset(**kwargs)

    def step(self, action: np.ndarray):
        """Step the env; on the last step of an episode add :data:`EPISODE_KEYS` to ``info``."""
        obs, reward, terminated, truncated, info = self.env.step(action)
        index = float(info.get("stability_index", math.nan))
        if math.isfinite(index):
            self._sum += index
            self._n += 1
            self._min = min(self._min, index)
        if "residual_torque" in info:
            self._res_sum += float(info["residual_torque"])
            self._res_n += 1
        if terminated or truncated:
            info["ep_stability_mean"] = self._sum / self._n if self._n else math.nan
            info["ep_stability_min"] = self._min if self._n else math.nan
            info["ep_distance"] = float(info.get("distance", math.nan))
            info["ep_diverged"] = int(bool(info.get("diverged", False)))
            info["ep_fell"] = int(bool(terminated))
            info["ep_residual_torque"] = self._res_sum / self._res_n if self._res_n else math.nan
        return obs, reward, terminated, truncated, info


def make_train_env(
    terrain: Any,
    max_episode_steps: int,
    env_kwargs: dict[str, Any] | None = None,
    randomization: Any = None,
    residual: ResidualConfig | PlanConfig | None = None,
) -> gym.Env:
    """One training env with a time limit and :class:`EpisodeStats`: the residual env (expert in the loop), or
    plain ``QuadUneven-v0`` in ``joint_pd`` mode (training from scratch).

    :param terrain: terrain kind, preset, YAML path or mapping, or a list of them (a
        :class:`~agents.rl.terrain_mix.TerrainMixEnv`: each episode on one of them).
    :param max_episode_steps: control steps before truncation.
    :param env_kwargs: extra QuadUneven-v0 arguments.
    :param randomization: the training world's randomization (None: nominal).
    :param residual: the residual env's settings and its expert's (a :class:`PlanConfig`: the plan-level env, whose
        episodes end after ``PlanConfig.max_control_steps`` control steps instead of ``max_episode_steps`` env
        steps); None: no expert (from scratch).
    """

    def one(spec: Any) -> gym.Env:
        if isinstance(residual, PlanConfig):
            return gym.make(
                PLAN_ENV_ID, config=residual, terrain=spec, randomization=randomization, **(env_kwargs or {})
            )
        if residual is None:
            return gym.make(
                "QuadUneven-v0",
                terrain=spec,
                max_episode_steps=max_episode_steps,
                randomization=randomization,
                **SCRATCH_ENV_KWARGS,
                **(env_kwargs or {}),
            )
        return gym.make(
            RESIDUAL_ENV_ID,
            config=residual,
            terrain=spec,
            max_episode_steps=max_episode_steps,
            randomization=randomization,
            **(env_kwargs or {}),
        )

    if isinstance(terrain, list | tuple):
        names = [terrain_label(spec) for spec in terrain]
        env: gym.Env = TerrainMixEnv([functools.partial(one, spec) for spec in terrain], names=names)
    else:
        env = one(terrain)
    return EpisodeStats(env)


def _ignoring_interrupts(env_fn: Callable[[], gym.Env]) -> gym.Env:
    """``env_fn()`` in a SubprocVecEnv worker that ignores SIGINT and SIGTERM from then on.

    Ctrl-C or a SIGTERM sent to the whole process group is then the trainer's to handle: it stops
    training, saves the model and closes the workers (which also end when the trainer's pipe closes).
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    return env_fn()


def build_vec_env(
    cfg: TrainConfig, n_envs: int, seed: int, monitor_dir: Path | None, vec_env: str | None = None
) -> VecEnv:
    """``n_envs`` monitored residual envs as an SB3 VecEnv (not normalised).

    :param seed: env i is seeded with ``seed + i``.
    :param monitor_dir: where Monitor writes ``N.monitor.csv`` (None: no file).
    :param vec_env: ``dummy``, ``subproc`` or ``auto`` (default: ``cfg.vec_env``).
    """
    kind = vec_env or cfg.vec_env
    if kind == "auto":
        kind = "subproc" if n_envs > 1 else "dummy"
    env_fn = functools.partial(
        make_train_env,
        cfg.terrain,
        cfg.max_episode_steps,
        dict(cfg.env_kwargs),
        cfg.randomization,
        cfg.env_config(),
    )
    if kind == "subproc":
        env_fn = functools.partial(_ignoring_interrupts, env_fn)
    return make_vec_env(
        env_fn,
        n_envs=n_envs,
        seed=seed,
        monitor_dir=str(monitor_dir) if monitor_dir is not None else None,
        monitor_kwargs={"info_keywords": EPISODE_KEYS},
        vec_env_cls=SubprocVecEnv if kind == "subproc" else DummyVecEnv,
        # forkserver (SB3's default) re-imports the compiled kernels in every worker; fork is fine
        # here because no GL context exists (training never renders).
        vec_env_kwargs={"start_method": "fork"} if kind == "subproc" else None,
    )


def normalize(venv: VecEnv, cfg: TrainConfig, training: bool) -> VecEnv:
    """Wrap ``venv`` in VecNormalize if the config asks for it (rewards only while training)."""
    if not (cfg.normalize_obs or cfg.normalize_reward):
        return venv
    return VecNormalize(
        venv,
        training=training,
        norm_obs=cfg.normalize_obs,
        norm_reward=cfg.normalize_reward and training,
        gamma=float(cfg.hyperparams.get("gamma", 0.99)),
    )


__all__ = [
    "EPISODE_KEYS",
    "EVAL_SEED_OFFSET",
    "SCRATCH_ENV_KWARGS",
    "EpisodeStats",
    "build_vec_env",
    "make_train_env",
    "normalize",
]
