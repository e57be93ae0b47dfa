"""Clamped cubic splines (paper §5, eq. 26-33): C² through knots, zero end velocities.

``N`` knots (lift-off, ``N - 2`` intermediate points, touch-down) at times ``tau`` give ``N - 1``
cubic segments. The knot velocities solve the tridiagonal C² system (the paper's eq. 32 written
for the knot slopes instead of the 4 (N - 1) coefficients: same spline, smaller system).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import solve_banded

from planners.spline_kernels import hermite_into
from quad_uneven_env.fields import excerpt


class ClampedCubicSpline:
    """Piecewise cubic through ``points`` (N x D) at increasing ``tau`` (N,), zero velocity at both ends.

    Evaluation is vectorised over time; outside ``[tau[0], tau[-1]]`` the spline holds its end
    point with zero velocity and acceleration.
    """

    def __init__(self, tau: np.ndarray, points: np.ndarray) -> None:
        tau = np.asarray(tau, dtype=float)
        pts = np.asarray(points, dtype=float)
        if tau.ndim != 1 or tau.size < 2 or pts.shape[0] != tau.size or np.any(np.diff(tau) <= 0.0):
            raise ValueError(f"tau must be N >= 2 increasing times matching points {pts.shape}, got {excerpt(tau)}")
        self.tau = tau
        self.points = pts
        self.slopes = _clamped_slopes(tau, pts)

    def __call__(self, t: np.ndarray, derivative: int = 0) -> np.ndarray:
        """Value (derivative 0), velocity (1) or acceleration (2) at times ``t`` (T,) -> (T, D)."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        tau, y, v = self.tau, self.points, self.slopes
        k = np.clip(np.searchsorted(tau, t, side="right") - 1, 0, tau.size - 2)
        h = (tau[k + 1] - tau[k])[:, None]
        tc = np.clip(t, tau[0], tau[-1])
        s = ((tc - tau[k]) / h[:, 0])[:, None]
        y0, y1, v0, v1 = y[k], y[k + 1], v[k] * h, v[k + 1] * h
        # Hermite basis in local time s in [0, 1].
        if derivative == 0:
            s2, s3 = s * s, s * s * s
            return (2 * s3 - 3 * s2 + 1) * y0 + (s3 - 2 * s2 + s) * v0 + (-2 * s3 + 3 * s2) * y1 + (s3 - s2) * v1
        outside = ((t < tau[0]) | (t > tau[-1]))[:, None]
        if derivative == 1:
            s2 = s * s
            d = (6 * s2 - 6 * s) * y0 + (3 * s2 - 4 * s + 1) * v0 + (-6 * s2 + 6 * s) * y1 + (3 * s2 - 2 * s) * v1
            return np.where(outside, 0.0, d / h)
        if derivative == 2:
            d = (12 * s - 6) * y0 + (6 * s - 4) * v0 + (-12 * s + 6) * y1 + (6 * s - 2) * v1
            return np.where(outside, 0.0, d / (h * h))
        raise ValueError(f"derivative must be 0, 1 or 2, got {derivative}")

    def evaluate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Value, velocity and acceleration (each (T, D)) at times ``t`` (T,) (s) in one compiled pass: the floats
        of ``self(t, 0)``, ``self(t, 1)`` and ``self(t, 2)``."""
        t = np.ascontiguousarray(np.atleast_1d(np.asarray(t, dtype=float)))
        shape = (t.shape[0], self.points.shape[1])
        pos, vel, acc = np.empty(shape), np.empty(shape), np.empty(shape)
        hermite_into(self.tau, self.points, self.slopes, t, pos, vel, acc)
        return pos, vel, acc


def _clamped_slopes(tau: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Knot velocities (N x D) of the C² cubic spline with zero end velocities."""
    n = tau.size
    slopes = np.zeros_like(y)
    if n <= 2:
        return slopes
    h = np.diff(tau)
    inv = 1.0 / h
    # Row k (interior knot): v[k-1]/h[k-1] + 2 v[k] (1/h[k-1] + 1/h[k]) + v[k+1]/h[k] = rhs.
    rhs = 3.0 * ((y[1:-1] - y[:-2]) * (inv[:-1] ** 2)[:, None] + (y[2:] - y[1:-1]) * (inv[1:] ** 2)[:, None])
    m = n - 2
    ab = np.zeros((3, m))
    ab[0, 1:] = inv[1:-1]  # super-diagonal: coefficient of v[k+1]
    ab[1, :] = 2.0 * (inv[:-1] + inv[1:])
    ab[2, :-1] = inv[1:-1]  # sub-diagonal: coefficient of v[k-1]
    slopes[1:-1] = solve_banded((1, 1), ab, rhs)
    return slopes
