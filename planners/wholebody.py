"""Whole-body COM placement: the base pose that puts the robot's COG on the planned path (exact derivatives).

With the base orientation fixed (identity, the paper), foot ``i`` relative to its hip is
``e_i = x_i - p_base - hip_i`` (world = base frame axes), the leg angles are ``q_i = IK(e_i)`` and
the whole-body COM is

    c = p_base + (1/M) sum_i [ m_leg hip_i + f(q_i) ],  f(q) = m1 P(q; lc1, 0) + m2 P(q; l1, lc2)

where ``P(q; a, b)`` is the point ``a`` along the thigh and ``b`` along the shank (linear in
``a, b``, so ``f = P(q; m1 lc1 + m2 l1, m2 lc2)``). Given the planned ``c(t)`` and the feet
``x_i(t)`` (stance: fixed; swing: the swing path) the base position solves ``c = p + off(p)`` by
Newton's method; velocities and accelerations follow from the analytic Jacobians
``J = dP/dq`` and the velocity-product terms ``(dJ/dt) q_dot``:

    K p_dot  = c_dot  - (1/M) sum A_i x_dot_i,                          A_i = F_i J_i^-1, K = I - (1/M) sum A_i
    K p_ddot = c_ddot - (1/M) sum [A_i x_ddot_i - A_i Jd_i qd_i + Fd_i qd_i]
    qd_i = J_i^-1 (x_dot_i - p_dot),  qdd_i = J_i^-1 (x_ddot_i - p_ddot - Jd_i qd_i)

With a time-varying base orientation ``R(t)`` (angular velocity ``omega``, acceleration
``alpha``, world frame) the same equations hold in the base-aligned rotating frame: every world
vector ``v`` becomes ``v_B = R^T v`` with ``v_B' = R^T (v' - omega x v)`` and
``v_B'' = R^T (v'' - 2 omega x v' - alpha x v + omega x (omega x v))``
(:func:`to_rotating_frame`); the base motion found there maps back with
:func:`from_rotating_frame` (:meth:`WholeBody.place_base_rotated`).

All functions are vectorised over leading axes (time, leg).
"""

from __future__ import annotations

import numpy as np

from planners.robot_geometry import RobotGeometry, robot_geometry
from planners.wholebody_kernels import place_base_grid
from quad_uneven_env.robot.description import RobotDescription
from quad_uneven_env.robot.kinematics import leg_ik_hip
from quad_uneven_env.spatial import cross, inv3


def leg_point(q: np.ndarray, a: float, b: float, qd: np.ndarray | None = None):
    """Point ``a`` (m) along the thigh and ``b`` (m) along the shank in the hip frame, with derivatives.

    :param q: (..., 3) leg angles (HAA, HFE, KFE) (rad).
    :param qd: optional (..., 3) joint velocities (rad/s).
    :return: ``(p, J)`` with p (..., 3) (m) and the Jacobian J = dp/dq (..., 3, 3) (m/rad); with
        ``qd`` also ``Jd_qd = (dJ/dt) qd`` (..., 3) (m/s^2), the velocity-product acceleration.
    """
    q = np.asarray(q, dtype=float)
    s1, c1 = np.sin(q[..., 0]), np.cos(q[..., 0])
    s2, c2 = np.sin(q[..., 1]), np.cos(q[..., 1])
    s23, c23 = np.sin(q[..., 1] + q[..., 2]), np.cos(q[..., 1] + q[..., 2])
    u = -a * s2 - b * s23
    w = -a * c2 - b * c23
    u2, u3 = -a * c2 - b * c23, -b * c23
    w2, w3 = a * s2 + b * s23, b * s23
    p = np.stack([u, -s1 * w, c1 * w], axis=-1)
    zero = np.zeros_like(u)
    J = np.stack(
        [
            np.stack([zero, u2, u3], axis=-1),
            np.stack([-c1 * w, -s1 * w2, -s1 * w3], axis=-1),
            np.stack([-s1 * w, c1 * w2, c1 * w3], axis=-1),
        ],
        axis=-2,
    )
    if qd is None:
        return p, J
    qd = np.asarray(qd, dtype=float)
    d1, d2, d23 = qd[..., 0], qd[..., 1], qd[..., 1] + qd[..., 2]
    u_vv = a * s2 * d2**2 + b * s23 * d23**2
    w_dot = w2 * qd[..., 1] + w3 * qd[..., 2]
    w_vv = a * c2 * d2**2 + b * c23 * d23**2
    jd = np.stack(
        [u_vv, s1 * d1**2 * w - 2 * c1 * d1 * w_dot - s1 * w_vv, -c1 * d1**2 * w - 2 * s1 * d1 * w_dot + c1 * w_vv],
        axis=-1,
    )
    return p, J, jd


