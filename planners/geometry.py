"""Small 2-D convex-polygon helpers for the desired COG points (horizontal plane, m)."""

from __future__ import annotations

import numpy as np


def _cross2(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """z component of the cross product of 2-D vectors (broadcast)."""
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def convex_hull_ccw(points: np.ndarray) -> np.ndarray:
    """Vertices (n, 2) of the convex hull of ``points`` (m, 2), counter-clockwise (monotone chain)."""
    pts = np.unique(np.asarray(points, dtype=float)[:, :2], axis=0)
    if len(pts) < 3:
        return pts

    def half(seq):
        out: list[np.ndarray] = []
        for p in seq:
            while len(out) >= 2 and _cross2(out[-1] - out[-2], p - out[-2]) <= 0:
                out.pop()
            out.append(p)
        return out

    lower, upper = half(pts), half(pts[::-1])
    return np.array(lower[:-1] + upper[:-1])


def clip_convex(subject: np.ndarray, clip: np.ndarray) -> np.ndarray:
    """Intersection of two convex CCW polygons (Sutherland-Hodgman); (0, 2) when empty."""
    out = np.asarray(subject, dtype=float)
    clip = np.asarray(clip, dtype=float)
    for i in range(len(clip)):
        if len(out) == 0:
            break
        a, b = clip[i], clip[(i + 1) % len(clip)]
        edge = b - a
        side = _cross2(edge, out - a)  # >= 0: inside (left of a CCW edge)
        new = []
        for j in range(len(out)):
            p, q = out[j], out[(j + 1) % len(out)]
            sp, sq = side[j], side[(j + 1) % len(out)]
            if sp >= 0:
                new.append(p)
            if (sp >= 0) != (sq >= 0):
                new.append(p + (q - p) * (sp / (sp - sq)))
        out = np.array(new).reshape(-1, 2)
    return out


def polygon_centroid(poly: np.ndarray) -> np.ndarray:
    """Area centroid (2,) of a simple polygon (n, 2); the vertex mean when degenerate."""
    poly = np.asarray(poly, dtype=float)
    if len(poly) < 3:
        return poly.mean(axis=0)
    x, y = poly[:, 0], poly[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cr = x * yn - xn * y
    area = cr.sum() / 2.0
    if abs(area) < 1e-12:
        return poly.mean(axis=0)
    return np.array([((x + xn) * cr).sum(), ((y + yn) * cr).sum()]) / (6.0 * area)
