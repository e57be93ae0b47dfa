"""Dynamics terms from Pinocchio (CRBA, RNEA, frame Jacobians) in canonical coordinates.

Pinocchio's free flyer uses ``v = [v_B, omega_B, qd]`` (base-frame linear velocity); the
canonical ``qvel = T v`` with ``T = diag(R_WB, I, I)``. Generalised forces map as
``f_mj = T^-T f_pin`` (same power), hence ``M_mj = T^-T M_pin T^-1`` and, since
``qacc = T a + Tdot v``, ``h_mj = T^-T rnea(q, v, a0)`` with ``a0`` the Pinocchio
acceleration of ``qacc = 0`` (``-omega x v_B`` on the linear rows). Conversions come from
:mod:`quad_uneven_env.robot.conventions`.
"""

from __future__ import annotations

import os
import tempfile

import mujoco
import numpy as np
import pinocchio as pin

from quad_uneven_env import constants as C
from quad_uneven_env.config import RobotConfig, load_robot_config
from quad_uneven_env.robot.conventions import qacc_mj_to_pin, qpos_mj_to_pin, qvel_mj_to_pin
from quad_uneven_env.robot.dynamics.base import DynamicsTerms
from quad_uneven_env.robot.model import robot_mjcf
from quad_uneven_env.spatial import quat_to_matrix


def build_pinocchio_model(cfg: RobotConfig) -> pin.Model:
    """Pinocchio model of ``robot_mjcf(cfg)`` (written to a temporary file, then removed)."""
    fd, path = tempfile.mkstemp(suffix=".xml")
    try:
        with os.fdopen(fd, "w") as f:
            f.write(robot_mjcf(cfg))
        return pin.buildModelFromMJCF(path)
    finally:
        os.remove(path)


class PinocchioDynamics:
    """CRBA / RNEA / frame Jacobians on the robot-only MJCF, converted to canonical coordinates."""

    backend = "pinocchio"

    def __init__(self, model: mujoco.MjModel, cfg: RobotConfig | None = None) -> None:
        cfg = cfg or load_robot_config()
        self.model = build_pinocchio_model(cfg)
        self.model.gravity.linear = np.asarray(model.opt.gravity, dtype=float)
        if self.model.nv != model.nv or self.model.nq != model.nq:
            raise ValueError(
                f"cfg {cfg.name!r} gives a Pinocchio model with nq={self.model.nq}, nv={self.model.nv}; "
                f"the MjModel has nq={model.nq}, nv={model.nv}"
            )
        pin_mass = sum(inertia.mass for inertia in self.model.inertias)
        mj_mass = float(model.body_subtreemass[model.body(C.TRUNK_BODY).id])
        if abs(pin_mass - mj_mass) > 1e-9 * mj_mass:
            raise ValueError(f"cfg {cfg.name!r}: robot mass {pin_mass} kg differs from the MjModel's {mj_mass} kg")
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
