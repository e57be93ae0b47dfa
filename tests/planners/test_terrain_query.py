"""The compiled terrain queries (planners/terrain_query_kernels.py) against their numpy twins."""

from __future__ import annotations

import numpy as np
import pytest

from planners.terrain_query import (
    BlockTerrain,
    capsule_clearance,
    capsule_clearance_numpy,
    max_height_in_disk,
    max_height_in_disk_numpy,
)
from quad_uneven_env.terrain import Terrain


@pytest.fixture(scope="module", params=["rough", "stairs", "stepping_stones"])
def heightfield(request):
    params = {"stepping_stones": {"gap": 0.12, "height_jitter": 0.08}}.get(request.param, {})
    terrain = Terrain({"kind": request.param, **params})
    return terrain.generate(np.random.default_rng(3))


def test_max_height_in_disk_equals_numpy(heightfield, rng):
    (x0, x1), (y0, y1) = heightfield.extent
    xy = np.column_stack([rng.uniform(x0 - 0.2, x1 + 0.2, 500), rng.uniform(y0 - 0.2, y1 + 0.2, 500)])  # edges too
    for radius in (0.0, 0.02, 0.15):
        got = max_height_in_disk(heightfield, xy, radius)
        np.testing.assert_allclose(got, max_height_in_disk_numpy(heightfield, xy, radius), rtol=0, atol=1e-12)


def test_capsule_clearance_equals_numpy(heightfield, rng):
    """Shank-like capsules above, touching and inside the surface, steep and vertical ones included."""
    (x0, x1), (y0, y1) = heightfield.extent
    n = 200
    a_xy = np.column_stack([rng.uniform(x0, x1, n), rng.uniform(y0, y1, n)])
    a = np.column_stack([a_xy, heightfield.height(a_xy[:, 0], a_xy[:, 1]) + rng.uniform(-0.05, 0.1, n)])
    b = a + rng.normal(scale=0.12, size=(n, 3))
    b[:10, :2] = a[:10, :2]  # vertical segments: no horizontal direction
    got = capsule_clearance(heightfield, a, b, 0.0175)
    ref = capsule_clearance_numpy(heightfield, a, b, 0.0175)
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12)
    assert (ref < 0).any() and (ref > 0.01).any()  # buried and clear capsules both tested


def test_maps_without_a_grid_take_the_numpy_path():
    """An analytic map (no grid): hand-computed values on the plane z = 0.2 x."""
    slope = BlockTerrain(slope=(0.2, 0.0))
    a, b = np.array([[0.0, 0.0, 0.1]]), np.array([[0.1, 0.0, 0.1]])
    # nearest plane point to the segment: from its end (0.1, 0, 0.1), 0.08 / sqrt(1.04) away; minus the radius
    assert capsule_clearance(slope, a, b, 0.01)[0] == pytest.approx(0.08 / np.sqrt(1.04) - 0.01, abs=2e-3)
    assert max_height_in_disk(slope, [[1.0, 0.0]], 0.1)[0] == pytest.approx(0.2 * 1.1)
