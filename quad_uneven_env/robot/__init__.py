"""The paper's robot: Table-1 parameters -> MuJoCo model, kinematics, conventions, dynamics backends.

``model`` (and so MuJoCo) is imported on first use of its names, so that the planners can use
``kinematics`` and ``conventions`` without a simulator.
"""

from typing import Any

__all__ = ["home_qpos", "robot_mjcf", "scene_mjcf"]


def __getattr__(name: str) -> Any:
    if name in __all__:
        from quad_uneven_env.robot import model

        return getattr(model, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
