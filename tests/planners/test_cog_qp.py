"""The COG planner's QP step (DAQP with an iteration limit) against quadprog, an independent solver, and on a
problem where quadprog, given the raw rows, cycles forever."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np

QP = Path(__file__).parent / "data" / "cog_qp_quadprog_cycles.npz"
"""A COG-planning QP saved from a commanded walk (vx -0.1, vy -0.05, yaw rate 0.3, default gait): row norms
span 0 to 2.6e4, 16 zero rows with an unbounded lower bound."""


def _quadprog(H, g, C, lo):
    """quadprog (Goldfarb-Idnani) on the unit-norm rows: the independent reference."""
    import quadprog

    live = np.linalg.norm(C, axis=1) > 0
    n = np.linalg.norm(C[live], axis=1)
    try:
        return quadprog.solve_qp(H, -g, (C[live] / n[:, None]).T, lo[live] / n, 0)[0]
    except ValueError as err:
        assert "inconsistent" in str(err)
        return None


def test_the_saved_qp_is_solved_and_matches_quadprog(tmp_path):
    """Solved within a minute in a child process (a hang must fail the test, not block the suite);
    the solution is feasible and equals quadprog's on the unit-norm rows (which it solves) to 1e-8."""
    code = (
        "import numpy as np, sys; from planners.cog_qp import solve_qp; "
        f"d = np.load({str(QP)!r}); z = solve_qp(d['H'], d['g'], d['C'], d['lo']); "
        "np.save(sys.argv[1], z)"
    )
    subprocess.run([sys.executable, "-c", code, str(tmp_path / "z.npy")], check=True, timeout=60)
    z = np.load(tmp_path / "z.npy")
    d = np.load(QP)
    H, g, C, lo = d["H"], d["g"], d["C"], d["lo"]
    assert (C @ z - lo).min() > -1e-8
    x = _quadprog(H, g, C, lo)
    np.testing.assert_allclose(z, x, atol=1e-8 * max(1.0, np.abs(x).max()))


def test_a_zero_row_with_a_positive_bound_is_infeasible():
    from planners.cog_qp import solve_qp

    H = np.eye(2)
    g = np.zeros(2)
    C = np.array([[1.0, 0.0], [0.0, 0.0]])
    assert solve_qp(H, g, C, np.array([1.0, 0.5])) is None
    np.testing.assert_allclose(solve_qp(H, g, C, np.array([1.0, -1.0])), [1.0, 0.0])


def test_the_saved_qp_through_the_warm_start_equals_quadprog():
    """The same problem through :class:`WarmStartQP`: cold (working set from the unconstrained optimum), then
    warm (the KKT shortcut from its own active set); both equal quadprog on all rows."""
    from planners.cog_qp import WarmStartQP

    d = np.load(QP)
    H, g, C, lo = d["H"], d["g"], d["C"], d["lo"]
    ref = _quadprog(H, g, C, lo)
    qp = WarmStartQP(H, g)
    cold = qp.solve(C, lo, qp.x_free)
    warm = qp.solve(C, lo, cold)
    assert qp.shortcuts == 1
    for x in (cold, warm):
        np.testing.assert_allclose(x, ref, atol=1e-7 * max(1.0, np.abs(ref).max()))


def test_random_qps_equal_quadprog_with_the_same_verdict_and_active_rows():
    """Random strictly convex QPs with many rows, some infeasible, some with redundant (duplicated) rows:
    the same optimum as quadprog to 1e-8, the same infeasibility verdict, and the reported active rows are
    tight at the optimum."""
    from planners.cog_qp import solve_qp_active

    rng = np.random.default_rng(7)
    solved = infeasible = 0
    for trial in range(200):
        n, m = 30, int(rng.integers(20, 120))
        M = rng.normal(size=(n, n))
        H = M @ M.T + 0.1 * np.eye(n)
        g = rng.normal(size=n)
        C = rng.normal(size=(m, n)) * rng.uniform(1e-2, 1e4, size=(m, 1))  # row norms over six decades
        lo = C @ rng.normal(size=n) - rng.uniform(-0.5, 2.0, size=m)
        if trial % 5 == 0:
            C, lo = np.vstack([C, C[:10]]), np.concatenate([lo, lo[:10]])  # degenerate: duplicated rows
        z, active = solve_qp_active(H, g, C, lo)
        ref = _quadprog(H, g, C, lo)
        assert (z is None) == (ref is None), trial
        if z is None:
            infeasible += 1
            continue
        solved += 1
        np.testing.assert_allclose(z, ref, atol=1e-8 * max(1.0, np.abs(ref).max()))
        slack = (C @ z - lo) / np.linalg.norm(C, axis=1)
        assert slack.min() > -1e-8 and np.all(np.abs(slack[active]) < 1e-7)
    assert solved > 50 and infeasible > 10  # both branches exercised


