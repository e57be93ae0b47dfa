"""Fixtures shared by the agents tests."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="module")
def local_ray():
    """One local Ray of 2 CPUs and no dashboard for the tests of a module (starting one costs seconds); shut down
    after them. Skips without the ``distributed`` extra."""
    ray = pytest.importorskip("ray")
    ray.init(num_cpus=2, include_dashboard=False, logging_level="WARNING")
    yield ray
    ray.shutdown()
