"""QuadUneven: the paper's 18-DOF quadruped on uneven terrain as a Gymnasium environment."""

import os

# Headless rendering by default; must be set before mujoco creates a GL context.
os.environ.setdefault("MUJOCO_GL", "egl")

__version__ = "0.1.0"

from gymnasium.envs.registration import register, registry

if "QuadUneven-v0" not in registry:
    register(
        id="QuadUneven-v0",
        entry_point="quad_uneven_env.env:QuadUnevenEnv",
        max_episode_steps=1000,
    )
