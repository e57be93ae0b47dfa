"""The COG planner's QP step: ``min 1/2 z'Hz + g'z  s.t.  C z >= lo`` (117 variables, ~600 rows).

:func:`solve_qp` is DAQP (a dual active-set solver with an iteration limit) on all rows. :class:`WarmStartQP` gives
the same optimum faster across the iterations of one SQP, where H and g stay fixed and only the
linearised rows move:

1. *Active-set guess.* The rows active at the previous iteration's optimum are taken as equalities and
   the KKT system is solved directly (H^-1 is computed once). The result is the optimum when every
   multiplier is >= 0 and every row holds (the KKT conditions, sufficient for a convex QP); it is
   accepted only then.
2. *Working set.* Otherwise :func:`solve_qp` solves the QP on the rows that can matter (violated or near their
   bound at the linearisation point, plus the previous active rows); every left-out row its solution
   violates is added and the QP solved again, until none is. The full feasible set lies inside each
   working set's, so the first working-set optimum that satisfies every row is the full optimum, and an
   infeasible working set means an infeasible problem.

Rows are compared in units of their own norm (z-space distances), as the solver sees them.
"""

from __future__ import annotations

import daqp
import numpy as np

SCREEN_SLACK = 0.05
"""A row enters the first working set when its slack at the linearisation point, divided by its norm (the
z-space distance to its boundary), is below this."""
FEASIBILITY_TOL = 1e-9
"""A row holds when its normalised slack is >= -FEASIBILITY_TOL."""
MULTIPLIER_TOL = 1e-9
"""An active-set guess is optimal when every multiplier (of a normalised row) is >= -MULTIPLIER_TOL."""
PRIMAL_TOL = 1e-9
"""DAQP's feasibility tolerance on a normalised row (its default, 1e-6, leaves plans ~1e-5 from quadprog's)."""
ITER_LIMIT = 2000
"""DAQP's active-set iterations per QP before it gives up (the planner's QPs take 5-30)."""


def solve_qp(H: np.ndarray, g: np.ndarray, C: np.ndarray, lo: np.ndarray) -> np.ndarray | None:
    """min 1/2 z'Hz + g'z s.t. C z >= lo; None when infeasible or not solved within :data:`ITER_LIMIT`.

    DAQP (a dual active-set solver, as fast as quadprog on these ~120-variable problems and equal to it to
    ~1e-13) with an iteration limit: quadprog has no limit, and on some problems its active set cycled
    forever inside its C loop, where no signal or time limit reaches it (once on raw rows; once more, on
    unit-norm rows of a warm-start working set, in a training run). A problem given up on is an
    infeasible plan for the planner (it shortens the stride or stands still); it never blocks.

    Every row is scaled to unit norm first (the rows' norms span 0 to ~3e4: reach, stability and friction
    rows in their own units). Zero rows are dropped (infeasible if their bound is positive).
    """
    return solve_qp_active(H, g, C, lo)[0]


def solve_qp_active(
    H: np.ndarray, g: np.ndarray, C: np.ndarray, lo: np.ndarray
) -> tuple[np.ndarray | None, np.ndarray]:
    """:func:`solve_qp` and the rows with a nonzero multiplier at its optimum (bool (n_rows,))."""
    norms = np.linalg.norm(C, axis=1)
    live = norms > 0.0
    rows = np.zeros(len(C), dtype=bool)
    if np.any(lo[~live] > 0.0):
        return None, rows
    scale = 1.0 / norms[live]
    lower = lo[live] * scale
    x, _, flag, info = daqp.solve(
        np.array(H, dtype=np.float64, order="C"),
        np.array(g, dtype=np.float64),
        np.ascontiguousarray(C[live] * scale[:, None]),
        np.full(len(lower), np.inf),
        lower,
        np.zeros(len(lower), dtype=np.int32),
        primal_tol=PRIMAL_TOL,
        iter_limit=ITER_LIMIT,
    )
    if flag < 1:  # -1 infeasible; -2 cycling, -4 iteration limit and the rest: not solved
        return None, rows
    rows[np.flatnonzero(live)[info["lam"] != 0.0]] = True
    return x, rows


class WarmStartQP:
    """The QPs of one SQP (fixed ``H`` (n, n) and ``g`` (n,)), each solved from the previous one's active set.

    :meth:`solve` returns what :func:`solve_qp` would (the same optimum, to rounding); :attr:`shortcuts`
    counts the solves the active-set guess settled without a solver call.
    """

    def __init__(self, H: np.ndarray, g: np.ndarray, Hinv: np.ndarray | None = None) -> None:
        """:param Hinv: H's inverse when the caller has it (computed otherwise)."""
        self.H, self.g = H, g
        self.Hinv = np.linalg.inv(H) if Hinv is None else Hinv
        self.x_free = -self.Hinv @ g
        self.active: np.ndarray | None = None
        self.shortcuts = 0

    def solve(self, C: np.ndarray, lo: np.ndarray, z: np.ndarray) -> np.ndarray | None:
        """The optimum of ``C x >= lo`` (rows (m, n), bounds (m,)) linearised at ``z`` (n,), or None (infeasible)."""
        norms = np.linalg.norm(C, axis=1)
        live = norms > 0.0
        if np.any(lo[~live] > 0.0):
            return None
        inv = np.zeros(len(C))
        inv[live] = 1.0 / norms[live]
        prev = self.active if self.active is not None and len(self.active) == len(C) else None
        if prev is not None and prev.any():
            x = self._guess(C, lo, inv, prev & live)
            if x is not None:
                self.shortcuts += 1
                return x
        work = live & ((C @ z - lo) * inv < SCREEN_SLACK)
        if prev is not None:
            work |= prev & live
        while True:
            if work.any():
                x, act = solve_qp_active(self.H, self.g, C[work], lo[work])
            else:
                x, act = self.x_free.copy(), np.zeros(0, dtype=bool)
            if x is None:
                self.active = None
                return None
            missing = live & ~work & ((C @ x - lo) * inv < -FEASIBILITY_TOL)
            if not missing.any():
                self.active = np.zeros(len(C), dtype=bool)
                self.active[np.flatnonzero(work)[act]] = True
                return x
            work |= missing

    def _guess(self, C: np.ndarray, lo: np.ndarray, inv: np.ndarray, rows: np.ndarray) -> np.ndarray | None:
        """The KKT point with ``rows`` active as equalities, if it is the optimum (else None)."""
        A = C[rows] * inv[rows, None]
        b = lo[rows] * inv[rows]
        Y = self.Hinv @ A.T
        try:
            lam = np.linalg.solve(A @ Y, b - A @ self.x_free)
        except np.linalg.LinAlgError:  # dependent rows: let the solver choose
            return None
        if not np.all(np.isfinite(lam)) or lam.min() < -MULTIPLIER_TOL:
            return None
        x = self.x_free + Y @ lam
        if ((C @ x - lo) * inv).min(initial=np.inf, where=inv > 0.0) < -FEASIBILITY_TOL:
            return None
        return x
