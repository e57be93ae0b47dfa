"""Piecewise 8th-order polynomials in normalised local time (the COG path of paper §4, eq. 24).

Each phase ``k`` of duration ``T_k`` carries one degree-8 polynomial per axis written in the
Bernstein basis of the local time ``s = (t - t_k) / T_k`` in [0, 1]: the paper's absolute-time
monomials ``t^8`` are ill-conditioned, the Bernstein form over [0, 1] is the best-conditioned
polynomial basis on an interval. The path is the same polynomial family as the paper's.
"""

from __future__ import annotations

from math import comb, factorial

import numpy as np

DEGREE = 8
N_COEF = DEGREE + 1

_BERN_TO_MONO = np.array(
    [
        [comb(DEGREE, i) * comb(DEGREE - i, k - i) * (-1) ** (k - i) if k >= i else 0 for k in range(N_COEF)]
        for i in range(N_COEF)
    ],
    dtype=float,
)
"""Row i: monomial coefficients (s^0 .. s^8) of the Bernstein polynomial b_{i,8}(s)."""


_K = np.arange(N_COEF)
_FALLING = [np.array([factorial(j) / factorial(j - d) if j >= d else 0.0 for j in _K]) for d in range(N_COEF)]
"""Per derivative d: j! / (j - d)!, the factor of s^(j - d) in the d-th derivative of s^j (0 for j < d)."""


def basis_rows(s: np.ndarray, derivative: int = 0) -> np.ndarray:
    """Bernstein basis (or its d-th derivative with respect to s) at local times ``s`` (S,) -> (S, 9)."""
    s = np.atleast_1d(np.asarray(s, dtype=float))
    powers = np.where(_K >= derivative, s[:, None] ** np.maximum(_K - derivative, 0), 0.0) * _FALLING[derivative]
    return powers @ _BERN_TO_MONO.T


def accel_gram() -> np.ndarray:
    """(9, 9) Gram matrix of the second s-derivatives: int_0^1 b_i''(s) b_j''(s) ds (exact Gauss rule)."""
    x, w = np.polynomial.legendre.leggauss(8)
    s = 0.5 * (x + 1.0)
    rows = basis_rows(s, 2)
    return (rows * (0.5 * w)[:, None]).T @ rows


class PiecewisePolynomial:
    """Piecewise degree-8 polynomial path in R^D over consecutive phases (absolute time, s).

    :param t_knots: (K + 1,) phase boundaries (s), increasing.
    :param coef: (K, 9, D) Bernstein coefficients per phase.
    """

    def __init__(self, t_knots: np.ndarray, coef: np.ndarray) -> None:
        self.t_knots = np.asarray(t_knots, dtype=float)
        self.coef = np.asarray(coef, dtype=float)
        self.durations = np.diff(self.t_knots)

    def _eval(self, t: np.ndarray, derivative: int) -> np.ndarray:
        t = np.atleast_1d(np.asarray(t, dtype=float))
        k = np.clip(np.searchsorted(self.t_knots[1:-1], t, side="right"), 0, len(self.durations) - 1)
        T = self.durations[k]
        s = np.clip((t - self.t_knots[k]) / T, 0.0, 1.0)
        rows = basis_rows(s, derivative)
        return np.einsum("ti,tij->tj", rows, self.coef[k]) / (T**derivative)[:, None]

    def position(self, t: np.ndarray) -> np.ndarray:
        """Position (T, D) in m at absolute times ``t`` (s); clamped to the plan's time span."""
        return self._eval(t, 0)

    def velocity(self, t: np.ndarray) -> np.ndarray:
        """Velocity (T, D) in m/s."""
        return self._eval(t, 1)

    def acceleration(self, t: np.ndarray) -> np.ndarray:
        """Acceleration (T, D) in m/s^2."""
        return self._eval(t, 2)

    def junction_jumps(self) -> np.ndarray:
        """(K - 1, 3) max-abs jumps of position, velocity and acceleration at each phase junction."""
        out = []
        for k in range(len(self.durations) - 1):
            left, right = [], []
            for d in range(3):
                left.append(basis_rows(np.array([1.0]), d)[0] @ self.coef[k] / self.durations[k] ** d)
                right.append(basis_rows(np.array([0.0]), d)[0] @ self.coef[k + 1] / self.durations[k + 1] ** d)
            out.append([np.abs(a - b).max() for a, b in zip(left, right, strict=True)])
        return np.array(out)
