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

import numba as nb
import numpy as np

from quad_uneven_env.jit import njit

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


@njit(nb.void(_f1, _i1, _i1, _i1, _f2), nogil=True)
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


@njit(
    nb.void(_f1, _f1, _i1, _i1, _i1, _f2, _f2, _f2, _f2, _f2, _f2, _i1, _f1, _f2, _f3, _f2, _f1),
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
