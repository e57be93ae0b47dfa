"""Compiled constraint rows of the COG planner's SQP (:meth:`planners.cog._Reduced.constraints`).

Each SQP iteration evaluates the tumbling moments at every sample time of every phase and their
exact Jacobian in the null-space variables (~600 rows x 117 columns). In numpy that is ~20 small
array operations per phase; here each row is one loop iteration of scalar arithmetic. The formulas
are those of :mod:`planners.cog` (its ``constraints`` docstring); ``tests/planners/test_cog.py``
checks the compiled rows against the numpy ones.
"""

from __future__ import annotations

import math

from quad_uneven_env.jit import njit


@njit(nogil=True)
def stability_rows_into(P0, A0, Bv, Ba, coef, p, kappa, mass, gravity, h_out, J_out):  # pragma: no cover - compiled
    """Tumbling moments and their Jacobian of one phase, written into ``h_out`` (S E,) and ``J_out`` (S E, 3 m).

    :param P0: (S, 9) position basis rows; ``A0`` (S, 9) acceleration rows (1/s^2, local time scaled).
    :param Bv: (S, m) position rows through the null space; ``Ba`` (S, m) acceleration rows.
    :param coef: (9, 3) the phase's Bernstein coefficients (m).
    :param p: (E, 3) support polygon vertices (m, world); ``kappa`` (E, 3) unit edge directions.
    :param mass: kg; ``gravity`` m/s^2. Row ``s E + e`` is edge ``e`` at sample ``s``; column ``a m + j``
        is variable ``j`` of axis ``a``.
    """
    S, E, m = P0.shape[0], p.shape[0], Bv.shape[1]
    P = [0.0, 0.0, 0.0]
    F = [0.0, 0.0, 0.0]
    for s in range(S):
        for a in range(3):
            x = 0.0
            acc = 0.0
            for c in range(P0.shape[1]):
                x += P0[s, c] * coef[c, a]
                acc += A0[s, c] * coef[c, a]
            P[a] = x
            F[a] = -mass * acc
        F[2] -= mass * gravity
        for e in range(E):
            r0, r1, r2 = P[0] - p[e, 0], P[1] - p[e, 1], P[2] - p[e, 2]
            k0, k1, k2 = kappa[e, 0], kappa[e, 1], kappa[e, 2]
            row = s * E + e
            # h = kappa . (r x F); dh/dP = F x kappa; dh/dP'' = -m kappa x r
            h_out[row] = k0 * (r1 * F[2] - r2 * F[1]) + k1 * (r2 * F[0] - r0 * F[2]) + k2 * (r0 * F[1] - r1 * F[0])
            gp0, gp1, gp2 = F[1] * k2 - F[2] * k1, F[2] * k0 - F[0] * k2, F[0] * k1 - F[1] * k0
            ga0 = -mass * (k1 * r2 - k2 * r1)
            ga1 = -mass * (k2 * r0 - k0 * r2)
            ga2 = -mass * (k0 * r1 - k1 * r0)
            for j in range(m):
                bv, ba = Bv[s, j], Ba[s, j]
                J_out[row, j] = gp0 * bv + ga0 * ba
                J_out[row, m + j] = gp1 * bv + ga1 * ba
                J_out[row, 2 * m + j] = gp2 * bv + ga2 * ba


@njit(nogil=True)
def reach_rows_into(P0, Bv, coef, offsets, sites, max_reach, bound, scale, h_out, J_out):  # pragma: no cover - compiled
    """Stance-leg reach rows of one phase, ``bound + scale (max_reach - |d|) >= bound``, written into
    ``h_out`` (S L,) and ``J_out`` (S L, 3 m), with ``d`` the hip-to-foot-site vector.

    :param offsets: (S or 1, L, 3) hip minus COG (m, world) at the samples; ``sites`` (L, 3) foot sites (m).
    :param max_reach: m; ``bound`` N m; ``scale`` N m per m. Row ``s L + l`` is leg ``l`` at sample ``s``.
    """
    S, L, m = P0.shape[0], sites.shape[0], Bv.shape[1]
    P = [0.0, 0.0, 0.0]
    for s in range(S):
        for a in range(3):
            x = 0.0
            for c in range(P0.shape[1]):
                x += P0[s, c] * coef[c, a]
            P[a] = x
        o = s if offsets.shape[0] > 1 else 0
        for leg in range(L):
            d0 = P[0] + offsets[o, leg, 0] - sites[leg, 0]
            d1 = P[1] + offsets[o, leg, 1] - sites[leg, 1]
            d2 = P[2] + offsets[o, leg, 2] - sites[leg, 2]
            dist = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            row = s * L + leg
            h_out[row] = bound + scale * (max_reach - dist)
            n0, n1, n2 = -scale * d0 / dist, -scale * d1 / dist, -scale * d2 / dist
            for j in range(m):
                bv = Bv[s, j]
                J_out[row, j] = n0 * bv
                J_out[row, m + j] = n1 * bv
                J_out[row, 2 * m + j] = n2 * bv
