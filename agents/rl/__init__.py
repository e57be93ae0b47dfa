"""Residual RL on top of the expert: the residual env, training config, vec envs, training, model I/O.

Importing this package registers ``QuadUnevenResidual-v0`` (``gym.make("agents.rl:QuadUnevenResidual-v0")``
from a bare interpreter). Stable-Baselines3 and torch are imported only by :func:`train` and model loading.
"""

from typing import Any

from agents.rl.config import TrainConfig, TrainConfigError, load_train_config
from agents.rl.residual_env import (
    RESIDUAL_ENV_ID,
    ResidualConfig,
    ResidualController,
    ResidualExpertEnv,
    make_residual_env,
)

__all__ = [
    "RESIDUAL_ENV_ID",
    "ResidualConfig",
    "ResidualController",
    "ResidualExpertEnv",
    "TrainConfig",
    "TrainConfigError",
    "load_train_config",
    "make_residual_env",
    "train",
]


def __getattr__(name: str) -> Any:
    if name == "train":  # deferred: Stable-Baselines3 and torch take seconds to import
        from agents.rl.training import train

        return train
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
