"""Compiled (numba) twins of :mod:`quad_uneven_env.spatial` for physics-rate kernels (tested equal to them)."""

from __future__ import annotations

import numba as nb

from quad_uneven_env.jit import njit

_f1 = nb.float64[:]
_f2 = nb.float64[:, :]


@njit(nb.boolean(_f2, _f2), nogil=True)
def inv3_into(A, out):  # pragma: no cover - compiled
    """out = A^-1 (3 x 3) by the adjugate, the arithmetic of :func:`~quad_uneven_env.spatial.inv3`;
    False (out untouched) if det(A) == 0."""
    a, b, c = A[0, 0], A[0, 1], A[0, 2]
    d, e, f = A[1, 0], A[1, 1], A[1, 2]
    g, h, i = A[2, 0], A[2, 1], A[2, 2]
    c00, c01, c02 = e * i - f * h, c * h - b * i, b * f - c * e
    c10, c11, c12 = f * g - d * i, a * i - c * g, c * d - a * f
    c20, c21, c22 = d * h - e * g, b * g - a * h, a * e - b * d
    det = a * c00 + b * c10 + c * c20
    if det == 0.0:
        return False
    out[0, 0], out[0, 1], out[0, 2] = c00 / det, c01 / det, c02 / det
    out[1, 0], out[1, 1], out[1, 2] = c10 / det, c11 / det, c12 / det
    out[2, 0], out[2, 1], out[2, 2] = c20 / det, c21 / det, c22 / det
    return True


@njit(nb.void(_f1, _f2), nogil=True)
def quat_to_matrix_into(q, R):  # pragma: no cover - compiled
    """mju_quat2Mat's arithmetic (unit quaternion w, x, y, z)."""
    if q[0] == 1.0 and q[1] == 0.0 and q[2] == 0.0 and q[3] == 0.0:
        for i in range(3):
            for j in range(3):
                R[i, j] = 1.0 if i == j else 0.0
        return
    q00, q01, q02, q03 = q[0] * q[0], q[0] * q[1], q[0] * q[2], q[0] * q[3]
    q11, q12, q13 = q[1] * q[1], q[1] * q[2], q[1] * q[3]
    q22, q23, q33 = q[2] * q[2], q[2] * q[3], q[3] * q[3]
    R[0, 0] = q00 + q11 - q22 - q33
    R[1, 1] = q00 - q11 + q22 - q33
    R[2, 2] = q00 - q11 - q22 + q33
    R[0, 1] = 2.0 * (q12 - q03)
    R[0, 2] = 2.0 * (q13 + q02)
    R[1, 0] = 2.0 * (q12 + q03)
    R[1, 2] = 2.0 * (q23 - q01)
    R[2, 0] = 2.0 * (q13 - q02)
    R[2, 1] = 2.0 * (q23 + q01)
