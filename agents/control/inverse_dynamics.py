"""Inverse dynamics on the constraint-eliminated model (paper §2.3, eq. 16-18).

Given the commanded ``beta_ddot`` (derivative of beta_dot in canonical velocity coordinates),
the full commanded acceleration is ``qacc = S beta_ddot + Sdot beta_dot`` and the torques solve
``S_a^T tau = rhs`` with ``rhs = M_beta beta_ddot + V_beta + G_beta = S^T (M qacc + h)``.

Structure used for speed (identical to the paper's formula): the base rows of S_a^T involve
only the stance legs' torques and a swing leg's rows are the identity, so S_a^T is block
diagonal after a permutation and its pseudo-inverse is the pseudo-inverse of each block:
``tau_swing = rhs_swing`` and ``tau_stance = A^# rhs_base`` with ``A = -[J_b,i^T J_L,i^-T]_i``
(6 x 3p). With 3 or 4 stance feet A has full row rank and ``A^# = A^T (A A^T)^-1``.

Contact forces: the printed eq. 18 uses only the six base rows, which leave F
under-determined with 3 or 4 stance feet (6 equations, 9 or 12 unknowns). Here F comes from
all 18 rows, ``J^T F = M qacc + h - B tau``: when the projected equation holds exactly
(2 or more stance feet with a consistent command), the residual lies in range(J^T) and the
leg rows ``J_L,i^T F_i = (M qacc + h - B tau)_i`` give F exactly; otherwise (0 or 1 stance
foot, or an unreachable base acceleration) F is the least-squares solution over all 18 rows
and ``result.exact`` is False.

Distributions: ``"pinv"`` is the paper's Moore-Penrose choice. ``"qp"`` picks, among all torques
solving eq. 16 (their null space only changes the internal contact forces), the one closest to
the pinv torques whose stance forces lie in a linearised friction cone (4-sided pyramid inside
the cone of the model's mu) with a minimum normal force. It is posed in the contact forces:
``min (F - F_pinv)^T W (F - F_pinv)`` (``W = blockdiag(J_L,i J_L,i^T)``, so the cost is
``|tau - tau_pinv|^2``) subject to the six base rows ``sum_i J_b,i^T F_i = (M qacc + h)_base``
and the cone rows; then ``tau_i = (M qacc + h)_i - J_L,i^T F_i``. Solver (``qp_solver``):
``"compiled"`` (default), a Goldfarb-Idnani dual active-set method compiled with the problem's fill
and the torques (:func:`agents.control.qp_kernels.distribute_qp`, one call); or ``"daqp"``, DAQP (a
dual active-set method for small dense QPs) through its Python wrapper, the reference it is tested
against and its fallback when it fails (iteration cap, degenerate step). Both are exact and report
infeasibility; the optimum is unique, so they agree to rounding. An infeasible problem is solved again with cones
of ``qp_kernels.wide_mu(mu)`` (twice as wide, at most 0.5) and, infeasible still, relaxed (see
``_relax``); an unsolved one falls back to "pinv" and sets ``result.qp_fallback``.
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import daqp
import mujoco
import numpy as np

from agents.control import inverse_dynamics_kernels as IK
from agents.control import qp_kernels as QK
from agents.control.elimination import (
    DAMPING,
    SINGULAR_SIGMA,
    ProjectedDynamics,
    StanceLayout,
    eliminate_constraints,
    layout_of,
)
from quad_uneven_env import constants as C
from quad_uneven_env.fields import excerpt
from quad_uneven_env.robot.dynamics.base import Dynamics, DynamicsTerms

DISTRIBUTIONS: tuple[str, ...] = ("pinv", "qp")
"""Allowed values of ``InverseDynamics(distribution=...)``."""

QP_SOLVERS: tuple[str, ...] = ("compiled", "daqp")
"""Allowed values of ``InverseDynamics(qp_solver=...)`` (module doc)."""


@dataclasses.dataclass
class IDResult:
    """Inverse-dynamics solution at one state (canonical coordinates, SI, world frame)."""

    tau: np.ndarray
    """(12,) joint torques (N m), JOINT_NAMES order."""
    contact_forces: np.ndarray
    """(4, 3) forces of the terrain on the feet (N, world frame); zeros for swing legs."""
    qacc: np.ndarray
    """(18,) commanded full acceleration S beta_ddot + Sdot beta_dot."""
    stance: tuple[bool, bool, bool, bool]
    """stance set used."""
    distribution: str
    """distribution actually used ("pinv" or "qp")."""
    qp_fallback: bool = False
    """"qp" was asked but infeasible or unsolved: the "pinv" torques were returned."""
    exact: bool = True
    """the projected equation (eq. 16) is solved exactly (False: least squares, e.g. < 2 stance feet)."""
    damped: bool = False
    """a stance leg Jacobian was singular and inverted with damping."""
    relaxed: bool = False
    """"qp" was infeasible with the commanded base acceleration: the forces closest to producing it
    inside the friction cones were used instead (the base acceleration is then not exact)."""


class IDWorkspace(NamedTuple):
    """Output buffers of the compiled inverse dynamics (:func:`inverse_dynamics_kernels.id_pinv`)."""

    tau: np.ndarray
    """(12,) joint torques (N m)."""
    F: np.ndarray
    """(4, 3) contact forces (N, world)."""
    qacc: np.ndarray
    """(18,) commanded full acceleration."""
    r: np.ndarray
    """(18,) M qacc + h."""
    Jinv: np.ndarray
    """(4, 3, 3) stance leg Jacobian inverses."""
    S: np.ndarray
    """(4, 3, 6) stance blocks of the elimination matrix S."""


class WorkspaceResult(NamedTuple):
    """A solution (pinv, or "qp" by the compiled step) still held in an :class:`InverseDynamics` workspace;
    :meth:`build` copies it out.

    The compiled step records this instead of copying every step; it is valid until the workspace is reused.
    """

    status: int
    """the kernel's status bits."""
    layout: StanceLayout
    """the stance layout solved for."""
    version: int
    """``workspace_version`` right after the solve."""
    relaxed: bool = False
    """the workspace holds the relaxed "qp" problem's solution (``IDResult.relaxed``)."""

    def build(self, inverse_dynamics: InverseDynamics, distribution: str) -> IDResult:
        """The :class:`IDResult` (``distribution`` as recorded).

        :raises RuntimeError: if the workspace was rewritten since.
        """
        if self.version != inverse_dynamics.workspace_version:
            raise RuntimeError(
                "controller.last: the inverse-dynamics buffers were reused since; read it right after the call"
            )
        result = inverse_dynamics.result_from_workspace(self.status, self.layout)
        result.distribution, result.relaxed = distribution, self.relaxed
        return result


