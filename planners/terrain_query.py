"""Conservative terrain queries for the planners (clearances, maxima over disks) on a :class:`HeightMap`.

Planners take any object with vectorised ``height(x, y)`` (m, world frame) and ``normal(x, y)``
(unit normals, (..., 3)): the environment's ``quad_uneven_env.terrain.HeightField`` (the
expert's privileged map) satisfies it.
"""

from __future__ import annotations

import numpy as np

from planners import terrain_query_kernels as TK
from planners.types import HeightMap

_RING = np.stack(
    [np.cos(np.linspace(0, 2 * np.pi, 8, endpoint=False)), np.sin(np.linspace(0, 2 * np.pi, 8, endpoint=False))], 1
)
_DISK = np.concatenate(
    [
        [[0.0, 0.0]],
        _RING,
        0.5 * _RING,
        np.array([[1.0, 1.0], [1.0, -1.0], [-1.0, 1.0], [-1.0, -1.0]]) * 0.75**0.5 / 2**0.5,
    ]
)


def max_height_in_disk(terrain: HeightMap, xy: np.ndarray, radius: float) -> np.ndarray:
    """Highest terrain point (m) within ``radius`` (m) of each world point ``xy`` (T, 2), sampled.

    Samples the centre, rings at ``radius`` and ``radius / 2`` and four diagonals: conservative
    to within the height change over the gap between samples. Compiled on a height field's grid
    (:mod:`planners.terrain_query_kernels`), :func:`max_height_in_disk_numpy` on any other map.
    """
    xy = np.ascontiguousarray(xy, dtype=float).reshape(-1, 2)
    grid = getattr(terrain, "kernel_args", None)
    if grid is None:
        return max_height_in_disk_numpy(terrain, xy, radius)
    out = np.empty(len(xy))
    TK.max_height_in_disk_into(*grid, xy, float(radius), _DISK, out)
    return out


def max_height_in_disk_numpy(terrain: HeightMap, xy: np.ndarray, radius: float) -> np.ndarray:
    """:func:`max_height_in_disk` in numpy, for any height map."""
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    pts = xy[:, None, :] + radius * _DISK[None, :, :]
    return terrain.height(pts[..., 0], pts[..., 1]).max(axis=1)


def sphere_clearance(terrain: HeightMap, centres: np.ndarray, radius: float) -> np.ndarray:
    """Lower bound (m) of the gap between a sphere at ``centres`` (T, 3) and the terrain.

    Any terrain point inside the sphere lies within ``radius`` horizontally of the centre and
    above ``z - radius``; so ``z - radius - max height in the disk`` bounds the gap from below
    (it is the exact gap on flat ground, pessimistic by ``r (1 - n_z)`` on slopes).
    """
    centres = np.asarray(centres, dtype=float).reshape(-1, 3)
    return centres[:, 2] - radius - max_height_in_disk(terrain, centres[:, :2], radius)


def capsule_clearance(
    terrain: HeightMap, a: np.ndarray, b: np.ndarray, radius: float, spacing: float = 0.005
) -> np.ndarray:
    """Gap (m) between the terrain and capsules: segments ``a`` -> ``b`` (N, 3) (m) of radius ``radius`` (m).

    The terrain is sampled every ``spacing`` (m) on the capsule's footprint (the strip within
    ``radius`` of the segment's ground projection, the only terrain that can come closer than
    ``radius`` to the axis); the gap is the smallest distance from a sample to the segment minus
    the radius: exact at the samples, so on a plane or a slope it is the true gap, and next to an
    edge it is at most about ``spacing / 2`` too large. Compiled on a height field's grid
    (:mod:`planners.terrain_query_kernels`), :func:`capsule_clearance_numpy` on any other map.
    """
    a = np.ascontiguousarray(a, dtype=float).reshape(-1, 3)
    b = np.ascontiguousarray(b, dtype=float).reshape(-1, 3)
    grid = getattr(terrain, "kernel_args", None)
    if grid is None:
        return capsule_clearance_numpy(terrain, a, b, radius, spacing)
    horiz = np.hypot(b[:, 0] - a[:, 0], b[:, 1] - a[:, 1])
    n_u, n_v = _capsule_samples(horiz, radius, spacing)
    out = np.empty(len(a))
    TK.capsule_clearance_into(*grid, a, b, float(radius), n_u, n_v, out)
    return out


