"""Compiled (numba) kernel behind ``MujocoDynamics.terms_from_data``: M, G, foot J and Jdot qdot.

The dynamics terms are read from what MuJoCo's position and velocity stages (``mj_step1``,
``mj_forward``) left in ``MjData``, in one compiled call instead of ~15 MuJoCo/numpy calls:

- ``M``: MuJoCo's own mass matrix, expanded from its CSR lower triangle ``data.M``
  (``M_rowadr``, ``M_rownnz``, ``M_colind``), exactly what ``mj_fullM`` returns;
- foot Jacobians (world frame): column ``e_k`` for the base translation (MuJoCo's free joint
  moves the body origin in the world frame), ``R e_k x (p - o)`` for the base-frame rotation
  and ``a_j x (p - x_j)`` for a hinge of world axis ``a_j`` (``data.xaxis``) through
  ``x_j`` (``data.xanchor``), the same columns ``mj_jacSite`` builds from ``cdof``;
- ``Jdot qdot`` (the foot's classical acceleration at ``qacc = 0``, world frame): the time
  derivative of ``J qvel`` at constant ``qvel``:
  ``w x (v_p - v_o) + sum_j qd_j [(w_(j-1) x a_j) x (p - x_j) + a_j x (v_p - v_(x_j))]`` with
  ``w`` the trunk's world angular velocity, ``w_(j-1)`` that of the frame carrying hinge j's
  axis and ``v_(x_j)`` the velocity of its anchor (the base rotation term has no derivative
  part because ``d/dt (R w_B) = R (w_B x w_B) = 0`` at constant ``w_B``);
- ``G`` (gradient of the potential energy): ``-m_sub (g . column)`` evaluated at the subtree
  centres of mass ``data.subtree_com`` of the trunk and of each hinge's body, the same as
  ``-m_total g^T J_com`` of ``mj_jacSubtreeCom``.

The kernel is compiled when this module is imported (explicit signatures, no on-disk cache:
nothing is written inside the package); the one-off cost is about a second.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

N_LEGS = 4
NV = 18

_f1 = nb.float64[:]
_f2 = nb.float64[:, :]
_f3 = nb.float64[:, :, :]
_i1 = nb.int64[:]

# idx layout: [trunk body, 4 foot sites, 12 hinge joint ids, 12 hinge dof addresses, 12 hinge bodies]
IDX_TRUNK, IDX_SITES, IDX_JNT, IDX_DOF, IDX_BODY, IDX_LEN = 0, 1, 5, 17, 29, 41
# par layout: [total mass, gravity (3), 12 subtree masses of the hinge bodies]
PAR_MASS, PAR_G, PAR_MSUB, PAR_LEN = 0, 1, 4, 16


@nb.njit(nb.void(_f1, _i1, _i1, _i1, _f2), cache=False, nogil=True)
def expand_csr_lower(M_csr, rowadr, rownnz, colind, M):  # pragma: no cover - compiled
    """Full symmetric M (nv, nv) from MuJoCo's CSR lower triangle (``data.M``)."""
    n = M.shape[0]
    for i in range(n):
        for j in range(n):
            M[i, j] = 0.0
    for i in range(n):
        a = rowadr[i]
        for k in range(rownnz[i]):
            j = colind[a + k]
            v = M_csr[a + k]
            M[i, j] = v
            M[j, i] = v