def friction_pyramid(normal_W: np.ndarray, mu: float) -> np.ndarray:
    """Rows c with ``c . F >= 0`` for F inside the 4-sided pyramid inscribed in the cone of ``mu``.

    :param normal_W: (3,) or (p, 3) contact normals (world frame, any length).
    :return: (5, 3) or (p, 5, 3): ``mu' n - t1``, ``mu' n + t1``, ``mu' n - t2``, ``mu' n + t2`` with
        ``mu' = mu / sqrt(2)`` (so the pyramid lies inside the true cone), then ``n`` (normal force).
    """
    n = np.asarray(normal_W, dtype=float)
    flat = np.ascontiguousarray(n.reshape(-1, 3))
    out = np.empty((len(flat), 5, 3))
    IK.friction_pyramid_into(flat, float(mu), out)
    return out.reshape((*n.shape[:-1], 5, 3))


class InverseDynamics:
    """Torques and contact forces realising a commanded ``beta_ddot`` for a stance set.

    :param dynamics: a backend from :func:`quad_uneven_env.robot.dynamics.make_dynamics`.
    :param distribution: ``"pinv"`` (paper) or ``"qp"`` (friction-cone aware, see module doc).
    :param mu: friction coefficient of the cone (default: the model's foot friction, if the
        backend has a model, else 1.0).
    :param min_normal_force: N, lower bound of each stance foot's normal force in "qp".
    :param qp_solver: ``"compiled"`` or ``"daqp"`` (module doc).
    """

    def __init__(
        self,
        dynamics: Dynamics,
        distribution: str = "pinv",
        mu: float | None = None,
        min_normal_force: float = 5.0,
        qp_solver: str = "compiled",
    ) -> None:
        if distribution not in DISTRIBUTIONS:
            raise ValueError(f"distribution must be one of {list(DISTRIBUTIONS)}, got {excerpt(distribution)}")
        if qp_solver not in QP_SOLVERS:
            raise ValueError(f"qp_solver must be one of {list(QP_SOLVERS)}, got {excerpt(qp_solver)}")
        self.qp_solver = qp_solver
        if min_normal_force < 0:
            raise ValueError(f"min_normal_force must be >= 0 N, got {min_normal_force}")
        self.dynamics = dynamics
        self.distribution = distribution
        if mu is None:
            model = getattr(dynamics, "model", None)
            mu = (
                float(model.geom_friction[model.geom(C.FOOT_GEOMS[0]).id, 0])
                if isinstance(model, mujoco.MjModel)
                else 1.0
            )
        self.set_mu(mu)
        self.min_normal_force = float(min_normal_force)
        self._qp: dict[int, _StanceQP] = {}
        self.cone_lower = np.array([0.0, 0.0, 0.0, 0.0, self.min_normal_force])
        """(5,) lower bounds of the friction-pyramid rows (the last one: the minimum normal force, N)."""
        self.cone_buffer = np.empty((C.N_LEGS, 5, 3))
        """(4, 5, 3) friction pyramids of the feet, rewritten by the kernels from the terrain normals."""
        self.up_normals = np.tile([0.0, 0.0, 1.0], (C.N_LEGS, 1))
        """(4, 3) the normals of level ground (+z): the cones without terrain normals."""
        self.workspace = IDWorkspace(
            np.zeros(C.N_JOINTS), np.zeros((C.N_LEGS, 3)), np.zeros(C.NV), np.zeros(C.NV),
            np.zeros((C.N_LEGS, 3, 3)), np.zeros((C.N_LEGS, 3, 6)),
        )  # fmt: skip
        """the compiled kernels' output buffers (rewritten by every compiled solve)."""
        self.workspace_version = 0
        """incremented whenever :attr:`workspace` is rewritten (:class:`WorkspaceResult` checks it)."""

    # ---------------------------------------------------------------- public API
    def set_mu(self, mu: float) -> None:
        """Change the friction coefficient of the "qp" cones (-, > 0) from the next solve on."""
        if not mu > 0:
            raise ValueError(f"mu must be > 0, got {mu}")
        self.mu = float(mu)
        self._cone_up = np.ascontiguousarray(
            np.broadcast_to(friction_pyramid(np.array([0.0, 0.0, 1.0]), self.mu), (C.N_LEGS, 5, 3))
        )

    def solve(
        self,
        qpos: np.ndarray,
        qvel: np.ndarray,
        beta_ddot: np.ndarray,
        stance,
        normals_W: np.ndarray | None = None,
    ) -> IDResult:
        """Inverse dynamics at (qpos (19,), qvel (18,)) for ``beta_ddot`` (n_beta,) and a stance set.

        :param beta_ddot: [base acceleration (6: world linear m/s^2, base-frame angular rad/s^2);
            swing-leg joint accelerations (rad/s^2) in leg order].
        :param stance: 4 booleans, leg order LF, RF, LH, RH.
        :param normals_W: (4, 3) terrain normals at the feet for the "qp" cones (default +z).
        """
        return self.solve_terms(self.dynamics.terms(qpos, qvel), beta_ddot, stance, normals_W)

    def solve_terms(
        self, terms: DynamicsTerms, beta_ddot: np.ndarray, stance, normals_W: np.ndarray | None = None
    ) -> IDResult:
        """As :meth:`solve`, from dynamics terms already computed (e.g. ``terms_from_data``)."""
        lay = layout_of(stance)
        if type(beta_ddot) is not np.ndarray or beta_ddot.dtype != np.float64:
            beta_ddot = np.asarray(beta_ddot, dtype=float)
        if beta_ddot.shape != (lay.n_beta,):
            raise ValueError(
                f"beta_ddot must have shape ({lay.n_beta},) for stance {lay.stance}, got {beta_ddot.shape}"
            )
        result = self.solve_compiled(terms.M, terms.h, terms.J_feet, terms.Jdot_qdot_feet, lay, beta_ddot, normals_W)
        if result is None:  # 1 or 2 stance feet (SVD pseudo-inverse), or inputs the kernel does not take
            result = self._solve(eliminate_constraints(terms, lay.stance), beta_ddot, normals_W)
        return result

    def solve_compiled(
        self,
        M: np.ndarray,
        h: np.ndarray,
        J_feet: np.ndarray,
        Jdot_qdot_feet: np.ndarray,
        lay: StanceLayout,
        beta_ddot: np.ndarray,
        normals_W: np.ndarray | None = None,
    ) -> IDResult | None:
        """Fast path of :meth:`solve_terms` on validated inputs (the terms' arrays, a layout, an
        (n_beta,) float64 ``beta_ddot``) by the compiled kernel; None when it does not apply (1 or 2
        stance feet, a degenerate stance, arrays it cannot take): then use :meth:`solve_terms`."""
        ws = self.workspace
        self.workspace_version += 1
        try:
            status = IK.id_pinv(
                M, h, J_feet, Jdot_qdot_feet, lay.mask, beta_ddot,
                1.0 / SINGULAR_SIGMA, DAMPING, *ws,
            )  # fmt: skip
        except TypeError:  # not float64 arrays of the kernel's ranks (numba dispatch)
            return None
        if status <= 0:
            return None
        result = self.result_from_workspace(status, lay)
        if self.distribution == "qp" and lay.n_stance:
            self.distribute_qp(lay, J_feet, ws.r, result, normals_W)
        return result

    def result_from_workspace(self, status: int, lay: StanceLayout) -> IDResult:
        """The pinv :class:`IDResult` (copies) of the compiled solve now in :attr:`workspace`."""
        ws = self.workspace
        return IDResult(
            ws.tau.copy(), ws.F.copy(), ws.qacc.copy(), lay.stance, "pinv",
            exact=bool(status & IK.EXACT), damped=bool(status & IK.DAMPED),
        )  # fmt: skip

    # ---------------------------------------------------------------- internals
    def _solve(self, proj: ProjectedDynamics, beta_ddot: np.ndarray, normals_W: np.ndarray | None) -> IDResult:
        lay, terms = proj.layout, proj.terms
        qacc = proj.qacc(beta_ddot)
        r = terms.M @ qacc
        r += terms.h  # (18,) = B tau + J^T F when consistent
        # rhs = S^T r = M_beta beta_ddot + V_beta + G_beta: swing rows of S are unit rows, so
        # rhs_swing = r_swing; rhs_base = r_base + A r_stance with A = S_stance^T (6 x 3p).
        tau = np.zeros(C.N_JOINTS)
        sw = lay.beta_index[6:]
        tau[sw - 6] = r[sw]
        F = np.zeros((C.N_LEGS, 3))
        exact = True
        if lay.n_stance:
            A = proj.S_stance.transpose(2, 0, 1).reshape(6, -1)  # base rows of S_a^T: -J_b^T J_L^-T
            r_st = r[lay.stance_dofs]
            rhs_b = r[:6] + A @ r_st
            if lay.n_stance >= 3 and np.linalg.cond(A @ A.T) < 1e12:
                tau_st = A.T @ np.linalg.solve(A @ A.T, rhs_b)
            else:  # 1-2 stance feet, or a degenerate stance (A A^T singular): SVD pseudo-inverse
                tau_st = np.linalg.pinv(A) @ rhs_b
                exact = bool(np.abs(A @ tau_st - rhs_b).max() < 1e-9 * max(1.0, np.abs(rhs_b).max()))
            tau[lay.stance_dofs - 6] = tau_st
            F = self._forces(proj, r, tau, r_st - tau_st, exact)
        else:
            exact = bool(np.abs(r[:6]).max() < 1e-9 * max(1.0, np.abs(r).max()))
        result = IDResult(tau, F, qacc, lay.stance, "pinv", exact=exact, damped=proj.damped)
        if self.distribution == "qp" and lay.n_stance:
            if exact:
                self.distribute_qp(lay, terms.J_feet, r, result, normals_W)
            else:
                result.qp_fallback = True
        return result

    @staticmethod
    def _forces(
        proj: ProjectedDynamics, r: np.ndarray, tau: np.ndarray, leg_rows: np.ndarray, exact: bool
    ) -> np.ndarray:
        """Contact forces from J^T F = r - B tau (18 rows): leg rows if consistent, else least squares."""
        lay = proj.layout
        F = np.zeros((C.N_LEGS, 3))
        if exact:
            F[lay.stance_legs] = (np.swapaxes(proj.J_L_inv, -1, -2) @ leg_rows.reshape(-1, 3, 1))[..., 0]  # J_L^-T
        else:
            resid = r.copy()
            resid[6:] -= tau
            J_st = proj.terms.J_feet[lay.stance_legs].reshape(-1, C.NV)
            F[lay.stance_legs] = np.linalg.lstsq(J_st.T, resid, rcond=None)[0].reshape(-1, 3)
        return F

    def distribute_qp(
        self, lay: StanceLayout, J_feet: np.ndarray, r: np.ndarray, result: IDResult, normals_W: np.ndarray | None
    ) -> None:
        """Replace ``result``'s pinv torques and forces by the friction-cone QP's (in place; module doc).

        :param J_feet: (4, 3, 18) foot Jacobians; ``r`` (18,) = M qacc + h; ``normals_W`` (4, 3) or None (+z).
        """
        if self.qp_solver == "compiled":
            try:
                status = QK.distribute_qp(
                    self.up_normals if normals_W is None else normals_W, self.mu, J_feet, lay.mask, r,
                    self.cone_lower, result.tau, result.contact_forces, self.cone_buffer,
                )  # fmt: skip
            except TypeError:  # arrays the kernel does not take (numba dispatch): the DAQP path converts them
                status = QK.QP_FAILED
            if status != QK.QP_FAILED:
                result.distribution, result.relaxed = "qp", status == QK.QP_RELAXED
                return
        p = lay.n_stance
        qp = self._qp.get(p)
        if qp is None:
            qp = self._qp[p] = _StanceQP(p)

        def fill(J_feet: np.ndarray, r: np.ndarray, normals_W: np.ndarray | None) -> bool:
            F0, low = result.contact_forces, self.cone_lower
            if normals_W is None:
                return IK.qp_fill(J_feet, lay.mask, r, F0, self._cone_up[:p], low, *qp.problem)
            cones = self.cone_buffer
            return IK.qp_fill_with_cones(normals_W, self.mu, J_feet, lay.mask, r, F0, cones, low, *qp.problem)

        try:
            inside = fill(J_feet, r, normals_W)
        except TypeError:  # arrays the kernels do not take (numba dispatch): convert once
            c = np.ascontiguousarray
            inside = fill(
                c(J_feet, dtype=float), c(r, dtype=float), None if normals_W is None else c(normals_W, dtype=float)
            )
        _, _, A, b, C_in, lower = qp.problem
        # The QP's optimum is the torque closest to "pinv"; when the "pinv" forces already lie in
        # every cone with the minimum normal force, they are that optimum (zero cost): skip the solve.
        if inside:
            result.distribution = "qp"
            return
        x = qp.solve()
        tau, F = result.tau.copy(), np.zeros((C.N_LEGS, 3))
        if x is None or not IK.qp_apply(x, C_in, lower, A, b, J_feet, lay.mask, r, tau, F):
            wide = QK.wide_mu(self.mu)
            if wide <= self.mu:
                self._relax(lay, J_feet, r, result, qp)
                return
            # infeasible in the narrow cones: the wide ones, as the compiled path
            normals = self.up_normals if normals_W is None else np.ascontiguousarray(normals_W, dtype=float)
            J_c, r_c = np.ascontiguousarray(J_feet, dtype=float), np.ascontiguousarray(r, dtype=float)
            if IK.qp_fill_with_cones(normals, wide, J_c, lay.mask, r_c, result.contact_forces,
                                    self.cone_buffer, self.cone_lower, *qp.problem):  # fmt: skip
                result.distribution = "qp"
                return
            x = qp.solve()
            if x is None or not IK.qp_apply(x, C_in, lower, A, b, J_c, lay.mask, r_c, tau, F):
                self._relax(lay, J_feet, r, result, qp)
                return
        result.tau, result.contact_forces, result.distribution = tau, F, "qp"

    def _relax(self, lay: StanceLayout, J_feet: np.ndarray, r: np.ndarray, result: IDResult, qp: _StanceQP) -> None:
        """Infeasible cones at the commanded base acceleration: keep the forces physical.

        Solves min |A F - b|^2 + 1e-3 (F - F0)^T H (F - F0) subject to the cones only (always
        feasible: F = 0 is), i.e. the base wrench closest to the commanded one that the feet can
        really push. Without it the "pinv" forces pull on the ground, the feet lift and the robot
        falls. The stance torques follow from the leg rows, r_i - J_L,i^T F_i.
        """
        H, g, A, b, _, _ = qp.problem
        x = qp.solve_relaxed(A.T @ A + QK.RELAX_WEIGHT * H, -A.T @ b + QK.RELAX_WEIGHT * g)
        if x is None:
            result.qp_fallback = True
            return
        tau, F = result.tau.copy(), np.zeros((C.N_LEGS, 3))
        F[lay.stance_legs] = x.reshape(-1, 3)
        for leg in lay.stance_legs:
            c = slice(6 + 3 * leg, 9 + 3 * leg)
            tau[3 * leg : 3 * leg + 3] = r[c] - J_feet[leg][:, c].T @ F[leg]
        result.tau, result.contact_forces, result.distribution, result.relaxed = tau, F, "qp", True


