"""QuadUneven: the paper's 18-DOF quadruped on uneven terrain as a Gymnasium environment.

Importing this package registers ``QuadUneven-v0`` with Gymnasium. It does not import Gymnasium or
MuJoCo itself (the planners use the pure parts of this package: config, kinematics, terrain
queries, stability): if Gymnasium is not loaded yet, the registration happens when it is.
"""

import importlib.abc
import importlib.util
import os
import sys

# Headless rendering by default; must be set before mujoco creates a GL context.
os.environ.setdefault("MUJOCO_GL", "egl")

__version__ = "0.2.0"

__all__ = ["ENV_ID", "__version__", "register_envs", "robots"]

ENV_ID = "QuadUneven-v0"
"""Gymnasium id of :class:`quad_uneven_env.env.QuadUnevenEnv`."""


def robots() -> list[str]:
    """Names of the shipped robots, each a ``robot=`` of ``gym.make("QuadUneven-v0", robot=...)``: the paper's
    Table-1 robot and the URDF robots of ``configs/robot/`` (these need the ``robots`` extra)."""
    from quad_uneven_env.robot.description import robot_names

    return robot_names()


def register_envs() -> None:
    """Register ``QuadUneven-v0`` (idempotent; imports Gymnasium)."""
    from gymnasium.envs.registration import register, registry

    if ENV_ID not in registry:
        register(
            id=ENV_ID,
            entry_point="quad_uneven_env.env:QuadUnevenEnv",
            vector_entry_point="quad_uneven_env.vector:make_vector_env",
            max_episode_steps=1000,
        )


class _RegisterOnGymnasiumImport(importlib.abc.MetaPathFinder):
    """One-shot import hook: runs :func:`register_envs` right after ``gymnasium`` finishes importing."""

    def find_spec(self, name, path=None, target=None):
        if name != "gymnasium":
            return None
        sys.meta_path.remove(self)
        spec = importlib.util.find_spec(name)
        if spec is None or spec.loader is None:
            return spec
        exec_module = spec.loader.exec_module

        def exec_then_register(module):
            exec_module(module)
            register_envs()

        spec.loader.exec_module = exec_then_register
        return spec


if "gymnasium" in sys.modules:
    register_envs()
elif not any(isinstance(f, _RegisterOnGymnasiumImport) for f in sys.meta_path):
    sys.meta_path.insert(0, _RegisterOnGymnasiumImport())
