"""The compiled contact-force QP solver (agents.control.qp_kernels) against DAQP, the reference."""

from __future__ import annotations

import daqp
import gymnasium as gym
import numpy as np
import pytest

import quad_uneven_env  # noqa: F401  (registers QuadUneven-v0)
from agents.control import inverse_dynamics as ID
from agents.control import inverse_dynamics_kernels as IK
from agents.control import qp_kernels as QK
from agents.expert import ExpertConfig, attach_expert

LOWER = np.array([0.0, 0.0, 0.0, 0.0, 5.0])
STAIRS = {"kind": "stairs", "riser": 0.08, "direction": "down"}


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _problem(rng, p, wrench_scale=1.0, tilt=0.3, mu=0.5, feet=None):
    """A problem shaped like the controller's: H = blockdiag(J_L J_L^T) + 1e-9 I, A = [I; skew(foot)] per
    foot (the base wrench), b about the weight of 50 kg, cones of random normals, g = -H F0 (F0 off the cones)."""
    n = 3 * p
    H, A = np.zeros((n, n)), np.zeros((6, n))
    feet = rng.normal(0.0, 0.3, (p, 3)) if feet is None else feet
    for k in range(p):
        JL = rng.normal(0.0, 0.2, (3, 3)) + 0.2 * np.eye(3)
        H[3 * k : 3 * k + 3, 3 * k : 3 * k + 3] = JL @ JL.T
        A[:3, 3 * k : 3 * k + 3] = np.eye(3)
        A[3:, 3 * k : 3 * k + 3] = _skew(feet[k] - [0.0, 0.0, 0.3])
    H += 1e-9 * np.eye(n)
    b = rng.normal(0.0, 1.0, 6) * wrench_scale * np.array([50.0, 50.0, 50.0, 20.0, 20.0, 20.0])
    b[2] += 490.0
    F0 = np.linalg.lstsq(A, b, rcond=None)[0] + rng.normal(0.0, 30.0, n)
    normals = rng.normal(0.0, tilt, (p, 3))
    normals[:, 2] = 1.0
    cones = np.empty((p, 5, 3))
    IK.friction_pyramid_into(normals, mu, cones)
    C, l = np.zeros((5 * p, n)), np.tile(LOWER, p)
    for k in range(p):
        C[5 * k : 5 * k + 5, 3 * k : 3 * k + 3] = cones[k]
    return H, -H @ F0, A, b, C, l


def _daqp(H, g, A, b, C, l):
    """DAQP as the controller calls it: x, or None unless solved."""
    rows = np.vstack([A, C])
    sense = np.zeros(len(rows), dtype=np.int32)
    sense[: len(b)] = 5
    up, lo = np.concatenate([b, np.full(len(l), 1e30)]), np.concatenate([b, l])
    x, _, flag, _ = daqp.solve(H, g, rows, up, lo, sense, primal_tol=1e-9, iter_limit=200)
    return np.asarray(x) if flag == 1 else None


def _compiled(H, g, A, b, C, l):
    x = np.empty(len(g))
    return QK.solve_qp(H, g, A, b, C, l, x), x


def _relaxed(H, g, A, b):
    Hr, gr = np.empty_like(H), np.empty_like(g)
    QK.relaxed_problem_into(H, g, A, b, Hr, gr)
    return Hr, gr


def _assert_same(problem, atol=0.0):
    """The compiled solver gives DAQP's verdict and solution (1e-8 relative, or ``atol`` N)."""
    H, g, A, b, C, l = problem
    ref = _daqp(H, g, A, b, C, l)
    status, x = _compiled(H, g, A, b, C, l)
    assert status != QK.QP_FAILED
    assert (status == QK.QP_SOLVED) == (ref is not None), (status, ref)
    if ref is not None:
        np.testing.assert_allclose(x, ref, rtol=0, atol=max(atol, 1e-8 * max(1.0, np.abs(ref).max())))
        assert (C @ x >= l - 1e-9).all() and (np.abs(A @ x - b) < 1e-9 * np.abs(b).max(initial=1.0)).all()
    return status


def test_matches_the_reference_on_a_known_problem():
    """Equality and inequality rows, one inequality active at the optimum: x = (0.5, 0.5, 1) by hand."""
    H, g = np.eye(3), np.array([0.0, 0.0, -1.0])
    A, b = np.array([[1.0, 1.0, 0.0]]), np.array([1.0])
    C, l = np.array([[0.0, 0.0, -1.0], [1.0, -1.0, 0.0]]), np.array([-1.0, 0.0])
    status, x = _compiled(H, g, A, b, C, l)
    assert status == QK.QP_SOLVED
    np.testing.assert_allclose(x, [0.5, 0.5, 1.0], atol=1e-14)
    status, _ = _compiled(H, g, A, b, np.vstack([C, [[-1.0, -1.0, 0.0]]]), np.array([-1.0, 0.0, -0.5]))
    assert status == QK.QP_INFEASIBLE  # x1 + x2 = 1 and x1 + x2 <= 0.5


