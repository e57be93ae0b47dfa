"""The paper's stability index (§3, eq. 19-23): tumbling moments about support polygon edges.

The robot is a point mass ``m`` at the COG ``P_G`` loaded by gravity and inertia,
``F = (-m x'', -m y'', -m (g + z''))``. The stance feet, ordered clockwise seen from above
(z up), span the support polygon; edge ``i`` runs from foot ``p_i`` to foot ``p_(i+1)`` with
unit vector ``kappa_i``. Its tumbling moment is ``kappa_i . ((P_G - p_i) x F)`` (N m):
positive when ``F`` pushes the COG towards the polygon's interior side of that edge. The
index is the minimum over the edges; positive means no edge tips. The feet may be at
different heights (uneven terrain). Eq. 23 of the paper prints the opposite edge direction;
the clockwise order of eq. 19 is what makes an interior COG positive, and is used here.

With fewer than three stance feet there is no support polygon: the index is ``-inf``
(``NO_SUPPORT``) and so is every edge moment, so nothing downstream can read stability into it
(and, unlike NaN, equal inputs give equal outputs).

Degenerate polygons have a defined value, never an exception, the same in the numpy and the
compiled path:

* coincident feet (closer than ``MIN_EDGE`` = 1e-9 m to the next one in clockwise order): their
  joining "edge" has no direction and bounds nothing, so it is left out of the minimum and reports
  the index as its moment. The index is that of the polygon with the coincident feet merged (for
  a static COG over a convex polygon the moment about an ever shorter corner edge never undercuts
  both of its neighbours, so this is also the limit). With fewer than three real edges left
  (fewer than three distinct feet) there is no polygon: ``NO_SUPPORT`` as above;
* collinear feet (three or more distinct points on one straight line) span a polygon of zero
  area: its edges run both ways along the line, so their moments are ``+M`` and ``-M`` about that
  line and the index is ``-|M|`` <= 0 (the robot tips about that line; the limit of ever thinner
  polygons).
"""

from __future__ import annotations

import math

import numpy as np

from quad_uneven_env.stability_kernels import MIN_EDGE, MIN_EDGES, edge_moments_into

NO_SUPPORT = -np.inf
"""Index returned without a support polygon (fewer than three feet, or fewer than three distinct ones)."""

GRAVITY = 9.81
"""m/s^2"""


def order_clockwise(feet: np.ndarray) -> np.ndarray:
    """Indices that order ``feet`` (n x 3) clockwise seen from above (decreasing polar angle about their centroid).

    Bit for bit the order of the compiled twin (:func:`quad_uneven_env.stability_kernels.edge_moments_into`):
    the same summation order for the centroid and libm's ``atan2`` (numpy's vectorised ``arctan2`` may
    differ in the last bit), so feet tied on one ray from the centroid (a collinear support) are
    ordered alike by both paths. A few feet: the scalar loop costs nothing.
    """
    xy = np.asarray(feet, dtype=float)[:, :2].tolist()
    n = len(xy)
    if n == 0:
        return np.zeros(0, dtype=np.intp)
    cx = cy = 0.0
    for x, y in xy:
        cx += x
        cy += y
    cx /= n
    cy /= n
    key = np.array([-math.atan2(y - cy, x - cx) for x, y in xy])
    return np.argsort(key, kind="stable")


def stability_index(
    cog: np.ndarray,
    cog_acc: np.ndarray,
    feet: np.ndarray,
    mass: float,
    g: float = GRAVITY,
) -> tuple[np.ndarray, np.ndarray]:
    """Stability index (N m) and the tumbling moment about every support polygon edge.

    :param cog: COG position P_G in the world frame (m), shape (3,) or (T, 3).
    :param cog_acc: COG acceleration in the world frame (m/s^2), same shape as ``cog``.
    :param feet: stance foot positions in the world frame (m), (n, 3), any order.
    :param mass: robot mass (kg).
    :param g: gravity (m/s^2), acting along -z.
    :return: ``(index, edge_moments)``: index shape () or (T,); edge_moments (n,) or (T, n),
        edge ``i`` going from the i-th to the (i+1)-th foot in clockwise order. Degenerate
        polygons (fewer than three feet, coincident or collinear feet): see the module docstring.
    """
    cog = np.asarray(cog, dtype=float)
    cog_acc = np.asarray(cog_acc, dtype=float)
    feet = np.asarray(feet, dtype=float).reshape(-1, 3)
    if cog.shape[-1] != 3 or cog.ndim > 2 or cog_acc.shape != cog.shape:
        raise ValueError(f"cog and cog_acc must both have shape (3,) or (T, 3), got {cog.shape} and {cog_acc.shape}")
    n = feet.shape[0]
    lead = cog.shape[:-1]
    if n < MIN_EDGES:
        return np.full(lead, NO_SUPPORT), np.full((*lead, n), NO_SUPPORT)
    if cog.ndim == 1:
        return _stability_index_one(cog, cog_acc, np.ascontiguousarray(feet), float(mass), float(g))
    ordered = feet[order_clockwise(feet)]
    edges = ordered[np.r_[1:n, 0]] - ordered
    length = np.sqrt((edges * edges).sum(axis=1))
    joined = length < MIN_EDGE  # coincident feet: not an edge
    if np.count_nonzero(~joined) < MIN_EDGES:
        return np.full(lead, NO_SUPPORT), np.full((*lead, n), NO_SUPPORT)
    kappa = edges / np.where(joined, 1.0, length)[:, None]
    fx, fy = -mass * cog_acc[..., 0:1], -mass * cog_acc[..., 1:2]
    fz = -mass * (g + cog_acc[..., 2:3])
    r = cog[..., None, :] - ordered  # (..., n, 3)
    rx, ry, rz = r[..., 0], r[..., 1], r[..., 2]
    # kappa . (r x F), written out: np.cross is slow on small arrays and this is a hot path.
    moments = kappa[:, 0] * (ry * fz - rz * fy) + kappa[:, 1] * (rz * fx - rx * fz) + kappa[:, 2] * (rx * fy - ry * fx)
    index = moments[..., ~joined].min(axis=-1)
    moments[..., joined] = index[..., None]
    return index, moments


def normalized_stability_index(
    cog: np.ndarray,
    cog_acc: np.ndarray,
    feet: np.ndarray,
    mass: float,
    g: float = GRAVITY,
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`stability_index` divided by ``m g``: a length (m), the static distance margin.

    For a static robot on flat ground it is the horizontal distance from the COG to the
    nearest support polygon edge.
    """
    index, moments = stability_index(cog, cog_acc, feet, mass, g)
    return index / (mass * g), moments / (mass * g)


def _stability_index_one(
    cog: np.ndarray, acc: np.ndarray, feet: np.ndarray, mass: float, g: float
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`stability_index` of one instant, compiled: the env calls it every step, where
    numpy's per-call overhead on 3-vectors would dominate. Same arithmetic (tested equal)."""
    moments = np.empty(feet.shape[0])
    index = edge_moments_into(cog, acc, feet, mass, g, moments)
    return np.float64(index), moments
