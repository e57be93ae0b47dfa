"""The paper's explicit (Lagrangian) dynamics, Appendix A eq. 35-39 (compiled kernel; numpy reference).

For every link l (trunk, 4 thighs, 4 shanks) with mass m_l, inertia I_l about its COM,
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

Each leg point (thigh COM, shank COM, foot) sits at ``hip + R_x(q1) [u, 0, s]`` with
``u = -a sin q2 - b sin(q2 + q3)``, ``s = -a cos q2 - b cos(q2 + q3)``; ``(a, b)`` is
``(lc1, 0)``, ``(l1, lc2)`` and ``(l1, l2)`` for the three points. Positions, Jacobians and
their time derivatives are closed-form in (q1, q2, q3); no symbolic engine, no simulator call.

Implementation: the 13 points (trunk COM, 4 x (thigh COM, shank COM, foot)) are processed in
one stacked pass; their B-frame Jacobians form J (13 x 6 x 18, rows v then w) and, with
D = blockdiag(m I, I_B) per point, ``M = J^T D J``, ``h = J^T [m (a0 - g_B); I alpha0 + w x I w]``
and ``G = J^T [-m g_B; 0]`` are three matrix products. The feet (zero mass) reuse the same J.
Every array carries a leading batch axis, so many states are evaluated in one call.
``terms`` runs the same formulas one state at a time in a compiled kernel
(:mod:`quad_uneven_env.robot.dynamics.explicit_kernels`); ``terms_numpy`` is the vectorised
numpy version it is tested against.
"""

from __future__ import annotations

import mujoco
import numpy as np

from quad_uneven_env import constants as C
from quad_uneven_env.robot.dynamics.base import DynamicsTerms
from quad_uneven_env.robot.dynamics.explicit_kernels import explicit_terms
from quad_uneven_env.spatial import cross, quat_to_matrix

_TOL = 1e-12
_AXES = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 1.0, 0.0))  # HAA, HFE, KFE


_IDX1, _IDX2 = np.array([1, 2, 0]), np.array([2, 0, 1])
_BD_ROWS = (6 + 3 * np.arange(4)[:, None, None] + np.arange(3)[None, :, None]) * np.ones((1, 1, 3), dtype=int)
_BD_COLS = np.swapaxes(_BD_ROWS, 1, 2)
_LEG = np.arange(4)[:, None]
_LEG_COLS = 6 + 3 * np.arange(4)[:, None] + np.arange(3)[None, :]


