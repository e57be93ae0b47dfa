"""Shared fixtures."""

from __future__ import annotations

import numpy as np
import pytest

from quad_uneven_env.config import RobotConfig, load_robot_config


@pytest.fixture(scope="session")
def robot_cfg() -> RobotConfig:
    """The paper's Table 1 robot."""
    return load_robot_config("paper")


@pytest.fixture
def rng() -> np.random.Generator:
    """A fixed-seed generator (tests must not use the global numpy RNG)."""
    return np.random.default_rng(12345)
