"""``stepping_stones``: square stones separated by pits, after the flat spawn platform."""

from __future__ import annotations

import numpy as np

from quad_uneven_env.terrain.grid import Grid, feature_start
from quad_uneven_env.terrain.kinds.base import Params, TerrainKind
from quad_uneven_env.terrain.params import Param


def _check(p: Params, where: str) -> None:
    for name in ("stone_size", "gap"):
        if p[name] < 2.0 * p["cell_size"]:
            raise ValueError(
                f"{where}.{name} must be >= 2 * cell_size = {2 * p['cell_size']:g} m (so the grid resolves it), "
                f"got {p[name]:g}"
            )


def stone_layout(p: Params) -> tuple[float, float, float]:
    """(x of the first stone column's -x edge, y of a stone row's -y edge, pitch) (m)."""
    return feature_start(p) + p["gap"], p["gap"] / 2.0, p["stone_size"] + p["gap"]


def _generate(p: Params, grid: Grid, rng: np.random.Generator) -> np.ndarray:
    x_first, y_edge, pitch = stone_layout(p)
    xs, ys = grid.xs, grid.ys
    ix = np.floor((xs - x_first) / pitch + 1e-9).astype(int)
    iy = np.floor((ys - y_edge) / pitch + 1e-9).astype(int)
    on_x = (xs >= x_first - 1e-9) & (xs - x_first - ix * pitch < p["stone_size"] - 1e-9)
    on_y = ys - y_edge - iy * pitch < p["stone_size"] - 1e-9
    # One top per stone: (rows of stones along y) x (columns along x); the shape depends on the params only.
    iy0 = int(np.floor((grid.origin[1] - y_edge) / pitch))
    n_iy = int(np.floor((ys[-1] - y_edge) / pitch)) - iy0 + 1
    n_ix = max(int(np.floor((xs[-1] - x_first) / pitch)) + 1, 1)
    j = p["height_jitter"]
    tops = rng.uniform(-j / 2.0, j / 2.0, size=(n_iy, n_ix))
    stone_top = tops[(iy - iy0)[:, None], np.clip(ix, 0, n_ix - 1)[None, :]]
    h = np.where(on_y[:, None] & on_x[None, :], stone_top, -p["hole_depth"])
    h[:, xs < feature_start(p) - 1e-9] = 0.0
    return h


KIND = TerrainKind(
    name="stepping_stones",
    doc=(
        "Flat spawn platform at 0 for x < x0 = spawn_radius + cell_size, then a pit of width `gap` and a field of "
        "square stones (`stone_size`, pitch stone_size + gap) separated by pits `hole_depth` deep. Stone rows "
        "are centred on y = ±pitch/2, ±3 pitch/2, ... (a gap runs along y = 0, so feet at the hips' y land on "
        "stones). Each stone's top is drawn from U(-height_jitter/2, +height_jitter/2). Stone and pit edges "
        "lie on the first node at or beyond the nominal edge."
    ),
    params=(
        Param("stone_size", 0.25, "m", "side of the square stone tops (>= 2 cell_size)", lo=0.0, hi=5.0, lo_open=True),
        Param("gap", 0.05, "m", "width of the pits between stones (>= 2 cell_size)", lo=0.0, hi=2.0, lo_open=True),
        Param("height_jitter", 0.05, "m", "stone tops uniform in ±height_jitter/2 around 0", lo=0.0, hi=0.3),
        Param("hole_depth", 0.3, "m", "depth of the pits below 0", lo=0.0, hi=2.0, lo_open=True),
    ),
    generate=_generate,
    z_bounds=lambda p: (-p["hole_depth"], p["height_jitter"] / 2.0),
    check=_check,
)
