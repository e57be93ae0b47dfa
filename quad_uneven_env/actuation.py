"""How an action becomes the actuators' command: the env's two action modes, written once.

- ``"torque"``: ctrl = action x torque limit (N m), the motors as modelled.
- ``"joint_pd"``: ctrl = the joint target standing pose + ``pd_scale`` x action (rad), clipped to the joint
  ranges; :func:`make_servos` has turned the motors into PD position servos (MuJoCo affine bias), so the target is
  tracked at physics rate and the torque saturates at the motor limit.
"""

from __future__ import annotations

import mujoco
import numpy as np

from quad_uneven_env import constants as C

ACTION_MODES = ("torque", "joint_pd")
"""Allowed ``action_mode`` of the env."""


class ActionMap:
    """The map from a clipped action in [-1, 1]^12 (``JOINT_NAMES`` order) to the 12 actuator commands.

    :param mode: one of :data:`ACTION_MODES`.
    :param torque_limit: (12,) N m, the motors' limits.
    :param joint_lo: (12,) rad, the joint ranges' lower ends.
    :param joint_hi: (12,) rad, their upper ends.
    :param pd_scale: rad per unit of action (``joint_pd``).
    """

    def __init__(
        self, mode: str, torque_limit: np.ndarray, joint_lo: np.ndarray, joint_hi: np.ndarray, pd_scale: float
    ) -> None:
        self.mode = mode
        self.torque_limit = torque_limit
        self.joint_lo = joint_lo
        self.joint_hi = joint_hi
        self.pd_scale = pd_scale
        self.home_joints = np.zeros(C.N_JOINTS)
        """(12,) rad, the episode's standing pose: ``joint_pd``'s zero action (set by :meth:`stand`)."""

    def ctrl_into(self, action: np.ndarray, out: np.ndarray) -> None:
        """Write the command of ``action`` into ``out`` (12,): torques (N m) or joint targets (rad)."""
        if self.mode == "torque":
            np.multiply(action, self.torque_limit, out=out)
        else:
            self.joint_targets_into(action, self.pd_scale, out)

    def joint_targets_into(self, action: np.ndarray, scale: float, out: np.ndarray) -> None:
        """Write the joint targets (rad) standing pose + ``scale`` x ``action``, clipped to the ranges, into ``out``."""
        np.clip(self.home_joints + scale * action, self.joint_lo, self.joint_hi, out=out)

    def stand(self, data: mujoco.MjData) -> None:
        """Take the pose in ``data.qpos`` as the episode's standing pose; in ``joint_pd`` mode the servos hold it."""
        self.home_joints = data.qpos[7:].copy()
        if self.mode == "joint_pd":
            data.ctrl[:] = self.home_joints


def make_servos(model: mujoco.MjModel, kp: float, kd: float, joint_lo: np.ndarray, joint_hi: np.ndarray) -> None:
    """Turn the 12 torque motors of ``model`` into PD position servos (MuJoCo affine bias), torque limits kept.

    :param kp: N m/rad. :param kd: N m s/rad. :param joint_lo: (12,) rad, the servos' lowest target.
    :param joint_hi: (12,) rad, their highest.
    """
    for i in range(C.N_JOINTS):
        lim = model.actuator_ctrlrange[i, 1]
        model.actuator_gainprm[i, 0] = kp
        model.actuator_biastype[i] = mujoco.mjtBias.mjBIAS_AFFINE
        model.actuator_biasprm[i, :3] = (0.0, -kp, -kd)
        model.actuator_forcelimited[i] = 1
        model.actuator_forcerange[i] = (-lim, lim)
        model.actuator_ctrlrange[i] = (joint_lo[i], joint_hi[i])
