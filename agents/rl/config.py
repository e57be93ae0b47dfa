"""Configuration of ``quad-uneven train``: one frozen dataclass, loaded from ``configs/rl/*.yaml``.

The YAML holds every field of :class:`TrainConfig`; command-line options override single fields
(:func:`load_train_config`). Every value is validated here, and a bad one raises
:class:`TrainConfigError` whose message starts with the field name.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from quad_uneven_env.config import CONFIG_DIR, read_yaml
from quad_uneven_env.terrain import parse_terrain_spec

RL_CONFIG_DIR = CONFIG_DIR / "rl"
"""Directory of the shipped training configs (``configs/rl/NAME.yaml``)."""

ALGOS = ("ppo", "sac")
"""Stable-Baselines3 algorithms ``quad-uneven train`` supports."""

VEC_ENVS = ("auto", "dummy", "subproc")
"""VecEnv classes: ``auto`` is SubprocVecEnv for n_envs > 1, else DummyVecEnv."""

FORBIDDEN_ENV_KWARGS = ("terrain", "controller", "action_mode", "render_mode")
"""QuadUneven-v0 arguments that ``env_kwargs`` may not set (the trainer or the residual env owns them)."""


class TrainConfigError(ValueError):
    """An invalid training option; the message starts with the field name."""


@dataclasses.dataclass(frozen=True)
class TrainConfig:
    """Everything one training run needs (SI units; steps are control steps of 20 ms)."""

    algo: str = "ppo"
    """``ppo`` or ``sac``."""
    terrain: str = "rough"
    """terrain kind, preset (``configs/terrain/``) or YAML path; a new surface is drawn at every reset."""
    timesteps: int = 100_000
    """total environment steps over all parallel envs."""
    time_limit_min: float = 0.0
    """wall-clock budget of the training loop (minutes); training stops there and saves; 0: none."""
    seed: int = 0
    """seed of the model and of the envs (env i gets seed + i; the evaluation env seed + 1000)."""
    n_envs: int = 2
    """parallel training envs."""
    vec_env: str = "auto"
    """``auto``, ``dummy`` or ``subproc``."""
    residual_scale: float = 0.1
    """residual torque per unit action as a fraction of the torque limit, in (0, 1]."""
    max_episode_steps: int = 1000
    """control steps per training episode (1000 = 20 s)."""
    env_kwargs: dict[str, Any] = dataclasses.field(default_factory=dict)
    """extra QuadUneven-v0 arguments (e.g. ``reward_weights``), also used by ``quad-uneven evaluate``."""
    normalize_obs: bool = True
    """VecNormalize the observations (statistics saved next to the model)."""
    normalize_reward: bool = True
    """VecNormalize the rewards (training only)."""
    eval_freq: int = 20_000
    """env steps (all envs) between evaluations of the deterministic policy; 0: none."""
    eval_episodes: int = 2
    """episodes per evaluation."""
    checkpoint_freq: int = 50_000
    """env steps (all envs) between checkpoints; 0: none."""
    hyperparams: dict[str, Any] = dataclasses.field(default_factory=dict)
    """keyword arguments of the SB3 algorithm class (``learning_rate``, ``n_steps``, ...)."""
    policy_kwargs: dict[str, Any] = dataclasses.field(default_factory=dict)
    """SB3 ``policy_kwargs`` (``net_arch``, ``log_std_init``, ...)."""

    def to_dict(self) -> dict[str, Any]:
        """A JSON-serialisable copy."""
        return dataclasses.asdict(self)


def _int(name: str, value: Any, low: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < low:
        raise TrainConfigError(f"{name} must be an integer >= {low}, got {value!r}")
    return int(value)


def _bool(name: str, value: Any) -> bool:
    if not isinstance(value, bool):
        raise TrainConfigError(f"{name} must be true or false, got {value!r}")
    return value


def _mapping(name: str, value: Any) -> dict[str, Any]:
    if value is None:
        return {}
    if not isinstance(value, Mapping) or not all(isinstance(k, str) for k in value):
        raise TrainConfigError(f"{name} must be a mapping with string keys, got {value!r}")
    return dict(value)


def validate(cfg: TrainConfig) -> TrainConfig:
    """``cfg`` checked field by field.

    :raises TrainConfigError: naming the first invalid field and its allowed values.
    """
    if cfg.algo not in ALGOS:
        raise TrainConfigError(f"algo must be one of {list(ALGOS)}, got {cfg.algo!r}")
    if cfg.vec_env not in VEC_ENVS:
        raise TrainConfigError(f"vec_env must be one of {list(VEC_ENVS)}, got {cfg.vec_env!r}")
    try:
        parse_terrain_spec(cfg.terrain)
    except ValueError as err:
        raise TrainConfigError(f"terrain: {err}") from None
    _int("timesteps", cfg.timesteps, 1)
    _int("seed", cfg.seed, 0)
    _int("n_envs", cfg.n_envs, 1)
    _int("max_episode_steps", cfg.max_episode_steps, 1)
    _int("eval_freq", cfg.eval_freq, 0)
    _int("eval_episodes", cfg.eval_episodes, 1)
    _int("checkpoint_freq", cfg.checkpoint_freq, 0)
    scale = cfg.residual_scale
    if isinstance(scale, bool) or not isinstance(scale, int | float) or not 0.0 < scale <= 1.0:
        raise TrainConfigError(f"residual_scale must be a number in (0, 1] (of the torque limit), got {scale!r}")
    limit = cfg.time_limit_min
    if isinstance(limit, bool) or not isinstance(limit, int | float) or not 0.0 <= limit < 1e6:
        raise TrainConfigError(f"time_limit_min must be a number of minutes >= 0 (0: none), got {limit!r}")
    _bool("normalize_obs", cfg.normalize_obs)
    _bool("normalize_reward", cfg.normalize_reward)
    env_kwargs = _mapping("env_kwargs", cfg.env_kwargs)
    bad = sorted(set(env_kwargs) & set(FORBIDDEN_ENV_KWARGS))
    if bad:
        raise TrainConfigError(f"env_kwargs may not set {bad} (the trainer and the residual env own them)")
    _mapping("hyperparams", cfg.hyperparams)
    _mapping("policy_kwargs", cfg.policy_kwargs)
    for key in ("policy_kwargs", "env", "seed", "verbose", "device", "policy"):
        if key in cfg.hyperparams:
            raise TrainConfigError(f"hyperparams may not set {key!r} (use the config field or option of that name)")
    return cfg


def default_config_path(algo: str) -> Path:
    """``configs/rl/{algo}_residual.yaml``."""
    return RL_CONFIG_DIR / f"{algo}_residual.yaml"


def load_train_config(
    path: str | os.PathLike[str] | None = None, overrides: Mapping[str, Any] | None = None
) -> TrainConfig:
    """Read a training config and apply ``overrides`` (None values are ignored), then validate.

    :param path: a YAML file; None: :func:`default_config_path` of the ``algo`` override (default ppo).
    :param overrides: field -> value, e.g. from the command line.
    :raises TrainConfigError: on an unknown or invalid field, or an ``algo`` override that differs from the file's.
    """
    overrides = {k: v for k, v in (overrides or {}).items() if v is not None}
    if path is None:
        algo = overrides.get("algo", "ppo")
        if algo not in ALGOS:
            raise TrainConfigError(f"algo must be one of {list(ALGOS)}, got {algo!r}")
        path = default_config_path(algo)
    try:
        raw = read_yaml(path)
    except ValueError as err:
        raise TrainConfigError(f"config: {err}") from None
    names = {f.name for f in dataclasses.fields(TrainConfig)}
    unknown = sorted((set(raw) | set(overrides)) - names)
    if unknown:
        raise TrainConfigError(f"{unknown[0]}: unknown field; allowed: {sorted(names)}")
    if "algo" in raw and "algo" in overrides and raw["algo"] != overrides["algo"]:
        raise TrainConfigError(
            f"algo: the config {str(path)!r} is for {raw['algo']!r}, got {overrides['algo']!r} "
            f"(use {default_config_path(overrides['algo']).name} or a config of that algo)"
        )
    return validate(TrainConfig(**{**raw, **overrides}))


__all__ = ["ALGOS", "RL_CONFIG_DIR", "TrainConfig", "TrainConfigError", "default_config_path", "load_train_config"]