def test_a_qp_the_solver_gives_up_on_is_not_solved_and_does_not_block(monkeypatch):
    """Past its iteration limit the solver returns None (an infeasible plan for the planner), not a hang
    and not a half-solved point."""
    import planners.cog_qp as cog_qp

    d = np.load(QP)
    H, g, C, lo = d["H"], d["g"], d["C"], d["lo"]
    assert cog_qp.solve_qp(H, g, C, lo) is not None
    monkeypatch.setattr(cog_qp, "ITER_LIMIT", 1)
    assert cog_qp.solve_qp(H, g, C, lo) is None


def test_an_active_set_guess_off_by_a_row_is_repaired_to_quadprogs_optimum():
    """A guess missing one active row, or with one inactive row too many, is repaired by single-row changes
    (a shortcut, no solver call); a guess too far off for :data:`MAX_REPAIRS` changes goes to the solver.
    Every answer is quadprog's optimum on all rows."""
    import planners.cog_qp as cog_qp

    d = np.load(QP)
    H, g, C, lo = d["H"], d["g"], d["C"], d["lo"]
    ref = _quadprog(H, g, C, lo)
    qp = cog_qp.WarmStartQP(H, g)
    qp.solve(C, lo, qp.x_free)
    optimal = qp.active.copy()
    assert optimal.sum() >= 3
    norms = np.linalg.norm(C, axis=1)
    live = norms > 0
    slack = np.full(len(C), -np.inf)
    slack[live] = (C[live] @ ref - lo[live]) / norms[live]
    inactive = np.flatnonzero(~optimal & (slack > 1e-3))
    missing, extra = optimal.copy(), optimal.copy()
    missing[np.flatnonzero(optimal)[0]] = False
    extra[inactive[0]] = True
    for guess in (missing, extra):
        qp.active = guess.copy()
        before = qp.shortcuts
        x = qp.solve(C, lo, ref)
        assert qp.shortcuts == before + 1
        np.testing.assert_array_equal(qp.active, optimal)
        np.testing.assert_allclose(x, ref, atol=1e-7 * max(1.0, np.abs(ref).max()))
    far = optimal.copy()
    far[np.flatnonzero(optimal)[: cog_qp.MAX_REPAIRS + 1]] = False  # more rows missing than changes allowed
    qp.active = far
    before = qp.shortcuts
    x = qp.solve(C, lo, ref)
    assert qp.shortcuts == before
    np.testing.assert_allclose(x, ref, atol=1e-7 * max(1.0, np.abs(ref).max()))


def test_the_whitened_solve_equals_daqp_on_the_original_problem():
    """The solve DAQP gets whitened (identity Hessian, rows times L^-T) has the optimum DAQP finds on H itself."""
    import daqp

    from planners.cog_qp import solve_qp, whitening

    d = np.load(QP)
    H, g, C, lo = d["H"], d["g"], d["C"], d["lo"]
    live = np.linalg.norm(C, axis=1) > 0
    n = np.linalg.norm(C[live], axis=1)
    A = np.ascontiguousarray(C[live] / n[:, None])
    x_ref, _, flag, _ = daqp.solve(
        np.array(H), np.array(g), A, np.full(len(A), np.inf), lo[live] / n, np.zeros(len(A), dtype=np.int32),
        primal_tol=1e-9,
    )  # fmt: skip
    assert flag == 1
    Linv = whitening(H)
    np.testing.assert_allclose(Linv @ H @ Linv.T, np.eye(len(H)), atol=1e-9)
    np.testing.assert_allclose(solve_qp(H, g, C, lo), x_ref, atol=1e-9 * max(1.0, np.abs(x_ref).max()))
