"""The robot: its description (the paper's Table 1 or a URDF through Pinocchio) -> MuJoCo model, kinematics,
conventions, dynamics backends. Every robot-specific fact of the project comes from here.

- :func:`load_robot` (:mod:`~quad_uneven_env.robot.description`): a robot by name or YAML path, a
  :class:`RobotDescription` (:mod:`~quad_uneven_env.robot.quadruped`);
- :func:`scene_mjcf`, :func:`robot_mjcf` (:mod:`~quad_uneven_env.robot.model`): its MuJoCo model;
- :mod:`~quad_uneven_env.robot.leg_chain`, :mod:`~quad_uneven_env.robot.kinematics`: leg kinematics;
- :mod:`~quad_uneven_env.robot.dynamics`: rigid-body dynamics backends.

``model`` (and so MuJoCo) is imported on first use of its names, so that the planners can use the descriptions
and the kinematics without a simulator.
"""

from typing import Any

from quad_uneven_env.robot.description import load_robot, robot_names
from quad_uneven_env.robot.quadruped import RobotDescription

__all__ = ["PhysicsOptions", "RobotDescription", "load_robot", "robot_mjcf", "robot_names", "scene_mjcf"]

_MODEL_NAMES = ("PhysicsOptions", "robot_mjcf", "scene_mjcf")


def __getattr__(name: str) -> Any:
    if name in _MODEL_NAMES:
        from quad_uneven_env.robot import model

        return getattr(model, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
