"""Stability-constrained COG path (paper §4): one 8th-order polynomial per phase per axis.

Problem (eq. 25), per gait cycle of K = 7 phases:

    min  sum_j (P(t_j) - P_des,j)^T W (P(t_j) - P_des,j) + lambda * int |P''(t)|^2 dt
    s.t. P, P', P'' continuous at the 6 junctions t_j               (C², equalities)
         P, P', P'' given at the start and end of the cycle         (equalities)
         kappa_e . ((P - p_e) x F) >= epsilon on every edge e of each phase's support polygon,
         F = -m (P'' + g e_z), at sample times of every phase         (stability, eq. 20-22)

The small ``lambda`` term (not in the paper) makes the path unique between the junctions: the
paper's cost only sees the six junction points. The equalities are eliminated exactly (null
space of the 24 linear conditions per axis), so continuity holds to rounding error. The
stability constraint is bilinear in the coefficients (P x P''); it is solved by sequential
quadratic programming with analytic constraint Jacobians (compiled: :mod:`planners.cog_kernels`) and
DAQP, a dual active-set solver with an iteration limit, each QP warm-started from the previous one's active set
(:mod:`planners.cog_qp`: the same optimum), or, as the baseline, by
``scipy.optimize.minimize(method="SLSQP")`` with analytic or finite-difference gradients. After
solving, the index is checked on a dense grid; sample times where it dips below ``epsilon`` are
added and the problem re-solved. Infeasibility raises
:class:`~planners.types.PlanningError` naming the phase, the edge and the violation.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Sequence
from functools import lru_cache

import numpy as np
import scipy.linalg
import scipy.optimize

from planners import cog_kernels as CK
from planners.blas import single_blas_thread
from planners.cog_qp import WarmStartQP, whitening
from planners.polynomial import N_COEF, PiecewisePolynomial, accel_gram, basis_rows
from planners.types import PlanningError
from quad_uneven_env.fields import excerpt
from quad_uneven_env.spatial import cross
from quad_uneven_env.stability import GRAVITY, order_clockwise

N_AXES = 3


@dataclasses.dataclass(frozen=True)
class CogProblem:
    """One gait cycle's COG planning problem (SI units, world frame, times from the cycle start)."""

    t_knots: np.ndarray
    """(K + 1,) phase boundaries (s)."""
    supports: Sequence[np.ndarray]
    """per phase, the stance footholds (n_k x 3, m) spanning its support polygon (any order)."""
    support_names: Sequence[Sequence[str]]
    """per phase, the leg names of ``supports`` (to name edges in errors)."""
    targets: np.ndarray
    """(K - 1, 3) desired COG positions at the junctions (m)."""
    start: np.ndarray
    """(3, 3) COG position, velocity, acceleration at the start (m, m/s, m/s^2)."""
    end: np.ndarray
    """(3, 3) the same at the end of the cycle."""
    mass: float
    """robot mass (kg)."""
    epsilon: float
    """stability margin (N m)."""
    weights: tuple[float, float, float] = (1.0, 1.0, 1.0)
    """diagonal of W (1/m^2) for x, y, z."""
    smoothing: float = 1e-3
    """lambda (s^3/m^2): weight of the integrated squared acceleration."""
    phase_names: Sequence[str] | None = None
    """optional names of the phases for error messages."""
    reach_sites: Sequence[np.ndarray] | None = None
    """optional, per phase: stance foot sites (n_k x 3, m, same order as ``supports``) that must stay in reach."""
    reach_offsets: Sequence[np.ndarray] | None = None
    """per phase: hip position minus COG (n_k x 3, m) of those legs (nominal whole-body COM offset),
    in the base frame (the world frame when ``reach_rotation`` is None)."""
    max_reach: float = np.inf
    """largest hip-to-foot-site distance (m) of a stance leg (keeps the knees off the stretched singularity)."""
    reach_rotation: Callable[[np.ndarray], np.ndarray] | None = None
    """optional base orientation ``R_WB(t)`` (S, 3, 3) at absolute times ``t`` (S,) (s) that turns
    ``reach_offsets`` into the world frame (a pitching body); None: identity."""