@pytest.mark.parametrize("p", [3, 4])
def test_random_problems_give_daqps_verdict_and_solution(p):
    rng = np.random.default_rng(p)
    verdicts = []
    for i in range(2000):
        scale, tilt = (0.3, 1.0, 2.0, 6.0)[i % 4], (0.0, 0.2, 0.5)[i % 3]
        problem = _problem(rng, p, scale, tilt)
        verdicts.append(_assert_same(problem))
        H, g, A, b, C, _ = problem
        Hr, gr = _relaxed(H, g, A, b)  # always feasible: x = 0 is
        assert _assert_same((Hr, gr, A[:0], b[:0], C, np.zeros(len(C))), atol=1e-9) == QK.QP_SOLVED
    assert 200 < verdicts.count(QK.QP_SOLVED) < 1800  # both verdicts are exercised


@pytest.mark.parametrize("p", [3, 4])
def test_hard_problems(p):
    """Near-active and degenerate rows, steep cones, the relaxed problem's apex, collinear feet."""
    rng = np.random.default_rng(10 + p)
    for _ in range(300):
        H, g, A, b, C, l = _problem(rng, p, 1.0, 0.2)
        x = _daqp(H, g, A, b, C, l)
        if x is None:
            continue
        # pinv forces a hair outside the optimum's active faces: the optimum barely moves
        for eps in (1e-12, 1e-9, 1e-6):
            _assert_same((H, -H @ (x + eps * rng.normal(size=len(x))), A, b, C, l))
        # every row duplicated (each active one twice), and the pyramid rows of the optimum made exactly active
        _assert_same((H, g, A, b, np.vstack([C, C]), np.concatenate([l, l])))
        _assert_same((H, g, A, b, C, np.minimum(l, C @ x)))
    for tilt in (0.6, 0.8, 1.0):  # steep footholds: mostly infeasible
        for _ in range(100):
            _assert_same(_problem(rng, p, 1.0, tilt))
    for _ in range(100):  # the base pulled down faster than free fall: relaxed optimum near every apex
        H, g, A, b, C, l = _problem(rng, p)
        b[:3] = [0.0, 0.0, -200.0]
        assert _assert_same((H, g, A, b, C, l)) == QK.QP_INFEASIBLE
        Hr, gr = _relaxed(H, g, A, b)
        _assert_same((Hr, gr, A[:0], b[:0], C, np.zeros(len(C))), atol=1e-9)
    feet = np.zeros((p, 3))
    feet[:, 0] = np.linspace(-0.3, 0.3, p)  # collinear feet: the base rows lose rank
    for _ in range(20):
        H, g, A, b, C, l = _problem(rng, p, feet=feet)
        status, _ = _compiled(H, g, A, b, C, l)
        assert status in (QK.QP_FAILED, QK.QP_INFEASIBLE, QK.QP_SOLVED)
        if status == QK.QP_SOLVED:  # then it must be right
            _assert_same((H, g, A, b, C, l))


def test_iteration_cap_and_bad_inputs_report_failure():
    H, g, A, b, C, l = _problem(np.random.default_rng(0), 4)
    x = np.empty(12)
    assert QK.solve_qp(-H, g, A, b, C, l, x) == QK.QP_FAILED  # not positive definite
    assert QK.solve_qp(H, g, np.vstack([A, A[:1]]), np.append(b, b[0]), C, l, x) == QK.QP_FAILED  # dependent rows
    assert QK.QP_MAX_ITER >= 50


def _recorded_problems(terrain, seconds, monkeypatch):
    """(problem, DAQP's x or None) of every QP the expert solved with qp_solver="daqp" in a rollout."""
    found = []
    solve, relaxed = ID._StanceQP.solve, ID._StanceQP.solve_relaxed

    def record(self):
        x = solve(self)
        found.append((tuple(a.copy() for a in self.problem), x))
        return x

    def record_relaxed(self, H, g):
        x = relaxed(self, H, g)
        C = self.problem[4]
        found.append(((H.copy(), g.copy(), np.zeros((0, len(g))), np.zeros(0), C.copy(), np.zeros(len(C))), x))
        return x

    monkeypatch.setattr(ID._StanceQP, "solve", record)
    monkeypatch.setattr(ID._StanceQP, "solve_relaxed", record_relaxed)
    env = gym.make("QuadUneven-v0", terrain=terrain, max_episode_steps=10**6)
    policy = attach_expert(env, ExpertConfig())
    policy.controller.qp_solver = "daqp"
    obs, _ = env.reset(seed=0)
    for _ in range(int(seconds / env.unwrapped.dt)):
        obs, *_ = env.step(policy.predict(obs)[0])
    monkeypatch.undo()
    return found


