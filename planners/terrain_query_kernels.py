"""Compiled twins of :mod:`planners.terrain_query`'s sampled queries on a height field's grid.

The foothold search asks for disk maxima and shank clearances at hundreds of candidates per leg and
cycle; in numpy each query builds (N, 21) or (N, U, V, 3) temporaries. Here each sample is one loop
iteration over MuJoCo's triangulated surface
(:func:`quad_uneven_env.terrain.heightfield_kernels.height_at`). Same samples, same formulas;
``tests/planners/test_terrain_query.py`` checks them equal.
"""

from __future__ import annotations

import math

from quad_uneven_env.jit import njit
from quad_uneven_env.terrain.heightfield_kernels import height_at


@njit(nogil=True)
def max_height_in_disk_into(flat, nrow, ncol, ox, oy, inv_cell, xy, radius, disk, out):  # pragma: no cover - compiled
    """Highest sampled surface point (m) within ``radius`` of each ``xy[n]`` into ``out[n]``; ``disk`` (D, 2) the
    unit-disk sample pattern (:data:`planners.terrain_query._DISK`)."""
    for n in range(xy.shape[0]):
        best = -math.inf
        for k in range(disk.shape[0]):
            x, y = xy[n, 0] + radius * disk[k, 0], xy[n, 1] + radius * disk[k, 1]
            h = height_at(flat, nrow, ncol, ox, oy, inv_cell, x, y)
            if h > best:
                best = h
        out[n] = best


@njit(nogil=True)
def capsule_clearance_into(
    flat, nrow, ncol, ox, oy, inv_cell, a, b, radius, n_u, n_v, out
):  # fmt: skip  # pragma: no cover - compiled
    """:func:`planners.terrain_query.capsule_clearance` of segments ``a[n] -> b[n]`` (m) into ``out[n]``, on an
    ``n_u`` x ``n_v`` sample grid per capsule footprint (the numpy function's sizes)."""
    for n in range(a.shape[0]):
        d0, d1, d2 = b[n, 0] - a[n, 0], b[n, 1] - a[n, 1], b[n, 2] - a[n, 2]
        horiz = math.hypot(d0, d1)
        if horiz > 1e-12:
            al0, al1 = d0 / horiz, d1 / horiz
        else:
            al0, al1 = 1.0, 0.0
        ac0, ac1 = -al1, al0
        dd = max(d0 * d0 + d1 * d1 + d2 * d2, 1e-12)
        length = horiz + 2.0 * radius
        best = math.inf
        for i in range(n_u):
            u = (i / (n_u - 1) if n_u > 1 else 0.0) * length - radius
            for j in range(n_v):
                v = -radius + (2.0 * radius * j / (n_v - 1) if n_v > 1 else 0.0)
                x = a[n, 0] + u * al0 + v * ac0
                y = a[n, 1] + u * al1 + v * ac1
                z = height_at(flat, nrow, ncol, ox, oy, inv_cell, x, y)
                p0, p1, p2 = x - a[n, 0], y - a[n, 1], z - a[n, 2]
                s = min(max((p0 * d0 + p1 * d1 + p2 * d2) / dd, 0.0), 1.0)
                e0, e1, e2 = p0 - s * d0, p1 - s * d1, p2 - s * d2
                dist = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
                if dist < best:
                    best = dist
        out[n] = best - radius
