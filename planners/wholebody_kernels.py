"""Compiled :meth:`planners.wholebody.WholeBody.place_base` over a time grid.

The expert builds the whole-body reference of every gait cycle on a 2 ms grid (~1550 points);
in numpy that is ~60 array operations on (T, 4, 3) arrays per Newton step. Here each time point
is one loop iteration of scalar arithmetic. The formulas are those of
:mod:`planners.wholebody` (its module docstring); ``tests/planners/test_reference.py`` checks the
two implementations agree.
"""

from __future__ import annotations

import math

import numpy as np

from quad_uneven_env.jit import njit
from quad_uneven_env.spatial_kernels import inv3_into


@njit(nogil=True, inline="always")
def _ik(ex, ey, ez, l1, l2, knee_sign):  # pragma: no cover - compiled
    """:func:`quad_uneven_env.robot.kinematics.leg_ik_hip` of one foot point (hip frame)."""
    q1 = math.atan2(ey, -ez)
    r = math.hypot(ey, ez)
    u, w = ex, -r
    c3 = min(max((u * u + w * w - l1 * l1 - l2 * l2) / (2.0 * l1 * l2), -1.0), 1.0)
    q3 = knee_sign * math.acos(c3)
    phi = math.atan2(-u, -w)
    alpha = math.atan2(l2 * math.sin(q3), l1 + l2 * math.cos(q3))
    return q1, phi - alpha, q3


@njit(nogil=True, inline="always")
def _point_jac(s1, c1, s2, c2, s23, c23, a, b, p, J):  # pragma: no cover - compiled
    """:func:`planners.wholebody.leg_point` position p (3,) and Jacobian J (3, 3) from the angles' sin/cos."""
    u = -a * s2 - b * s23
    w = -a * c2 - b * c23
    u2, u3 = -a * c2 - b * c23, -b * c23
    w2, w3 = a * s2 + b * s23, b * s23
    p[0], p[1], p[2] = u, -s1 * w, c1 * w
    J[0, 0], J[0, 1], J[0, 2] = 0.0, u2, u3
    J[1, 0], J[1, 1], J[1, 2] = -c1 * w, -s1 * w2, -s1 * w3
    J[2, 0], J[2, 1], J[2, 2] = -s1 * w, c1 * w2, c1 * w3


@njit(nogil=True)
def _leg_jd(trig, d1, d2, d3, a, b, out):  # pragma: no cover - compiled
    """(dJ/dt) qd of :func:`planners.wholebody.leg_point` into out (3,); ``trig``: (6,) sin, cos of q1, q2 and
    q2 + q3 (as :func:`_legs` stores them)."""
    s1, c1, s2, c2, s23, c23 = trig[0], trig[1], trig[2], trig[3], trig[4], trig[5]
    w = -a * c2 - b * c23
    w2, w3 = a * s2 + b * s23, b * s23
    d23 = d2 + d3
    u_vv = a * s2 * d2**2 + b * s23 * d23**2
    w_dot = w2 * d2 + w3 * d3
    w_vv = a * c2 * d2**2 + b * c23 * d23**2
    out[0] = u_vv
    out[1] = s1 * d1**2 * w - 2 * c1 * d1 * w_dot - s1 * w_vv
    out[2] = -c1 * d1**2 * w - 2 * s1 * d1 * w_dot + c1 * w_vv


@njit(nogil=True)
def _legs(x, p, hips, l1, l2, ma, mb, knee_sign, q, f, F, J, Jinv, A, trig):  # pragma: no cover - compiled
    """IK of the four legs for base position p, then f, F (COM moment), J, J^-1 and A = F J^-1 per leg; ``trig``
    (4, 6): sin, cos of q1, q2 and q2 + q3 per leg."""
    for leg in range(4):
        q1, q2, q3 = _ik(
            x[leg, 0] - p[0] - hips[leg, 0],
            x[leg, 1] - p[1] - hips[leg, 1],
            x[leg, 2] - p[2] - hips[leg, 2],
            l1,
            l2,
            knee_sign[leg],
        )
        q[leg, 0], q[leg, 1], q[leg, 2] = q1, q2, q3
        s1, c1, s2, c2 = math.sin(q1), math.cos(q1), math.sin(q2), math.cos(q2)
        s23, c23 = math.sin(q2 + q3), math.cos(q2 + q3)
        tr = trig[leg]
        tr[0], tr[1], tr[2], tr[3], tr[4], tr[5] = s1, c1, s2, c2, s23, c23
        _point_jac(s1, c1, s2, c2, s23, c23, ma, mb, f[leg], F[leg])
        _point_jac(s1, c1, s2, c2, s23, c23, l1, l2, f[4], J[leg])  # f[4]: scratch for the foot point
        inv3_into(J[leg], Jinv[leg])
        for r in range(3):
            for s in range(3):
                acc = 0.0
                for k in range(3):
                    acc += F[leg, r, k] * Jinv[leg, k, s]
                A[leg, r, s] = acc