@pytest.mark.parametrize("terrain", ["rough", STAIRS])
def test_problems_recorded_from_the_expert_match_daqp(terrain, monkeypatch):
    found = _recorded_problems(terrain, 2.0, monkeypatch)
    assert len(found) > 100
    sizes = set()
    for problem, ref in found:
        status, x = _compiled(*problem)
        assert status != QK.QP_FAILED
        assert (status == QK.QP_SOLVED) == (ref is not None)
        if ref is not None:
            np.testing.assert_allclose(x, ref, rtol=0, atol=1e-8 * max(1.0, np.abs(ref).max()))
        sizes.add(len(x))
    assert 9 in sizes


def test_a_failed_compiled_solve_falls_back_to_daqp(monkeypatch):
    """QP_FAILED (e.g. the iteration cap): InverseDynamics solves the same problem with DAQP."""
    from quad_uneven_env.robot.dynamics import make_dynamics

    env = gym.make("QuadUneven-v0", terrain="flat")
    env.reset(seed=0)
    m, d = env.unwrapped.model, env.unwrapped.data

    def make(distribution, solver="compiled"):
        return ID.InverseDynamics(make_dynamics("mujoco", m), distribution, qp_solver=solver)

    stance = (True,) * 4
    pushes = (([6.0, 3.0, 0, 0, 0, 0], False), ([12.0, 0, 0, 0, 0, 0], True), ([0, 0, -15.0, 0, 0, 0], True))
    for bdd, relaxed in pushes:
        bdd = np.array(bdd)  # base accelerations the pinv forces cannot give inside the cones
        ref = make("qp", "daqp").solve(d.qpos, d.qvel, bdd, stance)
        pinv = make("pinv").solve(d.qpos, d.qvel, bdd, stance)
        assert np.abs(ref.tau - pinv.tau).max() > 1.0 and ref.relaxed == relaxed, "the QP was not active"
        for failing in (False, True):
            with monkeypatch.context() as patch:
                if failing:
                    patch.setattr(ID.QK, "distribute_qp", lambda *a: QK.QP_FAILED)
                got = make("qp").solve(d.qpos, d.qvel, bdd, stance)
            np.testing.assert_allclose(got.tau, ref.tau, rtol=0, atol=1e-8)
            np.testing.assert_allclose(got.contact_forces, ref.contact_forces, rtol=0, atol=1e-7)
            assert (got.distribution, got.relaxed, got.qp_fallback) == ("qp", relaxed, False)


def test_a_problem_infeasible_in_narrow_cones_is_solved_in_the_wide_ones():
    """Cones of 0.25 cannot give a forward base acceleration of 3 m/s^2 on four feet; both solvers then solve it
    with cones of ``wide_mu(0.25)`` = 0.5: the optimum of a QP built with cones of 0.5. At 4 m/s^2 those cannot
    either: the relaxed problem in the wide cones, as a QP built with cones of 0.5 relaxes it."""
    from quad_uneven_env.robot.dynamics.base import make_dynamics

    assert [QK.wide_mu(mu) for mu in (0.07, 0.25, 0.4, 0.5, 0.8)] == [0.14, 0.5, 0.5, 0.5, 0.8]
    env = gym.make("QuadUneven-v0", terrain="flat")
    env.reset(seed=0)
    m, d = env.unwrapped.model, env.unwrapped.data

    def solve(mu, solver, ax):
        return ID.InverseDynamics(make_dynamics("mujoco", m), "qp", qp_solver=solver, mu=mu).solve(
            d.qpos, d.qvel, np.array([ax, 0.0, 0.0, 0.0, 0.0, 0.0]), (True,) * 4
        )

    for ax, relaxed in ((3.0, False), (4.0, True)):
        wide = solve(0.5, "daqp", ax)
        assert wide.relaxed == relaxed
        for solver in ("compiled", "daqp"):
            got = solve(0.25, solver, ax)
            assert (got.distribution, got.relaxed) == ("qp", relaxed)
            np.testing.assert_allclose(got.tau, wide.tau, rtol=0, atol=1e-7)
            np.testing.assert_allclose(got.contact_forces, wide.contact_forces, rtol=0, atol=1e-6)
