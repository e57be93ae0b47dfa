"""The paper's explicit (Lagrangian) dynamics, Appendix A eq. 35-39 (compiled kernel; numpy reference).

For every link l (trunk, 4 hip links, 4 thighs, 4 shanks) with mass m_l, inertia I_l about its COM,
COM Jacobian Jv_l and angular-velocity Jacobian Jw_l (both 3 x 18 in canonical coordinates):

    M = sum_l m_l Jv_l^T Jv_l + Jw_l^T I_l Jw_l                       (eq. 35, as NOTES.md reads it)
    V = sum_l m_l Jv_l^T (Jdot_v q_dot) + Jw_l^T (I_l Jdot_w q_dot + w_l x I_l w_l)
    G = -sum_l m_l Jv_l^T g                                           (gradient of the potential)

V is ``C(q, q_dot) q_dot`` written with the Jacobian time derivatives (Kane's form of the
Lagrangian, exact also for the base-frame angular velocity, which is not the derivative of
any coordinate). Everything is expressed in the base frame B, where it does not depend on
the base pose: a COM at ``r_B`` (relative to the base origin) has the B-frame velocity Jacobian
``[R^T, -[r_B]x, dr_B/dq_leg]`` (R = R_WB), and its acceleration at zero qacc is
``w x (w x r) + 2 w x r_dot + r_ddot|_{q_ddot=0}`` (w the base angular velocity in B).

The leg chains are the robot's (:class:`~quad_uneven_env.robot.dynamics.chains.LegChains`): joint k of a leg
sits at ``p_k`` in its parent's frame with rotation ``R_k`` and turns about ``a_k``, so its frame has the
orientation ``Q_k = Q_(k-1) R_k Rot(a_k, q_k)`` and origin ``o_k = o_(k-1) + Q_(k-1) p_k`` in B, its axis is
``z_k = Q_(k-1) R_k a_k``. A point ``c`` of link k (its COM; the foot on the shank) is at ``r = o_k + Q_k c``;
its Jacobian columns are ``z_j x (r - o_j)`` (translation) and ``z_j`` (rotation) for the joints j <= k that
move it. With the legs' angular velocities ``w_k = w_(k-1) + z_k qd_k`` and, at zero joint accelerations,
``alpha_k = alpha_(k-1) + qd_k w_(k-1) x z_k`` (relative to B), the origins' velocities and accelerations
follow by the rigid-body rule ``a_o(k) = a_o(k-1) + alpha_(k-1) x d + w_(k-1) x (w_(k-1) x d)`` with
``d = o_k - o_(k-1)``, and a point's ``r_ddot|_{q_ddot=0} = a_o(k) + alpha_k x e + w_k x (w_k x e)``
(``e = r - o_k``). Closed form in the joint angles, no symbolic engine, no simulator call. The paper's robot
(HAA and HFE axes through one hip point, no offsets, links along -z) is the special case ``R_k = I``,
``a = (x, y, y)``, ``p = (hip, 0, -l1 z)``, where the points reduce to the paper's
``hip + R_x(q1) [u, 0, s]``, ``u = -a sin q2 - b sin(q2 + q3)``, ``s = -a cos q2 - b cos(q2 + q3)``.

Implementation: the 17 points (trunk COM, 4 x (hip-link COM, thigh COM, shank COM, foot)) are processed in
one stacked pass; their B-frame Jacobians form J (17 x 6 x 18, rows v then w) and, with
D = blockdiag(m I, I_B) per point, ``M = J^T D J``, ``h = J^T [m (a0 - g_B); I alpha0 + w x I w]``
and ``G = J^T [-m g_B; 0]`` are three matrix products. The feet (zero mass) reuse the same J.
Every array carries a leading batch axis, so many states are evaluated in one call.
``terms`` runs the same formulas one state at a time in a compiled kernel
(:mod:`quad_uneven_env.robot.dynamics.explicit_kernels`), which skips the massless points (the paper
robot's hip links, the feet) in M, h and G; ``terms_numpy`` is the vectorised numpy version it is tested
against.
"""

from __future__ import annotations

import mujoco
import numpy as np

from quad_uneven_env import constants as C
from quad_uneven_env.robot.description import RobotDescription
from quad_uneven_env.robot.dynamics.base import DynamicsTerms
from quad_uneven_env.robot.dynamics.chains import LegChains, leg_chains
from quad_uneven_env.robot.dynamics.explicit_kernels import PTS_PER_LEG, explicit_terms
from quad_uneven_env.spatial import cross, quat_to_matrix