_SK_ROWS, _SK_COLS = np.array([0, 0, 1, 1, 2, 2]), np.array([1, 2, 0, 2, 0, 1])
_SK_SRC, _SK_SIGN = np.array([2, 1, 2, 0, 1, 0]), np.array([1.0, -1.0, -1.0, 1.0, 1.0, -1.0])  # [w]x^T = -[w]x
_RX_ROWS, _RX_COLS = np.array([1, 1, 2, 2]), np.array([1, 2, 1, 2])
_RY_ROWS, _RY_COLS = np.array([0, 0, 2, 2]), np.array([0, 2, 0, 2])
_TH = np.array([1, 2, 2])  # angle index of each point's link pitch: q2 (thigh), q2 + q3 (shank, foot)
_PT = (1 + np.arange(12))[:, None, None]  # point index of leg point (leg, pt) = 1 + 3 leg + pt
_ROW3 = np.arange(3)[None, :, None]
_LEGCOL = (6 + 3 * (np.arange(12) // 3))[:, None, None] + np.arange(3)[None, None, :]
_FEET = 1 + 3 * np.arange(4) + 2


def _check_axis(model: mujoco.MjModel, name: str, axis: tuple[float, float, float]) -> int:
    j = model.joint(name).id
    if not np.allclose(model.jnt_axis[j], axis, atol=_TOL) or not np.allclose(model.jnt_pos[j], 0.0, atol=_TOL):
        raise ValueError(f"joint {name}: explicit dynamics needs axis {axis} through the body origin")
    return int(model.jnt_dofadr[j])


def _along_minus_z(vec: np.ndarray, what: str) -> float:
    if not np.allclose(vec[:2], 0.0, atol=_TOL) or vec[2] > 0:
        raise ValueError(f"{what} must lie on the link's -z axis, got {vec}")
    return float(-vec[2])


class ExplicitDynamics:
    """Explicit Lagrangian dynamics of the HAA-HFE-KFE quadruped; parameters read from an MjModel.

    Only the model's parameters are read (masses, inertias, body offsets, gravity); the
    computation itself is pure numpy. The model must have the project's robot structure
    (free trunk, per leg HAA about x and HFE about y at the hip, KFE about y below, links along -z).
    """

    backend = "explicit"

    def __init__(self, model: mujoco.MjModel) -> None:
        if model.nv != C.NV or model.nq != C.NQ:
            raise ValueError(f"model must have nq={C.NQ}, nv={C.NV} (robot only), got nq={model.nq}, nv={model.nv}")
        trunk = model.body(C.TRUNK_BODY).id
        self.gravity_W = model.opt.gravity.copy()
        self.m_trunk = float(model.body_mass[trunk])
        self.r_trunk_B = model.body_ipos[trunk].copy()
        self.I_trunk_B = self._inertia(model, trunk)
        hips, a_pts, b_pts, masses, inertias = [], None, None, [], []
        for i, leg in enumerate(C.LEG_NAMES):
            dofs = [_check_axis(model, C.joint_name(leg, k), ax) for k, ax in zip(C.JOINT_KINDS, _AXES, strict=True)]
            if dofs != list(range(6 + 3 * i, 9 + 3 * i)):
                raise ValueError(f"leg {leg}: joint dofs must be {list(range(6 + 3 * i, 9 + 3 * i))}, got {dofs}")
            th, sh = model.body(C.thigh_body(leg)).id, model.body(C.shank_body(leg)).id
            for b in (th, sh):
                if not np.allclose(model.body_quat[b], [1, 0, 0, 0], atol=_TOL):
                    raise ValueError(f"body {model.body(b).name} must not be rotated in its parent")
            hips.append(model.body_pos[th].copy())
            l1 = _along_minus_z(model.body_pos[sh], f"{leg} shank body position")
            lc1 = _along_minus_z(model.body_ipos[th], f"{leg} thigh COM")
            lc2 = _along_minus_z(model.body_ipos[sh], f"{leg} shank COM")
            site = model.site(C.foot_site(leg)).id
            if model.site_bodyid[site] != sh:
                raise ValueError(f"site {C.foot_site(leg)} must belong to body {C.shank_body(leg)}")
            l2 = _along_minus_z(model.site_pos[site], f"{leg} foot site")
            a, b = np.array([lc1, l1, l1]), np.array([0.0, lc2, l2])
            if a_pts is None:
                a_pts, b_pts = a, b
            elif not (np.allclose(a, a_pts) and np.allclose(b, b_pts)):
                raise ValueError("explicit dynamics needs identical leg geometry on the four legs")
            masses.append([model.body_mass[th], model.body_mass[sh]])
            inertias.append([self._inertia(model, th), self._inertia(model, sh)])
        self.hips_B = np.array(hips)  # (4, 3)
        self.a_pts, self.b_pts = a_pts, b_pts  # (3,) per point: thigh COM, shank COM, foot
        self.m_links = np.array(masses)  # (4, 2)
        self.I_links = np.array(inertias)  # (4, 2, 3, 3) about the COM, link frame
        self.total_mass = self.m_trunk + float(self.m_links.sum())
        # link -> which of q2+q3 rotates it: thigh only q2, shank q2 + q3.
        self._AB = np.stack([a_pts, b_pts])  # (2, 3): coefficients of sin/cos(q2) and of q2 + q3
        self.I_pts = np.concatenate([self.I_links, np.zeros((4, 1, 3, 3))], 1)  # feet: no inertia
        self._m_all = np.concatenate([[self.m_trunk], np.concatenate([self.m_links, np.zeros((4, 1))], 1).ravel()])
        D0 = np.zeros((1, 13, 6, 6))
        D0[0, :, 0:3, 0:3] = self._m_all[:, None, None] * np.eye(3)
        D0[0, 0, 3:6, 3:6] = self.I_trunk_B
        self._D0 = D0
        # Motor rotor inertia (MJCF ``armature``): a constant added to the joint diagonal of M.
        self._armature_idx = np.arange(6, C.NV)
        self.armature = model.dof_armature[6:].copy()
        self._kernel_params = tuple(
            np.ascontiguousarray(x, dtype=float)
            for x in (self.hips_B, a_pts, b_pts, self._m_all, self.I_pts.reshape(12, 3, 3), self.I_trunk_B,
                      self.r_trunk_B, self.gravity_W)
        )  # fmt: skip

    @staticmethod
    def _inertia(model: mujoco.MjModel, body: int) -> np.ndarray:
        R = np.empty(9)
        mujoco.mju_quat2Mat(R, model.body_iquat[body])
        R = R.reshape(3, 3)
        return R @ np.diag(model.body_inertia[body]) @ R.T

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
        M[:, self._armature_idx, self._armature_idx] += self.armature
        return M, h, G, J_feet, Jdd

    def _terms(self, qpos: np.ndarray, qvel: np.ndarray) -> tuple[np.ndarray, ...]:
        """All 13 points (trunk COM, per leg thigh COM, shank COM, foot) in one stacked pass."""
        N = qpos.shape[0]
        R = quat_to_matrix(qpos[:, 3:7])  # (N, 3, 3) R_WB
        Rt = np.swapaxes(R, -1, -2)
        w = qvel[:, 3:6]  # (N, 3) base angular velocity, B frame
        WxT = np.zeros((N, 1, 3, 3))  # [w]x^T: v @ WxT = w x v
        WxT[:, 0, _SK_ROWS, _SK_COLS] = w[:, _SK_SRC] * _SK_SIGN
        ang = qpos[:, 7:].reshape(N, 4, 3).copy()
        ang[..., 2] += ang[..., 1]  # q1, q2, q2 + q3
        dang = qvel[:, 6:].reshape(N, 4, 3).copy()
        dang[..., 2] += dang[..., 1]
        sn, cs = np.sin(ang), np.cos(ang)
        s1, c1 = sn[..., 0:1], cs[..., 0:1]
        d1 = dang[..., 0:1]
        dsq = dang[..., 1:] * dang[..., 1:]
        # point kinematics in the HAA-rotated frame H, per leg and point (thigh COM, shank COM, foot)
        u = -(sn[..., 1:] @ self._AB)  # (N, 4, 3pts)
        s = -(cs[..., 1:] @ self._AB)
        ub, sb = -self.b_pts * sn[..., 2:3], -self.b_pts * cs[..., 2:3]
        H = np.zeros((N, 4, 3, 3, 5))  # columns: position, dp/dq1, dp/dq2, dp/dq3, acceleration at qacc = 0
        H[..., 0, 0], H[..., 2, 0], H[..., 1, 1] = u, s, -s
        H[..., 0, 2], H[..., 2, 2], H[..., 0, 3], H[..., 2, 3] = s, -u, sb, -ub
        H[..., 0, 4] = (sn[..., 1:] * dsq) @ self._AB
        H[..., 1, 4] = (-2.0 * d1) * ((sn[..., 1:] * dang[..., 1:]) @ self._AB)
        H[..., 2, 4] = (cs[..., 1:] * dsq) @ self._AB - (d1 * d1) * s
        Rx = np.zeros((N, 4, 3, 3))
        Rx[..., 0, 0] = 1.0
        Rx[..., _RX_ROWS, _RX_COLS] = np.concatenate([c1, -s1, s1, c1], -1)
        Bp = Rx[:, :, None] @ H  # (N, 4, 3pts, 3, 5), B frame
        r = Bp[..., 0] + self.hips_B[None, :, None, :]
        Jr = Bp[..., 1:4]
        rdot = (Jr @ qvel[:, 6:].reshape(N, 4, 1, 3, 1))[..., 0]
        acc = Bp[..., 4] + (r @ WxT + 2.0 * rdot) @ WxT  # classical acceleration, B frame
        # angular velocity Jacobians: columns e_x, a_y, k a_y (k = 0 thigh, 1 shank/foot)
        ay, eperp = Rx[..., 1], Rx[..., 2]  # (N, 4, 3) HFE/KFE axis and e_x x a_y
        Jw = np.zeros((N, 4, 3, 3, 3))
        Jw[..., 0, 0] = 1.0
        Jw[..., 1] = ay[:, :, None, :]
        Jw[:, :, 1:, :, 2] = ay[:, :, None, :]
        thd = dang[..., _TH]  # (N, 4, 3pts) link pitch rate
        w_rel = thd[..., None] * ay[:, :, None, :]
        w_rel[..., 0] += d1
        w_link = w_rel + w[:, None, None, :]
        alpha = w_rel @ WxT + (d1 * thd)[..., None] * eperp[:, :, None, :]
        Ry = np.zeros((N, 4, 3, 3, 3))
        Ry[..., 1, 1] = 1.0
        st, ct = sn[..., _TH], cs[..., _TH]
        Ry[..., _RY_ROWS, _RY_COLS] = np.stack([ct, st, -st, ct], -1)
        R_Bl = Rx[:, :, None] @ Ry
        I_B = R_Bl @ self.I_pts @ np.swapaxes(R_Bl, -1, -2)  # (N, 4, 3pts, 3, 3)
        tau = (I_B @ alpha[..., None])[..., 0] + cross(w_link, (I_B @ w_link[..., None])[..., 0])

        # ---- stacked Jacobians of the 13 points, B frame: rows (v, w), 18 columns
        r_all = np.concatenate([np.broadcast_to(self.r_trunk_B, (N, 1, 3)), r.reshape(N, 12, 3)], 1)
        J = np.zeros((N, 13, 6, C.NV))
        J[:, :, 0:3, 0:3] = Rt[:, None]
        J[:, :, _SK_ROWS, 3 + _SK_COLS] = r_all[..., _SK_SRC] * _SK_SIGN  # -[r]x = [r]x^T
        J[:, :, 3:6, 3:6] = np.eye(3)
        J[:, _PT, _ROW3, _LEGCOL] = Jr.reshape(N, 12, 3, 3)
        J[:, _PT, 3 + _ROW3, _LEGCOL] = Jw.reshape(N, 12, 3, 3)
        D = self._D0.repeat(N, 0)
        D[:, 1:, 3:6, 3:6] = I_B.reshape(N, 12, 3, 3)
        Jf = J.reshape(N, 78, C.NV)
        M = np.swapaxes(Jf, -1, -2) @ (D @ J).reshape(N, 78, C.NV)
        M[:, self._armature_idx, self._armature_idx] += self.armature

        g_B = self.gravity_W @ R  # (N, 3) = R^T g
        acc_t = ((self.r_trunk_B @ WxT[:, 0])[:, None, :] @ WxT[:, 0])[:, 0]
        tau_t = ((w @ self.I_trunk_B.T)[:, None, :] @ WxT[:, 0])[:, 0]
        Wr = np.zeros((N, 2, 13, 6))
        Wr[:, 0, 0, 0:3] = acc_t
        Wr[:, 0, 1:, 0:3] = acc.reshape(N, 12, 3)
        Wr[:, 0, :, 0:3] -= g_B[:, None, :]
        Wr[:, 1, :, 0:3] = -g_B[:, None, :]
        Wr[..., 0:3] *= self._m_all[:, None]
        Wr[:, 0, 0, 3:6] = tau_t
        Wr[:, 0, 1:, 3:6] = tau.reshape(N, 12, 3)
        hG = Wr.reshape(N, 2, 78) @ Jf  # (N, 2, 18): h and G
        J_feet = R[:, None] @ J[:, _FEET, 0:3, :]
        Jdot_qdot = acc[:, :, 2] @ Rt
        return M, hG[:, 0], hG[:, 1], J_feet, Jdot_qdot