@nb.njit(
    nb.void(_f1, _f1, _i1, _i1, _i1, _f2, _f2, _f2, _f2, _f2, _f2, _i1, _f1, _f2, _f3, _f2, _f1),
    cache=False,
    nogil=True,
)
def mujoco_terms(
    qvel, M_csr, rowadr, rownnz, colind, xpos, xmat, xanchor, xaxis, site_xpos, subtree_com, idx, par, M, J, Jdd, G
):  # pragma: no cover - compiled
    """Write M (18, 18), J (4, 3, 18), Jdot qdot (4, 3) and G (18,) from MjData arrays (see module doc)."""
    expand_csr_lower(M_csr, rowadr, rownnz, colind, M)
    tr = idx[IDX_TRUNK]
    o = xpos[tr]
    R = xmat[tr]  # row-major 3 x 3, R_WB
    w = np.empty(3)
    for i in range(3):
        w[i] = R[3 * i] * qvel[3] + R[3 * i + 1] * qvel[4] + R[3 * i + 2] * qvel[5]
    g0, g1, g2 = par[PAR_G], par[PAR_G + 1], par[PAR_G + 2]
    mt = par[PAR_MASS]
    # gravity on the base: translation, then rotation about R e_k at the whole-robot COM
    for i in range(NV):
        G[i] = 0.0
    G[0], G[1], G[2] = -mt * g0, -mt * g1, -mt * g2
    c = subtree_com[tr]
    d0, d1, d2 = c[0] - o[0], c[1] - o[1], c[2] - o[2]
    for k in range(3):
        e0, e1, e2 = R[k], R[3 + k], R[6 + k]
        G[3 + k] = -mt * (g0 * (e1 * d2 - e2 * d1) + g1 * (e2 * d0 - e0 * d2) + g2 * (e0 * d1 - e1 * d0))
    vp = np.empty(3)
    vx = np.empty(3)
    om = np.empty(3)
    acc = np.empty(3)
    for leg in range(N_LEGS):
        p = site_xpos[idx[IDX_SITES + leg]]
        Jl = J[leg]
        for i in range(3):
            for j in range(NV):
                Jl[i, j] = 0.0
            Jl[i, i] = 1.0
        d0, d1, d2 = p[0] - o[0], p[1] - o[1], p[2] - o[2]
        for k in range(3):
            e0, e1, e2 = R[k], R[3 + k], R[6 + k]
            Jl[0, 3 + k] = e1 * d2 - e2 * d1
            Jl[1, 3 + k] = e2 * d0 - e0 * d2
            Jl[2, 3 + k] = e0 * d1 - e1 * d0
        for k in range(3):
            jn, dof = idx[IDX_JNT + 3 * leg + k], idx[IDX_DOF + 3 * leg + k]
            a, x = xaxis[jn], xanchor[jn]
            r0, r1, r2 = p[0] - x[0], p[1] - x[1], p[2] - x[2]
            Jl[0, dof] = a[1] * r2 - a[2] * r1
            Jl[1, dof] = a[2] * r0 - a[0] * r2
            Jl[2, dof] = a[0] * r1 - a[1] * r0
            # gravity on the hinge: its body's subtree mass at the subtree COM
            b = idx[IDX_BODY + 3 * leg + k]
            cb = subtree_com[b]
            s0, s1, s2 = cb[0] - x[0], cb[1] - x[1], cb[2] - x[2]
            G[dof] = -par[PAR_MSUB + 3 * leg + k] * (
                g0 * (a[1] * s2 - a[2] * s1) + g1 * (a[2] * s0 - a[0] * s2) + g2 * (a[0] * s1 - a[1] * s0)
            )
        # foot velocity v_p = J qvel (only the base and this leg's columns are non-zero)
        for i in range(3):
            s = 0.0
            for j in range(6):
                s += Jl[i, j] * qvel[j]
            for k in range(3):
                dof = idx[IDX_DOF + 3 * leg + k]
                s += Jl[i, dof] * qvel[dof]
            vp[i] = s
        # classical acceleration at qacc = 0
        u0, u1, u2 = vp[0] - qvel[0], vp[1] - qvel[1], vp[2] - qvel[2]
        acc[0] = w[1] * u2 - w[2] * u1
        acc[1] = w[2] * u0 - w[0] * u2
        acc[2] = w[0] * u1 - w[1] * u0
        om[0], om[1], om[2] = w[0], w[1], w[2]
        for k in range(3):
            jn, dof = idx[IDX_JNT + 3 * leg + k], idx[IDX_DOF + 3 * leg + k]
            a, x = xaxis[jn], xanchor[jn]
            qd = qvel[dof]
            # velocity of the anchor x_j, carried by the frame before hinge j
            r0, r1, r2 = x[0] - o[0], x[1] - o[1], x[2] - o[2]
            vx[0] = qvel[0] + w[1] * r2 - w[2] * r1
            vx[1] = qvel[1] + w[2] * r0 - w[0] * r2
            vx[2] = qvel[2] + w[0] * r1 - w[1] * r0
            for i in range(k):
                ji, di = idx[IDX_JNT + 3 * leg + i], idx[IDX_DOF + 3 * leg + i]
                ai, xi = xaxis[ji], xanchor[ji]
                qi = qvel[di]
                t0, t1, t2 = x[0] - xi[0], x[1] - xi[1], x[2] - xi[2]
                vx[0] += qi * (ai[1] * t2 - ai[2] * t1)
                vx[1] += qi * (ai[2] * t0 - ai[0] * t2)
                vx[2] += qi * (ai[0] * t1 - ai[1] * t0)
            # a_dot = om x a; term (a_dot x (p - x) + a x (v_p - v_x)) qd
            ad0 = om[1] * a[2] - om[2] * a[1]
            ad1 = om[2] * a[0] - om[0] * a[2]
            ad2 = om[0] * a[1] - om[1] * a[0]
            r0, r1, r2 = p[0] - x[0], p[1] - x[1], p[2] - x[2]
            u0, u1, u2 = vp[0] - vx[0], vp[1] - vx[1], vp[2] - vx[2]
            acc[0] += qd * (ad1 * r2 - ad2 * r1 + a[1] * u2 - a[2] * u1)
            acc[1] += qd * (ad2 * r0 - ad0 * r2 + a[2] * u0 - a[0] * u2)
            acc[2] += qd * (ad0 * r1 - ad1 * r0 + a[0] * u1 - a[1] * u0)
            om[0] += qd * a[0]
            om[1] += qd * a[1]
            om[2] += qd * a[2]
        Jdd[leg, 0], Jdd[leg, 1], Jdd[leg, 2] = acc[0], acc[1], acc[2]


@nb.njit(
    nb.void(_f2, _f2, _f2, _f1, _f1, _f1, _f3, _f2, _f1, _f1, _f3, _f2, _f2, nb.float64[:, :, :, :], _f3),
    cache=False,
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