@njit(nogil=True)
def place_base_grid(
    c, cd, cdd, x, xd, xdd, hips, l1, l2, ma, mb, knee_sign, hip_moment, mass, newton_steps,
    p_out, pd_out, pdd_out, q_out, qd_out, qdd_out,
):  # pragma: no cover - compiled  # fmt: skip
    """:meth:`WholeBody.place_base` for T time points, into the (T, ...) outputs.

    Point 0 starts Newton from the COG-based guess of :meth:`WholeBody.place_base` with
    ``newton_steps`` steps; point t > 0 from the solution at t - 1 with one step fewer (at least one).

    :param c, cd, cdd: (T, 3) COG position, velocity, acceleration (world).
    :param x, xd, xdd: (T, 4, 3) foot sites (world).
    :param hips: (4, 3) hip positions (base frame = world axes).
    :param ma, mb: leg COM moment coefficients (kg m) along thigh and shank.
    :param knee_sign: (4,) knee branch per leg.
    :param hip_moment: (3,) leg masses at the hips (kg m).
    """
    T = c.shape[0]
    q = np.empty((4, 3))
    f = np.empty((5, 3))
    F = np.empty((4, 3, 3))
    J = np.empty((4, 3, 3))
    Jinv = np.empty((4, 3, 3))
    A = np.empty((4, 3, 3))
    trig = np.empty((4, 6))  # of the last _legs call: the final q's, reused by the acceleration terms
    K = np.empty((3, 3))
    Kinv = np.empty((3, 3))
    p = np.empty(3)
    res = np.empty(3)
    jd = np.empty((4, 3))
    fd = np.empty(3)
    v = np.empty(3)
    for t in range(T):
        if t == 0:
            # initial guess: the base where the COG is, corrected by the COM offset of that stance
            _legs(x[t], c[t], hips, l1, l2, ma, mb, knee_sign, q, f, F, J, Jinv, A, trig)
            for r in range(3):
                p[r] = c[t, r] - (hip_moment[r] + f[0, r] + f[1, r] + f[2, r] + f[3, r]) / mass
        # later points start from the previous solution (grid points are close: Newton converges
        # quadratically from there, so fewer steps reach machine precision)
        for _ in range(newton_steps if t == 0 else max(newton_steps - 1, 1)):
            _legs(x[t], p, hips, l1, l2, ma, mb, knee_sign, q, f, F, J, Jinv, A, trig)
            for r in range(3):
                res[r] = p[r] + (hip_moment[r] + f[0, r] + f[1, r] + f[2, r] + f[3, r]) / mass - c[t, r]
                for s in range(3):
                    K[r, s] = (1.0 if r == s else 0.0) - (A[0, r, s] + A[1, r, s] + A[2, r, s] + A[3, r, s]) / mass
            inv3_into(K, Kinv)
            for r in range(3):
                v[r] = Kinv[r, 0] * res[0] + Kinv[r, 1] * res[1] + Kinv[r, 2] * res[2]
            for r in range(3):
                p[r] -= v[r]
        _legs(x[t], p, hips, l1, l2, ma, mb, knee_sign, q, f, F, J, Jinv, A, trig)
        for r in range(3):
            for s in range(3):
                K[r, s] = (1.0 if r == s else 0.0) - (A[0, r, s] + A[1, r, s] + A[2, r, s] + A[3, r, s]) / mass
        inv3_into(K, Kinv)
        # velocity
        for r in range(3):
            acc = cd[t, r]
            for leg in range(4):
                for s in range(3):
                    acc -= A[leg, r, s] * xd[t, leg, s] / mass
            v[r] = acc
        for r in range(3):
            p_out[t, r] = p[r]
            pd_out[t, r] = Kinv[r, 0] * v[0] + Kinv[r, 1] * v[1] + Kinv[r, 2] * v[2]
        for leg in range(4):
            for r in range(3):
                acc = 0.0
                for s in range(3):
                    acc += Jinv[leg, r, s] * (xd[t, leg, s] - pd_out[t, s])
                qd_out[t, 3 * leg + r] = acc
                q_out[t, 3 * leg + r] = q[leg, r]
        # acceleration
        for r in range(3):
            v[r] = 0.0
        for leg in range(4):
            d1, d2, d3 = qd_out[t, 3 * leg], qd_out[t, 3 * leg + 1], qd_out[t, 3 * leg + 2]
            _leg_jd(trig[leg], d1, d2, d3, l1, l2, jd[leg])
            _leg_jd(trig[leg], d1, d2, d3, ma, mb, fd)
            for r in range(3):
                acc = fd[r]
                for s in range(3):
                    acc += A[leg, r, s] * (xdd[t, leg, s] - jd[leg, s])
                v[r] += acc
        for r in range(3):
            v[r] = cdd[t, r] - v[r] / mass
        for r in range(3):
            pdd_out[t, r] = Kinv[r, 0] * v[0] + Kinv[r, 1] * v[1] + Kinv[r, 2] * v[2]
        for leg in range(4):
            for r in range(3):
                acc = 0.0
                for s in range(3):
                    acc += Jinv[leg, r, s] * (xdd[t, leg, s] - pdd_out[t, s] - jd[leg, s])
                qdd_out[t, 3 * leg + r] = acc