class _StanceQP:
    """A preallocated "qp" problem for p stance feet (3p forces, 6 equalities, 5p cone rows), solved by DAQP
    (``qp_solver="daqp"``, and the compiled solver's fallback).

    DAQP (Arnström et al., a dual active-set solver for small dense QPs) solves these 12-variable
    problems exactly in a few active-set iterations, with no setup cost per solve (small problems).
    Each solve is independent of the previous one (no warm start), so results are reproducible.
    """

    def __init__(self, p: int) -> None:
        n, n_in = 3 * p, 5 * p
        self.problem = (
            np.zeros((n, n)),
            np.zeros(n),
            np.zeros((6, n)),
            np.zeros(6),
            np.zeros((n_in, n)),
            np.zeros(n_in),
        )
        # DAQP's form: lower <= A_all x <= upper, rows flagged equality (5) or inequality (0).
        self._A_all = np.zeros((6 + n_in, n))
        self._upper = np.full(6 + n_in, _QP_INF)
        self._lower = np.zeros(6 + n_in)
        self._sense = np.zeros(6 + n_in, dtype=np.int32)
        self._sense[:6] = _DAQP_EQUALITY
        self._cone_upper = np.full(n_in, _QP_INF)

    def solve(self) -> np.ndarray | None:
        """Solution x (3p,) of the current problem, None if it is infeasible or not solved."""
        H, g, A, b, C_in, lower = self.problem
        self._A_all[:6] = A
        self._A_all[6:] = C_in
        self._upper[:6] = b
        self._lower[:6] = b
        self._lower[6:] = lower
        return _daqp_solve(H, g, self._A_all, self._upper, self._lower, self._sense)

    def solve_relaxed(self, H: np.ndarray, g: np.ndarray) -> np.ndarray | None:
        """min 1/2 x^T H x + g^T x subject to the cone rows with zero lower bound (always feasible)."""
        C_in = self.problem[4]
        return _daqp_solve(H, g, C_in, self._cone_upper, np.zeros(len(C_in)), np.zeros(len(C_in), dtype=np.int32))


def _daqp_solve(
    H: np.ndarray, g: np.ndarray, A: np.ndarray, upper: np.ndarray, lower: np.ndarray, sense: np.ndarray
) -> np.ndarray | None:
    """DAQP on ``min 1/2 x^T H x + g^T x, lower <= A x <= upper``; None unless solved with a finite x."""
    x, _, flag, _ = daqp.solve(H, g, A, upper, lower, sense, primal_tol=_QP_PRIMAL_TOL, iter_limit=_QP_ITER_LIMIT)
    if flag != _DAQP_OPTIMAL:
        return None
    x = np.asarray(x)
    return x if np.isfinite(x).all() else None


_QP_INF = 1e30
"""DAQP's "no bound"."""
_DAQP_EQUALITY, _DAQP_OPTIMAL = 5, 1
"""DAQP's equality-row sense flag and its exit flag of an optimal solution."""
_QP_PRIMAL_TOL, _QP_ITER_LIMIT = 1e-9, 200
"""Constraint tolerance (N: well inside ``qp_apply``'s 1e-6 check) and active-set iteration cap (a
12-variable problem needs < 20; the cap bounds the worst physics step)."""
