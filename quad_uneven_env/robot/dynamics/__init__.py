"""Dynamics backends: one interface (:mod:`.base`), one module per backend, chosen by name.

``make_dynamics("explicit" | "pinocchio" | "mujoco", model)`` returns an object with
``terms(qpos, qvel) -> DynamicsTerms`` (M, h, G, foot Jacobians, Jdot qdot in MuJoCo's
coordinates). Backends are imported lazily: only the one asked for is compiled or loaded.
"""

from quad_uneven_env.robot.dynamics.base import BACKENDS, Dynamics, DynamicsTerms, make_dynamics

__all__ = ["BACKENDS", "Dynamics", "DynamicsTerms", "make_dynamics"]
