"""Compiled twin of :meth:`planners.spline.ClampedCubicSpline.__call__`: position, velocity and acceleration in one
pass (the reference grid evaluates every swing at ~1000 times per cycle). Element by element the numpy code's
arithmetic in its order, so the floats are the same (``tests/planners/test_gait_swing.py`` checks them equal)."""

from __future__ import annotations

from quad_uneven_env.jit import njit


@njit(nogil=True)
def hermite_into(tau, y, v, t, pos, vel, acc):  # pragma: no cover - compiled
    """Clamped cubic spline through ``y`` (N, D) with knot slopes ``v`` (N, D) at knot times ``tau`` (N,) (s),
    evaluated at times ``t`` (T,) (s) into ``pos``, ``vel``, ``acc`` (T, D): value, first and second derivative
    (zero derivatives outside [tau[0], tau[-1]], where the value holds the end point)."""
    n = tau.shape[0]
    lo, hi = tau[0], tau[n - 1]
    for i in range(t.shape[0]):
        ti = t[i]
        k = 0
        while k < n and tau[k] <= ti:  # searchsorted(tau, ti, side="right")
            k += 1
        k = min(max(k - 1, 0), n - 2)
        h = tau[k + 1] - tau[k]
        tc = min(max(ti, lo), hi)
        s = (tc - tau[k]) / h
        outside = ti < lo or ti > hi
        s2, s3 = s * s, s * s * s
        a0, a1, a2, a3 = 2 * s3 - 3 * s2 + 1, s3 - 2 * s2 + s, -2 * s3 + 3 * s2, s3 - s2
        b0, b1, b2, b3 = 6 * s2 - 6 * s, 3 * s2 - 4 * s + 1, -6 * s2 + 6 * s, 3 * s2 - 2 * s
        c0, c1, c2, c3 = 12 * s - 6, 6 * s - 4, -12 * s + 6, 6 * s - 2
        hh = h * h
        for j in range(y.shape[1]):
            y0, y1, v0, v1 = y[k, j], y[k + 1, j], v[k, j] * h, v[k + 1, j] * h
            pos[i, j] = a0 * y0 + a1 * v0 + a2 * y1 + a3 * v1
            vel[i, j] = 0.0 if outside else (b0 * y0 + b1 * v0 + b2 * y1 + b3 * v1) / h
            acc[i, j] = 0.0 if outside else (c0 * y0 + c1 * v0 + c2 * y1 + c3 * v1) / hh