def _solve3(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """x (..., 3) with A x = b for (..., 3, 3) A."""
    return (inv3(A) @ b[..., None])[..., 0]


class WholeBody:
    """Mass distribution of a robot for COM placement (identity or a given base orientation).

    :param robot: the robot (a ``RobotDescription`` or a :class:`~planners.robot_geometry.RobotGeometry`): two-link
        legs (the paper's Table 1) are computed by :func:`leg_point` and the compiled kernel; other legs by their
        chain model
        (:class:`~planners.robot_geometry.LegChainModel`, numpy only).
    """

    def __init__(self, robot: RobotDescription | RobotGeometry) -> None:
        geom = robot_geometry(robot)
        self.geometry = geom
        """the planners' view of the robot."""
        self.mass = geom.mass
        self.hips = geom.hips_B  # (4, 3)
        self.chain = geom.chain
        if self.chain is None:
            legs = geom.two_link
            self.l1, self.l2 = legs.thigh, legs.shank
            self.moment_ab = (
                legs.thigh_mass * legs.thigh_com + legs.shank_mass * legs.thigh,
                legs.shank_mass * legs.shank_com,
            )
            self.leg_mass = legs.thigh_mass + legs.shank_mass
            self.knee_sign = legs.knee_signs
            # Constant part of M (c - p_base): the leg masses placed at the hips.
            self._hip_moment = self.leg_mass * self.hips.sum(axis=0)
        else:
            # the leg masses at the hips, and the trunk's COM
            self._hip_moment = (self.chain.leg_mass[:, None] * self.hips).sum(axis=0) + self.chain.trunk_moment

    def ik(self, e: np.ndarray) -> np.ndarray:
        """Leg angles (..., 4, 3) (rad) for foot points ``e`` (..., 4, 3) relative to the hips (m)."""
        if self.chain is not None:
            return self.geometry.ik(e)
        return leg_ik_hip(e, self.l1, self.l2, self.knee_sign)

    def _moment(self, q: np.ndarray, qd: np.ndarray | None = None):
        """The legs' mass moments about their hips (kg m) and derivatives, as :func:`leg_point`."""
        if self.chain is not None:
            return self.chain.point(q, "com", qd)
        return leg_point(q, *self.moment_ab) if qd is None else leg_point(q, *self.moment_ab, qd)

    def _foot(self, q: np.ndarray, qd: np.ndarray | None = None):
        """The foot points from the hips (m) and derivatives, as :func:`leg_point`."""
        if self.chain is not None:
            return self.chain.point(q, "foot", qd)
        return leg_point(q, self.l1, self.l2) if qd is None else leg_point(q, self.l1, self.l2, qd)

    def com_offset(self, q_legs: np.ndarray) -> np.ndarray:
        """Whole-body COM minus base position (..., 3) (m, base-frame axes) for leg angles (..., 4, 3)."""
        f, _ = self._moment(q_legs)
        return (self._hip_moment + f.sum(axis=-2)) / self.mass

    def place_base(
        self,
        c: np.ndarray,
        c_d: np.ndarray,
        c_dd: np.ndarray,
        x: np.ndarray,
        x_d: np.ndarray,
        x_dd: np.ndarray,
        p_guess: np.ndarray | None = None,
        newton_steps: int = 4,
    ) -> tuple[np.ndarray, ...]:
        """Base position/velocity/acceleration and leg joint motion putting the whole-body COM on ``c``.

        :param c, c_d, c_dd: (..., 3) planned COG position (m), velocity (m/s), acceleration (m/s^2).
        :param x, x_d, x_dd: (..., 4, 3) foot-site positions, velocities, accelerations (world).
        :param p_guess: optional (..., 3) initial base position (m).
        :return: ``(p, p_d, p_dd, q, qd, qdd)``: base (..., 3) and leg joints (..., 4, 3) in rad, rad/s, rad/s^2.
        """
        M = self.mass
        p = c - self.com_offset(self.ik(x - (c[..., None, :] - 0.0) - self.hips)) if p_guess is None else p_guess
        eye = np.eye(3)
        for _ in range(newton_steps):
            q = self.ik(x - p[..., None, :] - self.hips)
            f, F = self._moment(q)
            _, J = self._foot(q)
            A = F @ inv3(J)
            res = p + (self._hip_moment + f.sum(axis=-2)) / M - c
            K = eye - A.sum(axis=-3) / M
            p = p - _solve3(K, res)
        q = self.ik(x - p[..., None, :] - self.hips)
        _, J = self._foot(q)
        _, F = self._moment(q)
        Jinv = inv3(J)
        A = F @ Jinv
        Kinv = inv3(eye - A.sum(axis=-3) / M)
        rhs = c_d - np.einsum("...lij,...lj->...i", A, x_d) / M
        p_d = (Kinv @ rhs[..., None])[..., 0]
        qd = np.einsum("...lij,...lj->...li", Jinv, x_d - p_d[..., None, :])
        _, _, jd = self._foot(q, qd)
        _, _, fd = self._moment(q, qd)
        inner = np.einsum("...lij,...lj->...li", A, x_dd - jd) + fd
        p_dd = (Kinv @ (c_dd - inner.sum(axis=-2) / M)[..., None])[..., 0]
        qdd = np.einsum("...lij,...lj->...li", Jinv, x_dd - p_dd[..., None, :] - jd)
        return p, p_d, p_dd, q, qd, qdd

    def place_base_compiled(
        self,
        c: np.ndarray,
        c_d: np.ndarray,
        c_dd: np.ndarray,
        x: np.ndarray,
        x_d: np.ndarray,
        x_dd: np.ndarray,
        newton_steps: int = 3,
    ) -> tuple[np.ndarray, ...]:
        """:meth:`place_base` of T time points by the compiled kernel (same formulas, no initial guess).

        :param c, c_d, c_dd: (T, 3) planned COG position (m), velocity (m/s), acceleration (m/s^2).
        :param x, x_d, x_dd: (T, 4, 3) foot-site positions, velocities, accelerations (world).
        :return: ``(p, p_d, p_dd, q, qd, qdd)``: base (T, 3); leg joints (T, 12) in rad, rad/s, rad/s^2.
        """
        if self.chain is not None:  # a URDF robot: the numpy path, joints as (T, 12)
            with np.errstate(divide="ignore", invalid="ignore"):  # a singular leg: non-finite rows, as the kernel's
                p, pd, pdd, q, qd, qdd = self.place_base(c, c_d, c_dd, x, x_d, x_dd, None, newton_steps + 1)
            return p, pd, pdd, q.reshape(-1, 12), qd.reshape(-1, 12), qdd.reshape(-1, 12)
        T = c.shape[0]
        f = np.ascontiguousarray
        p, pd, pdd = np.empty((T, 3)), np.empty((T, 3)), np.empty((T, 3))
        q, qd, qdd = np.empty((T, 12)), np.empty((T, 12)), np.empty((T, 12))
        place_base_grid(
            f(c, dtype=float), f(c_d, dtype=float), f(c_dd, dtype=float),
            f(x, dtype=float), f(x_d, dtype=float), f(x_dd, dtype=float),
            self.hips, self.l1, self.l2, *self.moment_ab, self.knee_sign.astype(float),
            self._hip_moment, self.mass, int(newton_steps), p, pd, pdd, q, qd, qdd,
        )  # fmt: skip
        return p, pd, pdd, q, qd, qdd

    def place_base_rotated(
        self,
        c: np.ndarray,
        c_d: np.ndarray,
        c_dd: np.ndarray,
        x: np.ndarray,
        x_d: np.ndarray,
        x_dd: np.ndarray,
        R: np.ndarray,
        omega: np.ndarray,
        alpha: np.ndarray,
        p_guess: np.ndarray | None = None,
        newton_steps: int = 4,
        compiled: bool = False,
    ) -> tuple[np.ndarray, ...]:
        """:meth:`place_base` for a base with orientation ``R`` (..., 3, 3) (R_WB) instead of identity.

        :param omega, alpha: (..., 3) base angular velocity (rad/s) and acceleration (rad/s^2), world frame.
        :param p_guess: optional (..., 3) initial base position (m, world).
        :param compiled: solve with :meth:`place_base_compiled` (inputs (T, ...), no ``p_guess``; joints
            then come as (T, 12)).
        :return: as :meth:`place_base`, base motion in the world frame.
        """
        cb = to_rotating_frame(R, omega, alpha, c, c_d, c_dd)
        xb = to_rotating_frame(R[..., None, :, :], omega[..., None, :], alpha[..., None, :], x, x_d, x_dd)
        if compiled:
            if p_guess is not None:
                raise ValueError("place_base_rotated: compiled=True takes no p_guess")
            pb, pb_d, pb_dd, q, qd, qdd = self.place_base_compiled(*cb, *xb, newton_steps)
        else:
            gb = None if p_guess is None else _apply(np.swapaxes(R, -1, -2), p_guess)
            pb, pb_d, pb_dd, q, qd, qdd = self.place_base(*cb, *xb, gb, newton_steps)
        return (*from_rotating_frame(R, omega, alpha, pb, pb_d, pb_dd), q, qd, qdd)


def to_rotating_frame(
    R: np.ndarray, omega: np.ndarray, alpha: np.ndarray, v: np.ndarray, v_d: np.ndarray, v_dd: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World vector ``v`` (..., 3) (m) and its time derivatives seen in the frame rotating with ``R`` (..., 3, 3).

    :param omega, alpha: (..., 3) angular velocity (rad/s) and acceleration (rad/s^2) of the frame, world frame.
    :return: ``(R^T v, d/dt, d2/dt2)`` (see the module doc).
    """
    R, w, a = (np.asarray(z, dtype=float) for z in (R, omega, alpha))
    wv = cross(w, v)
    Rt = np.swapaxes(R, -1, -2)
    vb = _apply(Rt, v)
    vb_d = _apply(Rt, v_d - wv)
    vb_dd = _apply(Rt, v_dd - 2.0 * cross(w, v_d) - cross(a, v) + cross(w, wv))
    return vb, vb_d, vb_dd


def from_rotating_frame(
    R: np.ndarray, omega: np.ndarray, alpha: np.ndarray, vb: np.ndarray, vb_d: np.ndarray, vb_dd: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Inverse of :func:`to_rotating_frame`: world vector (..., 3) (m) and its time derivatives."""
    R, w, a = (np.asarray(z, dtype=float) for z in (R, omega, alpha))
    v = _apply(R, vb)
    rel = _apply(R, vb_d)
    v_d = rel + cross(w, v)
    v_dd = _apply(R, vb_dd) + 2.0 * cross(w, rel) + cross(a, v) + cross(w, cross(w, v))
    return v, v_d, v_dd


def _apply(R: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``R @ v`` for stacks R (..., 3, 3) and v (..., 3), broadcast (matmul: faster than einsum on small stacks)."""
    return (R @ np.asarray(v, dtype=float)[..., None])[..., 0]
