"""A compiled dual active-set QP solver for the controller's contact-force problems (Goldfarb-Idnani).

:func:`solve_qp` solves ``min 1/2 x^T H x + g^T x`` subject to ``A x = b`` and ``C x >= l`` for a
positive definite H, the form of the "qp" torque distribution (:mod:`agents.control.inverse_dynamics`:
9 or 12 forces, 6 equality rows, 15 or 20 cone rows) and of its relaxed problem (cone rows only).
It is the method of Goldfarb and Idnani (1983), the one quadprog implements: start from the
unconstrained minimum (dual feasible), add the equality rows, then repeatedly add the most violated
inequality row, dropping active rows whose multiplier would turn negative, until none is violated.
The active set is kept as ``J = L^-T Q`` (``H = L L^T``) and an upper triangular R with
``J^T N = [R; 0]`` (N: the active rows' normals), updated by Givens rotations.

The optimum of a strictly convex QP is unique, so the solution is DAQP's (the reference, compared
in ``tests/agents/test_qp_kernels.py``) to rounding. Infeasibility is detected as in the method:
a violated row whose normal lies in the span of the active ones with no multiplier left to drop.
Every solve is bounded by an iteration cap; reaching it (or a numerically degenerate step) returns
:data:`QP_FAILED`, and the caller falls back to DAQP.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from agents.control import inverse_dynamics_kernels as IK
from quad_uneven_env.jit import njit

QP_SOLVED, QP_INFEASIBLE, QP_FAILED = 1, 0, -1
"""results of :func:`solve_qp`."""

QP_MAX_ITER = 100
"""active-set changes (additions and drops of inequality rows) per solve; a 12-variable problem needs < 30."""

QP_TOL = 1e-9
"""constraint tolerance (units of ``l``, N for the cone rows): a row violated by less counts as satisfied
(DAQP's ``primal_tol`` in the controller)."""

_DEPENDENT = 1e-20
"""a row whose part orthogonal to the active rows, ``|d_2|^2``, is below this fraction of ``n^T H^-1 n``
lies in their span (exact zero up to rounding)."""

_FAST = {"reassoc", "contract"}
"""fastmath flags of the inner products (vectorised sums; no assumption about NaN or Inf)."""

_f1 = nb.float64[:]
_f2 = nb.float64[:, :]
_f3 = nb.float64[:, :, :]


@njit(nogil=True, fastmath=_FAST)
def _direction(JT, R, nrm, q, d, z, r):  # pragma: no cover - compiled
    """d = J^T nrm, z = J[:, q:] d[q:] (primal step), r = R[:q, :q]^-1 d[:q] (dual step); returns
    ``(|d[q:]|^2, |d|^2)``. ``JT`` is J transposed (its rows are J's columns: contiguous)."""
    n = JT.shape[0]
    dd = 0.0
    zn = 0.0
    for k in range(n):
        s = 0.0
        for i in range(n):
            s += JT[k, i] * nrm[i]
        d[k] = s
        dd += s * s
        if k >= q:
            zn += s * s
    for i in range(n):
        z[i] = 0.0
    for k in range(q, n):
        dk = d[k]
        for i in range(n):
            z[i] += dk * JT[k, i]
    for i in range(q - 1, -1, -1):
        s = d[i]
        for k in range(i + 1, q):
            s -= R[i, k] * r[k]
        r[i] = s / R[i, i]
    return zn, dd


@njit(nogil=True, fastmath=_FAST)
def _rotate(X, j, k, c, s, start):  # pragma: no cover - compiled
    """Rows j, k of X (columns ``start:``) <- (c X_j + s X_k, c X_k - s X_j)."""
    for i in range(start, X.shape[1]):
        u, v = X[j, i], X[k, i]
        X[j, i] = c * u + s * v
        X[k, i] = c * v - s * u


@njit(nogil=True)
def _add(JT, R, d, q):  # pragma: no cover - compiled
    """Make row ``d = J^T n`` the q-th active one: rotate d[q+1:] into d[q] (rows of JT), R[:q+1, q] = d."""
    n = JT.shape[0]
    for j in range(n - 1, q, -1):
        a, b = d[j - 1], d[j]
        if b == 0.0:
            continue
        h = math.hypot(a, b)
        d[j - 1], d[j] = h, 0.0
        _rotate(JT, j - 1, j, a / h, b / h, 0)
    for i in range(q + 1):
        R[i, q] = d[i]


@njit(nogil=True)
def _drop(JT, R, active, u, q, pos):  # pragma: no cover - compiled
    """Remove the active row at position ``pos`` (of q): shift R's columns, ``active`` and u; restore R
    upper triangular by Givens rotations of its rows (and the same on JT's rows)."""
    for k in range(pos, q - 1):
        active[k] = active[k + 1]
        u[k] = u[k + 1]
        for i in range(q):
            R[i, k] = R[i, k + 1]
    for i in range(q):
        R[i, q - 1] = 0.0
    for j in range(pos, q - 1):
        a, b = R[j, j], R[j + 1, j]
        if b == 0.0:
            continue
        h = math.hypot(a, b)
        R[j + 1, j] = 0.0
        R[j, j] = h
        _rotate(R, j, j + 1, a / h, b / h, j + 1)
        _rotate(JT, j, j + 1, a / h, b / h, 0)


@njit(nb.int64(_f2, _f1, _f2, _f1, _f2, _f1, _f1), nogil=True, fastmath=_FAST)
def solve_qp(H, g, A, b, C, l, x):  # pragma: no cover - compiled
    """x = argmin 1/2 x^T H x + g^T x subject to A x = b, C x >= l (module doc); H positive definite.

    :param H: (n, n); ``g`` (n,); ``A`` (me, n), ``b`` (me,); ``C`` (mi, n), ``l`` (mi,); ``x`` (n,) output.
    :return: :data:`QP_SOLVED`, :data:`QP_INFEASIBLE`, or :data:`QP_FAILED` (H not positive definite,
        dependent equality rows, a degenerate step, or :data:`QP_MAX_ITER` reached; ``x`` is then garbage).
    """
    n, me, mi = H.shape[0], A.shape[0], C.shape[0]
    if me > n:
        return QP_FAILED
    # H = L L^T; J = L^-T (upper triangular)
    L = np.zeros((n, n))
    for j in range(n):
        s = H[j, j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        if not s > 0.0:
            return QP_FAILED
        L[j, j] = math.sqrt(s)
        for i in range(j + 1, n):
            s = H[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            L[i, j] = s / L[j, j]
    JT = np.zeros((n, n))  # J^T = L^-1, row by row (forward substitution)
    for i in range(n):
        JT[i, i] = 1.0
        for k in range(i):
            c = L[i, k]
            for m in range(k + 1):
                JT[i, m] -= c * JT[k, m]
        for m in range(i + 1):
            JT[i, m] /= L[i, i]
    # unconstrained minimum x = -J J^T g
    w = np.empty(n)
    for k in range(n):
        s = 0.0
        for i in range(n):
            s += JT[k, i] * g[i]
        w[k] = s
    for i in range(n):
        x[i] = 0.0
    for k in range(n):
        for i in range(n):
            x[i] -= w[k] * JT[k, i]
    R = np.zeros((n, n))
    d, z, r = np.empty(n), np.empty(n), np.empty(n)
    u = np.zeros(n + 1)
    active = np.empty(n + 1, dtype=np.int64)  # 0..me-1: equality rows, me + j: inequality row j
    is_active = np.zeros(mi, dtype=np.bool_)
    q = 0
    for e in range(me):
        zn, dd = _direction(JT, R, A[e], q, d, z, r)
        if not zn > _DEPENDENT * dd:
            return QP_FAILED
        s = -b[e]
        for i in range(n):
            s += A[e, i] * x[i]
        t = -s / zn
        for i in range(n):
            x[i] += t * z[i]
        for k in range(q):
            u[k] -= t * r[k]
        u[q] = t
        active[q] = e
        _add(JT, R, d, q)
        q += 1
    it = 0
    while True:
        # the most violated inactive inequality row
        ip, worst = -1, -QP_TOL
        for j in range(mi):
            if is_active[j]:
                continue
            s = -l[j]
            for i in range(n):
                s += C[j, i] * x[i]
            if s < worst:
                ip, worst = j, s
        if ip < 0:
            return QP_SOLVED
        slack, u_new = worst, 0.0
        while True:
            it += 1
            if it > QP_MAX_ITER:
                return QP_FAILED
            zn, dd = _direction(JT, R, C[ip], q, d, z, r)
            # partial step: largest dual step keeping the active inequalities' multipliers >= 0
            t1, drop = np.inf, -1
            for k in range(me, q):
                if r[k] > 0.0 and u[k] / r[k] < t1:
                    t1, drop = u[k] / r[k], k
            t2 = -slack / zn if zn > _DEPENDENT * dd else np.inf  # full step: row ip becomes active
            t = min(t1, t2)
            if t == np.inf:
                return QP_INFEASIBLE
            for k in range(q):
                u[k] -= t * r[k]
            u_new += t
            if t2 < np.inf:
                for i in range(n):
                    x[i] += t * z[i]
            if t == t2:
                u[q] = u_new
                active[q] = me + ip
                _add(JT, R, d, q)
                if not abs(R[q, q]) > 0.0:
                    return QP_FAILED
                q += 1
                is_active[ip] = True
                break
            is_active[active[drop] - me] = False
            _drop(JT, R, active, u, q, drop)
            q -= 1
            slack = -l[ip]
            for i in range(n):
                slack += C[ip, i] * x[i]


QP_INSIDE, QP_OPTIMAL, QP_RELAXED = 1, 2, 3
"""results of :func:`distribute_qp` besides :data:`QP_FAILED`: the pinv forces already lie in the cones (kept),
the QP's optimum was applied, the relaxed problem's solution was applied."""

RELAX_WEIGHT = 1e-3
"""weight of the distance to the pinv forces in the relaxed problem (``InverseDynamics._relax``)."""

WIDE_MU = 0.5
"""-: a problem infeasible with cones of ``mu`` (no forces in them give the commanded base wrench) is solved again
with cones of :func:`wide_mu` ``= min(2 mu, WIDE_MU)`` before it is relaxed: narrow cones ask little of the floor
wherever the motion allows it, and the wider ones only where the base needs more (a payload's or a push's
correction); with ``mu >= WIDE_MU`` nothing changes."""


@njit(nb.float64(nb.float64), nogil=True)
def wide_mu(mu):  # pragma: no cover - compiled
    """-: the friction of the second try of a problem infeasible with cones of ``mu`` (:data:`WIDE_MU`)."""
    return max(mu, min(2.0 * mu, WIDE_MU))


@njit(nb.void(_f2, _f1, _f2, _f1, _f2, _f1), nogil=True)
def relaxed_problem_into(H, g, A, b, H_out, g_out):  # pragma: no cover - compiled
    """``H_out = A^T A + RELAX_WEIGHT H``, ``g_out = -A^T b + RELAX_WEIGHT g`` (``InverseDynamics._relax``)."""
    n = H.shape[0]
    for i in range(n):
        s = 0.0
        for k in range(A.shape[0]):
            s -= A[k, i] * b[k]
        g_out[i] = s + RELAX_WEIGHT * g[i]
        for j in range(n):
            s = 0.0
            for k in range(A.shape[0]):
                s += A[k, i] * A[k, j]
            H_out[i, j] = s + RELAX_WEIGHT * H[i, j]


@njit(nb.int64(_f2, nb.float64, _f3, nb.int64, _f1, _f1, _f1, _f2, _f3), nogil=True)
def distribute_qp(normals, mu, J, mask, r, lower, tau, F, cones):  # pragma: no cover - compiled
    """The "qp" distribution (``InverseDynamics.distribute_qp``) with :func:`solve_qp`, in place.

    :param normals: (4, 3) terrain normals under the feet (world); ``mu`` the cones' friction coefficient.
    :param J: (4, 3, 18) foot Jacobians; ``mask`` the stance bitmask (3 or 4 legs); ``r`` (18,) = M qacc + h;
        ``lower`` (5,) the pyramid rows' lower bounds.
    :param tau: (12,) in: the pinv torques, out: the distribution's; ``F`` (4, 3) likewise for the forces.
    :param cones: (4, 5, 3) scratch: the stance legs' pyramids.
    :return: :data:`QP_INSIDE`, :data:`QP_OPTIMAL`, :data:`QP_RELAXED`, or :data:`QP_FAILED` (solver
        failure: ``tau`` and ``F`` are untouched, solve it with DAQP). Infeasible, the problem is solved again
        with cones of :func:`wide_mu` (the relaxed problem then uses those).
    """
    p = 0
    for leg in range(4):
        p += (mask >> leg) & 1
    n, n_in = 3 * p, 5 * p
    H, g, A, b = np.empty((n, n)), np.empty(n), np.zeros((6, n)), np.empty(6)
    C, l, x = np.empty((n_in, n)), np.empty(n_in), np.empty(n)
    wide = wide_mu(mu)
    for attempt in range(2 if wide > mu else 1):  # the narrow cones, then (infeasible there) the wide ones
        cone_mu = mu if attempt == 0 else wide
        if IK.qp_fill_with_cones(normals, cone_mu, J, mask, r, F, cones, lower, H, g, A, b, C, l):
            return QP_INSIDE
        status = solve_qp(H, g, A, b, C, l, x)
        if status == QP_FAILED:
            return QP_FAILED
        if status == QP_SOLVED and IK.qp_apply(x, C, l, A, b, J, mask, r, tau, F):
            return QP_OPTIMAL
    # infeasible at the commanded base acceleration: the relaxed problem, cone rows with zero lower bound
    H_r, g_r = np.empty((n, n)), np.empty(n)
    relaxed_problem_into(H, g, A, b, H_r, g_r)
    for i in range(n_in):
        l[i] = 0.0
    if solve_qp(H_r, g_r, A[:0], b[:0], C, l, x) != QP_SOLVED:
        return QP_FAILED
    for i in range(n):
        if not math.isfinite(x[i]):
            return QP_FAILED
    IK.stance_forces_and_torques_into(x, J, mask, r, tau, F)
    return QP_RELAXED
