"""A regular height grid with MuJoCo's collision surface: pure numpy, no simulator.

Grid convention (the same as a MuJoCo ``hfield``): ``heights[r, c]`` (m, world z) is the
node at world ``(x, y) = origin + (c, r) * cell_size``; rows run along +y, columns along +x.

The surface between the nodes is MuJoCo's triangulation: every cell is cut along the
diagonal from node ``(r, c)`` to node ``(r + 1, c + 1)``. With ``fu, fv`` in [0, 1] the
fractional x and y positions inside the cell, the lower triangle ``fu >= fv`` has the nodes
``(r, c), (r, c + 1), (r + 1, c + 1)`` and the upper triangle ``fu < fv`` the nodes
``(r, c), (r + 1, c), (r + 1, c + 1)``. (Checked against ``mujoco.mj_ray`` and contact
generation in ``tests/quad_uneven_env/test_terrain.py``.)

Outside the grid a query is clamped to the border: the height and normal are those of the
nearest point of the grid's rectangle (MuJoCo itself has no surface there).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike

from quad_uneven_env.fields import excerpt
from quad_uneven_env.terrain.heightfield_kernels import heights_into, normals_into, patch_stats_into

MAX_CELLS = 4_000_000
"""Largest grid (nrow * ncol nodes) accepted anywhere in the terrain package."""


class PatchStats(NamedTuple):
    """Terrain statistics of a disc around query points (arrays shaped like the broadcast query).

    The disc holds the grid nodes within ``radius`` of the query point plus the four corners of
    the cell under it (so it never holds fewer than four nodes).
    """

    plane_slope: np.ndarray
    """rad: tilt from horizontal of the least-squares plane through the disc's nodes."""
    plane_normal: np.ndarray
    """(..., 3) unit normal (world frame, z > 0) of that plane."""
    max_slope: np.ndarray
    """rad: steepest surface triangle touching the disc (a step or hole edge gives ~ atan(step / cell))."""
    roughness: np.ndarray
    """m: largest absolute distance (along z) of a disc node from the least-squares plane."""
    height_min: np.ndarray
    """m: lowest node height in the disc."""
    height_max: np.ndarray
    """m: highest node height in the disc (``height_max - height_min`` is the step/hole depth)."""


