"""``slope``: flat spawn, ramp up, plateau, ramp down, flat."""

from __future__ import annotations

import math

import numpy as np

from quad_uneven_env.terrain.grid import Grid, feature_start
from quad_uneven_env.terrain.kinds.base import Params, TerrainKind
from quad_uneven_env.terrain.params import Param


def ramp_height(p: Params) -> float:
    """Height (m) of the plateau: ramp_length * tan(angle_deg)."""
    return p["ramp_length"] * math.tan(math.radians(p["angle_deg"]))


def _generate(p: Params, grid: Grid, rng: np.random.Generator) -> np.ndarray:
    x0 = feature_start(p)
    ramp = p["ramp_length"]
    x3 = x0 + 2.0 * ramp + p["plateau_length"]
    x = grid.xs
    profile = ramp_height(p) * np.clip(np.minimum(x - x0, x3 - x) / ramp, 0.0, 1.0)
    return np.broadcast_to(profile, (grid.nrow, grid.ncol)).copy()


KIND = TerrainKind(
    name="slope",
    doc=(
        "Flat ground at 0 up to one cell beyond the spawn disc (x0 = spawn_radius + cell_size), then a ramp "
        "rising at `angle_deg` over `ramp_length` (x), a plateau of `plateau_length` at height "
        "ramp_length * tan(angle_deg), a ramp down of the same length and flat ground at 0. Constant along y. "
        "Deterministic (the rng is not used)."
    ),
    params=(
        Param("angle_deg", 10.0, "deg", "ramp angle from horizontal", lo=0.0, hi=30.0, lo_open=True),
        Param("ramp_length", 1.5, "m", "x length of each ramp", lo=0.0, hi=50.0, lo_open=True),
        Param("plateau_length", 1.0, "m", "x length of the plateau", lo=0.0, hi=50.0),
    ),
    generate=_generate,
    z_bounds=lambda p: (0.0, ramp_height(p)),
)
