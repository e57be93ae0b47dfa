"""Residual RL on top of the expert: the residual env, training config, vec envs, training, model I/O.

Importing this package registers ``QuadUnevenResidual-v0`` (a residual on the expert's torques) and
``QuadUnevenPlan-v0`` (a residual on the expert's plan, one step per gait cycle); from a bare interpreter
``gym.make("agents.rl:QuadUnevenResidual-v0")``. Stable-Baselines3 and torch are imported only by :func:`train` and
model loading.
"""

from typing import Any

from agents.rl.config import TrainConfig, TrainConfigError, load_train_config
from agents.rl.plan_config import PlanConfig
from agents.rl.plan_env import PLAN_ENV_ID, PlanExpertEnv, make_plan_env
from agents.rl.residual_env import (
    RESIDUAL_ENV_ID,
    ResidualConfig,
    ResidualController,
    ResidualExpertEnv,
    make_residual_env,
)

__all__ = [
    "PLAN_ENV_ID",
    "RESIDUAL_ENV_ID",
    "PlanConfig",
    "PlanExpertEnv",
    "ResidualConfig",
    "ResidualController",
    "ResidualExpertEnv",
    "TrainConfig",
    "TrainConfigError",
    "load_train_config",
    "make_plan_env",
    "make_residual_env",
    "train",
]


def __getattr__(name: str) -> Any:
    if name == "train":  # deferred: Stable-Baselines3 and torch take seconds to import
        from agents.rl.training import train

        return train
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
