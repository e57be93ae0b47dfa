"""Whole-body dynamics terms of the 18-DOF robot behind one interface, three backends.

``make_dynamics(backend, model)`` returns an object whose ``terms(qpos, qvel)`` gives, in the
canonical coordinates (MuJoCo's ``qpos``/``qvel``: world-frame base linear velocity,
base-frame angular velocity), the terms of ``M(q) qacc + h(q, qvel) = B tau + J^T F``:

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

import mujoco
import numpy as np

from quad_uneven_env.config import RobotConfig

BACKENDS: tuple[str, ...] = ("explicit", "pinocchio", "mujoco")
"""Allowed values of ``make_dynamics(backend=...)``."""


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


def make_dynamics(backend: str, model: mujoco.MjModel, cfg: RobotConfig | None = None) -> Dynamics:
    """Dynamics backend for the robot of ``model`` (a scene or robot-only MjModel).

    :param backend: one of ``"explicit"``, ``"pinocchio"``, ``"mujoco"``.
    :param model: the environment's MjModel (``env.unwrapped.model``); its robot parameters are used.
    :param cfg: robot config the Pinocchio model is generated from (default: the paper's);
        it is checked against ``model`` (nv and body masses).
    :raises ValueError: unknown backend, or a model that does not match the expected robot.
    """
    if backend == "explicit":
        from quad_uneven_env.robot.dynamics.explicit_backend import ExplicitDynamics

        return ExplicitDynamics(model)
    if backend == "pinocchio":
        from quad_uneven_env.robot.dynamics.pinocchio_backend import PinocchioDynamics

        return PinocchioDynamics(model, cfg)
    if backend == "mujoco":
        from quad_uneven_env.robot.dynamics.mujoco_backend import MujocoDynamics

        return MujocoDynamics(model)
    raise ValueError(f"backend must be one of {list(BACKENDS)}, got {backend!r}")
