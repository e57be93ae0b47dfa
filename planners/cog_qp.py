"""The COG planner's QP step: ``min 1/2 z'Hz + g'z  s.t.  C z >= lo`` (117 variables, ~600 rows).

:func:`solve_qp` is DAQP (a dual active-set solver with an iteration limit) on all rows. :class:`WarmStartQP` gives
the same optimum faster across the iterations of one SQP, where H and g stay fixed and only the
linearised rows move:

1. *Active-set guess.* The rows active at the previous iteration's optimum (or a guess the caller sets in
   :attr:`WarmStartQP.active`) are taken as equalities and the KKT system is solved directly (H^-1 is
   computed once). The result is the optimum when every multiplier is >= 0 and every row holds (the KKT
   conditions, sufficient for a convex QP); it is accepted only then. Until then, up to
   :data:`MAX_REPAIRS` times, the row with the most negative multiplier is dropped or, when every
   multiplier is >= 0, the most violated row added, and the KKT system solved again.
2. *Working set.* Otherwise :func:`solve_qp` solves the QP on the rows that can matter (violated or near their
   bound at the linearisation point, plus the previous active rows); every left-out row its solution
   violates is added and the QP solved again, until none is. The full feasible set lies inside each
   working set's, so the first working-set optimum that satisfies every row is the full optimum, and an
   infeasible working set means an infeasible problem.

Rows are compared in units of their own norm (z-space distances), as the solver sees them.

DAQP gets the problem whitened: with ``H = L L^T`` and ``u = L^T z`` the cost is ``1/2 u'u + (L^-1 g)'u`` and
the rows ``C L^-T``. On the planner's ~190 x 117 working sets DAQP's setup took ~0.6 ms of a ~0.75 ms solve
with H itself and ~0.06 ms with the identity (measured, DAQP 0.11); the transform here is one BLAS product
with ``L^-1``, which is fixed for a whole plan (:func:`whitening`). The optimum is the same to ~1e-13.
"""

from __future__ import annotations

import daqp
import numpy as np
import scipy.linalg

SCREEN_SLACK = 0.05
"""A row enters the first working set when its slack at the linearisation point, divided by its norm (the
z-space distance to its boundary), is below this."""
FEASIBILITY_TOL = 1e-9
"""A row holds when its normalised slack is >= -FEASIBILITY_TOL."""
MULTIPLIER_TOL = 1e-9
"""An active-set guess is optimal when every multiplier (of a normalised row) is >= -MULTIPLIER_TOL."""
PRIMAL_TOL = 1e-9
"""DAQP's feasibility tolerance on a normalised row (its default, 1e-6, leaves plans ~1e-5 from quadprog's)."""
MAX_REPAIRS = 3
"""single-row changes of the active-set guess before the working-set solve takes over (each costs one small
KKT solve, a few times cheaper than a solver call; where the guess from the previous SQP iteration settles,
it mostly needs 0-3)."""
ITER_LIMIT = 2000
"""DAQP's active-set iterations per QP before it gives up (the planner's QPs take 5-30)."""


def whitening(H: np.ndarray) -> np.ndarray:
    """``L^-1`` (n, n, lower triangular, read-only) of the Cholesky factor ``H = L L^T`` of a positive definite H."""
    L = np.linalg.cholesky(H)
    Linv = scipy.linalg.solve_triangular(L, np.eye(len(H)), lower=True)
    Linv.setflags(write=False)
    return Linv


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
    H: np.ndarray, g: np.ndarray, C: np.ndarray, lo: np.ndarray, Linv: np.ndarray | None = None
) -> tuple[np.ndarray | None, np.ndarray]:
    """:func:`solve_qp` and the rows with a nonzero multiplier at its optimum (bool (n_rows,)).

    :param Linv: :func:`whitening` of H when the caller has it (computed otherwise).
    """
    norms = np.linalg.norm(C, axis=1)
    live = norms > 0.0
    rows = np.zeros(len(C), dtype=bool)
    if np.any(lo[~live] > 0.0):
        return None, rows
    scale = 1.0 / norms[live]
    lower = lo[live] * scale
    if Linv is None:
        Linv = whitening(np.asarray(H, dtype=np.float64))
    u, _, flag, info = daqp.solve(
        np.eye(len(g)),  # fresh: DAQP takes a writable H
        Linv @ np.asarray(g, dtype=np.float64),
        (C[live] * scale[:, None]) @ Linv.T,
        np.full(len(lower), np.inf),
        lower,
        np.zeros(len(lower), dtype=np.int32),
        primal_tol=PRIMAL_TOL,
        iter_limit=ITER_LIMIT,
    )
    if flag < 1:  # -1 infeasible; -2 cycling, -4 iteration limit and the rest: not solved
        return None, rows
    rows[np.flatnonzero(live)[info["lam"] != 0.0]] = True
    return Linv.T @ u, rows


class WarmStartQP:
    """The QPs of one SQP (fixed ``H`` (n, n) and ``g`` (n,)), each solved from the previous one's active set.

    :meth:`solve` returns what :func:`solve_qp` would (the same optimum, to rounding); :attr:`shortcuts`
    counts the solves the active-set guess settled without a solver call. :attr:`active` (bool (m,)) is the
    active set of the last optimum; a caller may set it to a guess for rows of the next problem.
    """

    def __init__(
        self, H: np.ndarray, g: np.ndarray, Hinv: np.ndarray | None = None, Linv: np.ndarray | None = None
    ) -> None:
        """:param Hinv: H's inverse, :param Linv: its :func:`whitening`, when the caller has them (computed
        otherwise)."""
        self.H, self.g = H, g
        self.Hinv = np.linalg.inv(H) if Hinv is None else Hinv
        self.Linv = whitening(H) if Linv is None else Linv
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
            guess = self._guess(C, lo, inv, prev & live)
            if guess is not None:
                self.shortcuts += 1
                x, self.active = guess
                return x
        work = live & ((C @ z - lo) * inv < SCREEN_SLACK)
        if prev is not None:
            work |= prev & live
        while True:
            if work.any():
                x, act = solve_qp_active(self.H, self.g, C[work], lo[work], self.Linv)
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

    def _guess(
        self, C: np.ndarray, lo: np.ndarray, inv: np.ndarray, rows: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """The optimum and its active rows, found from the guess ``rows`` by at most :data:`MAX_REPAIRS`
        single-row changes; None when they do not reach a KKT point."""
        rows = rows.copy()
        valid = inv > 0.0
        idx = list(np.flatnonzero(rows))
        A = C[idx] * inv[idx, None]  # the active rows, unit norm
        Y = self.Hinv @ A.T  # H^-1 A^T, one column per active row
        for _ in range(MAX_REPAIRS + 1):
            try:
                lam = np.linalg.solve(A @ Y, lo[idx] * inv[idx] - A @ self.x_free)
            except np.linalg.LinAlgError:  # dependent rows: let the solver choose
                return None
            if not np.all(np.isfinite(lam)):
                return None
            if lam.size and lam.min() < -MULTIPLIER_TOL:
                j = int(np.argmin(lam))
                rows[idx.pop(j)] = False
                A, Y = np.delete(A, j, axis=0), np.delete(Y, j, axis=1)
                continue
            x = self.x_free + Y @ lam
            slack = np.where(valid, (C @ x - lo) * inv, np.inf)
            worst = int(np.argmin(slack))
            if slack[worst] >= -FEASIBILITY_TOL:
                return x, rows
            rows[worst] = True
            idx.append(worst)
            a = C[worst] * inv[worst]
            A, Y = np.vstack([A, a]), np.column_stack([Y, self.Hinv @ a])
        return None
