"""Kinematics of any :class:`~quad_uneven_env.robot.description.RobotDescription`'s legs (numpy, trunk frame).

Forward kinematics chains the joints' placements and rotations (any offsets, any rotated joint frames).
The inverse is analytic for the HAA-HFE-KFE chain the description guarantees (HAA about trunk x, HFE and KFE
about trunk y): with the HAA axis ``a1``, the pitch axis ``a2`` and ``n = a1 x a2``,

- the foot's offset along ``a2`` from the HAA axis is constant (the lateral hip offset, ``lat``);
- HAA turns the (``a2``, ``n``) components of the foot about ``a1``: their length fixes the foot's ``n``
  coordinate before HAA turns, and the angle between the two gives HAA;
- HFE and KFE form a planar two-link arm in the (``a1``, ``n``) plane: the law of cosines gives KFE, on the
  branch of the description's standing pose (its knee direction), and the remaining angle HFE.

Targets out of reach are pulled onto the reachable set (the knee then sits at its stretched limit).
Angles in rad, lengths in m, positions in the trunk frame.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import TYPE_CHECKING

import numpy as np

from quad_uneven_env import constants as C

if TYPE_CHECKING:
    from quad_uneven_env.robot.quadruped import LegDescription, RobotDescription


def axis_rotation(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) about the unit ``axis`` (3,) by ``angle`` (...) rad (Rodrigues)."""
    a = np.asarray(angle, dtype=float)[..., None, None]
    k = np.asarray(axis, dtype=float)
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(a) * K + (1.0 - np.cos(a)) * (K @ K)


def leg_fk_B(leg: LegDescription, q_leg: np.ndarray) -> np.ndarray:
    """Foot point (..., 3) in the trunk frame (m) for joint angles ``q_leg`` (..., 3) = (HAA, HFE, KFE)."""
    q = np.asarray(q_leg, dtype=float)
    p = np.zeros((*q.shape[:-1], 3))
    R = np.broadcast_to(np.eye(3), (*q.shape[:-1], 3, 3))
    for i, j in enumerate(leg.joints):
        p = p + R @ j.pos
        R = R @ j.rot @ axis_rotation(j.axis, q[..., i])
    return p + R @ leg.foot


def feet_positions_B(desc: RobotDescription, q_joints: np.ndarray) -> np.ndarray:
    """Foot points (..., 4, 3) in the trunk frame (m) for the 12 joint angles (..., 12)."""
    q = np.asarray(q_joints, dtype=float)
    return np.stack([leg_fk_B(leg, q[..., 3 * i : 3 * i + 3]) for i, leg in enumerate(desc.legs)], axis=-2)


def knee_position_B(leg: LegDescription, q_leg: np.ndarray) -> np.ndarray:
    """Knee (KFE origin) (..., 3) in the trunk frame (m)."""
    q = np.asarray(q_leg, dtype=float)
    R1 = leg.haa.rot @ axis_rotation(leg.haa.axis, q[..., 0])
    R2 = R1 @ leg.hfe.rot @ axis_rotation(leg.hfe.axis, q[..., 1])
    return leg.haa.pos + R1 @ leg.hfe.pos + R2 @ leg.kfe.pos


@dataclasses.dataclass(frozen=True)
class _Chain:
    """The constants of one leg's analytic inverse (see the module docstring)."""

    h: np.ndarray  # HAA origin, trunk frame
    a1: np.ndarray
    a2: np.ndarray
    n: np.ndarray
    alpha: np.ndarray  # HFE origin - HAA origin in (a1, a2, n) coordinates
    lat: float  # the foot's offset along a2 from the HAA origin
    U1: complex  # knee - HFE origin, (a1, n) plane
    U2: complex  # foot - knee at zero KFE, (a1, n) plane
    sigma: float  # +1 if the KFE axis is a2, -1 if it is -a2
    down: float  # sign of the foot's n coordinate before HAA turns (standing pose)
    branch: float  # sign of sin(knee angle) in the standing pose


