"""The paper's robot: Table-1 parameters -> MuJoCo model, kinematics, dynamics backends."""

from quad_uneven_env.robot.model import home_qpos, robot_mjcf, scene_mjcf

__all__ = ["home_qpos", "robot_mjcf", "scene_mjcf"]