def _capsule_samples(horiz: np.ndarray, radius: float, spacing: float) -> tuple[int, int]:
    """Samples along and across every capsule's footprint (the longest footprint sets them)."""
    n_u = int(np.ceil((horiz.max(initial=0.0) + 2.0 * radius) / spacing)) + 1
    return n_u, int(np.ceil(2.0 * radius / spacing)) + 1


def capsule_clearance_numpy(
    terrain: HeightMap, a: np.ndarray, b: np.ndarray, radius: float, spacing: float = 0.005
) -> np.ndarray:
    """:func:`capsule_clearance` in numpy, for any height map."""
    a = np.asarray(a, dtype=float).reshape(-1, 3)
    b = np.asarray(b, dtype=float).reshape(-1, 3)
    d = b - a
    horiz = np.hypot(d[:, 0], d[:, 1])
    along = np.where(horiz[:, None] > 1e-12, d[:, :2] / np.maximum(horiz, 1e-12)[:, None], [1.0, 0.0])
    across = np.column_stack([-along[:, 1], along[:, 0]])
    n_u, n_v = _capsule_samples(horiz, radius, spacing)
    u = np.linspace(0.0, 1.0, n_u)[None, :, None] * (horiz[:, None, None] + 2.0 * radius) - radius  # (N, U, 1)
    v = np.linspace(-radius, radius, n_v)[None, None, :]  # (1, 1, V)
    xy = a[:, None, None, :2] + u[..., None] * along[:, None, None] + v[..., None] * across[:, None, None]
    z = terrain.height(xy[..., 0], xy[..., 1])
    p = np.concatenate([xy, z[..., None]], axis=-1) - a[:, None, None]  # samples relative to a
    s = np.clip(np.einsum("nuvk,nk->nuv", p, d) / np.maximum((d * d).sum(axis=1), 1e-12)[:, None, None], 0.0, 1.0)
    dist = np.linalg.norm(p - s[..., None] * d[:, None, None], axis=-1)
    return dist.reshape(len(a), -1).min(axis=1) - radius


def surface_point(terrain: HeightMap, xy: np.ndarray) -> np.ndarray:
    """Points on the terrain surface (..., 3) above world ``xy`` (..., 2) (m)."""
    xy = np.asarray(xy, dtype=float)
    z = terrain.height(xy[..., 0], xy[..., 1])
    return np.concatenate([xy, np.asarray(z)[..., None]], axis=-1)


def foot_site_on(terrain: HeightMap, foothold: np.ndarray, foot_radius: float) -> np.ndarray:
    """Foot-site (sphere centre) positions (..., 3) for feet resting on surface points ``foothold`` (m)."""
    f = np.asarray(foothold, dtype=float)
    return f + foot_radius * terrain.normal(f[..., 0], f[..., 1])


class BlockTerrain:
    """Analytic height map: a plane ``ground + slope . (x, y)`` plus axis-aligned boxes (m).

    A small exact stand-in for tests and scripts that need no grid: ``blocks`` rows are
    ``(x_min, x_max, y_min, y_max, top_height)``; a box replaces the plane where it is higher.
    """

    def __init__(self, ground: float = 0.0, slope: tuple[float, float] = (0.0, 0.0), blocks: np.ndarray | None = None):
        self.ground = float(ground)
        self.slope = np.asarray(slope, dtype=float)
        self.blocks = np.zeros((0, 5)) if blocks is None else np.asarray(blocks, dtype=float).reshape(-1, 5)

    def height(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Surface height (m) at world (x, y)."""
        x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
        h = self.ground + self.slope[0] * x + self.slope[1] * y
        for x0, x1, y0, y1, top in self.blocks:
            inside = (x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)
            h = np.where(inside, np.maximum(h, top), h)
        return h

    def normal(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Unit normal of the plane (block tops are horizontal)."""
        x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
        plane = self.ground + self.slope[0] * x + self.slope[1] * y
        on_block = self.height(x, y) > plane + 1e-12
        n = np.array([-self.slope[0], -self.slope[1], 1.0]) / np.sqrt(1.0 + self.slope @ self.slope)
        out = np.broadcast_to(n, (*np.shape(x), 3)).copy()
        out[on_block] = (0.0, 0.0, 1.0)
        return out
