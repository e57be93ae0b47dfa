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

Degenerate polygons never divide by zero. Feet closer than ``MIN_EDGE`` (1e-9 m) to the next one in
clockwise order are coincident: their joining "edge" has no direction and bounds nothing, so it is
left out of the minimum and reports the index as its moment; with fewer than three real edges left
(fewer than three distinct feet) there is no polygon and the result is ``NO_SUPPORT`` as above.
Collinear feet span a polygon of zero area: its edges run both ways along the line, so their
moments have opposite signs and the index is <= 0 (the robot tips about that line).
"""

from __future__ import annotations

import numpy as np

from quad_uneven_env.stability_kernels import MIN_EDGE, edge_moments_into

NO_SUPPORT = -np.inf
"""Index returned when fewer than three feet are in stance (no support polygon)."""

GRAVITY = 9.81
"""m/s^2"""


def order_clockwise(feet: np.ndarray) -> np.ndarray:
    """Indices that order ``feet`` (n x 3) clockwise seen from above (decreasing polar angle)."""
    feet = np.asarray(feet, dtype=float)
    centre = feet[:, :2].mean(axis=0)
    angle = np.arctan2(feet[:, 1] - centre[1], feet[:, 0] - centre[0])
    return np.argsort(-angle, kind="stable")


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
        edge ``i`` going from the i-th to the (i+1)-th foot in clockwise order. With fewer
        than three feet: index and moments ``-inf``.
    """
    cog = np.asarray(cog, dtype=float)
    cog_acc = np.asarray(cog_acc, dtype=float)
    feet = np.asarray(feet, dtype=float).reshape(-1, 3)
    if cog.shape[-1] != 3 or cog.ndim > 2 or cog_acc.shape != cog.shape:
        raise ValueError(f"cog and cog_acc must both have shape (3,) or (T, 3), got {cog.shape} and {cog_acc.shape}")
    n = feet.shape[0]
    lead = cog.shape[:-1]
    if n < 3:
        return np.full(lead, NO_SUPPORT), np.full((*lead, n), NO_SUPPORT)
    if cog.ndim == 1:
        return _stability_index_one(cog, cog_acc, np.ascontiguousarray(feet), float(mass), float(g))
    ordered = feet[order_clockwise(feet)]
    edges = ordered[np.r_[1:n, 0]] - ordered
    length = np.linalg.norm(edges, axis=1, keepdims=True)
    joined = length[:, 0] < MIN_EDGE  # coincident feet: not an edge
    if np.count_nonzero(~joined) < 3:
        return np.full(lead, NO_SUPPORT), np.full((*lead, n), NO_SUPPORT)
    kappa = edges / np.where(joined[:, None], 1.0, length)
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
    edge_moments_into(cog, acc, feet, mass, g, moments)
    return np.float64(moments.min()), moments
