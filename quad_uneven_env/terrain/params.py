"""Declarative terrain parameters (:class:`quad_uneven_env.fields.Param`): the ones every kind shares.

Every terrain kind lists its parameters as ``Param`` objects; validation, the error messages and the
parameter tables of ``docs/terrain.md`` all come from these declarations.
"""

from __future__ import annotations

from quad_uneven_env.fields import REQUIRED, Param

SHARED_PARAMS: tuple[Param, ...] = (
    Param("length", 8.0, "m", "x extent of the grid", lo=0.0, hi=500.0, lo_open=True),
    Param("width", 3.0, "m", "y extent of the grid (centred on y = 0)", lo=0.0, hi=500.0, lo_open=True),
    Param("cell_size", 0.02, "m", "node spacing along x and y", lo=0.005, hi=0.5),
    Param("x_start", -1.5, "m", "world x of the grid's -x edge", lo=-500.0, hi=500.0),
    Param("spawn_radius", 0.6, "m", "radius of the flat area around spawn_xy = (0, 0)", lo=0.0, hi=50.0),
)
"""Parameters every kind except ``heightmap`` takes (heightmap takes cell_size, x_start, spawn_radius)."""

__all__ = ["REQUIRED", "SHARED_PARAMS", "Param"]