class HeightField:
    """Height grid ``heights`` (m) with node spacing ``cell_size`` (m) and node ``[0, 0]`` at ``origin``.

    :param heights: (nrow, ncol) world z (m) of the nodes; rows along +y, columns along +x; at least 2 x 2.
    :param cell_size: node spacing (m) along x and y; > 0.
    :param origin: world (x, y) (m) of node ``[0, 0]`` (the grid's -x, -y corner).
    :raises ValueError: on a non-2-D, too small, too large or non-finite grid, or a bad cell size/origin.
    """

    def __init__(self, heights: ArrayLike, cell_size: float, origin: ArrayLike = (0.0, 0.0)) -> None:
        h = np.array(heights, dtype=np.float64, copy=True)
        if h.ndim != 2 or h.shape[0] < 2 or h.shape[1] < 2:
            raise ValueError(f"heights must be a 2-D array with at least 2 x 2 nodes, got shape {h.shape}")
        if h.size > MAX_CELLS:
            raise ValueError(f"heights has {h.size} nodes; the cap is {MAX_CELLS} (nrow * ncol)")
        if not np.all(np.isfinite(h)):
            raise ValueError("heights must be finite (found NaN or Inf)")
        cell = float(cell_size)
        if not np.isfinite(cell) or cell <= 0.0:
            raise ValueError(f"cell_size must be a finite number > 0 (m), got {excerpt(cell_size)}")
        o = np.array(origin, dtype=np.float64).reshape(-1)
        if o.shape != (2,) or not np.all(np.isfinite(o)):
            raise ValueError(f"origin must be a finite world (x, y) pair (m), got {excerpt(origin)}")
        h.setflags(write=False)
        o.setflags(write=False)
        self._h = h
        self._flat = h.ravel()  # a view: flat indexing is faster than 2-D fancy indexing
        self._cell = cell
        self._origin = o

    # --- geometry ------------------------------------------------------------------------
    @property
    def heights(self) -> np.ndarray:
        """(nrow, ncol) node heights (m, world z), read-only; rows along +y, columns along +x."""
        return self._h

    @property
    def cell_size(self) -> float:
        """Node spacing (m)."""
        return self._cell

    @property
    def origin(self) -> np.ndarray:
        """World (x, y) (m) of node ``[0, 0]``, read-only."""
        return self._origin

    @property
    def shape(self) -> tuple[int, int]:
        """(nrow, ncol): nodes along y, nodes along x."""
        return self._h.shape  # type: ignore[return-value]

    @property
    def extent(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """((xmin, xmax), (ymin, ymax)) (m, world) of the grid's node rectangle."""
        nrow, ncol = self._h.shape
        x0, y0 = (float(v) for v in self._origin)
        return (x0, x0 + (ncol - 1) * self._cell), (y0, y0 + (nrow - 1) * self._cell)

    @property
    def xs(self) -> np.ndarray:
        """(ncol,) world x (m) of the node columns."""
        return self._origin[0] + self._cell * np.arange(self._h.shape[1])

    @property
    def ys(self) -> np.ndarray:
        """(nrow,) world y (m) of the node rows."""
        return self._origin[1] + self._cell * np.arange(self._h.shape[0])

    @property
    def kernel_args(self) -> tuple[np.ndarray, int, int, float, float, float]:
        """(flat heights, nrow, ncol, origin x, origin y, 1 / cell_size): the arguments of the
        compiled height kernel, for other compiled code that queries this surface."""
        nrow, ncol = self._h.shape
        return self._flat, nrow, ncol, float(self._origin[0]), float(self._origin[1]), 1.0 / self._cell

    # --- point queries -------------------------------------------------------------------
    def _locate(self, x: ArrayLike, y: ArrayLike):
        """Cell indices (r, c) and in-cell fractions (fv, fu) of clamped query points."""
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        if x.shape != y.shape:
            x, y = np.broadcast_arrays(x, y)
        nrow, ncol = self._h.shape
        # maximum/minimum instead of np.clip: this runs every env step and clip's overhead shows.
        u = np.minimum(np.maximum((x - self._origin[0]) * (1.0 / self._cell), 0.0), ncol - 1)
        v = np.minimum(np.maximum((y - self._origin[1]) * (1.0 / self._cell), 0.0), nrow - 1)
        c = np.minimum(u.astype(np.intp), ncol - 2)  # u >= 0, so truncation is floor
        r = np.minimum(v.astype(np.intp), nrow - 2)
        return r, c, v - r, u - c

    def height(self, x: ArrayLike, y: ArrayLike) -> np.ndarray:
        """Surface height (m, world z) at world (x, y) (m), broadcast; MuJoCo's triangulated surface.

        Points outside the grid are clamped to its border.
        """
        if isinstance(x, (float, int)) and isinstance(y, (float, int)):
            return np.float64(self._height_scalar(float(x), float(y)))
        x, y = np.broadcast_arrays(np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64))
        out = self.height_points(np.ascontiguousarray(x).reshape(-1), np.ascontiguousarray(y).reshape(-1))
        return out.reshape(x.shape) if x.shape else out[0]

    def height_numpy(self, x: ArrayLike, y: ArrayLike) -> np.ndarray:
        """:meth:`height` in numpy (the twin the compiled kernel is tested against)."""
        r, c, fv, fu = self._locate(x, y)
        flat, ncol = self._flat, self._h.shape[1]
        i00 = r * ncol + c
        h00, h11 = flat[i00], flat[i00 + ncol + 1]
        lower = fu >= fv
        # Third vertex: (r, c + 1) for the lower triangle, (r + 1, c) for the upper one.
        h_mid = flat[i00 + np.where(lower, 1, ncol)]
        # lower: h00 + fu (h01 - h00) + fv (h11 - h01); upper: h00 + fv (h10 - h00) + fu (h11 - h10)
        a, b = np.where(lower, fu, fv), np.where(lower, fv, fu)
        return h00 + a * (h_mid - h00) + b * (h11 - h_mid)

    def height_points(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """:meth:`height` of 1-D float64 arrays of equal length, compiled (the env's per-step scan).

        Same arithmetic as :meth:`height_numpy` (tested equal).
        """
        out = np.empty(x.shape[0])
        nrow, ncol = self._h.shape
        heights_into(self._flat, nrow, ncol, self._origin[0], self._origin[1], 1.0 / self._cell, x, y, out)
        return out

    def _height_scalar(self, x: float, y: float) -> float:
        """:meth:`height` of one point in plain Python (the same arithmetic, cheaper than numpy for one point)."""
        nrow, ncol = self._h.shape
        u = min(max((x - self._origin[0]) / self._cell, 0.0), ncol - 1.0)
        v = min(max((y - self._origin[1]) / self._cell, 0.0), nrow - 1.0)
        c, r = min(math.floor(u), ncol - 2), min(math.floor(v), nrow - 2)
        fu, fv = u - c, v - r
        h = self._h
        h00, h11 = float(h[r, c]), float(h[r + 1, c + 1])
        if fu >= fv:
            h01 = float(h[r, c + 1])
            return h00 + fu * (h01 - h00) + fv * (h11 - h01)
        h10 = float(h[r + 1, c])
        return h00 + fv * (h10 - h00) + fu * (h11 - h10)

    def gradient(self, x: ArrayLike, y: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """(dh/dx, dh/dy) (m/m) of the surface triangle under world (x, y) (m), broadcast.

        On a triangle edge the lower triangle (``fu >= fv``) wins; outside the grid, the border's.
        """
        r, c, fv, fu = self._locate(x, y)
        h = self._h
        lower = fu >= fv
        gx = np.where(lower, h[r, c + 1] - h[r, c], h[r + 1, c + 1] - h[r + 1, c]) / self._cell
        gy = np.where(lower, h[r + 1, c + 1] - h[r, c + 1], h[r + 1, c] - h[r, c]) / self._cell
        return gx, gy

    def normal(self, x: ArrayLike, y: ArrayLike) -> np.ndarray:
        """(..., 3) upward unit normal (world frame) of the surface triangle under world (x, y) (m)."""
        gx, gy = self.gradient(x, y)
        n = np.stack([-gx, -gy, np.ones_like(gx)], axis=-1)
        return n / np.linalg.norm(n, axis=-1, keepdims=True)

    def normal_points(self, points: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """:meth:`normal` under each row of ``points`` ((n, 2) or (n, 3) float64, m, world), compiled.

        Same arithmetic as :meth:`normal` (tested equal); for the controller's per-step query.

        :param out: optional (n, 3) float64 array to write into.
        :return: (n, 3) upward unit normals (world frame).
        """
        if out is None:
            out = np.empty((points.shape[0], 3))
        normals_into(*self.kernel_args, points, out)
        return out

    def slope(self, x: ArrayLike, y: ArrayLike) -> np.ndarray:
        """Tilt from horizontal (rad) of the surface triangle under world (x, y) (m), broadcast."""
        gx, gy = self.gradient(x, y)
        return np.arctan(np.hypot(gx, gy))

    # --- neighbourhood queries (foothold selection) ---------------------------------------
    def patch_stats(self, x: ArrayLike, y: ArrayLike, radius: float) -> PatchStats:
        """Slope, roughness and height range of the terrain in a disc of ``radius`` (m) around world (x, y).

        Vectorised over the broadcast query points (compiled, ~(2 radius / cell_size + 2)^2 node
        visits per point; :meth:`patch_stats_numpy` is the numpy twin). Nodes beyond the grid
        border take the border's height (clamping, as :meth:`height`).

        :param radius: disc radius (m), > 0 and at most 50 cells.
        :return: a :class:`PatchStats` of arrays shaped like the broadcast query.
        """
        radius = self._check_patch_radius(radius)
        x, y = np.broadcast_arrays(np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64))
        shape = x.shape
        out = np.empty((x.size, 8))
        xs, ys = np.ascontiguousarray(x).reshape(-1), np.ascontiguousarray(y).reshape(-1)
        nrow, ncol = self._h.shape
        k = int(np.ceil(radius / self._cell))
        ox, oy = float(self._origin[0]), float(self._origin[1])
        patch_stats_into(self._flat, nrow, ncol, ox, oy, self._cell, k, radius, xs, ys, out)
        return PatchStats(
            plane_slope=out[:, 0].reshape(shape),
            plane_normal=out[:, 1:4].reshape(*shape, 3),
            max_slope=out[:, 4].reshape(shape),
            roughness=out[:, 5].reshape(shape),
            height_min=out[:, 6].reshape(shape),
            height_max=out[:, 7].reshape(shape),
        )

    def _check_patch_radius(self, radius: float) -> float:
        radius = float(radius)
        if not np.isfinite(radius) or radius <= 0.0 or radius > 50 * self._cell:
            raise ValueError(f"radius must be in (0, {50 * self._cell:g}] m (50 cells), got {excerpt(radius)}")
        return radius

    def patch_stats_numpy(self, x: ArrayLike, y: ArrayLike, radius: float) -> PatchStats:
        """:meth:`patch_stats` in numpy (the reference the compiled kernel is tested against)."""
        radius = self._check_patch_radius(radius)
        x, y = np.broadcast_arrays(np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64))
        shape = x.shape
        xq, yq = x.reshape(-1, 1), y.reshape(-1, 1)
        nrow, ncol = self._h.shape
        k = int(np.ceil(radius / self._cell))
        p = 2 * k + 2
        # Patch of p x p nodes around the cell under the (unclamped) query point.
        u, v = (xq - self._origin[0]) / self._cell, (yq - self._origin[1]) / self._cell
        c0, r0 = np.floor(u).astype(np.intp), np.floor(v).astype(np.intp)
        off = np.arange(-k, k + 2)
        cols = (c0 + off)[:, None, :]  # (N, 1, p)
        rows = (r0 + off)[:, :, None]  # (N, p, 1)
        hp = self._h[np.clip(rows, 0, nrow - 1), np.clip(cols, 0, ncol - 1)]  # (N, p, p)
        dx = (self._origin[0] + cols * self._cell) - xq[:, :, None]
        dy = (self._origin[1] + rows * self._cell) - yq[:, :, None]
        dx, dy = np.broadcast_to(dx, hp.shape), np.broadcast_to(dy, hp.shape)
        corner = np.zeros((p, p), dtype=bool)
        corner[k : k + 2, k : k + 2] = True  # the cell under the query point
        mask = (dx * dx + dy * dy <= radius * radius) | corner
        w = mask.astype(np.float64)
        # Weighted least-squares plane h = a dx + b dy + c (normal equations, 3 x 3 per point).
        n = hp.shape[0]
        feats = np.stack([dx, dy, np.ones_like(dx)], axis=-1).reshape(n, p * p, 3)
        feats_w = feats * w.reshape(n, p * p, 1)
        # batched matmul: a 3-operand einsum is much slower here
        ata = np.swapaxes(feats_w, 1, 2) @ feats  # (N, 3, 3)
        atb = np.swapaxes(feats_w, 1, 2) @ hp.reshape(n, p * p, 1)  # (N, 3, 1)
        coef = np.linalg.solve(ata, atb)[..., 0]
        resid = hp - (feats @ coef[..., None]).reshape(hp.shape)
        roughness = np.max(np.where(mask, np.abs(resid), 0.0), axis=(1, 2))
        a, b = coef[:, 0], coef[:, 1]
        plane_n = np.stack([-a, -b, np.ones_like(a)], axis=-1)
        plane_n /= np.linalg.norm(plane_n, axis=-1, keepdims=True)
        hmin = np.min(np.where(mask, hp, np.inf), axis=(1, 2))
        hmax = np.max(np.where(mask, hp, -np.inf), axis=(1, 2))
        # Triangle gradients of every cell of the patch; keep cells with a corner in the disc.
        h00, h01, h10, h11 = hp[:, :-1, :-1], hp[:, :-1, 1:], hp[:, 1:, :-1], hp[:, 1:, 1:]
        lo = np.hypot(h01 - h00, h11 - h01) / self._cell
        up = np.hypot(h11 - h10, h10 - h00) / self._cell
        cell_in = mask[:, :-1, :-1] | mask[:, :-1, 1:] | mask[:, 1:, :-1] | mask[:, 1:, 1:]
        steep = np.max(np.where(cell_in, np.maximum(lo, up), 0.0), axis=(1, 2))
        return PatchStats(
            plane_slope=np.arctan(np.hypot(a, b)).reshape(shape),
            plane_normal=plane_n.reshape(*shape, 3),
            max_slope=np.arctan(steep).reshape(shape),
            roughness=roughness.reshape(shape),
            height_min=hmin.reshape(shape),
            height_max=hmax.reshape(shape),
        )

    def max_slope_and_roughness(self, x: ArrayLike, y: ArrayLike, radius: float) -> tuple[np.ndarray, np.ndarray]:
        """(max_slope (rad), roughness (m)) in a disc of ``radius`` (m) around world (x, y): see :meth:`patch_stats`."""
        s = self.patch_stats(x, y, radius)
        return s.max_slope, s.roughness

    def is_safe_foothold(
        self,
        x: ArrayLike,
        y: ArrayLike,
        radius: float,
        max_slope: float = np.deg2rad(30.0),
        max_step: float = 0.02,
    ) -> np.ndarray:
        """True where the disc of ``radius`` (m) has no triangle steeper than ``max_slope`` (rad)
        and a node height range below ``max_step`` (m): no block edge, hole or stair nosing nearby."""
        s = self.patch_stats(x, y, radius)
        return (s.max_slope <= max_slope) & (s.height_max - s.height_min <= max_step)

    def __repr__(self) -> str:
        (x0, x1), (y0, y1) = self.extent
        return (
            f"HeightField(shape={self.shape}, cell_size={self._cell:g} m, x=[{x0:g}, {x1:g}] m, y=[{y0:g}, {y1:g}] m, "
            f"z=[{self._h.min():g}, {self._h.max():g}] m)"
        )
