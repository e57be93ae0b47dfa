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
import itertools

import numpy as np

from quad_uneven_env import constants as C
from quad_uneven_env.fields import excerpt
from quad_uneven_env.robot.dynamics.base import DynamicsTerms

SINGULAR_SIGMA = 2e-3
"""m/rad: a leg Jacobian whose smallest singular value is about this small (the stretched knee,
or the foot on the HAA axis) is treated as singular and inverted with damping."""

DAMPING = 2e-3
"""m/rad: damping lambda of the damped least-squares inverse of a singular leg Jacobian."""


def check_stance(stance) -> tuple[bool, bool, bool, bool]:
    """Validate a stance set: 4 booleans in leg order LF, RF, LH, RH.

    :raises ValueError: naming the field and the allowed values.
    """
    try:
        flags = tuple(bool(s) for s in stance)
    except TypeError:
        flags = ()
    if len(flags) != C.N_LEGS or any(not isinstance(s, (bool, np.bool_, int, np.integer)) for s in stance):
        raise ValueError(f"stance must be 4 booleans in leg order {C.LEG_NAMES}, got {excerpt(stance)}")
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
    S0: np.ndarray
    """(18, n_beta) S without the stance rows: base identity and swing joints' unit entries."""
    leg_block: tuple[np.ndarray, np.ndarray, np.ndarray]
    """fancy index picking the (p, 3, 3) leg blocks J_L out of the stance feet's (p, 3, 18) Jacobians."""
    mask: int
    """stance bitmask: bit i set when leg i is in stance (the compiled kernels' encoding)."""

    @property
    def n_stance(self) -> int:
        """Number of stance feet p."""
        return len(self.stance_legs)

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
    p = len(st)
    leg_block = (np.arange(p)[:, None, None], np.arange(3)[None, :, None], dofs(st).reshape(p, 1, 3))
    S0 = np.zeros((C.NV, len(beta)))
    S0[beta, np.arange(len(beta))] = 1.0
    S0.flags.writeable = False
    mask = sum(1 << int(i) for i in st)
    return StanceLayout(stance, st, sw, beta, dofs(st).astype(int), S0, leg_block, mask)


_LAYOUTS = frozenset(itertools.product((False, True), repeat=C.N_LEGS))


def layout_of(stance) -> StanceLayout:
    """:class:`StanceLayout` of any stance given as 4 booleans (validated by :func:`check_stance`)."""
    return stance_layout(stance if type(stance) is tuple and stance in _LAYOUTS else check_stance(stance))


def leg_jacobian_inverse(J_L: np.ndarray) -> tuple[np.ndarray, bool]:
    """Inverses (p, 3, 3) of leg Jacobians J_L (p, 3, 3) (m/rad), damped near a singularity.

    A leg whose inverse has an entry above ``1 / SINGULAR_SIGMA`` (smallest singular value
    below about ``SINGULAR_SIGMA``) gets the damped least-squares inverse
    ``(J^T J + DAMPING^2 I)^-1 J^T`` instead of ``J^-1``: finite, never NaN.

    :return: the inverses and whether any leg was damped.
    """
    try:
        inv = np.linalg.inv(J_L)
        bad = np.abs(inv).max(axis=(1, 2)) > 1.0 / SINGULAR_SIGMA
    except np.linalg.LinAlgError:
        inv, bad = None, np.ones(len(J_L), dtype=bool)
    if not bad.any():
        return inv, False
    Jt = np.swapaxes(J_L, -1, -2)
    damped = np.linalg.solve(Jt @ J_L + (DAMPING**2) * np.eye(3), Jt)
    return (damped if inv is None else np.where(bad[:, None, None], damped, inv)), True