_LINK = np.array([0, 1, 2, 2])  # the link carrying each leg point: hip link, thigh, shank COM; foot on the shank
_MOVES = np.arange(3)[None, :] <= _LINK[:, None]  # (4 pts, 3 joints): joint j moves the point
_SK_ROWS, _SK_COLS = np.array([0, 0, 1, 1, 2, 2]), np.array([1, 2, 0, 2, 0, 1])
_SK_SRC, _SK_SIGN = np.array([2, 1, 2, 0, 1, 0]), np.array([1.0, -1.0, -1.0, 1.0, 1.0, -1.0])  # [w]x^T = -[w]x
_N_PTS = 1 + C.N_LEGS * PTS_PER_LEG
_PT = (1 + np.arange(C.N_LEGS * PTS_PER_LEG))[:, None, None]  # stacked index of leg point (leg, p)
_ROW3 = np.arange(3)[None, :, None]
_LEGCOL = (6 + 3 * (np.arange(C.N_LEGS * PTS_PER_LEG) // PTS_PER_LEG))[:, None, None] + np.arange(3)[None, None, :]
_FEET = 1 + PTS_PER_LEG * np.arange(C.N_LEGS) + 3


def _rotations(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """``Rot(a, q) = cos q I + sin q [a]x + (1 - cos q) a a^T``: (..., 4, 3, 3) for axes (4, 3), angles (..., 4)."""
    K = np.zeros((*axis.shape[:-1], 3, 3))
    K[..., _SK_ROWS, _SK_COLS] = -axis[..., _SK_SRC] * _SK_SIGN  # [a]x
    s, c = np.sin(angle)[..., None, None], np.cos(angle)[..., None, None]
    return c * np.eye(3) + s * K + (1.0 - c) * (axis[..., :, None] * axis[..., None, :])


class ExplicitDynamics:
    """Explicit Lagrangian dynamics of any HAA-HFE-KFE quadruped (:class:`LegChains`).

    :param robot: a :class:`~quad_uneven_env.robot.description.RobotDescription` (its nominal numbers, standard
        gravity), an MjModel of the project's robot structure (its numbers and gravity: a randomized scene's
        masses are read) or the chains themselves. Only parameters are read; the computation is closed-form.
    :raises ValueError: for an MjModel of another structure (see :meth:`LegChains.from_mjmodel`).
    """

    backend = "explicit"

    def __init__(self, robot: RobotDescription | mujoco.MjModel | LegChains) -> None:
        ch = leg_chains(robot)
        self.chains = ch
        self.gravity_W = ch.gravity_W.copy()
        self.m_trunk = ch.trunk_mass
        self.r_trunk_B = ch.trunk_com.copy()
        self.I_trunk_B = ch.trunk_inertia.copy()
        self.total_mass = ch.total_mass
        # leg points (leg, p): the three links' COMs and the foot, in the frame of the link that carries them
        self.pt_local = np.concatenate([ch.link_com, ch.foot[:, None, :]], 1)  # (4, 4, 3)
        self.I_pts = np.concatenate([ch.link_inertia, np.zeros((C.N_LEGS, 1, 3, 3))], 1)  # (4, 4, 3, 3)
        m_pts = np.concatenate([ch.link_mass, np.zeros((C.N_LEGS, 1))], 1)  # (4, 4)
        self._m_all = np.concatenate([[ch.trunk_mass], m_pts.ravel()])
        pt_on = (m_pts > 0) | np.any(self.I_pts != 0, axis=(-2, -1))
        pt_on[:, 3] = False  # the feet: no mass, only their Jacobians and accelerations
        D0 = np.zeros((1, _N_PTS, 6, 6))
        D0[0, :, 0:3, 0:3] = self._m_all[:, None, None] * np.eye(3)
        D0[0, 0, 3:6, 3:6] = self.I_trunk_B
        self._D0 = D0
        # Motor rotor inertia (MJCF ``armature``): a constant added to the joint diagonal of M.
        self._armature_idx = np.arange(6, C.NV)
        self.armature = ch.armature.copy()
        self._kernel_params = (
            *(np.ascontiguousarray(x, dtype=float) for x in (ch.joint_pos, ch.joint_rot, ch.joint_axis, self.pt_local,
                                                              self._m_all, self.I_pts.reshape(-1, 3, 3))),
            np.ascontiguousarray(pt_on.ravel(), dtype=np.int64),
            *(np.ascontiguousarray(x, dtype=float) for x in (self.I_trunk_B, self.r_trunk_B, self.gravity_W,
                                                              self.armature)),
        )  # fmt: skip

    def terms(self, qpos: np.ndarray, qvel: np.ndarray) -> DynamicsTerms:
        """Dynamics terms at ``qpos`` (..., 19) and ``qvel`` (..., 18); a leading batch axis is kept."""
        qpos = np.asarray(qpos, dtype=float)
        qvel = np.asarray(qvel, dtype=float)
        if qpos.shape[-1] != C.NQ or qvel.shape[-1] != C.NV or qpos.shape[:-1] != qvel.shape[:-1]:
            raise ValueError(f"qpos must be (..., {C.NQ}) and qvel (..., {C.NV}), got {qpos.shape}, {qvel.shape}")
        batch = qpos.shape[:-1]
        out = self._terms_compiled(qpos.reshape(-1, C.NQ), qvel.reshape(-1, C.NV))
        return DynamicsTerms(*(x.reshape(batch + x.shape[1:]) for x in out))

    def terms_numpy(self, qpos: np.ndarray, qvel: np.ndarray) -> DynamicsTerms:
        """As :meth:`terms`, by the vectorised numpy implementation (reference of the compiled kernel)."""
        qpos = np.asarray(qpos, dtype=float)
        qvel = np.asarray(qvel, dtype=float)
        batch = qpos.shape[:-1]
        out = self._terms(qpos.reshape(-1, C.NQ), qvel.reshape(-1, C.NV))
        return DynamicsTerms(*(x.reshape(batch + x.shape[1:]) for x in out))

    def _terms_compiled(self, qpos: np.ndarray, qvel: np.ndarray) -> tuple[np.ndarray, ...]:
        """Same formulas as :meth:`_terms`, one state at a time in the compiled kernel."""
        N = qpos.shape[0]
        M, h, G = np.empty((N, C.NV, C.NV)), np.empty((N, C.NV)), np.empty((N, C.NV))
        J_feet, Jdd = np.empty((N, C.N_LEGS, 3, C.NV)), np.empty((N, C.N_LEGS, 3))
        explicit_terms(
            np.ascontiguousarray(qpos), np.ascontiguousarray(qvel), *self._kernel_params, M, h, G, J_feet, Jdd
        )
        return M, h, G, J_feet, Jdd

    def _leg_frames(self, q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, ...]:
        """Per state, leg and frame k = 1..3 (HAA, HFE, KFE), relative to the trunk, trunk frame: orientation
        Q (N, 4, 3, 3, 3), origin o, axis z, angular velocity w and acceleration alpha, origin velocity v and
        acceleration a at qacc = 0 (each (N, 4, 3, 3): frame, xyz)."""
        ch = self.chains
        N = q.shape[0]
        Q = np.broadcast_to(np.eye(3), (N, C.N_LEGS, 3, 3))
        o, w, al, v, a = (np.zeros((N, C.N_LEGS, 3)) for _ in range(5))
        frames = []
        for k in range(3):
            d = (Q @ ch.joint_pos[:, k, :, None])[..., 0]
            a = a + cross(al, d) + cross(w, cross(w, d))
            v = v + cross(w, d)
            o = o + d
            P = Q @ ch.joint_rot[:, k]
            z = (P @ ch.joint_axis[:, k, :, None])[..., 0]
            Q = P @ _rotations(ch.joint_axis[:, k], q[..., k])
            al = al + qd[..., k, None] * cross(w, z)
            w = w + qd[..., k, None] * z
            frames.append((Q, o, z, w, al, v, a))
        return tuple(np.stack(x, axis=2) for x in zip(*frames, strict=True))

    def _terms(self, qpos: np.ndarray, qvel: np.ndarray) -> tuple[np.ndarray, ...]:
        """All 17 points (trunk COM, per leg hip-link, thigh, shank COM and foot) in one stacked pass."""
        N = qpos.shape[0]
        R = quat_to_matrix(qpos[:, 3:7])  # (N, 3, 3) R_WB
        Rt = np.swapaxes(R, -1, -2)
        w = qvel[:, 3:6]  # (N, 3) base angular velocity, B frame
        WxT = np.zeros((N, 1, 3, 3))  # [w]x^T: v @ WxT = w x v
        WxT[:, 0, _SK_ROWS, _SK_COLS] = w[:, _SK_SRC] * _SK_SIGN
        qd = qvel[:, 6:].reshape(N, C.N_LEGS, 3)
        Q, o, z, wk, alk, vo, ao = self._leg_frames(qpos[:, 7:].reshape(N, C.N_LEGS, 3), qd)
        # the leg points (N, 4 legs, 4 pts, ...) on their links
        Qp, op, wp, alp = Q[:, :, _LINK], o[:, :, _LINK], wk[:, :, _LINK], alk[:, :, _LINK]
        e = (Qp @ self.pt_local[..., None])[..., 0]
        r = op + e
        rdot = vo[:, :, _LINK] + cross(wp, e)
        rdd = ao[:, :, _LINK] + cross(alp, e) + cross(wp, cross(wp, e))
        acc = rdd + cross(w[:, None, None, :], cross(w[:, None, None, :], r) + 2.0 * rdot)  # classical, B frame
        # leg columns: v rows z_j x (r - o_j), w rows z_j, for the joints j moving the point
        Jr = cross(z[:, :, None, :, :], r[:, :, :, None, :] - o[:, :, None, :, :]) * _MOVES[..., None]
        Jw = np.broadcast_to(z[:, :, None], Jr.shape) * _MOVES[..., None]  # (N, 4, 4 pts, 3 joints, xyz)
        w_link = w[:, None, None, :] + wp
        alpha = cross(w[:, None, None, :], wp) + alp
        I_B = Qp @ self.I_pts @ np.swapaxes(Qp, -1, -2)  # (N, 4, 4 pts, 3, 3)
        tau = (I_B @ alpha[..., None])[..., 0] + cross(w_link, (I_B @ w_link[..., None])[..., 0])

        # ---- stacked Jacobians of the 17 points, B frame: rows (v, w), 18 columns
        n_leg = C.N_LEGS * PTS_PER_LEG
        r_all = np.concatenate([np.broadcast_to(self.r_trunk_B, (N, 1, 3)), r.reshape(N, n_leg, 3)], 1)
        J = np.zeros((N, _N_PTS, 6, C.NV))
        J[:, :, 0:3, 0:3] = Rt[:, None]
        J[:, :, _SK_ROWS, 3 + _SK_COLS] = r_all[..., _SK_SRC] * _SK_SIGN  # -[r]x = [r]x^T
        J[:, :, 3:6, 3:6] = np.eye(3)
        J[:, _PT, _ROW3, _LEGCOL] = np.swapaxes(Jr, -1, -2).reshape(N, n_leg, 3, 3)
        J[:, _PT, 3 + _ROW3, _LEGCOL] = np.swapaxes(Jw, -1, -2).reshape(N, n_leg, 3, 3)
        D = self._D0.repeat(N, 0)
        D[:, 1:, 3:6, 3:6] = I_B.reshape(N, n_leg, 3, 3)
        Jf = J.reshape(N, 6 * _N_PTS, C.NV)
        M = np.swapaxes(Jf, -1, -2) @ (D @ J).reshape(N, 6 * _N_PTS, C.NV)
        M[:, self._armature_idx, self._armature_idx] += self.armature

        g_B = self.gravity_W @ R  # (N, 3) = R^T g
        acc_t = ((self.r_trunk_B @ WxT[:, 0])[:, None, :] @ WxT[:, 0])[:, 0]
        tau_t = ((w @ self.I_trunk_B.T)[:, None, :] @ WxT[:, 0])[:, 0]
        Wr = np.zeros((N, 2, _N_PTS, 6))
        Wr[:, 0, 0, 0:3] = acc_t
        Wr[:, 0, 1:, 0:3] = acc.reshape(N, n_leg, 3)
        Wr[:, 0, :, 0:3] -= g_B[:, None, :]
        Wr[:, 1, :, 0:3] = -g_B[:, None, :]
        Wr[..., 0:3] *= self._m_all[:, None]
        Wr[:, 0, 0, 3:6] = tau_t
        Wr[:, 0, 1:, 3:6] = tau.reshape(N, n_leg, 3)
        hG = Wr.reshape(N, 2, 6 * _N_PTS) @ Jf  # (N, 2, 18): h and G
        J_feet = R[:, None] @ J[:, _FEET, 0:3, :]
        Jdot_qdot = acc[:, :, 3] @ Rt
        return M, hG[:, 0], hG[:, 1], J_feet, Jdot_qdot
