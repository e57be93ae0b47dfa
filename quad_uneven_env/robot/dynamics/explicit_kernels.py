"""Compiled (numba) kernel of the explicit Lagrangian dynamics (:mod:`quad_uneven_env.robot.dynamics.explicit_backend`).

Separate from :mod:`quad_uneven_env.robot.dynamics.mujoco_kernels` so that only the users of the
"explicit" backend pay for its compilation (explicit signature, at import, cached on disk by
:func:`quad_uneven_env.jit.njit`).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from quad_uneven_env.jit import njit

NV = 18
N_LEGS = 4
PTS_PER_LEG = 4
"""Points per leg: the COMs of the hip link (HAA), thigh (HFE) and shank (KFE), then the foot."""

_f1 = nb.float64[:]
_f2 = nb.float64[:, :]
_f3 = nb.float64[:, :, :]
_f4 = nb.float64[:, :, :, :]
_i1 = nb.int64[:]


@njit(
    nb.void(_f2, _f2, _f3, _f4, _f3, _f3, _f1, _f3, _i1, _f2, _f1, _f1, _f1, _f3, _f2, _f2, _f4, _f3),
    nogil=True,
)
def explicit_terms(
    qpos, qvel, joint_pos, joint_rot, joint_axis, pt_local, m_all, I_pts, pt_on, I_trunk_B, r_trunk_B, gravity_W,
    armature, M, h, G, J_feet, Jdd,
):  # pragma: no cover - compiled  # fmt: skip
    """The explicit Lagrangian terms (the backend's formulas) of N states, one state at a time.

    ``qpos`` (N, 19), ``qvel`` (N, 18); per leg and joint ``joint_pos`` (4, 3, 3), ``joint_rot`` (4, 3, 3, 3),
    ``joint_axis`` (4, 3, 3) (the chains' placements); ``pt_local`` (4, 4, 3) each leg point in its link's
    frame (hip link, thigh, shank COM, then the foot in the shank frame); ``m_all`` (17,) trunk then the leg
    points; ``I_pts`` (16, 3, 3) the leg points' inertias about their COM in the link frame; ``pt_on`` (16,)
    1 where a leg point has mass or inertia (a massless hip link and the feet are skipped in M, h, G).
    ``armature`` (12,) is added to the joints' diagonal of M. Writes M (N, 18, 18), h, G (N, 18),
    J_feet (N, 4, 3, 18), Jdd (N, 4, 3).

    A point on link k has non-zero Jacobian columns only on the base and its leg's first k + 1 joints, so
    ``M = sum J^T D J`` runs over 7 to 9 columns per point, on the upper triangle (mirrored at the end).
    """
    R = np.empty((3, 3))
    Jp = np.zeros((6, NV))
    DJ = np.empty((6, 9))
    cols = np.empty(9, dtype=np.int64)
    wrh = np.empty(6)
    IB = np.empty((3, 3))
    tmp = np.empty((3, 3))
    P = np.empty((3, 3))
    # per leg frame f = 0 (trunk), 1 (HAA), 2 (HFE), 3 (KFE), trunk frame: orientation, origin, angular velocity
    # and acceleration relative to the trunk, origin velocity and acceleration relative to the trunk at qacc = 0
    Qf = np.empty((4, 3, 3))
    Of = np.empty((4, 3))
    Wf = np.empty((4, 3))
    Af = np.empty((4, 3))
    Vf = np.empty((4, 3))
    Aof = np.empty((4, 3))
    Zf = np.empty((3, 3))  # joint axes, trunk frame
    gB = np.empty(3)
    for i in range(6):
        cols[i] = i
    for a in range(3):
        Jp[3 + a, 3 + a] = 1.0
    for a in range(3):
        for e in range(3):
            Qf[0, a, e] = 1.0 if a == e else 0.0
        Of[0, a] = Wf[0, a] = Af[0, a] = Vf[0, a] = Aof[0, a] = 0.0
    for n in range(qpos.shape[0]):
        qw, qx, qy, qz = qpos[n, 3], qpos[n, 4], qpos[n, 5], qpos[n, 6]
        s = 1.0 / (qw * qw + qx * qx + qy * qy + qz * qz)
        R[0, 0] = (qw * qw + qx * qx - qy * qy - qz * qz) * s
        R[1, 1] = (qw * qw - qx * qx + qy * qy - qz * qz) * s
        R[2, 2] = (qw * qw - qx * qx - qy * qy + qz * qz) * s
        R[0, 1] = 2.0 * (qx * qy - qw * qz) * s
        R[1, 0] = 2.0 * (qx * qy + qw * qz) * s
        R[0, 2] = 2.0 * (qx * qz + qw * qy) * s
        R[2, 0] = 2.0 * (qx * qz - qw * qy) * s
        R[1, 2] = 2.0 * (qy * qz - qw * qx) * s
        R[2, 1] = 2.0 * (qy * qz + qw * qx) * s
        w0, w1, w2 = qvel[n, 3], qvel[n, 4], qvel[n, 5]
        for a in range(3):
            gB[a] = R[0, a] * gravity_W[0] + R[1, a] * gravity_W[1] + R[2, a] * gravity_W[2]
            for e in range(3):
                Jp[a, e] = R[e, a]  # base translation columns of every point: R^T
        for i in range(NV):
            h[n, i] = 0.0
            G[n, i] = 0.0
            for j in range(NV):
                M[n, i, j] = 0.0
        for pt in range(1 + N_LEGS * PTS_PER_LEG):
            if pt == 0:  # the trunk's COM
                r0, r1, r2 = r_trunk_B[0], r_trunk_B[1], r_trunk_B[2]
                x0, x1, x2 = w1 * r2 - w2 * r1, w2 * r0 - w0 * r2, w0 * r1 - w1 * r0
                ac0, ac1, ac2 = w1 * x2 - w2 * x1, w2 * x0 - w0 * x2, w0 * x1 - w1 * x0  # w x (w x r)
                Jp[0, 3], Jp[0, 4], Jp[0, 5] = 0.0, r2, -r1
                Jp[1, 3], Jp[1, 4], Jp[1, 5] = -r2, 0.0, r0
                Jp[2, 3], Jp[2, 4], Jp[2, 5] = r1, -r0, 0.0
                for a in range(3):
                    for e in range(3):
                        IB[a, e] = I_trunk_B[a, e]
                wl0, wl1, wl2 = w0, w1, w2
                al0, al1, al2 = 0.0, 0.0, 0.0
                ncol = 6
            else:
                leg = (pt - 1) // PTS_PER_LEG
                p = (pt - 1) % PTS_PER_LEG
                c = 6 + 3 * leg
                if p == 0:  # ---- the leg's frames, base to KFE (relative to the trunk, trunk frame)
                    for k in range(3):
                        qk, dk = qpos[n, 7 + 3 * leg + k], qvel[n, c + k]
                        Qp, pk, Rk, ak = Qf[k], joint_pos[leg, k], joint_rot[leg, k], joint_axis[leg, k]
                        for a in range(3):
                            for e in range(3):
                                P[a, e] = Qp[a, 0] * Rk[0, e] + Qp[a, 1] * Rk[1, e] + Qp[a, 2] * Rk[2, e]
                        d0 = Qp[0, 0] * pk[0] + Qp[0, 1] * pk[1] + Qp[0, 2] * pk[2]
                        d1 = Qp[1, 0] * pk[0] + Qp[1, 1] * pk[1] + Qp[1, 2] * pk[2]
                        d2 = Qp[2, 0] * pk[0] + Qp[2, 1] * pk[1] + Qp[2, 2] * pk[2]
                        o0, o1, o2 = Wf[k, 0], Wf[k, 1], Wf[k, 2]
                        x0, x1, x2 = o1 * d2 - o2 * d1, o2 * d0 - o0 * d2, o0 * d1 - o1 * d0  # w x d
                        Of[k + 1, 0], Of[k + 1, 1], Of[k + 1, 2] = Of[k, 0] + d0, Of[k, 1] + d1, Of[k, 2] + d2
                        Vf[k + 1, 0], Vf[k + 1, 1], Vf[k + 1, 2] = Vf[k, 0] + x0, Vf[k, 1] + x1, Vf[k, 2] + x2
                        b0, b1, b2 = Af[k, 0], Af[k, 1], Af[k, 2]
                        Aof[k + 1, 0] = Aof[k, 0] + b1 * d2 - b2 * d1 + o1 * x2 - o2 * x1
                        Aof[k + 1, 1] = Aof[k, 1] + b2 * d0 - b0 * d2 + o2 * x0 - o0 * x2
                        Aof[k + 1, 2] = Aof[k, 2] + b0 * d1 - b1 * d0 + o0 * x1 - o1 * x0
                        z0 = P[0, 0] * ak[0] + P[0, 1] * ak[1] + P[0, 2] * ak[2]
                        z1 = P[1, 0] * ak[0] + P[1, 1] * ak[1] + P[1, 2] * ak[2]
                        z2 = P[2, 0] * ak[0] + P[2, 1] * ak[1] + P[2, 2] * ak[2]
                        Zf[k, 0], Zf[k, 1], Zf[k, 2] = z0, z1, z2
                        # Q_(k+1) = P Rot(a, q) = cos P + sin [z x P columns] + (1 - cos) z a^T
                        sq, cq = math.sin(qk), math.cos(qk)
                        vq = 1.0 - cq
                        Qn = Qf[k + 1]
                        for e in range(3):
                            p0, p1, p2 = P[0, e], P[1, e], P[2, e]
                            Qn[0, e] = cq * p0 + sq * (z1 * p2 - z2 * p1) + vq * z0 * ak[e]
                            Qn[1, e] = cq * p1 + sq * (z2 * p0 - z0 * p2) + vq * z1 * ak[e]
                            Qn[2, e] = cq * p2 + sq * (z0 * p1 - z1 * p0) + vq * z2 * ak[e]
                        Af[k + 1, 0] = b0 + dk * (o1 * z2 - o2 * z1)
                        Af[k + 1, 1] = b1 + dk * (o2 * z0 - o0 * z2)
                        Af[k + 1, 2] = b2 + dk * (o0 * z1 - o1 * z0)
                        Wf[k + 1, 0], Wf[k + 1, 1], Wf[k + 1, 2] = o0 + dk * z0, o1 + dk * z1, o2 + dk * z2
                k = p if p < 3 else 2  # the link carrying the point
                if p < 3 and pt_on[PTS_PER_LEG * leg + p] == 0:
                    continue
                f = k + 1
                Qk, lp = Qf[f], pt_local[leg, p]
                e0 = Qk[0, 0] * lp[0] + Qk[0, 1] * lp[1] + Qk[0, 2] * lp[2]
                e1 = Qk[1, 0] * lp[0] + Qk[1, 1] * lp[1] + Qk[1, 2] * lp[2]
                e2 = Qk[2, 0] * lp[0] + Qk[2, 1] * lp[1] + Qk[2, 2] * lp[2]
                r0, r1, r2 = Of[f, 0] + e0, Of[f, 1] + e1, Of[f, 2] + e2
                o0, o1, o2 = Wf[f, 0], Wf[f, 1], Wf[f, 2]
                x0, x1, x2 = o1 * e2 - o2 * e1, o2 * e0 - o0 * e2, o0 * e1 - o1 * e0  # w_k x e
                rd0, rd1, rd2 = Vf[f, 0] + x0, Vf[f, 1] + x1, Vf[f, 2] + x2
                b0, b1, b2 = Af[f, 0], Af[f, 1], Af[f, 2]
                # acceleration relative to the trunk at qacc = 0, then acc = rdd + w x (w x r + 2 rdot)
                rdd0 = Aof[f, 0] + b1 * e2 - b2 * e1 + o1 * x2 - o2 * x1
                rdd1 = Aof[f, 1] + b2 * e0 - b0 * e2 + o2 * x0 - o0 * x2
                rdd2 = Aof[f, 2] + b0 * e1 - b1 * e0 + o0 * x1 - o1 * x0
                x0 = w1 * r2 - w2 * r1 + 2.0 * rd0
                x1 = w2 * r0 - w0 * r2 + 2.0 * rd1
                x2 = w0 * r1 - w1 * r0 + 2.0 * rd2
                ac0 = rdd0 + w1 * x2 - w2 * x1
                ac1 = rdd1 + w2 * x0 - w0 * x2
                ac2 = rdd2 + w0 * x1 - w1 * x0
                # leg columns: v rows z_j x (r - o_j), w rows z_j, for the joints j <= k moving the point
                for m_ in range(k + 1):
                    za, za1, za2 = Zf[m_, 0], Zf[m_, 1], Zf[m_, 2]
                    t0, t1, t2 = r0 - Of[m_ + 1, 0], r1 - Of[m_ + 1, 1], r2 - Of[m_ + 1, 2]
                    Jp[0, c + m_] = za1 * t2 - za2 * t1
                    Jp[1, c + m_] = za2 * t0 - za * t2
                    Jp[2, c + m_] = za * t1 - za1 * t0
                    Jp[3, c + m_], Jp[4, c + m_], Jp[5, c + m_] = za, za1, za2
                    cols[6 + m_] = c + m_
                ncol = 7 + k
                # base rotation columns: v rows -[r]x (w rows: I, set once)
                Jp[0, 3], Jp[0, 4], Jp[0, 5] = 0.0, r2, -r1
                Jp[1, 3], Jp[1, 4], Jp[1, 5] = -r2, 0.0, r0
                Jp[2, 3], Jp[2, 4], Jp[2, 5] = r1, -r0, 0.0
                if p == 3:  # foot: world-frame Jacobian R J_v and classical acceleration R acc
                    for a in range(3):
                        for j in range(NV):
                            J_feet[n, leg, a, j] = 0.0
                        for jj in range(ncol):
                            j = cols[jj]
                            J_feet[n, leg, a, j] = R[a, 0] * Jp[0, j] + R[a, 1] * Jp[1, j] + R[a, 2] * Jp[2, j]
                        Jdd[n, leg, a] = R[a, 0] * ac0 + R[a, 1] * ac1 + R[a, 2] * ac2
                    continue
                # the link's absolute angular velocity and acceleration (trunk frame), inertia I_B = Q I Q^T
                wl0, wl1, wl2 = w0 + o0, w1 + o1, w2 + o2
                al0 = w1 * o2 - w2 * o1 + b0
                al1 = w2 * o0 - w0 * o2 + b1
                al2 = w0 * o1 - w1 * o0 + b2
                Ip = I_pts[PTS_PER_LEG * leg + p]
                for a in range(3):
                    for e in range(3):
                        tmp[a, e] = Qk[a, 0] * Ip[0, e] + Qk[a, 1] * Ip[1, e] + Qk[a, 2] * Ip[2, e]
                for a in range(3):
                    for e in range(a, 3):
                        IB[a, e] = tmp[a, 0] * Qk[e, 0] + tmp[a, 1] * Qk[e, 1] + tmp[a, 2] * Qk[e, 2]
                        IB[e, a] = IB[a, e]
            mass = m_all[pt]
            # wrenches: h row [m (acc - g_B); I alpha + w_l x I w_l], G row [-m g_B; 0]
            Iw0 = IB[0, 0] * wl0 + IB[0, 1] * wl1 + IB[0, 2] * wl2
            Iw1 = IB[1, 0] * wl0 + IB[1, 1] * wl1 + IB[1, 2] * wl2
            Iw2 = IB[2, 0] * wl0 + IB[2, 1] * wl1 + IB[2, 2] * wl2
            wrh[0], wrh[1], wrh[2] = mass * (ac0 - gB[0]), mass * (ac1 - gB[1]), mass * (ac2 - gB[2])
            wrh[3] = IB[0, 0] * al0 + IB[0, 1] * al1 + IB[0, 2] * al2 + wl1 * Iw2 - wl2 * Iw1
            wrh[4] = IB[1, 0] * al0 + IB[1, 1] * al1 + IB[1, 2] * al2 + wl2 * Iw0 - wl0 * Iw2
            wrh[5] = IB[2, 0] * al0 + IB[2, 1] * al1 + IB[2, 2] * al2 + wl0 * Iw1 - wl1 * Iw0
            g0, g1, g2 = -mass * gB[0], -mass * gB[1], -mass * gB[2]
            # D J on the non-zero columns, then M += J^T D J (upper triangle), h += J^T wrh, G += J^T [-m g_B; 0]
            for jj in range(ncol):
                j = cols[jj]
                for a in range(3):
                    DJ[a, jj] = mass * Jp[a, j]
                    DJ[3 + a, jj] = IB[a, 0] * Jp[3, j] + IB[a, 1] * Jp[4, j] + IB[a, 2] * Jp[5, j]
            for ii in range(ncol):
                i = cols[ii]
                sh = 0.0
                for a in range(6):
                    sh += Jp[a, i] * wrh[a]
                h[n, i] += sh
                G[n, i] += Jp[0, i] * g0 + Jp[1, i] * g1 + Jp[2, i] * g2
                for jj in range(ii, ncol):
                    sm = 0.0
                    for a in range(6):
                        sm += Jp[a, i] * DJ[a, jj]
                    M[n, i, cols[jj]] += sm
        for i in range(NV):
            for j in range(i + 1, NV):
                M[n, j, i] = M[n, i, j]
        for i in range(NV - 6):
            M[n, 6 + i, 6 + i] += armature[i]