@dataclasses.dataclass
class ProjectedDynamics:
    """Constraint-eliminated dynamics at one state for one stance set (canonical coordinates, SI).

    Holds the stance legs' blocks of S (``-J_L^-1 J_b``) and of Sdot beta_dot (``-J_L^-1 Jdot qdot``);
    S, Sdot beta_dot, M_beta, V_beta and G_beta are assembled from them on first access.
    """

    layout: StanceLayout
    J_L_inv: np.ndarray
    """(p, 3, 3) inverses (damped if singular) of the stance legs' 3 x 3 Jacobians."""
    J_b: np.ndarray
    """(p, 3, 6) base columns of the stance feet's Jacobians."""
    S_stance: np.ndarray
    """(p, 3, 6) the stance legs' rows of S (base columns): -J_L^-1 J_b."""
    Sdot_stance: np.ndarray
    """(p, 3) the stance legs' entries of Sdot beta_dot: -J_L^-1 Jdot qdot (rad/s^2)."""
    damped: bool
    """a stance leg Jacobian was singular and inverted with damping."""
    terms: DynamicsTerms
    """the full dynamics the projection was made from."""

    @functools.cached_property
    def S(self) -> np.ndarray:
        """(18, n_beta) qvel = S beta_dot (eq. 6-8)."""
        S = self.layout.S0.copy()
        S[self.layout.stance_dofs, :6] = self.S_stance.reshape(-1, 6)
        return S

    @functools.cached_property
    def Sdot_betadot(self) -> np.ndarray:
        """(18,) Sdot beta_dot (m/s^2, rad/s^2): qacc = S beta_ddot + Sdot beta_dot."""
        out = np.zeros(C.NV)
        out[self.layout.stance_dofs] = self.Sdot_stance.reshape(-1)
        return out

    @functools.cached_property
    def M_beta(self) -> np.ndarray:
        """(n_beta, n_beta) S^T M S (eq. 16), symmetric positive definite."""
        return self.S.T @ self.terms.M @ self.S

    @functools.cached_property
    def V_beta(self) -> np.ndarray:
        """(n_beta,) S^T (V + M Sdot beta_dot) (eq. 17)."""
        return self.S.T @ (self.terms.h - self.terms.G + self.terms.M @ self.Sdot_betadot)

    @functools.cached_property
    def G_beta(self) -> np.ndarray:
        """(n_beta,) S^T G (eq. 17)."""
        return self.S.T @ self.terms.G

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

    def qacc(self, beta_ddot: np.ndarray) -> np.ndarray:
        """(18,) full acceleration S beta_ddot + Sdot beta_dot."""
        lay = self.layout
        out = np.zeros(C.NV)
        out[lay.beta_index] = beta_ddot
        if lay.n_stance:
            out[lay.stance_dofs] = (self.S_stance @ beta_ddot[:6] + self.Sdot_stance).reshape(-1)
        return out


def eliminate_constraints(terms: DynamicsTerms, stance) -> ProjectedDynamics:
    """Project the full dynamics ``terms`` onto the stance set's independent coordinates (§2.3).

    ``Sdot beta_dot`` uses the measured ``Jdot_qdot_feet`` of ``terms`` (the feet's classical
    acceleration at zero qacc), which equals the eq. 8 derivative when qvel satisfies the
    stance constraint.

    :param terms: dynamics terms at the current state (any backend).
    :param stance: 4 booleans, leg order LF, RF, LH, RH; any of the 16 sets.
    """
    lay = layout_of(stance)
    if not lay.n_stance:
        z = np.zeros((0, 3, 6))
        return ProjectedDynamics(lay, np.zeros((0, 3, 3)), z, z, np.zeros((0, 3)), False, terms)
    full = lay.n_stance == C.N_LEGS
    J_st = terms.J_feet if full else terms.J_feet[lay.stance_legs]  # (p, 3, 18)
    J_b = J_st[:, :, :6]
    J_L_inv, damped = leg_jacobian_inverse(J_st[lay.leg_block])
    Jdq = terms.Jdot_qdot_feet if full else terms.Jdot_qdot_feet[lay.stance_legs]
    S_st = J_L_inv @ J_b
    S_st *= -1.0
    Sd_st = (J_L_inv @ Jdq[..., None])[..., 0]
    Sd_st *= -1.0
    return ProjectedDynamics(lay, J_L_inv, J_b, S_st, Sd_st, damped, terms)
