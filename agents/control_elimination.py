"""Constraint elimination of the paper's §2.3: the contact forces drop out of the dynamics.

Stance feet do not move, ``J_st qvel = 0`` (eq. 3-4). With the independent velocities
``beta_dot = [base (6); joints of the swing legs in leg order]`` (eq. 5) every admissible
``qvel`` is ``S beta_dot`` (eq. 6-8): the base rows of S are the identity; a stance leg's
joint rows are ``-J_L,i^-1 J_b,i`` (``J_b,i`` the 3 x 6 base columns and ``J_L,i`` the 3 x 3 leg
columns of the foot Jacobian); a swing leg's joints copy their beta entries. Then
``J_st S = 0`` (eq. 14), ``S^T J^T F = 0`` and the projected dynamics (eq. 16-17) read

    M_beta beta_ddot + V_beta + G_beta = S_a^T tau,
    M_beta = S^T M S,  V_beta = S^T (V + M Sdot beta_dot),  G_beta = S^T G,

with ``S_ua`` (6 x n_beta, base rows) and ``S_a`` (12 x n_beta, joint rows) the partition of S.
``Sdot beta_dot`` follows from differentiating the constraint: zero except on a stance leg's
rows, ``-J_L,i^-1 (Jdot qdot)_i``. All velocities are canonical (MuJoCo's qvel).

A stretched knee makes ``J_L,i`` singular: :func:`leg_jacobian_inverse` then returns the
damped least-squares inverse ``(J^T J + lambda^2 I)^-1 J^T`` (finite, flagged ``damped``).
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np

from quad_uneven_env import constants as C
from quad_uneven_env.robot.dynamics import DynamicsTerms

SINGULARITY_RATIO = 1e-3
"""Below this |det J_L| / (|col1| |col2| |col3|) (Hadamard ratio, 0 = singular, 1 = orthogonal
columns) a leg Jacobian is treated as singular and inverted with damping."""

DAMPING = 1e-3
"""m: damping lambda of the damped least-squares inverse of a singular leg Jacobian."""


def check_stance(stance) -> tuple[bool, bool, bool, bool]:
    """Validate a stance set: 4 booleans in leg order LF, RF, LH, RH.

    :raises ValueError: naming the field and the allowed values.
    """
    try:
        flags = tuple(bool(s) for s in stance)
    except TypeError:
        flags = ()
    if len(flags) != C.N_LEGS or any(not isinstance(s, (bool, np.bool_, int, np.integer)) for s in stance):
        raise ValueError(f"stance must be 4 booleans in leg order {C.LEG_NAMES}, got {stance!r}")
    return flags  # type: ignore[return-value]


@dataclasses.dataclass(frozen=True)
class StanceLayout:
    """Index bookkeeping of one stance set (cached: there are only 16)."""

    stance: tuple[bool, bool, bool, bool]
    stance_legs: np.ndarray
    """(p,) indices of the stance legs."""
    swing_legs: np.ndarray
    """(4 - p,) indices of the swing legs."""
    beta_index: np.ndarray
    """(n_beta,) qvel indices forming beta_dot: 0..5 then the swing legs' joint dofs."""
    stance_dofs: np.ndarray
    """(3p,) qvel indices of the stance legs' joints."""

    @property
    def n_beta(self) -> int:
        """Number of independent coordinates, 18 - 3p."""
        return len(self.beta_index)


@functools.lru_cache(maxsize=16)
def stance_layout(stance: tuple[bool, bool, bool, bool]) -> StanceLayout:
    """Cached :class:`StanceLayout` of a (validated) stance tuple."""
    st = np.array([i for i in range(C.N_LEGS) if stance[i]], dtype=int)
    sw = np.array([i for i in range(C.N_LEGS) if not stance[i]], dtype=int)
    dofs = lambda legs: (6 + 3 * legs[:, None] + np.arange(3)).reshape(-1)  # noqa: E731
    beta = np.concatenate([np.arange(6), dofs(sw)]).astype(int)
    return StanceLayout(stance, st, sw, beta, dofs(st).astype(int))


