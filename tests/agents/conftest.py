"""Fixtures shared by the agents tests."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="module")
def local_ray():
    """One local Ray of 2 CPUs and no dashboard for the tests of a module (starting one costs seconds); shut down
    after them. Skips without the ``distributed`` extra."""
    pytest.importorskip("ray")
    from agents.evaluation.ray_backend import ray_session

    with ray_session(num_cpus=2) as ray:
        yield ray
