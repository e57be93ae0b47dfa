"""Compiled (numba) twin of :func:`quad_uneven_env.stability.stability_index` for one instant (the env's hot path)."""

from __future__ import annotations

import math

import numba as nb
import numpy as np

MIN_EDGE = 1e-9
"""m: a support polygon edge shorter than this joins coincident feet and is not an edge (see
:func:`quad_uneven_env.stability.stability_index`)."""


@nb.njit(cache=False, nogil=True)
def edge_moments_into(cog, acc, feet, mass, g, out):  # pragma: no cover - compiled
    n = feet.shape[0]
    cx = 0.0
    cy = 0.0
    for i in range(n):
        cx += feet[i, 0] / n
        cy += feet[i, 1] / n
    key = np.empty(n)
    for i in range(n):
        key[i] = -math.atan2(feet[i, 1] - cy, feet[i, 0] - cx)
    order = np.argsort(key, kind="mergesort")
    fx, fy, fz = -mass * acc[0], -mass * acc[1], -mass * (g + acc[2])
    for k in range(n):
        p = order[k]
        q = order[(k + 1) % n]
        ex, ey, ez = feet[q, 0] - feet[p, 0], feet[q, 1] - feet[p, 1], feet[q, 2] - feet[p, 2]
        norm = math.sqrt(ex * ex + ey * ey + ez * ez)
        rx, ry, rz = cog[0] - feet[p, 0], cog[1] - feet[p, 1], cog[2] - feet[p, 2]
        if norm < MIN_EDGE:  # coincident feet: the edge bounds nothing (filled in below)
            out[k] = math.inf
            continue
        out[k] = (ex * (ry * fz - rz * fy) + ey * (rz * fx - rx * fz) + ez * (rx * fy - ry * fx)) / norm
    n_edges = 0
    lowest = math.inf
    for k in range(n):
        if out[k] < math.inf:
            n_edges += 1
            lowest = min(lowest, out[k])
    for k in range(n):
        if n_edges < 3:
            out[k] = -math.inf
        elif out[k] == math.inf:
            out[k] = lowest
