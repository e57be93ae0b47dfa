"""QuadUneven: the paper's 18-DOF quadruped on uneven terrain as a Gymnasium environment."""

import os

# Headless rendering by default; must be set before mujoco creates a GL context.
os.environ.setdefault("MUJOCO_GL", "egl")

__version__ = "0.1.0"
