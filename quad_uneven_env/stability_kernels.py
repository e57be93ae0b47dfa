"""Compiled (numba) twin of :func:`quad_uneven_env.stability.stability_index` for one instant (the env's hot path).

The rules for degenerate support polygons are those of :mod:`quad_uneven_env.stability` (they are
defined here, where both paths read them).
"""

from __future__ import annotations

import math

import numpy as np

from quad_uneven_env.jit import njit

MIN_EDGE = 1e-9
"""m: a support polygon edge shorter than this joins coincident feet and is not an edge (see
:func:`quad_uneven_env.stability.stability_index`)."""

MIN_EDGES = 3
"""Real (not zero-length) edges a support polygon needs; with fewer the index is ``-inf`` (no support)."""


@njit(nogil=True)
def edge_moments_into(cog, acc, feet, mass, g, out):  # pragma: no cover - compiled
    """Tumbling moment (N m) of every clockwise edge of ``feet`` (n, 3) into ``out`` (n,); returns the index.

    Same arithmetic and degenerate-polygon rules as :func:`quad_uneven_env.stability.stability_index`.
    """
    n = feet.shape[0]
    if n < MIN_EDGES:
        for k in range(n):
            out[k] = -math.inf
        return -math.inf
    # Centroid as numpy's mean computes it (sum, then divide), so both paths order ties alike.
    cx = 0.0
    cy = 0.0
    for i in range(n):
        cx += feet[i, 0]
        cy += feet[i, 1]
    cx /= n
    cy /= n
    key = np.empty(n)
    for i in range(n):
        key[i] = -math.atan2(feet[i, 1] - cy, feet[i, 0] - cx)
    order = np.argsort(key, kind="mergesort")
    fx, fy, fz = -mass * acc[0], -mass * acc[1], -mass * (g + acc[2])
    index = math.inf
    n_edges = 0
    for k in range(n):
        p = order[k]
        q = order[(k + 1) % n]
        ex, ey, ez = feet[q, 0] - feet[p, 0], feet[q, 1] - feet[p, 1], feet[q, 2] - feet[p, 2]
        norm = math.sqrt(ex * ex + ey * ey + ez * ez)
        if norm < MIN_EDGE:  # coincident feet: the edge bounds nothing (filled in below)
            out[k] = math.inf
            continue
        rx, ry, rz = cog[0] - feet[p, 0], cog[1] - feet[p, 1], cog[2] - feet[p, 2]
        out[k] = (ex * (ry * fz - rz * fy) + ey * (rz * fx - rx * fz) + ez * (rx * fy - ry * fx)) / norm
        index = min(index, out[k])
        n_edges += 1
    for k in range(n):
        if n_edges < MIN_EDGES:
            out[k] = -math.inf
        elif out[k] == math.inf:
            out[k] = index
    return index if n_edges >= MIN_EDGES else -math.inf
