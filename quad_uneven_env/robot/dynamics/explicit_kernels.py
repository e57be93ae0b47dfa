"""Compiled (numba) kernel of the explicit Lagrangian dynamics (:mod:`quad_uneven_env.robot.dynamics.explicit_backend`).

Separate from :mod:`quad_uneven_env.robot.dynamics.mujoco_kernels` so that only the users of the
"explicit" backend pay for its compilation (explicit signature, at import, no on-disk cache).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from quad_uneven_env.jit import njit

NV = 18

_f1 = nb.float64[:]
_f2 = nb.float64[:, :]
_f3 = nb.float64[:, :, :]


@njit(
    nb.void(_f2, _f2, _f2, _f1, _f1, _f1, _f3, _f2, _f1, _f1, _f3, _f2, _f2, nb.float64[:, :, :, :], _f3),
    nogil=True,
)
def explicit_terms(
    qpos, qvel, hips_B, a_pts, b_pts, m_all, I_pts, I_trunk_B, r_trunk_B, gravity_W, M, h, G, J_feet, Jdd
):  # pragma: no cover - compiled
    """The explicit Lagrangian terms (``dynamics_explicit``'s formulas) of N states, one state at a time.

    ``qpos`` (N, 19), ``qvel`` (N, 18); ``I_pts`` (12, 3, 3) leg-point inertias about their COM in
    the link frame (zero for the feet); ``m_all`` (13,) trunk then leg points. Writes M (N, 18, 18),
    h, G (N, 18), J_feet (N, 4, 3, 18), Jdd (N, 4, 3). Per point the B-frame Jacobian has non-zero
    columns only on the base and its leg, so ``M = sum J^T D J`` runs over 9 columns per point.
    """
    R = np.empty((3, 3))
    Jp = np.zeros((6, NV))
    DJ = np.empty((6, 9))
    cols = np.empty(9, dtype=np.int64)
    wrh = np.empty(6)
    wrg = np.empty(6)
    IB = np.empty((3, 3))
    RB = np.empty((3, 3))
    tmp = np.empty((3, 3))
    for i in range(6):
        cols[i] = i
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
        gB = np.empty(3)
        for a in range(3):
            gB[a] = R[0, a] * gravity_W[0] + R[1, a] * gravity_W[1] + R[2, a] * gravity_W[2]
        for i in range(NV):
            h[n, i] = 0.0
            G[n, i] = 0.0
            for j in range(NV):
                M[n, i, j] = 0.0
        for pt in range(13):
            leg = (pt - 1) // 3
            k = (pt - 1) % 3
            # ---- point position r, leg Jacobian columns, acceleration at qacc = 0 (B frame)
            for a in range(6):
                for j in range(NV):
                    Jp[a, j] = 0.0
            if pt == 0:
                r0, r1, r2 = r_trunk_B[0], r_trunk_B[1], r_trunk_B[2]
                x0, x1, x2 = w1 * r2 - w2 * r1, w2 * r0 - w0 * r2, w0 * r1 - w1 * r0
                ac0, ac1, ac2 = w1 * x2 - w2 * x1, w2 * x0 - w0 * x2, w0 * x1 - w1 * x0  # w x (w x r)
                for a in range(3):
                    for e in range(3):
                        IB[a, e] = I_trunk_B[a, e]
                wl0, wl1, wl2 = w0, w1, w2
                al0, al1, al2 = 0.0, 0.0, 0.0
                ncol = 6
            else:
                c = 6 + 3 * leg
                q1, q2, q3 = qpos[n, 7 + 3 * leg], qpos[n, 8 + 3 * leg], qpos[n, 9 + 3 * leg]
                d1, d2, d3 = qvel[n, c], qvel[n, c + 1], qvel[n, c + 2]
                q23, d23 = q2 + q3, d2 + d3
                s1, c1 = math.sin(q1), math.cos(q1)
                s2, c2 = math.sin(q2), math.cos(q2)
                s23, c23 = math.sin(q23), math.cos(q23)
                A_, B_ = a_pts[k], b_pts[k]
                u = -(s2 * A_ + s23 * B_)
                sv = -(c2 * A_ + c23 * B_)
                ub, sb = -B_ * s23, -B_ * c23
                hp = (u, 0.0, sv)
                hq1 = (0.0, -sv, 0.0)
                hq2 = (sv, 0.0, -u)
                hq3 = (sb, 0.0, -ub)
                dd2, dd23 = d2 * d2, d23 * d23
                ha = (
                    s2 * dd2 * A_ + s23 * dd23 * B_,
                    (-2.0 * d1) * (s2 * d2 * A_ + s23 * d23 * B_),
                    c2 * dd2 * A_ + c23 * dd23 * B_ - (d1 * d1) * sv,
                )
                # Rx(q1) applied to the H-frame columns: (x, y, z) -> (x, c1 y - s1 z, s1 y + c1 z)
                pr0, pr1, pr2 = hp[0], c1 * hp[1] - s1 * hp[2], s1 * hp[1] + c1 * hp[2]
                r0, r1, r2 = pr0 + hips_B[leg, 0], pr1 + hips_B[leg, 1], pr2 + hips_B[leg, 2]
                for m_, hc in enumerate((hq1, hq2, hq3)):
                    Jp[0, c + m_] = hc[0]
                    Jp[1, c + m_] = c1 * hc[1] - s1 * hc[2]
                    Jp[2, c + m_] = s1 * hc[1] + c1 * hc[2]
                b0, b1, b2 = ha[0], c1 * ha[1] - s1 * ha[2], s1 * ha[1] + c1 * ha[2]
                rd0 = Jp[0, c] * d1 + Jp[0, c + 1] * d2 + Jp[0, c + 2] * d3
                rd1 = Jp[1, c] * d1 + Jp[1, c + 1] * d2 + Jp[1, c + 2] * d3
                rd2 = Jp[2, c] * d1 + Jp[2, c + 1] * d2 + Jp[2, c + 2] * d3
                # acc = b + w x (w x r + 2 rdot)
                x0 = w1 * r2 - w2 * r1 + 2.0 * rd0
                x1 = w2 * r0 - w0 * r2 + 2.0 * rd1
                x2 = w0 * r1 - w1 * r0 + 2.0 * rd2
                ac0 = b0 + w1 * x2 - w2 * x1
                ac1 = b1 + w2 * x0 - w0 * x2
                ac2 = b2 + w0 * x1 - w1 * x0
                # angular velocity Jacobian: e_x, a_y, (shank/foot) a_y; a_y = Rx e_y, e_perp = Rx e_z
                ay0, ay1, ay2 = 0.0, c1, s1
                ep0, ep1, ep2 = 0.0, -s1, c1
                Jp[3, c] = 1.0
                Jp[3, c + 1], Jp[4, c + 1], Jp[5, c + 1] = ay0, ay1, ay2
                if k > 0:
                    Jp[3, c + 2], Jp[4, c + 2], Jp[5, c + 2] = ay0, ay1, ay2
                th, thd = (q2, d2) if k == 0 else (q23, d23)
                wr0, wr1, wr2 = thd * ay0 + d1, thd * ay1, thd * ay2
                wl0, wl1, wl2 = wr0 + w0, wr1 + w1, wr2 + w2
                al0 = w1 * wr2 - w2 * wr1 + d1 * thd * ep0
                al1 = w2 * wr0 - w0 * wr2 + d1 * thd * ep1
                al2 = w0 * wr1 - w1 * wr0 + d1 * thd * ep2
                # I_B = (Rx Ry) I (Rx Ry)^T
                st, ct = math.sin(th), math.cos(th)
                RB[0, 0], RB[0, 1], RB[0, 2] = ct, 0.0, st
                RB[1, 0], RB[1, 1], RB[1, 2] = s1 * st, c1, -s1 * ct
                RB[2, 0], RB[2, 1], RB[2, 2] = -c1 * st, s1, c1 * ct
                Ip = I_pts[3 * leg + k]
                for a in range(3):
                    for e in range(3):
                        tmp[a, e] = RB[a, 0] * Ip[0, e] + RB[a, 1] * Ip[1, e] + RB[a, 2] * Ip[2, e]
                for a in range(3):
                    for e in range(3):
                        IB[a, e] = tmp[a, 0] * RB[e, 0] + tmp[a, 1] * RB[e, 1] + tmp[a, 2] * RB[e, 2]
                for m_ in range(3):
                    cols[6 + m_] = c + m_
                ncol = 9
            # base columns: v rows [R^T, -[r]x], w rows [0, I]
            for a in range(3):
                for e in range(3):
                    Jp[a, e] = R[e, a]
                Jp[3 + a, 3 + a] = 1.0
            Jp[0, 4], Jp[0, 5] = r2, -r1
            Jp[1, 3], Jp[1, 5] = -r2, r0
            Jp[2, 3], Jp[2, 4] = r1, -r0
            mass = m_all[pt]
            # wrenches: h row [m (acc - g_B); I alpha + w_l x I w_l], G row [-m g_B; 0]
            Iw0 = IB[0, 0] * wl0 + IB[0, 1] * wl1 + IB[0, 2] * wl2
            Iw1 = IB[1, 0] * wl0 + IB[1, 1] * wl1 + IB[1, 2] * wl2
            Iw2 = IB[2, 0] * wl0 + IB[2, 1] * wl1 + IB[2, 2] * wl2
            wrh[0], wrh[1], wrh[2] = mass * (ac0 - gB[0]), mass * (ac1 - gB[1]), mass * (ac2 - gB[2])
            wrh[3] = IB[0, 0] * al0 + IB[0, 1] * al1 + IB[0, 2] * al2 + wl1 * Iw2 - wl2 * Iw1
            wrh[4] = IB[1, 0] * al0 + IB[1, 1] * al1 + IB[1, 2] * al2 + wl2 * Iw0 - wl0 * Iw2
            wrh[5] = IB[2, 0] * al0 + IB[2, 1] * al1 + IB[2, 2] * al2 + wl0 * Iw1 - wl1 * Iw0
            wrg[0], wrg[1], wrg[2] = -mass * gB[0], -mass * gB[1], -mass * gB[2]
            wrg[3], wrg[4], wrg[5] = 0.0, 0.0, 0.0
            # D J on the non-zero columns, then M += J^T D J, h += J^T wrh, G += J^T wrg
            for jj in range(ncol):
                j = cols[jj]
                for a in range(3):
                    DJ[a, jj] = mass * Jp[a, j]
                    DJ[3 + a, jj] = IB[a, 0] * Jp[3, j] + IB[a, 1] * Jp[4, j] + IB[a, 2] * Jp[5, j]
            for ii in range(ncol):
                i = cols[ii]
                sh, sg = 0.0, 0.0
                for a in range(6):
                    sh += Jp[a, i] * wrh[a]
                    sg += Jp[a, i] * wrg[a]
                h[n, i] += sh
                G[n, i] += sg
                for jj in range(ncol):
                    sm = 0.0
                    for a in range(6):
                        sm += Jp[a, i] * DJ[a, jj]
                    M[n, i, cols[jj]] += sm
            if pt > 0 and k == 2:  # foot: world-frame Jacobian R J_v and classical acceleration R acc
                for a in range(3):
                    for j in range(NV):
                        J_feet[n, leg, a, j] = R[a, 0] * Jp[0, j] + R[a, 1] * Jp[1, j] + R[a, 2] * Jp[2, j]
                    Jdd[n, leg, a] = R[a, 0] * ac0 + R[a, 1] * ac1 + R[a, 2] * ac2
