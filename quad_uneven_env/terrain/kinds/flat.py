"""``flat``: level ground at height 0."""

from __future__ import annotations

import numpy as np

from quad_uneven_env.terrain.grid import Grid, with_positive_range
from quad_uneven_env.terrain.kinds.base import Params, TerrainKind


def _generate(p: Params, grid: Grid, rng: np.random.Generator) -> np.ndarray:
    return np.zeros((grid.nrow, grid.ncol))


KIND = TerrainKind(
    name="flat",
    doc="Level ground at height 0 m. Only the shared parameters.",
    params=(),
    generate=_generate,
    z_bounds=lambda p: with_positive_range(0.0, 0.0),
)
