"""Shared fixtures."""

from __future__ import annotations

import numpy as np
import pytest

from quad_uneven_env.robot.description import RobotDescription, load_robot


@pytest.fixture(scope="session")
def paper_robot() -> RobotDescription:
    """The paper's Table 1 robot."""
    return load_robot("paper")


@pytest.fixture
def rng() -> np.random.Generator:
    """A fixed-seed generator (tests must not use the global numpy RNG)."""
    return np.random.default_rng(12345)