def leg_jacobian_inverse(J_L: np.ndarray) -> tuple[np.ndarray, bool]:
    """Inverses (p, 3, 3) of leg Jacobians J_L (p, 3, 3), damped near a singularity.

    Closed form (adjugate over determinant); a leg whose Hadamard ratio is below
    ``SINGULARITY_RATIO`` gets ``(J^T J + DAMPING^2 I)^-1 J^T`` instead.

    :return: the inverses and whether any leg was damped.
    """
    a0, a1, a2 = J_L[..., :, 0], J_L[..., :, 1], J_L[..., :, 2]
    c12, c20, c01 = np.cross(a1, a2), np.cross(a2, a0), np.cross(a0, a1)
    det = np.einsum("pi,pi->p", a0, c12)
    scale = np.linalg.norm(a0, axis=-1) * np.linalg.norm(a1, axis=-1) * np.linalg.norm(a2, axis=-1)
    ok = np.abs(det) > SINGULARITY_RATIO * scale
    if ok.all():
        return np.stack([c12, c20, c01], axis=-2) / det[:, None, None], False
    inv = np.empty_like(J_L)
    good = np.nonzero(ok)[0]
    inv[good] = np.stack([c12[good], c20[good], c01[good]], axis=-2) / det[good, None, None]
    for k in np.nonzero(~ok)[0]:
        J = J_L[k]
        inv[k] = np.linalg.solve(J.T @ J + DAMPING**2 * np.eye(3), J.T)
    return inv, True


@dataclasses.dataclass
class ProjectedDynamics:
    """Constraint-eliminated dynamics at one state for one stance set (canonical coordinates, SI)."""

    layout: StanceLayout
    S: np.ndarray
    """(18, n_beta) qvel = S beta_dot (eq. 6-8)."""
    Sdot_betadot: np.ndarray
    """(18,) Sdot beta_dot (m/s^2, rad/s^2): qacc = S beta_ddot + Sdot beta_dot."""
    M_beta: np.ndarray
    """(n_beta, n_beta) S^T M S."""
    V_beta: np.ndarray
    """(n_beta,) S^T (V + M Sdot beta_dot)."""
    G_beta: np.ndarray
    """(n_beta,) S^T G."""
    J_L_inv: np.ndarray
    """(p, 3, 3) inverses (damped if singular) of the stance legs' 3 x 3 Jacobians."""
    J_b: np.ndarray
    """(p, 3, 6) base columns of the stance feet's Jacobians."""
    damped: bool
    """a stance leg Jacobian was singular and inverted with damping."""
    terms: DynamicsTerms
    """the full dynamics the projection was made from."""

    @property
    def S_ua(self) -> np.ndarray:
        """(6, n_beta) base (unactuated) rows of S."""
        return self.S[:6]

    @property
    def S_a(self) -> np.ndarray:
        """(12, n_beta) joint (actuated) rows of S."""
        return self.S[6:]

    @property
    def beta_index(self) -> np.ndarray:
        """(n_beta,) qvel indices forming beta_dot."""
        return self.layout.beta_index


def eliminate_constraints(terms: DynamicsTerms, stance) -> ProjectedDynamics:
    """Project the full dynamics ``terms`` onto the stance set's independent coordinates (§2.3).

    ``Sdot beta_dot`` uses the measured ``Jdot_qdot_feet`` of ``terms`` (the feet's classical
    acceleration at zero qacc), which equals the eq. 8 derivative when qvel satisfies the
    stance constraint.

    :param terms: dynamics terms at the current state (any backend).
    :param stance: 4 booleans, leg order LF, RF, LH, RH; any of the 16 sets.
    """
    lay = stance_layout(check_stance(stance))
    st = lay.stance_legs
    nb = lay.n_beta
    S = np.zeros((C.NV, nb))
    S[:6, :6] = np.eye(6)
    S[lay.beta_index[6:], np.arange(6, nb)] = 1.0
    Sdot_bd = np.zeros(C.NV)
    J_st = terms.J_feet[st]  # (p, 3, 18)
    J_b = J_st[:, :, :6]
    if len(st):
        J_L = np.stack([J_st[k, :, 6 + 3 * leg : 9 + 3 * leg] for k, leg in enumerate(st)])
        J_L_inv, damped = leg_jacobian_inverse(J_L)
        S[lay.stance_dofs, :6] = -np.einsum("pij,pjk->pik", J_L_inv, J_b).reshape(-1, 6)
        Sdot_bd[lay.stance_dofs] = -np.einsum("pij,pj->pi", J_L_inv, terms.Jdot_qdot_feet[st]).reshape(-1)
    else:
        J_L_inv, damped = np.zeros((0, 3, 3)), False
    MS = terms.M @ S
    M_beta = S.T @ MS
    V_beta = S.T @ (terms.h - terms.G + terms.M @ Sdot_bd)
    G_beta = S.T @ terms.G
    return ProjectedDynamics(lay, S, Sdot_bd, M_beta, V_beta, G_beta, J_L_inv, J_b, damped, terms)