@dataclasses.dataclass
class CogStats:
    """How the solve went."""

    solve_time: float = 0.0
    """wall time (s)."""
    iterations: int = 0
    """SQP iterations (QP solves) or SLSQP iterations."""
    refinements: int = 0
    """dense-check rounds that added sample times."""
    min_stability: float = np.inf
    """smallest stability index (N m) on the dense check grid."""
    n_constraints: int = 0
    """sampled inequality constraints (stability edges and stance-leg reach) in the final problem."""
    method: str = ""
    """solver used."""


@lru_cache(maxsize=64)
def _equality_structure(durations: tuple[float, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-axis equality matrix A (24 x 9K) for the boundary and C² conditions, its null space and pseudo-inverse."""
    K = len(durations)
    n = K * N_COEF
    r0 = [basis_rows(np.array([0.0]), d)[0] for d in range(3)]
    r1 = [basis_rows(np.array([1.0]), d)[0] for d in range(3)]
    rows = []
    for d in range(3):  # start p, v, a
        row = np.zeros(n)
        row[:N_COEF] = r0[d] / durations[0] ** d
        rows.append(row)
    for d in range(3):  # end p, v, a
        row = np.zeros(n)
        row[-N_COEF:] = r1[d] / durations[-1] ** d
        rows.append(row)
    for k in range(K - 1):
        for d in range(3):
            row = np.zeros(n)
            row[k * N_COEF : (k + 1) * N_COEF] = r1[d] / durations[k] ** d
            row[(k + 1) * N_COEF : (k + 2) * N_COEF] = -r0[d] / durations[k + 1] ** d
            rows.append(row)
    A = np.array(rows)
    return A, scipy.linalg.null_space(A), np.linalg.pinv(A)


@lru_cache(maxsize=64)
def _cost_structure(durations: tuple[float, ...]) -> tuple[np.ndarray, np.ndarray]:
    """Junction selector R ((K-1) x 9K, position at each phase end) and acceleration Gram G (9K x 9K)."""
    K = len(durations)
    r1 = basis_rows(np.array([1.0]), 0)[0]
    R = np.zeros((K - 1, K * N_COEF))
    for k in range(K - 1):
        R[k, k * N_COEF : (k + 1) * N_COEF] = r1
    G = scipy.linalg.block_diag(*[accel_gram() / T**3 for T in durations])
    return R, G


@lru_cache(maxsize=64)
def _hessian(
    durations: tuple[float, ...], weights: tuple[float, float, float], smoothing: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The cost's Hessian H (3m x 3m) in the null-space variables, its inverse and its whitening ``L^-1``
    (:func:`planners.cog_qp.whitening`) (shared: never write to them; they depend on the phase durations and
    the weights only, not on the footholds or the targets)."""
    _, N, _ = _equality_structure(durations)
    R, G = _cost_structure(durations)
    RN, GN = R @ N, G @ N
    m = N.shape[1]
    H = np.zeros((N_AXES * m, N_AXES * m))
    for a in range(N_AXES):
        sl = slice(a * m, (a + 1) * m)
        H[sl, sl] = 2.0 * (weights[a] * RN.T @ RN + smoothing * N.T @ GN)
    H += 1e-12 * np.eye(H.shape[0])
    Hinv = np.linalg.inv(H)
    Hinv.setflags(write=False)  # H stays writable: quadprog (the tests' reference solver) refuses a read-only one
    return H, Hinv, whitening(H)


class _Reduced:
    """The problem in the null-space variables z (3 axes x m): x_axis = x0_axis + N z_axis."""

    def __init__(self, prob: CogProblem) -> None:
        self.prob = prob
        self.durations = tuple(float(d) for d in np.diff(prob.t_knots))
        self.K = len(self.durations)
        A, N, Apinv = _equality_structure(self.durations)
        self.N = N
        self.m = N.shape[1]
        b = np.zeros((A.shape[0], N_AXES))
        b[0:3] = prob.start
        b[3:6] = prob.end
        self.x0 = Apinv @ b  # (9K, 3)
        R, G = _cost_structure(self.durations)
        w = np.asarray(prob.weights, dtype=float)
        lam = prob.smoothing
        RN, GN = R @ N, G @ N
        g = np.zeros(N_AXES * self.m)
        for a in range(N_AXES):
            sl = slice(a * self.m, (a + 1) * self.m)
            g[sl] = 2.0 * (w[a] * RN.T @ (R @ self.x0[:, a] - prob.targets[:, a]) + lam * GN.T @ self.x0[:, a])
        self.H, self.Hinv, self.Linv = _hessian(self.durations, tuple(float(v) for v in w), float(lam))
        self.g = g
        self.const = float(sum(w[a] * np.sum((R @ self.x0[:, a] - prob.targets[:, a]) ** 2) for a in range(N_AXES)))
        # Support polygon edges per phase (clockwise seen from above).
        self.edges = []
        for feet, names in zip(prob.supports, prob.support_names, strict=True):
            feet = np.asarray(feet, dtype=float)
            order = order_clockwise(feet)
            p = feet[order]
            e = np.roll(p, -1, axis=0) - p
            kappa = e / np.linalg.norm(e, axis=1, keepdims=True)
            labels = [f"{names[i]}->{names[j]}" for i, j in zip(order, np.roll(order, -1), strict=True)]
            self.edges.append((p, kappa, labels))
        self.samples: list[np.ndarray] = []
        self.reach = prob.reach_sites is not None and np.isfinite(prob.max_reach)
        self.reach_scale = prob.mass * GRAVITY  # N m per m: reach rows share the moments' scale

    def coef(self, z: np.ndarray) -> np.ndarray:
        """(K, 9, 3) Bernstein coefficients for the reduced variables z."""
        x = self.x0 + self.N @ z.reshape(N_AXES, self.m).T
        return x.reshape(self.K, N_COEF, N_AXES)

    def set_samples(self, samples: list[np.ndarray]) -> None:
        """Local sample times per phase; precompute the basis rows mapped through the null space."""
        self.samples = samples
        self.rows = []
        for k, s in enumerate(samples):
            Nk = self.N[k * N_COEF : (k + 1) * N_COEF]
            T = self.durations[k]
            B0, B2 = _sample_rows(s)
            self.rows.append((B0 @ Nk, B2 @ Nk / T**2, B0, B2 / T**2))
        if self.reach:
            self.offsets_W = [np.ascontiguousarray(self._world_offsets(k, s)) for k, s in enumerate(samples)]
            self._reach_sites = [np.ascontiguousarray(r, dtype=float) for r in self.prob.reach_sites]
        legs = [len(e[0]) + (len(self._reach_sites[k]) if self.reach else 0) for k, e in enumerate(self.edges)]
        self.n_rows = sum(len(s) * n for s, n in zip(samples, legs, strict=True))
        self.row_keys = self._row_keys()

    def _row_keys(self) -> list[tuple[int, float, str]]:
        """(phase, local sample time, constraint label) of every stacked row, in :meth:`constraints`' order."""
        keys = []
        for k, s in enumerate(self.samples):
            times = [round(float(t), 9) for t in s]
            keys += [(k, t, label) for t in times for label in self.edges[k][2]]
            if self.reach:
                keys += [(k, t, f"reach {leg}") for t in times for leg in self.prob.support_names[k]]
        return keys

    def rows_of(self, keys: frozenset[tuple[int, float, str]]) -> np.ndarray:
        """bool (n_rows,): the rows named in ``keys`` (names of rows not in this layout are ignored)."""
        return np.fromiter((key in keys for key in self.row_keys), dtype=bool, count=self.n_rows)

    def _world_offsets(self, k: int, s: np.ndarray) -> np.ndarray:
        """(S or 1, n_k, 3) hip-minus-COG offsets (m, world) of phase ``k`` at local times ``s``."""
        off = np.asarray(self.prob.reach_offsets[k], dtype=float)
        rot = self.prob.reach_rotation
        if rot is None:
            return off[None]
        t = self.prob.t_knots[k] + np.asarray(s) * self.durations[k]
        return np.einsum("sij,lj->sli", rot(t), off)

    def constraints(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Tumbling moments h (n_con,) at the samples and their Jacobian dh/dz (n_con x 3m), exact
        (compiled, :mod:`planners.cog_kernels`; the numpy form is :meth:`constraints_numpy`).

        Rows per phase: its stability rows (sample-major, then edge), then its reach rows (sample, leg).
        """
        coef = np.ascontiguousarray(self.coef(z))
        h = np.empty(self.n_rows)
        J = np.empty((self.n_rows, N_AXES * self.m))
        m, g = float(self.prob.mass), GRAVITY
        i = 0
        for k in range(self.K):
            Bv, Ba, P0, A0 = self.rows[k]
            p, kappa, _ = self.edges[k]
            n = P0.shape[0] * p.shape[0]
            CK.stability_rows_into(P0, A0, Bv, Ba, coef[k], p, kappa, m, g, h[i : i + n], J[i : i + n])
            i += n
            if self.reach:
                sites = self._reach_sites[k]
                n = P0.shape[0] * sites.shape[0]
                CK.reach_rows_into(
                    P0, Bv, coef[k], self.offsets_W[k], sites, float(self.prob.max_reach), float(self.bound),
                    float(self.reach_scale), h[i : i + n], J[i : i + n],
                )  # fmt: skip
                i += n
        return h, J

    def constraints_numpy(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`constraints` in numpy (the reference of the compiled rows)."""
        coef = self.coef(z)
        m, g = self.prob.mass, GRAVITY
        hs, Js = [], []
        for k in range(self.K):
            Bv, Ba, P0, A0 = self.rows[k]
            P = P0 @ coef[k]  # (S, 3)
            acc = A0 @ coef[k]
            F = -m * acc
            F[:, 2] -= m * g
            p, kappa, _ = self.edges[k]
            r = P[:, None, :] - p[None]  # (S, E, 3)
            h = (kappa[None] * cross(r, F[:, None, :])).sum(axis=-1)
            gP = cross(F[:, None, :], kappa[None])  # d h / d P
            ga = -m * cross(kappa[None], r)  # d h / d P''
            J = gP[..., None] * Bv[:, None, None, :] + ga[..., None] * Ba[:, None, None, :]
            hs.append(h.ravel())
            Js.append(J.reshape(-1, N_AXES * self.m))
            if self.reach:
                d = P[:, None, :] + self.offsets_W[k] - self.prob.reach_sites[k][None]  # (S, L, 3)
                dist = np.linalg.norm(d, axis=-1)
                n = d / dist[..., None]
                # bound + scale (max_reach - |d|) >= bound  <=>  |d| <= max_reach
                hs.append((self.bound + self.reach_scale * (self.prob.max_reach - dist)).ravel())
                Js.append((-self.reach_scale * n[..., None] * Bv[:, None, None, :]).reshape(-1, N_AXES * self.m))
        return np.concatenate(hs), np.concatenate(Js)

    def locate(self, index: int) -> tuple[int, str]:
        """Phase and constraint label (support edge "LF->RF" or "reach LF") of stacked constraint ``index``."""
        k, _, label = self.row_keys[index]
        return k, label


def _sample_rows(s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Bernstein rows (S, 9) of the position and the second derivative at local times ``s`` (S,) (read-only,
    cached: every plan uses the same uniform sample grids)."""
    return _sample_rows_of(np.asarray(s, dtype=float).tobytes())


@lru_cache(maxsize=256)
def _sample_rows_of(key: bytes) -> tuple[np.ndarray, np.ndarray]:
    s = np.frombuffer(key)
    rows = basis_rows(s, 0), basis_rows(s, 2)
    for r in rows:
        r.setflags(write=False)
    return rows


def _dense_index(red: _Reduced, coef: np.ndarray, n: int = 241) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per phase: dense local times and the tumbling moments (S, E) on them."""
    s = np.linspace(0.0, 1.0, n)
    B0, B2 = _sample_rows(s)
    out = []
    for k in range(red.K):
        T = red.durations[k]
        P = B0 @ coef[k]
        acc = B2 @ coef[k] / T**2
        F = -red.prob.mass * acc
        F[:, 2] -= red.prob.mass * GRAVITY
        p, kappa, _ = red.edges[k]
        h = (kappa[None] * cross(P[:, None, :] - p[None], F[:, None, :])).sum(axis=-1)
        out.append((s, h))
    return out


def _infeasible(red: _Reduced, z: np.ndarray, bound: float, what: str, rows: np.ndarray | None = None) -> PlanningError:
    h, _ = red.constraints(z)
    i = int(np.argmin(np.where(rows, h, np.inf) if rows is not None else h))
    k, label = red.locate(i)
    name = red.prob.phase_names[k] if red.prob.phase_names else f"phase {k}"
    if label.startswith("reach"):
        dist = red.prob.max_reach - (h[i] - bound) / red.reach_scale
        return PlanningError(
            f"COG path infeasible ({what}): {name}, {label}: hip-to-foot distance {dist:.4f} m "
            f"> max reach {red.prob.max_reach:.4f} m (violation {dist - red.prob.max_reach:.4f} m)"
        )
    return PlanningError(
        f"COG path infeasible ({what}): {name}, support edge {label}: stability moment {h[i]:.4f} N m "
        f"< required {bound:.4f} N m (violation {bound - h[i]:.4f} N m)"
    )


def _least_violating(C: np.ndarray, lo: np.ndarray, z: np.ndarray) -> np.ndarray:
    """The z maximising the smallest slack of C z >= lo (an LP, HiGHS): where an infeasible problem fails least."""
    n = C.shape[1]
    cost = np.zeros(n + 1)
    cost[-1] = -1.0
    A = np.hstack([-C, np.ones((C.shape[0], 1))])  # t - C z <= -lo
    res = scipy.optimize.linprog(
        cost, A_ub=A, b_ub=-lo, bounds=[(-10.0, 10.0)] * n + [(None, 1e3)], method="highs"
    )  # fmt: skip
    return res.x[:n] if res.status == 0 else z


def _sqp(
    red: _Reduced, z: np.ndarray, bound: float, stats: CogStats, qp: WarmStartQP, max_iter: int = 30
) -> np.ndarray:
    h, J = red.constraints(z)
    if h.min() >= bound:  # the best unconstrained path is already stable
        return z
    # Rows the variables cannot move (the given start and end states): check them, then drop them,
    # so a measured start state between epsilon and epsilon + margin stays plannable.
    fixed = np.abs(J).max(axis=1) < 1e-12
    if np.any(fixed & (h < red.prob.epsilon)):
        raise _infeasible(red, z, red.prob.epsilon, "the given start or end state itself", fixed)
    for _ in range(max_iter):
        lo = np.where(fixed, -1e20, bound - h + J @ z)
        z_new = qp.solve(J, lo, z)
        stats.iterations += 1
        if z_new is None:
            raise _infeasible(red, _least_violating(J, lo, z), bound, "no stable path in the linearised problem")
        step = np.abs(z_new - z).max()
        z = z_new
        h, J = red.constraints(z)
        if h[~fixed].min() >= bound - 1e-5 and step < 1e-4:
            return z
    if h[~fixed].min() < bound - 1e-4:
        raise _infeasible(red, z, bound, f"SQP did not converge in {max_iter} iterations")
    return z


def _slsqp(red: _Reduced, z: np.ndarray, bound: float, stats: CogStats, finite_difference: bool) -> np.ndarray:
    def fun(v):
        return 0.5 * v @ red.H @ v + red.g @ v

    def jac(v):
        return red.H @ v + red.g

    cons = {"type": "ineq", "fun": lambda v: red.constraints(v)[0] - bound}
    if not finite_difference:
        cons["jac"] = lambda v: red.constraints(v)[1]
    res = scipy.optimize.minimize(
        fun, z, jac=None if finite_difference else jac, constraints=[cons], method="SLSQP",
        options={"maxiter": 500, "ftol": 1e-12},
    )  # fmt: skip
    stats.iterations += int(res.nit)
    if not res.success:
        raise _infeasible(red, res.x, bound, f"SLSQP: {res.message}")
    return res.x


@single_blas_thread
def plan_cog(
    prob: CogProblem,
    method: str = "sqp",
    samples_per_phase: int = 12,
    margin: float | None = None,
    max_refinements: int = 6,
) -> tuple[PiecewisePolynomial, CogStats]:
    """Solve the COG problem; returns the path and solver statistics.

    :param method: ``"sqp"`` (sequential QP on DAQP, default), ``"slsqp"`` (scipy, analytic
        gradients) or ``"slsqp-fd"`` (scipy with finite-difference gradients, the reference).
    :param samples_per_phase: initial stability sample times per phase (uniform in local time).
    :param margin: extra moment (N m) enforced at the samples above ``epsilon``; default
        ``1e-3 m g`` (1 mm of static margin), so the dense check rarely needs a refinement.
    :raises PlanningError: naming the phase, the support edge and the violation when infeasible.
    """
    if method not in ("sqp", "slsqp", "slsqp-fd"):
        raise ValueError(f"method must be 'sqp', 'slsqp' or 'slsqp-fd', got {excerpt(method)}")
    t0 = time.perf_counter()
    stats = CogStats(method=method)
    red = _Reduced(prob)
    margin = 1e-3 * prob.mass * GRAVITY if margin is None else margin
    bound = prob.epsilon + margin
    red.bound = bound
    samples = [np.linspace(0.0, 1.0, samples_per_phase) for _ in range(red.K)]
    red.set_samples(samples)
    z = np.linalg.solve(red.H, -red.g)  # best unconstrained path: the first linearisation point
    qp = WarmStartQP(red.H, red.g, red.Hinv, red.Linv)
    active: frozenset[tuple[int, float, str]] = frozenset()  # a refinement's QPs start from the rows active before it
    for it in range(max_refinements + 1):
        if method == "sqp":
            qp.active = red.rows_of(active)
            z = _sqp(red, z, bound, stats, qp)
            active = frozenset(red.row_keys[i] for i in np.flatnonzero(qp.active))
        else:
            z = _slsqp(red, z, bound, stats, finite_difference=(method == "slsqp-fd"))
        dense = _dense_index(red, red.coef(z))
        worst = min(float(h.min()) for _, h in dense)
        if worst >= prob.epsilon - 1e-9:
            break
        if it == max_refinements:
            k = int(np.argmin([h.min() for _, h in dense]))
            s, h = dense[k]
            i, e = np.unravel_index(np.argmin(h), h.shape)
            name = prob.phase_names[k] if prob.phase_names else f"phase {k}"
            raise PlanningError(
                f"COG path: {name}, support edge {red.edges[k][2][e]}: stability moment {h[i, e]:.4f} N m "
                f"< epsilon {prob.epsilon:.4f} N m at local time {s[i]:.3f} after {max_refinements} refinements"
            )
        stats.refinements += 1
        new = []
        for (s, h), old in zip(dense, samples, strict=True):
            v = np.pad(h.min(axis=1), 1, constant_values=np.inf)
            local_min = (v[1:-1] <= v[:-2]) & (v[1:-1] <= v[2:]) & (v[1:-1] < prob.epsilon)
            new.append(np.unique(np.concatenate([old, s[local_min]])))
        samples = new
        red.set_samples(samples)
    coef = red.coef(z)
    path = PiecewisePolynomial(prob.t_knots, coef)
    stats.min_stability = worst
    stats.n_constraints = len(red.constraints(z)[0])  # stability and stance-reach rows
    stats.solve_time = time.perf_counter() - t0
    return path, stats
