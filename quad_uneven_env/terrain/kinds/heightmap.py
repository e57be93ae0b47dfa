"""``heightmap``: the user's own height grid (an array or a .npy file), used as given."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from quad_uneven_env.terrain.grid import SPAWN_XY, Grid, check_spawn_inside, spawn_blend_radius, with_positive_range
from quad_uneven_env.terrain.heightfield import MAX_CELLS
from quad_uneven_env.terrain.kinds.base import Params, TerrainKind
from quad_uneven_env.terrain.params import REQUIRED, SHARED_PARAMS, Param

SPAWN_FLAT_TOLERANCE = 1e-3
"""m: largest height range allowed among the nodes of the spawn area."""

_SHARED = {q.name: q for q in SHARED_PARAMS}


def check_npy_header(path: Path, where: str) -> None:
    """Refuse a .npy file from its header alone (before any data is read) unless it holds a 2-D numeric
    array of at most ``MAX_CELLS`` nodes: a header can claim a shape far larger than memory.

    :raises ValueError: naming ``where.heights``.
    """
    fmt = np.lib.format
    try:
        with path.open("rb") as f:
            version = fmt.read_magic(f)
            read = fmt.read_array_header_1_0 if version == (1, 0) else fmt.read_array_header_2_0
            shape, _fortran, dtype = read(f)
    except (OSError, ValueError, SyntaxError, TypeError) as exc:
        raise ValueError(f"{where}.heights: cannot read {str(path)!r} as a .npy array ({exc})") from None
    if dtype.kind not in "iuf":
        raise ValueError(f"{where}.heights: {str(path)!r} holds {dtype} values, not numbers (m)")
    if len(shape) != 2:
        raise ValueError(f"{where}.heights must be a 2-D array (rows along y, columns along x), got shape {shape}")
    if shape[0] * shape[1] > MAX_CELLS:
        raise ValueError(f"{where}.heights has {shape[0]} x {shape[1]} nodes in its header; the cap is {MAX_CELLS}")


def _load(value: Any, where: str) -> np.ndarray:
    if isinstance(value, (str, os.PathLike)):
        path = Path(value)
        if path.suffix != ".npy" or not path.is_file():
            raise ValueError(f"{where}.heights: {str(path)!r} is not an existing .npy file")
        check_npy_header(path, where)
        try:
            value = np.load(path, allow_pickle=False)
        except (OSError, ValueError) as exc:
            raise ValueError(f"{where}.heights: cannot read {str(path)!r} as a .npy array ({exc})") from exc
    try:
        raw = np.asarray(value)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where}.heights must be a 2-D array of numbers (m) or a .npy path ({exc})") from exc
    if raw.dtype.kind not in "iuf":  # bools, strings, complex or objects are not heights
        raise ValueError(f"{where}.heights must hold real numbers (m; float or int), got dtype {raw.dtype}")
    if raw.ndim != 2 or raw.shape[0] < 2 or raw.shape[1] < 2:
        raise ValueError(
            f"{where}.heights must be a 2-D array (rows along y, columns along x) of at least 2 x 2, "
            f"got shape {raw.shape}"
        )
    if raw.shape[0] * raw.shape[1] > MAX_CELLS:  # before the copy: a broadcast view costs no memory, its copy does
        raise ValueError(f"{where}.heights has {raw.shape[0]} x {raw.shape[1]} nodes; the cap is {MAX_CELLS}")
    h = np.array(raw, dtype=np.float64)
    if not np.all(np.isfinite(h)):
        raise ValueError(f"{where}.heights must be finite (found NaN or Inf)")
    h.setflags(write=False)
    return h


def _grid(p: Params) -> Grid:
    nrow, ncol = p["heights"].shape
    cell = p["cell_size"]
    origin = p["origin"] if p["origin"] is not None else (p["x_start"], -(nrow - 1) * cell / 2.0)
    return Grid(nrow, ncol, cell, (float(origin[0]), float(origin[1])))


def spawn_nodes(p: Params) -> np.ndarray:
    """Heights (m) of the nodes of every triangle touching the spawn disc."""
    x, y = _grid(p).mesh()
    return p["heights"][np.hypot(x - SPAWN_XY[0], y - SPAWN_XY[1]) <= spawn_blend_radius(p) + 1e-9]


def _check(p: dict[str, Any], where: str) -> None:
    p["heights"] = _load(p["heights"], where)
    if p["origin"] is not None and p["x_start"] != _SHARED["x_start"].default:
        raise ValueError(
            f"{where}: origin and x_start both place the grid; give one of them (origin={p['origin']}, "
            f"x_start={p['x_start']:g} m)"
        )
    check_spawn_inside(_grid(p), p, where, "origin, x_start or spawn_radius")
    nodes = spawn_nodes(p)
    if nodes.size and float(np.ptp(nodes)) > SPAWN_FLAT_TOLERANCE:
        raise ValueError(
            f"{where}.heights: the spawn area (spawn_radius={p['spawn_radius']:g} m around {SPAWN_XY}) must be flat "
            f"within {SPAWN_FLAT_TOLERANCE * 1e3:g} mm; its heights span {np.ptp(nodes) * 1e3:.3g} mm"
        )


def _generate(p: Params, grid: Grid, rng: np.random.Generator) -> np.ndarray:
    return np.array(p["heights"], dtype=np.float64)


def _bounds(p: Params) -> tuple[float, float]:
    return with_positive_range(float(p["heights"].min()), float(p["heights"].max()))


def _spawn_height(p: Params) -> float:
    nodes = spawn_nodes(p)
    return float(nodes.mean()) if nodes.size else 0.0


KIND = TerrainKind(
    name="heightmap",
    doc=(
        "The user's heights, used as given (up to MuJoCo's float32 storage: ~1e-7 of the height range): "
        "`heights` is a 2-D array (m; rows along +y, columns along +x) or the path of a .npy file. The grid "
        "has the array's shape; `length` and `width` are not accepted. The spawn area (nodes of every "
        "triangle touching the spawn disc) must already be flat within 1 mm, else ValueError. spawn_height is "
        "the mean of those nodes. The rng is not used."
    ),
    params=(
        Param("heights", REQUIRED, "m", "2-D heights (rows along y, columns along x) or a .npy path", kind="array"),
        _SHARED["cell_size"],
        Param(
            "origin", None, "m", "world (x, y) of element [0, 0]; null: centred on y = 0, -x edge at x_start", kind="xy"
        ),
        _SHARED["x_start"],
        _SHARED["spawn_radius"],
    ),
    generate=_generate,
    z_bounds=_bounds,
    check=_check,
    spawn_height=_spawn_height,
    grid=_grid,
    shared=False,
)
