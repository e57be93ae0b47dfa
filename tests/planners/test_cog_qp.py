"""The COG planner's QP step on a problem where quadprog, given the raw rows, cycles forever."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

QP = Path(__file__).parent / "data" / "cog_qp_quadprog_cycles.npz"
"""A COG-planning QP saved from a commanded walk (vx -0.1, vy -0.05, yaw rate 0.3, default gait): row norms
span 0 to 2.6e4, 16 zero rows with an unbounded lower bound."""


def test_the_saved_qp_is_solved_and_matches_daqp(tmp_path):
    """Solved within a minute in a child process (a hang must fail the test, not block the suite);
    the solution is feasible and equals DAQP's (an independent active-set solver) to 1e-6."""
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
    import daqp

    live = np.linalg.norm(C, axis=1) > 0
    A = C[live] / np.linalg.norm(C[live], axis=1)[:, None]
    b = lo[live] / np.linalg.norm(C[live], axis=1)
    x, _, flag, _ = daqp.solve(H, g, A, np.full(len(A), 1e30), b, np.zeros(len(A), dtype=np.int32))
    assert flag == 1
    np.testing.assert_allclose(z, x, atol=1e-6 * max(1.0, np.abs(x).max()))


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
    from planners.cog_qp import WarmStartQP, solve_qp

    d = np.load(QP)
    H, g, C, lo = d["H"], d["g"], d["C"], d["lo"]
    ref = solve_qp(H, g, C, lo)
    qp = WarmStartQP(H, g)
    cold = qp.solve(C, lo, qp.x_free)
    warm = qp.solve(C, lo, cold)
    assert qp.shortcuts == 1
    for x in (cold, warm):
        np.testing.assert_allclose(x, ref, atol=1e-7 * max(1.0, np.abs(ref).max()))


def test_a_quadprog_error_other_than_infeasibility_is_raised_not_read_as_infeasible():
    from planners.cog_qp import solve_qp

    H = np.eye(2)
    H.setflags(write=False)  # quadprog refuses read-only buffers with a ValueError
    with pytest.raises(ValueError, match="read-only"):
        solve_qp(H, np.zeros(2), np.eye(2), np.zeros(2))
