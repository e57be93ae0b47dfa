"""What the residual agent sees of the expert: its plan at this instant and how far the robot is from it.

The residual corrects the expert, so it needs what the expert wanted and what it did, not only the
robot's state (``QuadUneven-v0``'s observation). :func:`expert_feature_fields` is the layout (data, like
the env's :func:`quad_uneven_env.observations.observation_fields`); :func:`expert_features` fills it from
the expert's current plan (:meth:`agents.expert.ExpertPolicy.planned_now`, which plans nothing new), its
last torques and the measured state. Errors are planned minus measured, in the yaw-aligned base frame
(x forward along the trunk's heading, z up), so a turn of the whole robot leaves them unchanged. Every
entry is clipped to its bounds.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
from gymnasium import spaces

from quad_uneven_env import physics
from quad_uneven_env.observations import ObsField, observation_structure

EXPERT_FEATURE_FIELDS: tuple[ObsField, ...] = (
    ObsField("expert_base_pos_error", 3, -0.5, 0.5, "m", "planned minus measured trunk origin, yaw frame"),
    ObsField("expert_base_vel_error", 3, -2.0, 2.0, "m/s", "planned minus measured trunk velocity, yaw frame"),
    ObsField(
        "expert_base_rot_error", 3, -1.0, 1.0, "rad", "rotation vector from the measured to the planned trunk attitude"
    ),
    ObsField("expert_joint_pos_error", 12, -1.0, 1.0, "rad", "planned minus measured joint angles"),
    ObsField("expert_joint_vel_error", 12, -20.0, 20.0, "rad/s", "planned minus measured joint velocities"),
    ObsField("expert_planned_stance", 4, 0.0, 1.0, "-", "1 if the plan has the foot in stance now, leg order"),
    ObsField("expert_cycle_phase", 2, -1.0, 1.0, "-", "sin and cos of 2 pi x the phase of the planned gait cycle"),
    ObsField("expert_base_acc_ref", 3, -10.0, 10.0, "m/s^2", "planned trunk acceleration, yaw frame"),
    ObsField("expert_torque", 12, -1.0, 1.0, "-", "the expert's last joint torques / torque limit"),
)
"""The expert features, in order (appended to the env's observation by the residual env)."""

EXPERT_FEATURE_SIZE = sum(f.size for f in EXPERT_FEATURE_FIELDS)
"""Length of the expert feature vector."""

_LOW = np.concatenate([np.full(f.size, f.low) for f in EXPERT_FEATURE_FIELDS])
_HIGH = np.concatenate([np.full(f.size, f.high) for f in EXPERT_FEATURE_FIELDS])
_SLICES = observation_structure(EXPERT_FEATURE_FIELDS)


def augmented_space(env_space: spaces.Box) -> spaces.Box:
    """``env_space`` with the expert features appended."""
    low, high = np.concatenate([env_space.low, _LOW]), np.concatenate([env_space.high, _HIGH])
    return spaces.Box(low.astype(np.float32), high.astype(np.float32))


def _yaw_rotation(quat_wxyz: np.ndarray) -> np.ndarray:
    """R_WY (3 x 3): the yaw-only rotation of the trunk (heading of its x axis in the world xy plane)."""
    R = physics.quat_to_rotation(quat_wxyz)
    yaw = math.atan2(R[1, 0], R[0, 0])
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def expert_features(expert, data: mujoco.MjData) -> np.ndarray:
    """The expert features (:data:`EXPERT_FEATURE_FIELDS`) at the simulator state ``data``.

    :param expert: an :class:`agents.expert.ExpertPolicy` that has been reset with the env.
    :param data: the simulator's data (what the expert measures: ``qpos``, ``qvel`` and ``time``).
    :return: (EXPERT_FEATURE_SIZE,) float32, clipped to the field bounds (a non-finite entry reads 0).
    """
    ref, phase = expert.planned_now(float(data.time))
    q, v = data.qpos, data.qvel
    R_WY = _yaw_rotation(q[3:7])
    out = np.empty(EXPERT_FEATURE_SIZE)
    out[_SLICES["expert_base_pos_error"]] = R_WY.T @ (ref.p_base_W - q[:3])
    out[_SLICES["expert_base_vel_error"]] = R_WY.T @ (ref.v_base_W - v[:3])
    quat_err = np.empty(4)
    meas_conj = np.empty(4)
    mujoco.mju_negQuat(meas_conj, q[3:7])
    mujoco.mju_mulQuat(quat_err, meas_conj, np.asarray(ref.quat_WB, dtype=float))
    rot = np.empty(3)
    mujoco.mju_quat2Vel(rot, quat_err, 1.0)
    out[_SLICES["expert_base_rot_error"]] = rot
    out[_SLICES["expert_joint_pos_error"]] = ref.q_joints - q[7:]
    out[_SLICES["expert_joint_vel_error"]] = ref.qd_joints - v[6:]
    out[_SLICES["expert_planned_stance"]] = np.asarray(ref.stance, dtype=float)
    out[_SLICES["expert_cycle_phase"]] = (math.sin(2 * math.pi * phase), math.cos(2 * math.pi * phase))
    out[_SLICES["expert_base_acc_ref"]] = R_WY.T @ ref.a_base_W
    out[_SLICES["expert_torque"]] = expert.last_torques / expert.env.idx.torque_limit
    # A non-finite plan is refused by the expert; should one get through, the agent still sees a finite
    # observation (NaN as no error, infinities at the bounds), never NaN.
    np.nan_to_num(out, copy=False, nan=0.0)
    np.clip(out, _LOW, _HIGH, out=out)
    return out.astype(np.float32)


__all__ = [
    "EXPERT_FEATURE_FIELDS",
    "EXPERT_FEATURE_SIZE",
    "augmented_space",
    "expert_features",
]
