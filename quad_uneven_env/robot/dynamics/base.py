"""The interface every dynamics backend implements: :class:`Dynamics` and the :class:`DynamicsTerms` it returns.

A backend (made by :func:`quad_uneven_env.robot.dynamics.make_dynamics`) has a method ``terms(qpos, qvel)`` that
gives, in the canonical coordinates (MuJoCo's ``qpos``/``qvel``: world-frame base
linear velocity, base-frame angular velocity), the terms of ``M(q) qacc + h(q, qvel) = B tau + J^T F``:

- ``M`` (18 x 18, kg / kg m / kg m^2), ``h = V + G`` (18, N / N m), ``G`` (18);
- ``J_feet`` (4 x 3 x 18): world-frame translational Jacobians of the foot sites (leg order);
- ``Jdot_qdot_feet`` (4 x 3, m/s^2): the feet's world-frame classical acceleration at
  ``qacc = 0``, so that ``p_ddot_foot = J qacc + Jdot_qdot``.

Backends: ``"explicit"`` (the paper's Lagrangian explicit method, closed form, numba-compiled,
:mod:`quad_uneven_env.robot.dynamics.explicit_backend`), ``"pinocchio"`` (CRBA/RNEA,
:mod:`quad_uneven_env.robot.dynamics.pinocchio_backend`) and ``"mujoco"`` (mj_fullM, qfrc_bias,
mj_jacSite/mj_jacDot, :mod:`quad_uneven_env.robot.dynamics.mujoco_backend`).
"""

from __future__ import annotations

import dataclasses
from typing import Protocol

import numpy as np


@dataclasses.dataclass
class DynamicsTerms:
    """Dynamics terms at one state, canonical (MuJoCo) coordinates, SI units.

    With a leading batch axis when the explicit backend is given a batch of states.
    """

    M: np.ndarray
    """(18, 18) joint-space inertia matrix."""
    h: np.ndarray
    """(18,) bias forces V + G (Coriolis/centrifugal plus gravity), N and N m."""
    G: np.ndarray
    """(18,) gravity forces (gradient of the potential energy), N and N m."""
    J_feet: np.ndarray
    """(4, 3, 18) world-frame translational Jacobians of the foot sites, leg order LF, RF, LH, RH."""
    Jdot_qdot_feet: np.ndarray
    """(4, 3) world-frame classical acceleration of the foot points at qacc = 0 (m/s^2)."""

    @property
    def V(self) -> np.ndarray:
        """(18,) Coriolis and centrifugal forces h - G."""
        return self.h - self.G


class Dynamics(Protocol):
    """What every backend offers."""

    backend: str

    def terms(self, qpos: np.ndarray, qvel: np.ndarray) -> DynamicsTerms:
        """Dynamics terms at ``qpos`` (19,) and ``qvel`` (18,), canonical coordinates."""
        ...