def _chain(leg: LegDescription, q_stand: np.ndarray) -> _Chain:
    h = leg.haa.pos
    R1 = leg.haa.rot
    a1 = R1 @ leg.haa.axis
    o2 = h + R1 @ leg.hfe.pos
    R2 = R1 @ leg.hfe.rot
    a2 = R2 @ leg.hfe.axis
    o3 = o2 + R2 @ leg.kfe.pos
    R3 = R2 @ leg.kfe.rot
    a3 = R3 @ leg.kfe.axis
    f0 = o3 + R3 @ leg.foot
    n = np.cross(a1, a2)
    basis = np.stack([a1, a2, n])
    alpha = basis @ (o2 - h)
    u1, u2 = o3 - o2, f0 - o3
    U1, U2 = complex(u1 @ a1, u1 @ n), complex(u2 @ a1, u2 @ n)
    sigma = float(np.sign(a3 @ a2))
    lat = float(alpha[1] + (u1 + u2) @ a2)
    # branches from the standing pose
    q1, _q2, q3 = q_stand
    f = leg_fk_B(leg, q_stand)
    r = f - h
    w_n = float((axis_rotation(a1, -q1) @ r) @ n)  # the foot's n coordinate before HAA turns
    psi = np.angle(U2 / U1) - sigma * q3
    return _Chain(h, a1, a2, n, alpha, lat, U1, U2, sigma, 1.0 if w_n >= 0 else -1.0, 1.0 if np.sin(psi) >= 0 else -1.0)


@functools.lru_cache(maxsize=64)
def _chains(desc: RobotDescription) -> tuple[_Chain, ...]:
    q = np.asarray(desc.standing_joints, dtype=float)
    return tuple(_chain(leg, q[3 * i : 3 * i + 3]) for i, leg in enumerate(desc.legs))


def chain_constants(desc: RobotDescription) -> tuple[_Chain, ...]:
    """Per leg, the constants of its analytic inverse (see the module docstring): HAA origin ``h``, axes ``a1``,
    ``a2``, ``n``, the HFE offset ``alpha`` and the lateral offset ``lat`` (m), the planar thigh ``U1`` and shank
    ``U2`` (complex, m), the KFE axis sign ``sigma`` and the standing pose's knee ``branch``."""
    return _chains(desc)


def _wrap(angle: np.ndarray) -> np.ndarray:
    return (angle + np.pi) % (2.0 * np.pi) - np.pi


def leg_ik_B(desc: RobotDescription, leg_index: int, p_foot_B: np.ndarray) -> np.ndarray:
    """Joint angles (..., 3) = (HAA, HFE, KFE) placing leg ``leg_index``'s foot point at ``p_foot_B`` (..., 3).

    The knee takes the branch of the description's standing pose (:attr:`RobotDescription.knee_directions`);
    the hip the side of it (the foot below the trunk). Angles are wrapped into [-pi, pi).
    """
    c = _chains(desc)[leg_index]
    r = np.asarray(p_foot_B, dtype=float) - c.h
    gx = r @ c.a1 - c.alpha[0]
    wy, wz = r @ c.a2, r @ c.n
    gy = -c.alpha[2] + c.down * np.sqrt(np.maximum(wy * wy + wz * wz - c.lat * c.lat, 0.0))
    q1 = np.arctan2(wz, wy) - np.arctan2(c.alpha[2] + gy, c.lat)
    L1, L2 = abs(c.U1), abs(c.U2)
    G = gx + 1j * gy
    cos_psi = np.clip((np.abs(G) ** 2 - L1 * L1 - L2 * L2) / (2.0 * L1 * L2), -1.0, 1.0)
    psi = c.branch * np.arccos(cos_psi)
    q3 = c.sigma * (np.angle(c.U2 / c.U1) - psi)
    # e^{-i q2} (U1 + U2 e^{-i sigma q3}) = G
    q2 = np.angle(c.U1 + c.U2 * np.exp(-1j * c.sigma * q3)) - np.angle(G)
    return np.stack([_wrap(q1), _wrap(q2), _wrap(q3)], axis=-1)


def feet_ik_B(desc: RobotDescription, p_feet_B: np.ndarray) -> np.ndarray:
    """The 12 joint angles (..., 12) placing the four foot points at ``p_feet_B`` (..., 4, 3) (trunk frame)."""
    p = np.asarray(p_feet_B, dtype=float)
    return np.concatenate([leg_ik_B(desc, i, p[..., i, :]) for i in range(C.N_LEGS)], axis=-1)


def knee_signs(desc: RobotDescription) -> np.ndarray:
    """(4,) +1 where the knee is in front of the HFE-foot line in the standing pose (trunk x), -1 behind."""
    out = np.empty(C.N_LEGS)
    q = np.asarray(desc.standing_joints, dtype=float)
    for i, leg in enumerate(desc.legs):
        qi = q[3 * i : 3 * i + 3]
        R1 = leg.haa.rot @ axis_rotation(leg.haa.axis, qi[0])
        hfe = leg.haa.pos + R1 @ leg.hfe.pos
        knee, foot = knee_position_B(leg, qi), leg_fk_B(leg, qi)
        # the knee's x relative to the straight line from the HFE origin to the foot, at the knee's height
        t = (knee[2] - hfe[2]) / (foot[2] - hfe[2])
        out[i] = 1.0 if knee[0] > hfe[0] + t * (foot[0] - hfe[0]) else -1.0
    return out
