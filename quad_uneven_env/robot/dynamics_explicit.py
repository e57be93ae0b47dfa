"""The paper's explicit (Lagrangian) dynamics, Appendix A eq. 35-39, in vectorised numpy.

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
Every function accepts a leading batch axis.
"""

from __future__ import annotations

import mujoco
import numpy as np

from quad_uneven_env import constants as C
from quad_uneven_env.robot.dynamics import DynamicsTerms

_TOL = 1e-12
_AXES = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 1.0, 0.0))  # HAA, HFE, KFE


def _skew(r: np.ndarray) -> np.ndarray:
    """[r]x for r (..., 3) -> (..., 3, 3)."""
    z = np.zeros(r.shape[:-1])
    x, y, w = r[..., 0], r[..., 1], r[..., 2]
    return np.stack([np.stack([z, -w, y], -1), np.stack([w, z, -x], -1), np.stack([-y, x, z], -1)], -2)


def _quat_to_R(quat: np.ndarray) -> np.ndarray:
    """R_WB (..., 3, 3) of quaternions (..., 4) (w, x, y, z), normalised here."""
    q = quat / np.linalg.norm(quat, axis=-1, keepdims=True)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


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
        self._knee_in_link = np.array([0.0, 1.0])

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
        out = self._terms(qpos.reshape(-1, C.NQ), qvel.reshape(-1, C.NV))
        return DynamicsTerms(*(x.reshape(batch + x.shape[1:]) for x in out))

    def _terms(self, qpos: np.ndarray, qvel: np.ndarray) -> tuple[np.ndarray, ...]:
        N = qpos.shape[0]
        R = _quat_to_R(qpos[:, 3:7])  # (N, 3, 3) R_WB
        w = qvel[:, 3:6]  # (N, 3) base angular velocity, B frame
        q = qpos[:, 7:].reshape(N, 4, 3)
        qd = qvel[:, 6:].reshape(N, 4, 3)
        q1, q2, q23 = q[..., 0:1], q[..., 1:2], q[..., 1:2] + q[..., 2:3]  # (N, 4, 1)
        d1, d2, d23 = qd[..., 0:1], qd[..., 1:2], qd[..., 1:2] + qd[..., 2:3]
        s1, c1, s2, c2, s23, c23 = np.sin(q1), np.cos(q1), np.sin(q2), np.cos(q2), np.sin(q23), np.cos(q23)
        a, b = self.a_pts, self.b_pts  # (3,) broadcast over the three leg points
        u = -a * s2 - b * s23  # (N, 4, 3)
        s = -a * c2 - b * c23
        ub, sb = -b * s23, -b * c23
        zero = np.zeros_like(u)
        c1b, s1b = np.broadcast_to(c1, u.shape), np.broadcast_to(s1, u.shape)
        # positions of the points relative to the base origin, B frame: (N, 4, 3pts, 3)
        r = self.hips_B[None, :, None, :] + np.stack([u, -s1 * s, c1 * s], -1)
        # dr/dq_leg: (N, 4, 3pts, 3xyz, 3joints)
        Jr = np.stack(
            [
                np.stack([zero, -c1 * s, -s1 * s], -1),
                np.stack([s, s1 * u, -c1 * u], -1),
                np.stack([sb, s1b * ub, -c1b * ub], -1),
            ],
            -1,
        )
        rdot = np.einsum("nlpij,nlj->nlpi", Jr, qd)
        # r_ddot at q_ddot = 0: R_x(q1) [w_ddx, -2 q1d w_dz, w_ddz - q1d^2 s]
        wdz = a * d2 * s2 + b * d23 * s23
        wddx = a * d2 * d2 * s2 + b * d23 * d23 * s23
        wddz = a * d2 * d2 * c2 + b * d23 * d23 * c23
        y_, z_ = -2.0 * d1 * wdz, wddz - d1 * d1 * s
        rddot0 = np.stack([wddx, c1 * y_ - s1 * z_, s1 * y_ + c1 * z_], -1)
        wB = w[:, None, None, :]
        acc_B = np.cross(wB, np.cross(wB, r)) + 2.0 * np.cross(wB, rdot) + rddot0  # (N, 4, 3, 3)

        # ---- link angular quantities (thigh, shank), B frame
        kin = self._knee_in_link  # (2,)
        ex = np.broadcast_to(np.array([1.0, 0.0, 0.0]), (N, 4, 3))
        ay = np.concatenate([np.zeros_like(c1), c1, s1], -1)  # (N, 4, 3) HFE/KFE axis in B
        # Jw_rel: (N, 4, 2links, 3, 3joints)
        Jw_rel = np.stack(
            [
                np.broadcast_to(ex[:, :, None, :], (N, 4, 2, 3)),
                np.broadcast_to(ay[:, :, None, :], (N, 4, 2, 3)),
                ay[:, :, None, :] * kin[None, None, :, None],
            ],
            -1,
        )
        w_rel = np.einsum("nlkij,nlj->nlki", Jw_rel, qd)
        ex_x_ay = np.concatenate([np.zeros_like(c1), -s1, c1], -1)  # (N, 4, 3)
        wdot_rel0 = (d1 * (d2 + kin * qd[..., 2:3]))[..., None] * ex_x_ay[:, :, None, :]  # (N, 4, 2, 3)
        w_link = wB[:, :, :, :] + w_rel  # (N, 4, 2, 3)
        alpha = np.cross(wB, w_rel) + wdot_rel0
        # link rotations R_Bl = R_x(q1) R_y(theta), theta = q2 (thigh) or q2 + q3 (shank)
        th = q2 + kin * q[..., 2:3]  # (N, 4, 2)
        st, ct = np.sin(th), np.cos(th)
        s1l, c1l = np.broadcast_to(s1, th.shape), np.broadcast_to(c1, th.shape)
        zl = np.zeros_like(th)
        R_Bl = np.stack(
            [
                np.stack([ct, zl, st], -1),
                np.stack([s1l * st, c1l, -s1l * ct], -1),
                np.stack([-c1l * st, s1l, c1l * ct], -1),
            ],
            -2,
        )
        I_B = np.einsum("nlkij,lkjm,nlkpm->nlkip", R_Bl, self.I_links, R_Bl)  # (N, 4, 2, 3, 3)

        # ---- full Jacobians of the 9 links (trunk + 8), B frame, 18 columns
        Rt = np.swapaxes(R, -1, -2)
        Jv = np.zeros((N, 9, 3, C.NV))
        Jw = np.zeros((N, 9, 3, C.NV))
        Jv[:, :, :, 0:3] = Rt[:, None]
        Jv[:, 0, :, 3:6] = -_skew(np.broadcast_to(self.r_trunk_B, (N, 3)))
        r_links = r[:, :, :2]  # (N, 4, 2, 3)
        Jv[:, 1:, :, 3:6] = -_skew(r_links).reshape(N, 8, 3, 3)
        Jw[:, :, :, 3:6] = np.eye(3)
        for i in range(4):
            cols = slice(6 + 3 * i, 9 + 3 * i)
            Jv[:, 1 + 2 * i : 3 + 2 * i, :, cols] = Jr[:, i, :2]
            Jw[:, 1 + 2 * i : 3 + 2 * i, :, cols] = Jw_rel[:, i]
        m = np.concatenate([[self.m_trunk], self.m_links.reshape(-1)])  # (9,)
        I_all = np.concatenate([np.broadcast_to(self.I_trunk_B, (N, 1, 3, 3)), I_B.reshape(N, 8, 3, 3)], 1)
        M = np.einsum("l,nlip,nliq->npq", m, Jv, Jv) + np.einsum("nlip,nlij,nljq->npq", Jw, I_all, Jw)

        # ---- bias: linear accelerations at qacc = 0 and Euler torques
        acc_t = np.cross(w, np.cross(w, self.r_trunk_B))  # (N, 3)
        acc_all = np.concatenate([acc_t[:, None], acc_B[:, :, :2].reshape(N, 8, 3)], 1)  # (N, 9, 3)
        w_all = np.concatenate([w[:, None], w_link.reshape(N, 8, 3)], 1)
        alpha_all = np.concatenate([np.zeros((N, 1, 3)), alpha.reshape(N, 8, 3)], 1)
        Iw = np.einsum("nlij,nlj->nli", I_all, w_all)
        torque = np.einsum("nlij,nlj->nli", I_all, alpha_all) + np.cross(w_all, Iw)
        g_B = np.einsum("nji,j->ni", R, self.gravity_W)  # R^T g
        force = m[None, :, None] * (acc_all - g_B[:, None, :])
        h = np.einsum("nlip,nli->np", Jv, force) + np.einsum("nlip,nli->np", Jw, torque)
        G = -np.einsum("nlip,nli->np", Jv, m[None, :, None] * np.broadcast_to(g_B[:, None, :], (N, 9, 3)))

        # ---- feet: world-frame Jacobians and classical accelerations at qacc = 0
        r_f = r[:, :, 2]  # (N, 4, 3)
        Jf_B = np.zeros((N, 4, 3, C.NV))
        Jf_B[:, :, :, 3:6] = -_skew(r_f)
        for i in range(4):
            Jf_B[:, i, :, 6 + 3 * i : 9 + 3 * i] = Jr[:, i, 2]
        J_feet = np.einsum("nij,nljq->nliq", R, Jf_B)
        J_feet[:, :, :, 0:3] = np.eye(3)
        Jdot_qdot = np.einsum("nij,nlj->nli", R, acc_B[:, :, 2])
        return M, h, G, J_feet, Jdot_qdot
