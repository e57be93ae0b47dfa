"""The robot's own model: a nominal MuJoCo model into which the measured state is copied.

A controller on a real robot does not know the world's friction, its payload or its link masses
as the simulator has drawn them; it knows its nominal description (``configs/robot/*.yaml``) and
what its sensors measure. :class:`NominalModel` is that knowledge: an ``MjModel`` compiled from the
nominal robot configuration (the same scene MJCF as the environment, so body, joint, site and dof
ids agree) with contacts disabled, and an ``MjData`` into which :meth:`NominalModel.measure` copies
the measured state each physics step and runs only the position and velocity stages the dynamics
terms need (``mj_kinematics``, ``mj_comPos``, ``mj_makeM``, ``mj_comVel``, ``mj_rne``). Its ``M``,
``qfrc_bias``, frames and subtree centres of mass are then what the nominal robot would have at the measured state.

When the simulated robot is exactly nominal the two models compile from the same MJCF, and the
nominal data equal the simulator's bit for bit (tested); :meth:`NominalModel.matches` says whether
a simulator model's robot parameters (:data:`ROBOT_PARAMETER_FIELDS`) are the nominal ones.
"""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np

from quad_uneven_env.robot.description import RobotDescription
from quad_uneven_env.robot.model import PhysicsOptions, scene_mjcf

ROBOT_PARAMETER_FIELDS: tuple[str, ...] = (
    "body_mass", "body_inertia", "body_ipos", "body_iquat", "body_pos", "body_quat", "body_subtreemass",
    "jnt_axis", "jnt_pos", "dof_armature", "site_pos",
)  # fmt: skip
"""MjModel fields that determine the dynamics terms the controller reads (M, h, G, foot Jacobians, COG)."""


class NominalModel:
    """A nominal robot model and its data, fed with the measured state.

    :param robot: the nominal robot (the expert's own description of itself); its model is generated as the env
        generates its own (:func:`quad_uneven_env.robot.model.scene_mjcf`).
    :param terrain: an object with ``hfield_asset_xml()`` and ``hfield_geom_xml(friction)`` (the env's
        :class:`~quad_uneven_env.terrain.Terrain`): only the height field's size enters the model, so
        that its ids match the simulator's; its elevations are never uploaded (contacts are off).
    :param timestep: s, physics timestep (recorded in the model; the nominal model is never stepped).
    """

    def __init__(self, robot: RobotDescription, terrain: Any, timestep: float) -> None:
        hfield = (terrain.hfield_asset_xml(), terrain.hfield_geom_xml(robot.friction))
        xml = scene_mjcf(robot, *hfield, PhysicsOptions(timestep=timestep))
        self.model = mujoco.MjModel.from_xml_string(xml)
        """the nominal MjModel (contacts disabled)."""
        self.model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
        self.data = mujoco.MjData(self.model)
        """the nominal MjData: the measured state and the stages computed from it."""
        self.friction = float(robot.friction)
        """nominal friction coefficient of the feet and the terrain (-)."""

    def measure(self, qpos: np.ndarray, qvel: np.ndarray, time: float) -> mujoco.MjData:
        """Copy the measured state and run the position and velocity stages; returns :attr:`data`.

        :param qpos: (19,) measured base position (m, world), base quaternion (w, x, y, z) and joint angles (rad).
        :param qvel: (18,) measured base linear velocity (m/s, world), angular velocity (rad/s, base frame)
            and joint velocities (rad/s).
        :param time: s, the simulator's clock.
        """
        m, d = self.model, self.data
        d.qpos[:] = qpos
        d.qvel[:] = qvel
        d.time = time
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        mujoco.mj_makeM(m, d)
        mujoco.mj_comVel(m, d)
        mujoco.mj_rne(m, d, 0, d.qfrc_bias)
        return d

    def matches(self, model: mujoco.MjModel) -> bool:
        """True if ``model``'s robot parameters (:data:`ROBOT_PARAMETER_FIELDS`, gravity) are the nominal ones."""
        nominal = self.model
        if not np.array_equal(model.opt.gravity, nominal.opt.gravity):
            return False
        for name in ROBOT_PARAMETER_FIELDS:
            a, b = getattr(model, name), getattr(nominal, name)
            if a.shape != b.shape or not np.array_equal(a, b):
                return False
        return True
