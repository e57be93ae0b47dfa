"""``slope``: flat spawn, ramp up, plateau, ramp down, flat."""

from __future__ import annotations

import math

import numpy as np

from quad_uneven_env.terrain.grid import Grid, feature_start, shared_grid
from quad_uneven_env.terrain.kinds.base import Params, TerrainKind
from quad_uneven_env.terrain.params import Param


def ramp_height(p: Params) -> float:
    """Height (m) of the plateau: ramp_length * tan(angle_deg)."""
    return p["ramp_length"] * math.tan(math.radians(p["angle_deg"]))


def slope_end(p: Params) -> float:
    """World x (m) where the ramp down meets the ground again: x0 + 2 ramp_length + plateau_length."""
    return feature_start(p) + 2.0 * p["ramp_length"] + p["plateau_length"]


def _check(p: Params, where: str) -> None:
    end = shared_grid(p).xs[-1]
    if slope_end(p) > end + 1e-9:
        raise ValueError(
            f"{where}: the ramps and plateau (2 ramp_length + plateau_length = "
            f"{2 * p['ramp_length'] + p['plateau_length']:g} m from x = {feature_start(p):g} m) end at x = "
            f"{slope_end(p):g} m, beyond the grid's end x = {end:g} m: shorten ramp_length or plateau_length, or raise "
            f"length to at least {slope_end(p) - p['x_start']:g} m"
        )


def _generate(p: Params, grid: Grid, rng: np.random.Generator) -> np.ndarray:
    x0 = feature_start(p)
    ramp = p["ramp_length"]
    x3 = slope_end(p)
    x = grid.xs
    profile = ramp_height(p) * np.clip(np.minimum(x - x0, x3 - x) / ramp, 0.0, 1.0)
    return np.broadcast_to(profile, (grid.nrow, grid.ncol)).copy()


KIND = TerrainKind(
    name="slope",
    doc=(
        "Flat ground at 0 up to one cell beyond the spawn disc (x0 = spawn_radius + cell_size), then a ramp "
        "rising at `angle_deg` over `ramp_length` (x), a plateau of `plateau_length` at height "
        "ramp_length * tan(angle_deg), a ramp down of the same length and flat ground at 0. Constant along y. "
        "The ramp down must end on the grid (else ValueError naming the lengths). Deterministic (the rng is not "
        "used)."
    ),
    params=(
        Param("angle_deg", 10.0, "deg", "ramp angle from horizontal", lo=0.0, hi=30.0, lo_open=True),
        Param("ramp_length", 1.5, "m", "x length of each ramp", lo=0.0, hi=50.0, lo_open=True),
        Param("plateau_length", 1.0, "m", "x length of the plateau", lo=0.0, hi=50.0),
    ),
    generate=_generate,
    z_bounds=lambda p: (0.0, ramp_height(p)),
    check=_check,
)
