"""Dynamics backends: one interface (:mod:`.base`), one module per backend, chosen by name here.

``make_dynamics("explicit" | "pinocchio" | "mujoco", model)`` returns an object with
``terms(qpos, qvel) -> DynamicsTerms`` (M, h, G, foot Jacobians, Jdot qdot in MuJoCo's
coordinates). Backends are imported lazily: only the one asked for is compiled or loaded.
"""

from __future__ import annotations

import mujoco

from quad_uneven_env.robot.description import RobotDescription
from quad_uneven_env.robot.dynamics.base import Dynamics, DynamicsTerms

BACKENDS: tuple[str, ...] = ("explicit", "pinocchio", "mujoco")
"""Allowed values of ``make_dynamics(backend=...)``."""


def make_dynamics(backend: str, robot: RobotDescription | mujoco.MjModel) -> Dynamics:
    """Dynamics backend of any HAA-HFE-KFE quadruped (the paper's robot, a URDF robot, a user's YAML).

    :param backend: one of ``"explicit"``, ``"pinocchio"``, ``"mujoco"``.
    :param robot: the robot's description (``env.unwrapped.robot``: its nominal masses and inertias, standard
        gravity; the mujoco backend compiles its robot-only MJCF) or an MjModel of it (``env.unwrapped.model``,
        a scene or robot-only model: its masses, after any randomization, and its gravity; the mujoco
        backend's :meth:`~quad_uneven_env.robot.dynamics.mujoco_backend.MujocoDynamics.terms_from_data` reads
        that model's MjData).
    :raises ValueError: unknown backend, or a model that is not the project's robot structure (naming the
        body, joint or site).
    """
    if backend == "explicit":
        from quad_uneven_env.robot.dynamics.explicit_backend import ExplicitDynamics

        return ExplicitDynamics(robot)
    if backend == "pinocchio":
        from quad_uneven_env.robot.dynamics.pinocchio_backend import PinocchioDynamics

        return PinocchioDynamics(robot)
    if backend == "mujoco":
        from quad_uneven_env.robot.dynamics.mujoco_backend import MujocoDynamics

        return MujocoDynamics(robot)
    raise ValueError(f"backend must be one of {list(BACKENDS)}, got {backend!r}")


__all__ = ["BACKENDS", "Dynamics", "DynamicsTerms", "make_dynamics"]
