"""Dynamics terms from Pinocchio (CRBA, RNEA, frame Jacobians) in canonical coordinates.

The ``pin.Model`` is built from the robot's leg chains (:class:`~quad_uneven_env.robot.dynamics.chains.LegChains`,
from a description or an MjModel): a free-flyer trunk, then per leg three revolute joints at the chains'
placements (``pin.SE3(rot, pos)``) about their axes, each link's inertia (mass, COM, full tensor) on its joint,
the armature on the joint's diagonal and a foot frame named like the MJCF's foot site. One builder serves every
robot: the paper's has no URDF, and a URDF robot's description already carries what Pinocchio reads from its
URDF (tests/quad_uneven_env/test_robots.py checks the description's MJCF against ``buildModelFromUrdf``).

Pinocchio's free flyer uses ``v = [v_B, omega_B, qd]`` (base-frame linear velocity); the
canonical ``qvel = T v`` with ``T = diag(R_WB, I, I)``. Generalised forces map as
``f_mj = T^-T f_pin`` (same power), hence ``M_mj = T^-T M_pin T^-1`` and, since
``qacc = T a + Tdot v``, ``h_mj = T^-T rnea(q, v, a0)`` with ``a0`` the Pinocchio
acceleration of ``qacc = 0`` (``-omega x v_B`` on the linear rows). Conversions come from
:mod:`quad_uneven_env.robot.conventions`.
"""

from __future__ import annotations

import mujoco
import numpy as np
import pinocchio as pin

from quad_uneven_env import constants as C
from quad_uneven_env.robot.conventions import qacc_mj_to_pin, qpos_mj_to_pin, qvel_mj_to_pin
from quad_uneven_env.robot.description import RobotDescription
from quad_uneven_env.robot.dynamics.base import DynamicsTerms
from quad_uneven_env.robot.dynamics.chains import LegChains, leg_chains
from quad_uneven_env.spatial import quat_to_matrix

_CANONICAL = {(1.0, 0.0, 0.0): pin.JointModelRX, (0.0, 1.0, 0.0): pin.JointModelRY, (0.0, 0.0, 1.0): pin.JointModelRZ}


def _revolute(axis: np.ndarray) -> pin.JointModel:
    """Pinocchio's revolute joint about ``axis`` (unit, joint frame): RX/RY/RZ for +x/+y/+z, else unaligned."""
    key = tuple(float(v) for v in axis)
    return _CANONICAL[key]() if key in _CANONICAL else pin.JointModelRevoluteUnaligned(np.asarray(axis, dtype=float))


def build_pinocchio_model(robot: RobotDescription | mujoco.MjModel | LegChains) -> pin.Model:
    """``pin.Model`` of a robot: a free-flyer trunk (joint ``root``), the joints of
    :data:`~quad_uneven_env.constants.JOINT_NAMES` (dofs in that order) and the foot frames of
    :data:`~quad_uneven_env.constants.FOOT_SITES`; gravity, masses, inertias and armature the chains'.

    :raises ValueError: for an MjModel of another structure (see :meth:`LegChains.from_mjmodel`).
    """
    ch = leg_chains(robot)
    model = pin.Model()
    model.name = ch.name
    root = model.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), C.ROOT_JOINT)
    model.appendBodyToJoint(root, pin.Inertia(ch.trunk_mass, ch.trunk_com, ch.trunk_inertia), pin.SE3.Identity())
    for i, leg in enumerate(C.LEG_NAMES):
        parent = root
        for k, kind in enumerate(C.JOINT_KINDS):
            placement = pin.SE3(ch.joint_rot[i, k], ch.joint_pos[i, k])
            jid = model.addJoint(parent, _revolute(ch.joint_axis[i, k]), placement, C.joint_name(leg, kind))
            inertia = pin.Inertia(float(ch.link_mass[i, k]), ch.link_com[i, k], ch.link_inertia[i, k])
            model.appendBodyToJoint(jid, inertia, pin.SE3.Identity())
            parent = jid
        model.addFrame(pin.Frame(C.foot_site(leg), parent, pin.SE3(np.eye(3), ch.foot[i]), pin.FrameType.OP_FRAME))
    model.armature[6:] = ch.armature
    model.gravity.linear = np.asarray(ch.gravity_W, dtype=float)
    return model


class PinocchioDynamics:
    """CRBA / RNEA / frame Jacobians on :func:`build_pinocchio_model`'s model, converted to canonical coordinates.

    :param robot: a :class:`~quad_uneven_env.robot.description.RobotDescription` (its nominal numbers, standard
        gravity), an MjModel of the project's robot structure (its numbers and gravity) or the leg chains.
    """

    backend = "pinocchio"

    def __init__(self, robot: RobotDescription | mujoco.MjModel | LegChains) -> None:
        self.chains = leg_chains(robot)
        self.model = build_pinocchio_model(self.chains)
        self.data = self.model.createData()
        self.foot_frames = [self.model.getFrameId(s) for s in C.FOOT_SITES]

    def terms(self, qpos: np.ndarray, qvel: np.ndarray) -> DynamicsTerms:
        """Dynamics terms at ``qpos`` (19,) and ``qvel`` (18,), canonical coordinates."""
        qpos = np.asarray(qpos, dtype=float)
        qvel = np.asarray(qvel, dtype=float)
        model, data = self.model, self.data
        q = qpos_mj_to_pin(qpos)
        q[3:7] /= np.linalg.norm(q[3:7])
        v = qvel_mj_to_pin(qpos, qvel)
        a0 = qacc_mj_to_pin(qpos, qvel, np.zeros_like(qvel))
        R = quat_to_matrix(qpos[3:7])
        M_pin = pin.crba(model, data, q).copy()
        M_pin = np.triu(M_pin) + np.triu(M_pin, 1).T
        f_pin = pin.rnea(model, data, q, v, a0).copy()
        G_pin = pin.computeGeneralizedGravity(model, data, q).copy()
        # T^-1 = diag(R^T, I, I): T^-T x only rotates the first three entries by R.
        M = M_pin.copy()
        M[:3, :] = R @ M[:3, :]
        M[:, :3] = M[:, :3] @ R.T
        h, G = f_pin, G_pin
        h[:3] = R @ h[:3]
        G[:3] = R @ G[:3]
        # Feet: Jacobians and classical accelerations (a = a0 is qacc = 0), world-aligned frames.
        pin.forwardKinematics(model, data, q, v, a0)
        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacements(model, data)
        J_feet = np.empty((C.N_LEGS, 3, C.NV))
        Jdd = np.empty((C.N_LEGS, 3))
        for i, fid in enumerate(self.foot_frames):
            J = pin.getFrameJacobian(model, data, fid, pin.LOCAL_WORLD_ALIGNED)
            J_feet[i] = J[:3]
            J_feet[i, :, :3] = J[:3, :3] @ R.T
            Jdd[i] = pin.getFrameClassicalAcceleration(model, data, fid, pin.LOCAL_WORLD_ALIGNED).linear
        return DynamicsTerms(M, h, G, J_feet, Jdd)
