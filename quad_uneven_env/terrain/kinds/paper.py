"""``paper``: a reconstruction of the paper's Fig. 3 scene (the figure itself is not in the text).

The feet stand on raised, non-coplanar blocks: with the foot sites 0.02 m above the block tops,
the paper's COG heights (0.544 m at the start, 0.5743 m at the end, Table 1) are natural for the
Table-1 robot. The block positions and heights are this project's reconstruction, not the paper's.
"""

from __future__ import annotations

import types

import numpy as np

from quad_uneven_env.terrain.grid import Grid
from quad_uneven_env.terrain.kinds.base import Params, TerrainKind
from quad_uneven_env.terrain.params import Param


def _frozen(rows: list[list[float]]) -> np.ndarray:
    a = np.array(rows, dtype=np.float64)
    a.setflags(write=False)
    return a


PAPER_BLOCKS = types.MappingProxyType(
    {
        # (x, y, top height) (m, world) per leg in LF, RF, LH, RH order.
        "start": _frozen([[0.26, 0.185, 0.19], [0.26, -0.185, 0.17], [-0.24, 0.185, 0.18], [-0.24, -0.185, 0.16]]),
        "target": _frozen([[0.46, 0.185, 0.23], [0.46, -0.185, 0.21], [-0.04, 0.185, 0.20], [-0.04, -0.185, 0.19]]),
    }
)
"""Scripted foothold blocks of the ``paper`` kind: ``"start"`` and ``"target"`` -> (4, 3) read-only arrays
of block-top centres (x, y, z) (m, world), legs in LF, RF, LH, RH order. A foot site standing on a block
is ``cfg.foot_radius`` (0.02 m) above its top."""

FIELD_START_X = 0.6
"""World x (m) where the seeded block field beyond the scripted blocks begins (times the kind's ``scale``)."""

BASE_HEIGHT_MAX = 0.15
"""m (times ``scale``): the highest ``base_height``, below the lowest block top (0.16 m)."""

BLOCK_SIZE_MAX = 0.2
"""m (times ``scale``): the widest ``block_size``, the blocks' spacing along x (0.2 m), so that none merge."""


def blocks(p: Params, key: str) -> np.ndarray:
    """(4, 3) block-top centres (x, y, z) (m, world) of ``PAPER_BLOCKS[key]`` times the kind's ``scale``."""
    return PAPER_BLOCKS[key] * p["scale"]


def _generate(p: Params, grid: Grid, rng: np.random.Generator) -> np.ndarray:
    xs, ys = grid.xs, grid.ys
    pitch, base = p["field_pitch"], p["base_height"]
    h = np.full((grid.nrow, grid.ncol), base)
    # Seeded field: tiles of `pitch` from FIELD_START_X, centred on y = k pitch (feet near y = ±0.185 sit mid-tile).
    field_x = FIELD_START_X * p["scale"]
    ix = np.floor((xs - field_x) / pitch + 1e-9).astype(int)
    iy = np.floor(ys / pitch + 0.5 + 1e-9).astype(int)
    iy0 = int(iy.min())
    n_ix = max(int(ix.max()) + 1, 1)
    tops = base + rng.uniform(0.0, p["block_jitter"], size=(int(iy.max()) - iy0 + 1, n_ix))
    field = tops[(iy - iy0)[:, None], np.clip(ix, 0, n_ix - 1)[None, :]]
    h = np.where((xs >= field_x - 1e-9)[None, :], field, h)
    half = p["block_size"] / 2.0 + 1e-9
    for xc, yc, top in np.concatenate([blocks(p, "start"), blocks(p, "target")]):
        on = (np.abs(ys - yc) <= half)[:, None] & (np.abs(xs - xc) <= half)[None, :]
        h[on] = top
    return h


def _bounds(p: Params) -> tuple[float, float]:
    tops = max(float(blocks(p, "start")[:, 2].max()), float(blocks(p, "target")[:, 2].max()))
    return p["base_height"], max(tops, p["base_height"] + p["block_jitter"])


def _check(p: Params, where: str) -> None:
    x0, lx, k = p["x_start"], p["length"], p["scale"]
    for name, most in (("base_height", BASE_HEIGHT_MAX), ("block_size", BLOCK_SIZE_MAX)):
        if p[name] > most * k:
            raise ValueError(f"{where}.{name} must be <= {most:g} * scale = {most * k:g} m, got {p[name]:g}")
    tops = np.concatenate([blocks(p, "start"), blocks(p, "target")])
    half = p["block_size"] / 2.0
    if x0 > tops[:, 0].min() - half - p["cell_size"] or x0 + lx < FIELD_START_X * k:
        raise ValueError(
            f"{where}: x_start and length must put the scripted blocks and x = {FIELD_START_X * k:g} m on the grid"
        )
    if p["width"] / 2.0 < np.abs(tops[:, 1]).max() + half + p["cell_size"]:
        raise ValueError(f"{where}.width must be > {2 * (np.abs(tops[:, 1]).max() + half + p['cell_size']):g} m")


KIND = TerrainKind(
    name="paper",
    doc=(
        "A reconstruction of the paper's Fig. 3 scene (the figure is missing from the text): raised ground at "
        "`base_height` everywhere, 8 scripted square blocks (`block_size` top) centred on the start and target "
        "footholds of `PAPER_BLOCKS` (tops 0.16-0.23 m), and beyond x = 0.6 m a seeded field of square tiles "
        "(`field_pitch`, centred on y = k field_pitch) with tops base_height + U(0, block_jitter), so a robot "
        "can keep walking 5+ m. The spawn area is NOT flat here: it is the four start blocks, and spawn_height "
        "is the highest start-block top (0.19 m); spawn_radius is only checked to fit in the grid. `scale` "
        "magnifies the scripted blocks (positions and tops) and the field's start x; a suite scaled to a robot "
        "(`scale: leg_length`) sets it with every length, and base_height <= 0.15 scale, block_size <= 0.2 scale."
    ),
    params=(
        Param("base_height", 0.12, "m", "height of the ground around the blocks (<= 0.15 scale)", lo=0.0, hi=1.5),
        Param("block_size", 0.16, "m", "side of the scripted blocks' square tops (<= 0.2 scale)", lo=0.04, hi=2.0),
        Param("block_jitter", 0.06, "m", "field tiles' tops are base_height + U(0, block_jitter)", lo=0.0, hi=0.3),
        Param("field_pitch", 0.2, "m", "side of the field's square tiles", lo=0.1, hi=1.0),
        Param("scale", 1.0, "-", "magnification of the scripted blocks and the field start", lo=0.25, hi=10.0),
    ),
    generate=_generate,
    z_bounds=_bounds,
    check=_check,
    spawn_height=lambda p: float(blocks(p, "start")[:, 2].max()),
)
