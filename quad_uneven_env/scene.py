"""The env's compiled MuJoCo scene: the robot over the terrain's height field.

MuJoCo's warnings go to the :data:`MUJOCO_LOGGER` logger, not to ``MUJOCO_LOG.TXT`` in the working directory
(:func:`route_mujoco_warnings`), and its automatic reset is off: a diverging state stays for the env to see and
report (``info["diverged"]``, ``info["termination_reason"]``).
"""

from __future__ import annotations

import logging

import mujoco

from quad_uneven_env.robot.description import RobotDescription
from quad_uneven_env.robot.model import PhysicsOptions, scene_mjcf
from quad_uneven_env.terrain import Terrain

MUJOCO_LOGGER = logging.getLogger("mujoco")
"""Where MuJoCo's warnings go (level INFO) instead of ``MUJOCO_LOG.TXT`` in the working directory: the env
installs :func:`route_mujoco_warnings` unless a warning handler is already set. The env reports what they mean
(``info["diverged"]``, ``info["termination_reason"]``)."""


def _log_mujoco_warning(message: str) -> None:
    MUJOCO_LOGGER.info(message)


def route_mujoco_warnings() -> None:
    """Send MuJoCo's warnings to :data:`MUJOCO_LOGGER` (process-wide; a handler set before, by the user or another
    library, is kept). Without a handler MuJoCo prints them and appends them to ``MUJOCO_LOG.TXT`` in the current
    directory."""
    if mujoco.get_mju_user_warning() is None:
        mujoco.set_mju_user_warning(_log_mujoco_warning)


def scene_xml(robot: RobotDescription, terrain: Terrain, timestep: float) -> str:
    """The scene's MJCF: ``robot`` over ``terrain``'s height field, MuJoCo's ``timestep`` (s)."""
    return scene_mjcf(
        robot,
        terrain.hfield_asset_xml(),
        terrain.hfield_geom_xml(robot.friction),
        PhysicsOptions(timestep=float(timestep)),
    )


def compile_scene(robot: RobotDescription, terrain: Terrain, timestep: float) -> mujoco.MjModel:
    """The compiled :func:`scene_xml`, with MuJoCo's warnings routed and its automatic reset off."""
    route_mujoco_warnings()
    model = mujoco.MjModel.from_xml_string(scene_xml(robot, terrain, timestep))
    # Divergence must end the episode visibly, not be hidden by MuJoCo's automatic reset.
    model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_AUTORESET
    return model
