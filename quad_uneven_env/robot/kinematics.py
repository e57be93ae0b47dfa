"""Closed-form kinematics of a two-link HAA-HFE-KFE leg in the hip frame (the paper's Table-1 legs,
:class:`~quad_uneven_env.robot.quadruped.TwoLinkLegs`).

The hip frame is parallel to the body frame with its origin at the hip (the intersection
of the HAA and HFE axes). At zero angles a leg hangs straight down (-z). Angles in rad,
lengths in m.
"""

from __future__ import annotations

import numpy as np


def leg_fk_hip(q_leg: np.ndarray, l1: float, l2: float) -> np.ndarray:
    """Foot point in the hip frame (m) for joint angles ``q_leg = (HAA, HFE, KFE)`` (..., 3)."""
    q = np.asarray(q_leg, dtype=float)
    q1, q2, q3 = q[..., 0], q[..., 1], q[..., 2]
    u = -l1 * np.sin(q2) - l2 * np.sin(q2 + q3)
    w = -l1 * np.cos(q2) - l2 * np.cos(q2 + q3)
    return np.stack([u, -np.sin(q1) * w, np.cos(q1) * w], axis=-1)


def leg_ik_hip(p_foot_H: np.ndarray, l1: float, l2: float, knee_sign: float) -> np.ndarray:
    """Joint angles (HAA, HFE, KFE) placing the foot at ``p_foot_H`` (..., 3) in the hip frame.

    ``knee_sign`` (+1 or -1) picks the knee branch (sign of KFE). Targets beyond reach are
    pulled onto the reachable sphere (the knee then sits at its stretched limit).
    """
    p = np.asarray(p_foot_H, dtype=float)
    px, py, pz = p[..., 0], p[..., 1], p[..., 2]
    q1 = np.arctan2(py, -pz)
    r = np.hypot(py, pz)
    u, w = px, -r
    d2 = u * u + w * w
    c3 = np.clip((d2 - l1 * l1 - l2 * l2) / (2.0 * l1 * l2), -1.0, 1.0)
    q3 = knee_sign * np.arccos(c3)
    phi = np.arctan2(-u, -w)
    alpha = np.arctan2(l2 * np.sin(q3), l1 + l2 * np.cos(q3))
    return np.stack([q1, phi - alpha, q3], axis=-1)
