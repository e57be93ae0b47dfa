"""Small spatial helpers used across the project (numpy): cross products, 3 x 3 inverses, quaternions.

Quaternions are (w, x, y, z), MuJoCo's order; ``R_WB`` maps base-frame vectors to the world frame.
The compiled twins for physics-rate kernels are in :mod:`quad_uneven_env.spatial_kernels`.
"""

from __future__ import annotations

import math

import numpy as np


def wrap_angle(angle: float) -> float:
    """``angle`` (rad) wrapped to [-pi, pi)."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def yaw_of_quat(quat_wxyz: np.ndarray) -> float:
    """rad, in [-pi, pi]: heading of a body (its x axis projected on the world's horizontal plane, about world
    z) from its world orientation quaternion (w, x, y, z)."""
    w, x, y, z = (float(c) for c in quat_wxyz)
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a x b`` over the last axis (3), broadcast; componentwise (np.cross is slow on small stacks)."""
    a, b = np.broadcast_arrays(np.asarray(a, dtype=float), np.asarray(b, dtype=float))
    out = np.empty(a.shape)
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


def inv3(A: np.ndarray) -> np.ndarray:
    """Inverse of (..., 3, 3) matrices by the adjugate (batched LAPACK is slower on 3 x 3)."""
    a, b, c = A[..., 0, 0], A[..., 0, 1], A[..., 0, 2]
    d, e, f = A[..., 1, 0], A[..., 1, 1], A[..., 1, 2]
    g, h, i = A[..., 2, 0], A[..., 2, 1], A[..., 2, 2]
    co = np.empty(A.shape)
    co[..., 0, 0], co[..., 0, 1], co[..., 0, 2] = e * i - f * h, c * h - b * i, b * f - c * e
    co[..., 1, 0], co[..., 1, 1], co[..., 1, 2] = f * g - d * i, a * i - c * g, c * d - a * f
    co[..., 2, 0], co[..., 2, 1], co[..., 2, 2] = d * h - e * g, b * g - a * h, a * e - b * d
    det = a * co[..., 0, 0] + b * co[..., 1, 0] + c * co[..., 2, 0]
    return co / det[..., None, None]


def quat_to_matrix(quat_wxyz: np.ndarray) -> np.ndarray:
    """Rotation matrices R_WB (..., 3, 3) of quaternions (..., 4) (w, x, y, z), normalised here."""
    q = np.asarray(quat_wxyz, dtype=float)
    norm = np.linalg.norm(q) if q.ndim == 1 else np.linalg.norm(q, axis=-1)[..., None]
    q = q / norm
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    R = np.empty((*q.shape[:-1], 3, 3))
    R[..., 0, 0], R[..., 0, 1], R[..., 0, 2] = 1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)
    R[..., 1, 0], R[..., 1, 1], R[..., 1, 2] = 2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)
    R[..., 2, 0], R[..., 2, 1], R[..., 2, 2] = 2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)
    return R
