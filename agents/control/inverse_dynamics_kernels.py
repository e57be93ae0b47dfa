"""Compiled (numba) kernels of the controller's hot path: pinv inverse dynamics, PD command, contacts.

Same mathematics as the numpy code in :mod:`agents.control.elimination` and
:mod:`agents.control.inverse_dynamics`, written on the block structure instead of assembled matrices:

- leg Jacobian inverses in closed form (adjugate / determinant), damped least squares
  ``(J^T J + lambda^2 I)^-1 J^T`` for a leg whose inverse has an entry above ``1 / SINGULAR_SIGMA``
  (all stance legs when a determinant is exactly zero, as ``np.linalg.inv`` then raises);
- ``qacc``: base = ``beta_ddot[:6]``, swing joints = their ``beta_ddot`` entries, stance leg i
  ``-J_L,i^-1 (J_b,i beta_ddot[:6] + Jdot qdot_i)`` (= ``S beta_ddot + Sdot beta_dot``);
- ``r = M qacc + h``; swing torques ``r_swing``; with ``A = [S_i^T]_i`` (``S_i = -J_L,i^-1 J_b,i``)
  the stance torques ``A^T (A A^T)^-1 (r_base + A r_stance)`` with ``A A^T = sum_i S_i^T S_i``
  (6 x 6, Cholesky): the Moore-Penrose solution when A has full row rank (3 or 4 stance feet);
- contact forces ``F_i = J_L,i^-T (r_i - tau_i)``.

One or two stance feet (A rank deficient: the pseudo-inverse needs an SVD) and a failed
Cholesky are left to the numpy path (status 0).

Kernels are compiled at import with explicit signatures (no on-disk cache).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from quad_uneven_env.jit import njit
from quad_uneven_env.spatial_kernels import inv3_into

N_LEGS = 4
NV = 18

_f1 = nb.float64[:]
_f2 = nb.float64[:, :]
_f3 = nb.float64[:, :, :]

DONE, DAMPED, EXACT = 1, 2, 4
"""status bits of :func:`id_pinv` (0: not handled, use the numpy path)."""


@njit(nb.int64(_f2, _f1, _f3, _f2, nb.int64, _f1, nb.float64, nb.float64, _f1, _f2, _f1, _f1, _f3, _f3),
         nogil=True)  # fmt: skip
def id_pinv(M, h, J, Jdd, mask, bdd, inv_sigma, damping, tau, F, qacc, r, Jinv, S):  # pragma: no cover - compiled
    """Pinv inverse dynamics (module doc) for the stance bitmask ``mask`` (bit i: leg i in stance).

    Writes tau (12,), F (4, 3), qacc (18,), r = M qacc + h (18,), Jinv (4, 3, 3) and
    S (4, 3, 6) = -J_L^-1 J_b (stance legs only). Returns status bits DONE | DAMPED | EXACT,
    0 when the numpy path must be used (1 or 2 stance feet, A A^T not positive definite),
    -1 when ``bdd`` does not have 18 - 3p entries.
    """
    if M.shape[0] != NV or M.shape[1] != NV or h.shape[0] != NV or J.shape[0] != N_LEGS or J.shape[1] != 3:
        return 0
    if J.shape[2] != NV or Jdd.shape[0] != N_LEGS or Jdd.shape[1] != 3:
        return 0
    p = 0
    for i in range(N_LEGS):
        p += (mask >> i) & 1
    if bdd.shape[0] != NV - 3 * p:
        return -1
    if p == 1 or p == 2:
        return 0
    for i in range(12):
        tau[i] = 0.0
    for i in range(N_LEGS):
        for k in range(3):
            F[i, k] = 0.0
    for i in range(6):
        qacc[i] = bdd[i]
    n = 6
    for leg in range(N_LEGS):
        if not (mask >> leg) & 1:
            for k in range(3):
                qacc[6 + 3 * leg + k] = bdd[n]
                n += 1
    # leg Jacobian inverses, damped near a singularity
    JL = np.empty((3, 3))
    zero_det = False
    bad = np.zeros(N_LEGS, dtype=np.bool_)
    for leg in range(N_LEGS):
        if (mask >> leg) & 1:
            c = 6 + 3 * leg
            for a in range(3):
                for b in range(3):
                    JL[a, b] = J[leg, a, c + b]
            if inv3_into(JL, Jinv[leg]):
                big = 0.0
                for a in range(3):
                    for b in range(3):
                        big = max(big, abs(Jinv[leg, a, b]))
                bad[leg] = big > inv_sigma
            else:
                zero_det = True
    damped = False
    H = np.empty((3, 3))
    Hi = np.empty((3, 3))
    for leg in range(N_LEGS):
        if (mask >> leg) & 1 and (bad[leg] or zero_det):
            damped = True
            c = 6 + 3 * leg
            for a in range(3):
                for b in range(3):
                    JL[a, b] = J[leg, a, c + b]
            for a in range(3):
                for b in range(3):
                    s = 0.0
                    for k in range(3):
                        s += JL[k, a] * JL[k, b]
                    H[a, b] = s + (damping * damping if a == b else 0.0)
            inv3_into(H, Hi)  # positive definite: det > 0
            for a in range(3):
                for b in range(3):
                    s = 0.0
                    for k in range(3):
                        s += Hi[a, k] * JL[b, k]
                    Jinv[leg, a, b] = s
    # stance rows of S and of qacc
    for leg in range(N_LEGS):
        if (mask >> leg) & 1:
            for a in range(3):
                for c in range(6):
                    s = 0.0
                    for k in range(3):
                        s -= Jinv[leg, a, k] * J[leg, k, c]
                    S[leg, a, c] = s
            for a in range(3):
                s = 0.0
                for c in range(6):
                    s += S[leg, a, c] * bdd[c]
                for k in range(3):
                    s -= Jinv[leg, a, k] * Jdd[leg, k]
                qacc[6 + 3 * leg + a] = s
    # r = M qacc + h
    for i in range(NV):
        s = h[i]
        for j in range(NV):
            s += M[i, j] * qacc[j]
        r[i] = s
    for leg in range(N_LEGS):
        if not (mask >> leg) & 1:
            for k in range(3):
                tau[3 * leg + k] = r[6 + 3 * leg + k]
    if p == 0:
        big_b, big = 0.0, 1.0
        for i in range(NV):
            big = max(big, abs(r[i]))
            if i < 6:
                big_b = max(big_b, abs(r[i]))
        return DONE | (EXACT if big_b < 1e-9 * big else 0)
    # stance torques: A^T (A A^T)^-1 (r_base + A r_stance), A = [S_i^T]_i
    rhs = np.empty(6)
    AAt = np.zeros((6, 6))
    for c in range(6):
        rhs[c] = r[c]
    for leg in range(N_LEGS):
        if (mask >> leg) & 1:
            for c in range(6):
                s = 0.0
                for a in range(3):
                    s += S[leg, a, c] * r[6 + 3 * leg + a]
                rhs[c] += s
                for e in range(c + 1):
                    s = 0.0
                    for a in range(3):
                        s += S[leg, a, c] * S[leg, a, e]
                    AAt[c, e] += s
    # Cholesky A A^T = L L^T (lower triangle in place), then y = (L L^T)^-1 rhs
    for c in range(6):
        s = AAt[c, c]
        for k in range(c):
            s -= AAt[c, k] * AAt[c, k]
        if not s > 0.0:
            return 0
        d = math.sqrt(s)
        AAt[c, c] = d
        for e in range(c + 1, 6):
            s = AAt[e, c]
            for k in range(c):
                s -= AAt[e, k] * AAt[c, k]
            AAt[e, c] = s / d
    for c in range(6):
        s = rhs[c]
        for k in range(c):
            s -= AAt[c, k] * rhs[k]
        rhs[c] = s / AAt[c, c]
    for c in range(5, -1, -1):
        s = rhs[c]
        for k in range(c + 1, 6):
            s -= AAt[k, c] * rhs[k]
        rhs[c] = s / AAt[c, c]
    res = np.empty(3)
    for leg in range(N_LEGS):
        if (mask >> leg) & 1:
            for a in range(3):
                s = 0.0
                for c in range(6):
                    s += S[leg, a, c] * rhs[c]
                tau[3 * leg + a] = s
                res[a] = r[6 + 3 * leg + a] - s
            for a in range(3):  # F = J_L^-T (r - tau)
                s = 0.0
                for k in range(3):
                    s += Jinv[leg, k, a] * res[k]
                F[leg, a] = s
    return DONE | EXACT | (DAMPED if damped else 0)


@njit(nb.int64(_f1, _f1, _f1, _f1, _f1, _f1, _f1, _f1, _f1, _f1, _f1, _f1, nb.int64, _f1), nogil=True)
def beta_command(qpos, qvel, p, quat, v, w, a, dw, qj, qdj, qddj, gains, mask, out):  # pragma: no cover - compiled
    """PD command beta_ddot (see ``ComputedTorqueController.beta_ddot_command``) into ``out[:n_beta]``.

    ``gains`` = (kp_pos, kd_pos, kp_rot, kd_rot, kp_joint, kd_joint). The orientation error is
    MuJoCo's ``mju_subQuat(q_ref, q)`` and ``R_rel = quat2Mat(q^-1 q_ref)``, reproduced here.
    Returns n_beta, or -k when input k has the wrong length (reference fields 1: p, 2: quat,
    3: v, 4: w, 5: a, 6: dw, 7: q, 8: qd, 9: qdd; 10: qpos, 11: qvel).
    """
    if qpos.shape[0] != 19:
        return -10
    if qvel.shape[0] != NV:
        return -11
    if p.shape[0] != 3:
        return -1
    if quat.shape[0] != 4:
        return -2
    if v.shape[0] != 3:
        return -3
    if w.shape[0] != 3:
        return -4
    if a.shape[0] != 3:
        return -5
    if dw.shape[0] != 3:
        return -6
    if qj.shape[0] != 12:
        return -7
    if qdj.shape[0] != 12:
        return -8
    if qddj.shape[0] != 12:
        return -9
    kp, kd, kpr, kdr, kpj, kdj = gains[0], gains[1], gains[2], gains[3], gains[4], gains[5]
    for i in range(3):
        out[i] = a[i] + kd * (v[i] - qvel[i]) + kp * (p[i] - qpos[i])
    # q_rel = conj(q) * q_ref (Hamilton product, as mju_negQuat + mju_mulQuat)
    q0, q1, q2, q3 = qpos[3], -qpos[4], -qpos[5], -qpos[6]
    r0, r1, r2, r3 = quat[0], quat[1], quat[2], quat[3]
    w0 = q0 * r0 - q1 * r1 - q2 * r2 - q3 * r3
    w1 = q0 * r1 + q1 * r0 + q2 * r3 - q3 * r2
    w2 = q0 * r2 - q1 * r3 + q2 * r0 + q3 * r1
    w3 = q0 * r3 + q1 * r2 - q2 * r1 + q3 * r0
    # rotation vector (mju_quat2Vel with dt = 1)
    nrm = math.sqrt(w1 * w1 + w2 * w2 + w3 * w3)
    if nrm < 1e-15:
        e0, e1, e2 = 1.0, 0.0, 0.0
    else:
        e0, e1, e2 = w1 / nrm, w2 / nrm, w3 / nrm
    ang = 2.0 * math.atan2(nrm, w0)
    if ang > math.pi:
        ang -= 2.0 * math.pi
    e0, e1, e2 = e0 * ang, e1 * ang, e2 * ang
    # R_rel (mju_quat2Mat, not normalised)
    if w0 == 1.0 and w1 == 0.0 and w2 == 0.0 and w3 == 0.0:
        R = np.eye(3)
    else:
        R = np.empty((3, 3))
        R[0, 0] = w0 * w0 + w1 * w1 - w2 * w2 - w3 * w3
        R[1, 1] = w0 * w0 - w1 * w1 + w2 * w2 - w3 * w3
        R[2, 2] = w0 * w0 - w1 * w1 - w2 * w2 + w3 * w3
        R[0, 1] = 2.0 * (w1 * w2 - w0 * w3)
        R[0, 2] = 2.0 * (w1 * w3 + w0 * w2)
        R[1, 0] = 2.0 * (w1 * w2 + w0 * w3)
        R[1, 2] = 2.0 * (w2 * w3 - w0 * w1)
        R[2, 0] = 2.0 * (w1 * w3 - w0 * w2)
        R[2, 1] = 2.0 * (w2 * w3 + w0 * w1)
    f0, f1, f2 = dw[0] + kdr * w[0], dw[1] + kdr * w[1], dw[2] + kdr * w[2]
    out[3] = (R[0, 0] * f0 + R[0, 1] * f1 + R[0, 2] * f2) - kdr * qvel[3] + kpr * e0
    out[4] = (R[1, 0] * f0 + R[1, 1] * f1 + R[1, 2] * f2) - kdr * qvel[4] + kpr * e1
    out[5] = (R[2, 0] * f0 + R[2, 1] * f1 + R[2, 2] * f2) - kdr * qvel[5] + kpr * e2
    n = 6
    for leg in range(N_LEGS):
        if not (mask >> leg) & 1:
            for k in range(3):
                j = 3 * leg + k
                out[n] = qddj[j] + kdj * (qdj[j] - qvel[6 + j]) + kpj * (qj[j] - qpos[7 + j])
                n += 1
    return n


@njit(nb.int64(nb.int32[:, :], nb.int64[:], nb.int64), nogil=True)
def foot_contact_mask(geom, foot_of_geom, terrain_geom):  # pragma: no cover - compiled
    """Bitmask (bit i: foot i) of the contacts ``geom`` (ncon, 2) between a foot geom and the terrain geom."""
    out = 0
    n_legs = N_LEGS
    for c in range(geom.shape[0]):
        g0, g1 = geom[c, 0], geom[c, 1]
        if g0 == terrain_geom:
            leg = foot_of_geom[g1]
        elif g1 == terrain_geom:
            leg = foot_of_geom[g0]
        else:
            continue
        if leg < n_legs:
            out |= 1 << leg
    return out


@njit(nb.void(_f1, _f1, _f1), nogil=True)
def clip_into(x, limit, out):  # pragma: no cover - compiled
    """out = clip(x, -limit, limit) elementwise."""
    for i in range(x.shape[0]):
        v = x[i]
        out[i] = v if v != v else min(max(v, -limit[i]), limit[i])  # NaN passes through, as np.clip


@njit(nb.boolean(_f1, _f1), nogil=True)
def copy_if_finite(x, out):  # pragma: no cover - compiled
    """out[:] = x if every x is finite (returns True); else False and out untouched."""
    for i in range(x.shape[0]):
        if not math.isfinite(x[i]):
            return False
    for i in range(x.shape[0]):
        out[i] = x[i]
    return True


@njit(nb.boolean(_f3, nb.int64, _f1, _f2, _f3, _f1, _f2, _f1, _f2, _f1, _f2, _f1), nogil=True)
def qp_fill(J, mask, r, F0, cones, lower, H, g, A, b, C, l):  # pragma: no cover - compiled
    """The "qp" problem in the stance forces x = [F_i]_i (see ``inverse_dynamics``), into preallocated arrays.

    H = blockdiag(J_L,i J_L,i^T) + 1e-9 I, g = -blockdiag(J_L,i J_L,i^T) F0, A = [J_b,i^T]_i,
    b = r[:6], C = blockdiag(cones[k]) (k-th stance leg), l = lower per leg.
    Returns whether F0 already satisfies the cones, C x0 >= l (then it is the QP's optimum).
    """
    n = H.shape[0]
    for i in range(n):
        for j in range(n):
            H[i, j] = 0.0
    for i in range(C.shape[0]):
        for j in range(n):
            C[i, j] = 0.0
    for i in range(6):
        b[i] = r[i]
    W = np.empty((3, 3))
    k = 0
    inside = True
    for leg in range(N_LEGS):
        if not (mask >> leg) & 1:
            continue
        c0 = 6 + 3 * leg
        for a in range(3):
            for e in range(3):
                s = 0.0
                for m in range(3):
                    s += J[leg, a, c0 + m] * J[leg, e, c0 + m]
                W[a, e] = s
        for a in range(3):
            s = 0.0
            for e in range(3):
                H[3 * k + a, 3 * k + e] = W[a, e]
                s += W[a, e] * F0[leg, e]
            H[3 * k + a, 3 * k + a] += 1e-9
            g[3 * k + a] = -s
            for c in range(6):
                A[c, 3 * k + a] = J[leg, a, c]
        for a in range(5):
            for e in range(3):
                C[5 * k + a, 3 * k + e] = cones[k, a, e]
            l[5 * k + a] = lower[a]
            if cones[k, a, 0] * F0[leg, 0] + cones[k, a, 1] * F0[leg, 1] + cones[k, a, 2] * F0[leg, 2] < lower[a]:
                inside = False
        k += 1
    return inside


@njit(nb.void(_f1, _f3, nb.int64, _f1, _f1, _f2), nogil=True)
def stance_forces_and_torques_into(x, J, mask, r, tau, F):  # pragma: no cover - compiled
    """The stance forces x (3p,) into F (4, 3) (zeros for swing legs) and each stance leg's torques
    r_i - J_L,i^T F_i into tau (12,) (swing legs' entries untouched)."""
    k = 0
    for leg in range(N_LEGS):
        for a in range(3):
            F[leg, a] = 0.0
        if not (mask >> leg) & 1:
            continue
        for a in range(3):
            F[leg, a] = x[3 * k + a]
        c0 = 6 + 3 * leg
        for a in range(3):
            s = r[c0 + a]
            for e in range(3):
                s -= J[leg, e, c0 + a] * F[leg, e]
            tau[3 * leg + a] = s
        k += 1


@njit(nb.boolean(_f1, _f2, _f1, _f2, _f1, _f3, nb.int64, _f1, _f1, _f2), nogil=True)
def qp_apply(x, C, l, A, b, J, mask, r, tau, F):  # pragma: no cover - compiled
    """Accept the QP solution x if finite, inside the cones (1e-6) and on the base equation (1e-6 relative);
    then write the stance forces into F (4, 3) and the stance torques r_i - J_L,i^T F_i into tau."""
    for i in range(x.shape[0]):
        if not math.isfinite(x[i]):
            return False
    for i in range(C.shape[0]):
        s = 0.0
        for j in range(x.shape[0]):
            s += C[i, j] * x[j]
        if not s >= l[i] - 1e-6:
            return False
    big, err = 1.0, 0.0
    for i in range(6):
        s = -b[i]
        for j in range(x.shape[0]):
            s += A[i, j] * x[j]
        err = max(err, abs(s))
        big = max(big, abs(b[i]))
    if not err < 1e-6 * big:
        return False
    stance_forces_and_torques_into(x, J, mask, r, tau, F)
    return True


@njit(nb.void(_f2, nb.float64, _f3), nogil=True)
def friction_pyramid_into(normals, mu, out):  # pragma: no cover - compiled
    """out (p, 5, 3): ``mu' n - t1, mu' n + t1, mu' n - t2, mu' n + t2, n`` per normal (``inverse_dynamics``)."""
    mus = mu / math.sqrt(2.0)
    for i in range(normals.shape[0]):
        nn = math.sqrt(normals[i, 0] ** 2 + normals[i, 1] ** 2 + normals[i, 2] ** 2)
        n0, n1, n2 = normals[i, 0] / nn, normals[i, 1] / nn, normals[i, 2] / nn
        h0, h1 = (1.0, 0.0) if abs(n0) < 0.9 else (0.0, 1.0)
        a0, a1, a2 = -n2 * h1, n2 * h0, n0 * h1 - n1 * h0  # n x (h0, h1, 0)
        tn = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
        a0, a1, a2 = a0 / tn, a1 / tn, a2 / tn
        b0, b1, b2 = n1 * a2 - n2 * a1, n2 * a0 - n0 * a2, n0 * a1 - n1 * a0  # n x t1
        m0, m1, m2 = mus * n0, mus * n1, mus * n2
        out[i, 0, 0], out[i, 0, 1], out[i, 0, 2] = m0 - a0, m1 - a1, m2 - a2
        out[i, 1, 0], out[i, 1, 1], out[i, 1, 2] = m0 + a0, m1 + a1, m2 + a2
        out[i, 2, 0], out[i, 2, 1], out[i, 2, 2] = m0 - b0, m1 - b1, m2 - b2
        out[i, 3, 0], out[i, 3, 1], out[i, 3, 2] = m0 + b0, m1 + b1, m2 + b2
        out[i, 4, 0], out[i, 4, 1], out[i, 4, 2] = n0, n1, n2


@njit(nb.void(_f2, nb.int64, nb.float64, _f3), nogil=True)
def stance_pyramids_into(normals, mask, mu, out):  # pragma: no cover - compiled
    """out[:p] = friction pyramids (p, 5, 3) of ``normals[leg]`` for the p stance legs of ``mask``, in order."""
    p = 0
    for leg in range(N_LEGS):
        p += (mask >> leg) & 1
    stance = np.empty((p, 3))
    k = 0
    for leg in range(N_LEGS):
        if (mask >> leg) & 1:
            for e in range(3):
                stance[k, e] = normals[leg, e]
            k += 1
    friction_pyramid_into(stance, mu, out)


@njit(
    nb.boolean(_f2, nb.float64, _f3, nb.int64, _f1, _f2, _f3, _f1, _f2, _f1, _f2, _f1, _f2, _f1),
    nogil=True,
)
def qp_fill_with_cones(normals, mu, J, mask, r, F0, cones, lower, H, g, A, b, C, l):  # pragma: no cover - compiled
    """:func:`stance_pyramids_into` (``normals`` -> ``cones``) then :func:`qp_fill`, in one call."""
    stance_pyramids_into(normals, mask, mu, cones)
    p = 0
    for leg in range(N_LEGS):
        p += (mask >> leg) & 1
    return qp_fill(J, mask, r, F0, cones[:p], lower, H, g, A, b, C, l)
