"""The one place where MuJoCo's and Pinocchio's free-flyer conventions meet.

MuJoCo (canonical): ``qpos = [p_W, quat (w, x, y, z), q_j]``,
``qvel = [v_W (world-frame linear velocity of the base origin), omega_B, qd_j]``.
Pinocchio: ``q = [p_W, quat (x, y, z, w), q_j]``, ``v = [v_B, omega_B, qd_j]`` with the
linear velocity in the base frame. Hence ``qvel = T(q) v`` with ``T = diag(R_WB, I, I)``.
"""

from __future__ import annotations

import numpy as np

from quad_uneven_env.spatial import quat_to_matrix


def qpos_mj_to_pin(qpos: np.ndarray) -> np.ndarray:
    """MuJoCo qpos (19,) -> Pinocchio q (19,): quaternion reordered to (x, y, z, w)."""
    qpos = np.asarray(qpos, dtype=float)
    q = qpos.copy()
    q[3:7] = qpos[[4, 5, 6, 3]]
    return q


def qpos_pin_to_mj(q: np.ndarray) -> np.ndarray:
    """Pinocchio q (19,) -> MuJoCo qpos (19,): quaternion reordered to (w, x, y, z)."""
    q = np.asarray(q, dtype=float)
    qpos = q.copy()
    qpos[3:7] = q[[6, 3, 4, 5]]
    return qpos


def velocity_map(qpos: np.ndarray) -> np.ndarray:
    """T (nv x nv) with ``qvel_mj = T @ v_pin``: the base block is R_WB, the rest identity."""
    nv = len(qpos) - 1
    T = np.eye(nv)
    T[:3, :3] = quat_to_matrix(qpos[3:7])
    return T


def qvel_mj_to_pin(qpos: np.ndarray, qvel: np.ndarray) -> np.ndarray:
    """MuJoCo qvel -> Pinocchio v: the base linear velocity rotated into the base frame."""
    v = np.array(qvel, dtype=float)
    v[:3] = quat_to_matrix(qpos[3:7]).T @ v[:3]
    return v


def qvel_pin_to_mj(qpos: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Pinocchio v -> MuJoCo qvel: the base linear velocity rotated into the world frame."""
    qvel = np.array(v, dtype=float)
    qvel[:3] = quat_to_matrix(qpos[3:7]) @ qvel[:3]
    return qvel


def qacc_pin_to_mj(qpos: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Pinocchio a (d/dt of v) -> MuJoCo qacc: ``T a + Tdot v`` with ``Tdot v = R (omega_B x v_B)``."""
    R = quat_to_matrix(qpos[3:7])
    qacc = np.array(a, dtype=float)
    qacc[:3] = R @ (a[:3] + np.cross(v[3:6], v[:3]))
    return qacc


def qacc_mj_to_pin(qpos: np.ndarray, qvel: np.ndarray, qacc: np.ndarray) -> np.ndarray:
    """MuJoCo qacc -> Pinocchio a, the inverse of :func:`qacc_pin_to_mj`."""
    R = quat_to_matrix(qpos[3:7])
    v_B = R.T @ np.asarray(qvel[:3], dtype=float)
    a = np.array(qacc, dtype=float)
    a[:3] = R.T @ qacc[:3] - np.cross(qvel[3:6], v_B)
    return a


def mass_matrix_pin_to_mj(qpos: np.ndarray, M_pin: np.ndarray) -> np.ndarray:
    """Pinocchio mass matrix -> MuJoCo's: ``T^-T M_pin T^-1`` (kinetic energy is invariant)."""
    Tinv = np.linalg.inv(velocity_map(qpos))
    return Tinv.T @ M_pin @ Tinv
