"""The node layout of a terrain grid, fixed by the spec's parameters alone (never by the seed)."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from quad_uneven_env.terrain.heightfield import MAX_CELLS

SPAWN_XY: tuple[float, float] = (0.0, 0.0)
"""World (x, y) (m) above which the robot's trunk starts; it walks along +x."""

MIN_Z_RANGE = 0.1
"""m: elevation range given to MuJoCo when a terrain is flat (MuJoCo needs a positive range)."""


@dataclasses.dataclass(frozen=True)
class Grid:
    """Node layout: ``nrow`` nodes along y, ``ncol`` along x, spacing ``cell_size`` (m), node [0, 0] at ``origin``."""

    nrow: int
    """nodes along y."""
    ncol: int
    """nodes along x."""
    cell_size: float
    """node spacing (m)."""
    origin: tuple[float, float]
    """world (x, y) (m) of node [0, 0]."""

    @property
    def xs(self) -> np.ndarray:
        """(ncol,) world x (m) of the node columns."""
        return self.origin[0] + self.cell_size * np.arange(self.ncol)

    @property
    def ys(self) -> np.ndarray:
        """(nrow,) world y (m) of the node rows."""
        return self.origin[1] + self.cell_size * np.arange(self.nrow)

    def mesh(self) -> tuple[np.ndarray, np.ndarray]:
        """(X, Y): (nrow, ncol) world x and y (m) of every node."""
        return np.meshgrid(self.xs, self.ys, indexing="xy")

    @property
    def size(self) -> tuple[float, float]:
        """(length along x, width along y) (m) of the node rectangle."""
        return (self.ncol - 1) * self.cell_size, (self.nrow - 1) * self.cell_size

    @property
    def center(self) -> tuple[float, float]:
        """World (x, y) (m) of the rectangle's centre."""
        lx, ly = self.size
        return self.origin[0] + lx / 2, self.origin[1] + ly / 2


def check_grid(grid: Grid, where: str, fields: str) -> None:
    """Raise ValueError (naming ``fields``) if ``grid`` has too few or too many nodes."""
    if grid.nrow < 2 or grid.ncol < 2:
        raise ValueError(f"{where}: {fields} give a {grid.nrow} x {grid.ncol} grid; at least 2 x 2 nodes are needed")
    if grid.nrow * grid.ncol > MAX_CELLS:
        raise ValueError(
            f"{where}: {fields} give {grid.nrow} x {grid.ncol} = {grid.nrow * grid.ncol} nodes; "
            f"the cap is {MAX_CELLS} (raise cell_size or shrink the terrain)"
        )


def shared_grid(p: Mapping[str, Any]) -> Grid:
    """Grid of the shared parameters: ``length`` x ``width`` rounded to whole cells, centred on y = 0."""
    cell = p["cell_size"]
    ncol = round(p["length"] / cell) + 1
    nrow = round(p["width"] / cell) + 1
    return Grid(nrow, ncol, cell, (p["x_start"], -(nrow - 1) * cell / 2.0))


def check_spawn_inside(grid: Grid, p: Mapping[str, Any], where: str, fields: str) -> None:
    """Raise ValueError unless the spawn disc (``spawn_radius`` around SPAWN_XY) lies inside the grid."""
    r = p["spawn_radius"]
    lx, ly = grid.size
    x0, y0 = grid.origin
    sx, sy = SPAWN_XY
    if not (x0 <= sx - r and sx + r <= x0 + lx and y0 <= sy - r and sy + r <= y0 + ly):
        raise ValueError(
            f"{where}: the spawn disc (radius spawn_radius={r:g} m around {SPAWN_XY}) must lie inside the grid "
            f"x in [{x0:g}, {x0 + lx:g}], y in [{y0:g}, {y0 + ly:g}] m; change {fields}"
        )


def feature_start(p: Mapping[str, Any]) -> float:
    """World x (m) where a kind's features (ramp, first step, stones) start.

    One cell beyond the spawn disc, so that every surface triangle touching the disc is flat.
    """
    return SPAWN_XY[0] + p["spawn_radius"] + p["cell_size"]


def spawn_blend_radius(p: Mapping[str, Any]) -> float:
    """Distance (m) from SPAWN_XY within which every node is forced flat: the disc plus one cell diagonal."""
    return p["spawn_radius"] + math.sqrt(2.0) * p["cell_size"]


def with_positive_range(z_min: float, z_max: float) -> tuple[float, float]:
    """(z_min, z_max) (m) widened to at least MIN_Z_RANGE above z_min when the terrain is (nearly) flat."""
    if z_max - z_min < 1e-6:
        return z_min, z_min + MIN_Z_RANGE
    return z_min, z_max
