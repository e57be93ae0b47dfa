"""COG path optimisation (paper §4): exact Jacobians, continuity, stability, solver agreement, infeasibility."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from planners.cog import CogProblem, _Reduced, plan_cog
from planners.gait import PAPER_DURATIONS, walk_cycle
from planners.polynomial import basis_rows
from planners.types import PlanningError
from quad_uneven_env.constants import LEG_NAMES
from quad_uneven_env.stability import stability_index

START = np.array([[0.25, 0.185, 0.0], [0.25, -0.185, 0.03], [-0.25, 0.185, 0.01], [-0.25, -0.185, 0.0]])


def make_problem(epsilon=0.1, targets=None, step=0.2):
    phases = walk_cycle(PAPER_DURATIONS)
    target = START + np.array([step, 0.0, 0.02])
    feet = [np.where(np.asarray(p.moved)[:, None], target, START) for p in phases]
    sup = [f[np.asarray(p.stance)] for f, p in zip(feet, phases, strict=True)]
    names = [[n for n, s in zip(LEG_NAMES, p.stance, strict=True) if s] for p in phases]
    t_knots = np.array([0.0] + [p.t_end for p in phases])
    if targets is None:
        targets = np.array([[0.0, 0.0, 0.37]] * 6)
    start = np.array([[0.0, 0.0, 0.36], [0, 0, 0], [0, 0, 0]])
    end = np.array([[step, 0.0, 0.38], [0, 0, 0], [0, 0, 0]])
    return CogProblem(t_knots, sup, names, targets, start, end, 50.0, epsilon, phase_names=[p.name() for p in phases])


def dense_index(prob, path, n=4001):
    t = np.linspace(0.0, prob.t_knots[-1], n)
    k = np.clip(np.searchsorted(prob.t_knots[1:-1], t, side="right"), 0, 6)
    p, a = path.position(t), path.acceleration(t)
    out = np.empty(n)
    for j in range(7):
        sel = k == j
        out[sel] = stability_index(p[sel], a[sel], prob.supports[j], prob.mass)[0]
    return out


def test_bernstein_rows_are_exact_derivatives(rng):
    s = rng.uniform(0.05, 0.95, 7)
    h = 1e-6
    np.testing.assert_allclose((basis_rows(s + h) - basis_rows(s - h)) / (2 * h), basis_rows(s, 1), atol=1e-6)
    np.testing.assert_allclose((basis_rows(s + h, 1) - basis_rows(s - h, 1)) / (2 * h), basis_rows(s, 2), atol=1e-5)
    np.testing.assert_allclose(basis_rows(s).sum(axis=1), 1.0)


def test_constraint_jacobian_matches_finite_differences(rng):
    red = _Reduced(make_problem())
    red.set_samples([np.linspace(0, 1, 5)] * 7)
    z = rng.normal(scale=0.05, size=3 * red.m)
    h, J = red.constraints(z)
    # Moments agree with the independent stability module.
    coef = red.coef(z)
    P = basis_rows(red.samples[2]) @ coef[2]
    A = basis_rows(red.samples[2], 2) @ coef[2] / red.durations[2] ** 2
    _, mom = stability_index(P, A, red.prob.supports[2], 50.0)
    off = sum(len(red.samples[k]) * len(red.edges[k][2]) for k in range(2))
    np.testing.assert_allclose(np.sort(h[off : off + mom.size]), np.sort(mom.ravel()), rtol=1e-10, atol=1e-9)
    fd = np.empty_like(J)
    eps = 1e-6
    for i in range(J.shape[1]):
        dz = np.zeros_like(z)
        dz[i] = eps
        fd[:, i] = (red.constraints(z + dz)[0] - red.constraints(z - dz)[0]) / (2 * eps)
    np.testing.assert_allclose(J, fd, rtol=1e-5, atol=1e-4)


@pytest.mark.parametrize("epsilon", [0.1, 40.0])
def test_path_continuous_stable_and_on_boundary(epsilon):
    prob = make_problem(epsilon)
    path, stats = plan_cog(prob)
    assert path.junction_jumps().max() <= 1e-9
    t_end = prob.t_knots[-1]
    np.testing.assert_allclose(path.position(np.array([0.0, t_end])), prob.start[:1].tolist() + prob.end[:1].tolist())
    np.testing.assert_allclose(path.velocity(np.array([0.0, t_end])), 0.0, atol=1e-9)
    np.testing.assert_allclose(path.acceleration(np.array([0.0, t_end])), 0.0, atol=1e-9)
    assert dense_index(prob, path).min() >= epsilon - 1e-6
    assert stats.min_stability >= epsilon - 1e-9
    if epsilon > 1.0:
        assert stats.iterations > 0  # the constraint was active


def test_sqp_matches_slsqp_baseline():
    prob = make_problem(40.0)
    p1, _ = plan_cog(prob, method="sqp")
    p2, _ = plan_cog(prob, method="slsqp")
    t = np.linspace(0, prob.t_knots[-1], 301)
    assert np.abs(p1.position(t) - p2.position(t)).max() < 2e-4


def test_infeasible_names_phase_and_edge():
    prob = make_problem(400.0)  # 0.8 m static margin: impossible
    with pytest.raises(PlanningError, match=r"phase \d \(.*\).*edge [LR][FH]->[LR][FH].*N m"):
        plan_cog(prob)


def test_unconstrained_optimum_hits_reachable_targets():
    # Targets well inside every polygon and a tiny epsilon: the junction points are (nearly) met.
    prob = make_problem(0.1, targets=None)
    prob = dataclasses.replace(
        prob, targets=np.column_stack([np.linspace(0.03, 0.17, 6), np.zeros(6), np.full(6, 0.37)])
    )
    path, stats = plan_cog(prob)
    err = np.abs(path.position(prob.t_knots[1:-1]) - prob.targets).max()
    assert err < 0.02
    assert stats.iterations == 0 or stats.min_stability >= 0.1


def test_unstable_start_state_raises_naming_it():
    prob = make_problem(0.1)
    start = prob.start.copy()
    start[0, 1] = 0.19  # outside the support polygon (left feet at y = 0.185): the given state is unstable
    with pytest.raises(PlanningError, match=r"start or end state.*phase 0.*edge"):
        plan_cog(dataclasses.replace(prob, start=start))
    start[0, 1] = 0.12  # 6.5 cm inside: plannable
    path, _ = plan_cog(dataclasses.replace(prob, start=start))
    assert dense_index(dataclasses.replace(prob, start=start), path).min() >= 0.1 - 1e-6


def _rot_z(t):
    a = 0.3 * np.asarray(t, dtype=float)
    c, s = np.cos(a), np.sin(a)
    R = np.zeros((a.size, 3, 3))
    R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1], R[:, 2, 2] = c, -s, s, c, 1.0
    return R


def with_reach(base: CogProblem, rotation=None) -> CogProblem:
    """``base`` with stance-leg reach rows (hips 0.25 m x 0.12 m from the COG, 0.42 m reach)."""
    hips = np.array([[0.25, 0.12, 0.0], [0.25, -0.12, 0.0], [-0.25, 0.12, 0.0], [-0.25, -0.12, 0.0]])
    offsets = [hips[[LEG_NAMES.index(n) for n in names]] for names in base.support_names]
    sites = [s + np.array([0.0, 0.0, 0.02]) for s in base.supports]
    return dataclasses.replace(base, reach_sites=sites, reach_offsets=offsets, max_reach=0.42, reach_rotation=rotation)


@pytest.mark.parametrize("rotation", [None, _rot_z])
def test_compiled_constraint_rows_equal_the_numpy_rows(rng, rotation):
    """Stability and reach rows (with and without a yawing body) from the kernels equal the numpy form, at
    random points far from any solution (edges crossed, legs over-stretched)."""
    prob = with_reach(make_problem(), rotation)
    red = _Reduced(prob)
    red.bound = 0.3
    red.set_samples([np.sort(rng.uniform(0.0, 1.0, 4 + k)) for k in range(7)])
    for scale in (0.01, 0.3):
        z = rng.normal(scale=scale, size=3 * red.m)
        h, J = red.constraints(z)
        h_ref, J_ref = red.constraints_numpy(z)
        assert h.shape == h_ref.shape and J.shape == J_ref.shape
        np.testing.assert_allclose(h, h_ref, rtol=1e-12, atol=1e-10)
        np.testing.assert_allclose(J, J_ref, rtol=1e-12, atol=1e-10)
        assert (h < red.bound).any() and (h > red.bound).any()  # both sides of the constraint


def test_warm_started_qps_equal_the_full_qp(rng):
    """Each QP of an SQP solved from the previous one's active set (the KKT shortcut or the solver on a
    working set) has the optimum on all rows of quadprog (an independent solver), and the same verdict on
    an infeasible one."""
    from planners.cog_qp import WarmStartQP

    def solve_qp(H, g, C, lo):
        import quadprog

        n = np.linalg.norm(C, axis=1)
        live = n > 0
        if np.any(lo[~live] > 0):
            return None  # 0 >= positive bound
        try:
            return quadprog.solve_qp(H, -g, (C[live] / n[live, None]).T, lo[live] / n[live], 0)[0]
        except ValueError:
            return None

    red = _Reduced(make_problem(40.0))
    red.bound = 40.0
    red.set_samples([np.linspace(0, 1, 12)] * 7)
    qp = WarmStartQP(red.H, red.g)
    z = np.linalg.solve(red.H, -red.g)
    for _ in range(6):
        h, J = red.constraints(z)
        lo = red.bound - h + J @ z
        x_full = solve_qp(red.H, red.g, J, lo)
        x = qp.solve(J, lo, z)
        assert x_full is not None and x is not None
        np.testing.assert_allclose(x, x_full, atol=1e-8 * max(1.0, np.abs(x_full).max()))
        z = x
    assert qp.shortcuts >= 2  # the converging SQP keeps its active set
    assert 0 < qp.active.sum() < len(lo)
    # a random linearisation point: the guess fails its checks, the working set finds the optimum
    z_far = rng.normal(scale=0.05, size=z.shape)
    h, J = red.constraints(z_far)
    lo = red.bound - h + J @ z_far
    np.testing.assert_allclose(qp.solve(J, lo, z_far), solve_qp(red.H, red.g, J, lo), atol=1e-8)
    # an impossible margin: both infeasible
    assert solve_qp(red.H, red.g, J, lo + 1e3) is None
    assert qp.solve(J, lo + 1e3, z_far) is None


def test_refinements_start_from_the_active_rows_and_give_the_cold_solvers_path(monkeypatch):
    """With 4 samples per phase the dense check refines several times, each refinement's first QP starting
    from the rows active before it, each later QP from the previous one's: fewer solver calls, and the path
    of QPs that all start cold, to 1e-9 m."""
    import planners.cog_qp as cog_qp

    calls = []
    solver = cog_qp.solve_qp_active
    monkeypatch.setattr(cog_qp, "solve_qp_active", lambda *a: calls.append(1) or solver(*a))
    prob = make_problem(40.0)
    warm, stats = plan_cog(prob, samples_per_phase=4)
    warm_calls = len(calls)
    assert stats.refinements >= 2

    original = cog_qp.WarmStartQP.solve

    def cold(self, C, lo, z):
        self.active = None
        return original(self, C, lo, z)

    monkeypatch.setattr(cog_qp.WarmStartQP, "solve", cold)
    calls.clear()
    cold_path, cold_stats = plan_cog(prob, samples_per_phase=4)
    assert cold_stats.refinements == stats.refinements
    assert warm_calls < len(calls)
    t = np.linspace(0, prob.t_knots[-1], 301)
    np.testing.assert_allclose(warm.position(t), cold_path.position(t), atol=1e-9)


def test_active_rows_carried_into_a_refined_layout_are_the_same_constraints():
    """Rows named (phase, sample time, edge or reach leg) in one sample layout are found in a refined layout
    (samples added between them): each carried row has the old row's moment and Jacobian, stability and
    reach rows of a yawing body alike."""
    prob = with_reach(make_problem(40.0), _rot_z)
    old = _Reduced(prob)
    old.bound = 40.0
    samples = [np.linspace(0, 1, 5)] * 7
    old.set_samples(samples)
    new = _Reduced(prob)
    new.bound = 40.0
    new.set_samples([np.unique(np.concatenate([s, [0.13, 0.61]])) for s in samples])
    z = np.random.default_rng(3).normal(scale=0.02, size=3 * old.m)
    h_old, J_old = old.constraints(z)
    h_new, J_new = new.constraints(z)
    chosen = np.zeros(old.n_rows, dtype=bool)
    chosen[::7] = True
    assert any(old.locate(i)[1].startswith("reach") for i in np.flatnonzero(chosen))
    mapped = new.rows_of(frozenset(old.row_keys[i] for i in np.flatnonzero(chosen)))
    assert mapped.sum() == chosen.sum() and new.n_rows > old.n_rows
    np.testing.assert_array_equal(h_new[mapped], h_old[chosen])
    np.testing.assert_array_equal(J_new[mapped], J_old[chosen])
    assert [new.locate(i) for i in np.flatnonzero(mapped)] == [old.locate(i) for i in np.flatnonzero(chosen)]
