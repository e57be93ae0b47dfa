"""Named reward terms: pure functions of measured quantities, scaled by :class:`RewardWeights`.

``reward = sum(terms.values())`` exactly; the env reports every term in ``info``. The command tracking
terms (:data:`COMMAND_REWARD_TERMS`) exist only in an env with a ``command``; without one the terms and the
reward are exactly those of :func:`reward_terms`.
"""

from __future__ import annotations

import math

import numpy as np

from quad_uneven_env.config import RewardWeights

REWARD_TERMS: tuple[str, ...] = ("forward_progress", "stability", "torque", "energy", "alive", "fall")

COMMAND_REWARD_TERMS: tuple[str, ...] = ("command_tracking_lin", "command_tracking_yaw")
"""The terms added after :data:`REWARD_TERMS` when the env has a ``command``."""


def reward_terms(
    weights: RewardWeights,
    cog_vel_x: float,
    stability_index_normalized: float,
    torque_fraction: np.ndarray,
    power_abs: float,
    weight_force: float,
    fell: bool,
) -> dict[str, float]:
    """The named, weighted reward terms of one control step.

    :param cog_vel_x: whole-robot COG velocity along +x averaged over the step (m/s).
    :param stability_index_normalized: measured stability index / (m g) (m); -inf without support.
    :param torque_fraction: (12,) applied torque / torque limit, averaged over the step.
    :param power_abs: sum over joints of |tau * qd| averaged over the step (W).
    :param weight_force: m g (N), to make the power term a speed.
    :param fell: the step ended in a fall or a divergence.
    """
    stab = min(max(stability_index_normalized / weights.stability_scale, -1.0), 1.0)
    return {
        "forward_progress": weights.forward_progress * float(cog_vel_x),
        "stability": weights.stability * float(stab),
        "torque": -weights.torque * float(torque_fraction @ torque_fraction) / len(torque_fraction),
        "energy": -weights.energy * float(power_abs) / weight_force,
        "alive": 0.0 if fell else weights.alive,
        "fall": -weights.fall if fell else 0.0,
    }


def command_reward_terms(
    weights: RewardWeights, v_xy_H: np.ndarray, yaw_rate: float, command: np.ndarray
) -> dict[str, float]:
    """The command tracking terms of one control step (legged_gym's exponential kernels).

    ``command_tracking_lin = w_lin exp(-|v_xy - v_cmd|^2 / sigma_lin^2)``,
    ``command_tracking_yaw = w_yaw exp(-(yaw_rate - yaw_rate_cmd)^2 / sigma_yaw^2)``.

    :param v_xy_H: (2,) trunk horizontal velocity (m/s) in the yaw-aligned base frame, at the end of the step.
    :param yaw_rate: trunk angular velocity about world z (rad/s), at the end of the step.
    :param command: (3,) the commanded vx, vy (m/s) and yaw rate (rad/s) in effect during the step.
    """
    ex, ey = float(v_xy_H[0]) - float(command[0]), float(v_xy_H[1]) - float(command[1])
    eyaw = float(yaw_rate) - float(command[2])
    return {
        "command_tracking_lin": weights.command_tracking_lin
        * math.exp(-(ex * ex + ey * ey) / weights.command_sigma_lin**2),
        "command_tracking_yaw": weights.command_tracking_yaw * math.exp(-(eyaw * eyaw) / weights.command_sigma_yaw**2),
    }
