"""``stairs``: a flight of steps up, down, or up then down (pyramid)."""

from __future__ import annotations

import numpy as np

from quad_uneven_env.terrain.grid import Grid, feature_start, shared_grid
from quad_uneven_env.terrain.kinds.base import Params, TerrainKind
from quad_uneven_env.terrain.params import Param

DIRECTIONS = ("up", "down", "pyramid")


def step_levels(p: Params, x: np.ndarray) -> np.ndarray:
    """Integer step level at world x (m): height = riser * level (down: negative)."""
    n = p["n_steps"]
    k = np.floor((np.asarray(x) - feature_start(p)) / p["tread"] + 1e-9).astype(int)  # tread index, -1 before
    up = np.clip(k + 1, 0, n)
    if p["direction"] == "up":
        return up
    if p["direction"] == "down":
        return -up
    return np.where(k < n, up, np.clip(2 * n - 1 - k, 0, n))


def last_edge(p: Params) -> float:
    """World x (m) of the flight's last step edge: x0 + (n_steps - 1) tread (pyramid: x0 + (2 n_steps - 1) tread)."""
    edges = 2 * p["n_steps"] if p["direction"] == "pyramid" else p["n_steps"]
    return feature_start(p) + (edges - 1) * p["tread"]


def _check(p: Params, where: str) -> None:
    if p["tread"] < 2.0 * p["cell_size"]:
        raise ValueError(f"{where}.tread must be in [max(0.15, 2 * cell_size), 1] m, got {p['tread']:g}")
    end = shared_grid(p).xs[-1]
    if last_edge(p) > end + 1e-9:
        raise ValueError(
            f"{where}: the {p['direction']} flight of n_steps={p['n_steps']} treads of {p['tread']:g} m from "
            f"x = {feature_start(p):g} m has its last step edge at x = {last_edge(p):g} m, beyond the grid's end "
            f"x = {end:g} m: lower n_steps or tread, or raise length to at least "
            f"{last_edge(p) + p['cell_size'] - p['x_start']:g} m"
        )


def _generate(p: Params, grid: Grid, rng: np.random.Generator) -> np.ndarray:
    profile = p["riser"] * step_levels(p, grid.xs)
    return np.broadcast_to(profile, (grid.nrow, grid.ncol)).astype(np.float64)


def _bounds(p: Params) -> tuple[float, float]:
    top = p["riser"] * p["n_steps"]
    return (-top, 0.0) if p["direction"] == "down" else (0.0, top)


KIND = TerrainKind(
    name="stairs",
    doc=(
        "Flat ground at 0 up to x0 = spawn_radius + cell_size, then `n_steps` steps of `tread` (x) and `riser` "
        "(z) each: `up` climbs to n_steps * riser and stays there; `down` descends to -n_steps * riser; "
        "`pyramid` climbs n_steps (the top step is one tread long) and descends back to 0. Constant along y. "
        "A step edge lies on the first node at or beyond x0 + k tread; the riser is the one-cell-wide "
        "triangle strip before it. The last step edge must lie on the grid (else ValueError naming the fields). "
        "Deterministic (the rng is not used)."
    ),
    params=(
        Param("riser", 0.08, "m", "height of each step", lo=0.0, hi=0.25, lo_open=True),
        Param("tread", 0.3, "m", "x depth of each step", lo=0.15, hi=1.0),
        Param("n_steps", 5, "-", "steps per flight", kind="int", lo=1, hi=100),
        Param("direction", "pyramid", "-", "up, down, or pyramid (up then down)", kind="choice", choices=DIRECTIONS),
    ),
    generate=_generate,
    z_bounds=_bounds,
    check=_check,
)
