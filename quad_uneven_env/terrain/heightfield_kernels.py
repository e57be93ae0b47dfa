"""Compiled (numba) twins of :class:`quad_uneven_env.terrain.heightfield.HeightField`'s numpy queries.

Heights, normals and patch statistics of MuJoCo's triangulated height field at many points, on the
flattened grid (``HeightField.kernel_args``); tested equal to the numpy methods.
"""

from __future__ import annotations

import math

import numpy as np

from quad_uneven_env.jit import njit


@njit(nogil=True, inline="always")
def height_at(flat, nrow, ncol, ox, oy, inv_cell, x, y):  # pragma: no cover - compiled
    """MuJoCo's triangulated surface (m) at one point (x, y) (m, world); see :meth:`HeightField.height`."""
    u = min(max((x - ox) * inv_cell, 0.0), ncol - 1.0)
    v = min(max((y - oy) * inv_cell, 0.0), nrow - 1.0)
    c = min(int(u), ncol - 2)
    r = min(int(v), nrow - 2)
    fu, fv = u - c, v - r
    i00 = r * ncol + c
    h00, h11 = flat[i00], flat[i00 + ncol + 1]
    if fu >= fv:
        hm = flat[i00 + 1]
        return h00 + fu * (hm - h00) + fv * (h11 - hm)
    hm = flat[i00 + ncol]
    return h00 + fv * (hm - h00) + fu * (h11 - hm)


@njit(nogil=True)
def heights_into(flat, nrow, ncol, ox, oy, inv_cell, xs, ys, out):  # pragma: no cover - compiled
    """MuJoCo's triangulated surface at (xs[k], ys[k]) into out[k]; see :meth:`HeightField.height`."""
    for k in range(xs.shape[0]):
        out[k] = height_at(flat, nrow, ncol, ox, oy, inv_cell, xs[k], ys[k])


@njit(nogil=True)
def normals_into(flat, nrow, ncol, ox, oy, inv_cell, points, out):  # pragma: no cover - compiled
    """Upward unit normal of the surface triangle under (points[k, 0], points[k, 1]) into out[k]."""
    for k in range(points.shape[0]):
        u = min(max((points[k, 0] - ox) * inv_cell, 0.0), ncol - 1.0)
        v = min(max((points[k, 1] - oy) * inv_cell, 0.0), nrow - 1.0)
        c = min(int(u), ncol - 2)
        r = min(int(v), nrow - 2)
        fu, fv = u - c, v - r
        i00 = r * ncol + c
        if fu >= fv:
            gx = (flat[i00 + 1] - flat[i00]) * inv_cell
            gy = (flat[i00 + ncol + 1] - flat[i00 + 1]) * inv_cell
        else:
            gx = (flat[i00 + ncol + 1] - flat[i00 + ncol]) * inv_cell
            gy = (flat[i00 + ncol] - flat[i00]) * inv_cell
        norm = math.sqrt(gx * gx + gy * gy + 1.0)
        out[k, 0] = -gx / norm
        out[k, 1] = -gy / norm
        out[k, 2] = 1.0 / norm


@njit(nogil=True)
def patch_stats_into(flat, nrow, ncol, ox, oy, cell, k, radius, xs, ys, out):  # pragma: no cover - compiled
    """:meth:`HeightField.patch_stats` of (xs[n], ys[n]) into out[n] = (plane slope, plane normal (3),
    max slope, roughness, height min, height max); same arithmetic as ``patch_stats_numpy``."""
    p = 2 * k + 2
    hp = np.empty((p, p))
    dxs = np.empty(p)
    dys = np.empty(p)
    mask = np.empty((p, p), dtype=np.bool_)
    r2 = radius * radius
    for n in range(xs.shape[0]):
        x, y = xs[n], ys[n]
        c0 = math.floor((x - ox) / cell)
        r0 = math.floor((y - oy) / cell)
        for j in range(p):
            dxs[j] = (ox + (c0 - k + j) * cell) - x
            dys[j] = (oy + (r0 - k + j) * cell) - y
        s_xx = s_xy = s_x = s_yy = s_y = s_1 = b_x = b_y = b_1 = 0.0
        hmin, hmax = np.inf, -np.inf
        for i in range(p):
            row = min(max(r0 - k + i, 0), nrow - 1)
            dy = dys[i]
            for j in range(p):
                col = min(max(c0 - k + j, 0), ncol - 1)
                h = flat[row * ncol + col]
                hp[i, j] = h
                dx = dxs[j]
                m = dx * dx + dy * dy <= r2 or (k <= i < k + 2 and k <= j < k + 2)
                mask[i, j] = m
                if m:
                    s_xx += dx * dx
                    s_xy += dx * dy
                    s_x += dx
                    s_yy += dy * dy
                    s_y += dy
                    s_1 += 1.0
                    b_x += dx * h
                    b_y += dy * h
                    b_1 += h
                    hmin = min(hmin, h)
                    hmax = max(hmax, h)
        # Weighted least-squares plane h = a dx + b dy + c: the 3 x 3 normal equations by Cramer's rule.
        det = s_xx * (s_yy * s_1 - s_y * s_y) - s_xy * (s_xy * s_1 - s_y * s_x) + s_x * (s_xy * s_y - s_yy * s_x)
        a = (b_x * (s_yy * s_1 - s_y * s_y) - s_xy * (b_y * s_1 - s_y * b_1) + s_x * (b_y * s_y - s_yy * b_1)) / det
        b = (s_xx * (b_y * s_1 - b_1 * s_y) - b_x * (s_xy * s_1 - s_y * s_x) + s_x * (s_xy * b_1 - b_y * s_x)) / det
        c = (s_xx * (s_yy * b_1 - s_y * b_y) - s_xy * (s_xy * b_1 - b_y * s_x) + b_x * (s_xy * s_y - s_yy * s_x)) / det
        rough = 0.0
        # The steepest triangle: the largest hypot (x / cell is monotone, so max(hypot) / cell = max(hypot / cell)).
        # A hypot is evaluated only where its squared length could reach the largest so far (a 1e-9 relative
        # margin over rounding): the others cannot change the maximum, which stays the same float.
        steep_h = 0.0
        below = 0.0
        for i in range(p):
            for j in range(p):
                if mask[i, j]:
                    rough = max(rough, abs(hp[i, j] - (a * dxs[j] + b * dys[i] + c)))
                if i < p - 1 and j < p - 1 and (mask[i, j] or mask[i, j + 1] or mask[i + 1, j] or mask[i + 1, j + 1]):
                    h00, h01, h10, h11 = hp[i, j], hp[i, j + 1], hp[i + 1, j], hp[i + 1, j + 1]
                    u, v = h01 - h00, h11 - h01
                    if u * u + v * v >= below:
                        steep_h = max(steep_h, math.hypot(u, v))
                        below = steep_h * steep_h * (1.0 - 1e-9)
                    u, v = h11 - h10, h10 - h00
                    if u * u + v * v >= below:
                        steep_h = max(steep_h, math.hypot(u, v))
                        below = steep_h * steep_h * (1.0 - 1e-9)
        steep = steep_h / cell
        norm = math.sqrt(a * a + b * b + 1.0)
        out[n, 0] = math.atan(math.hypot(a, b))
        out[n, 1] = -a / norm
        out[n, 2] = -b / norm
        out[n, 3] = 1.0 / norm
        out[n, 4] = math.atan(steep)
        out[n, 5] = rough
        out[n, 6] = hmin
        out[n, 7] = hmax
