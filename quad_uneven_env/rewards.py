"""Named reward terms: pure functions of measured quantities, scaled by :class:`RewardWeights`.

``reward = sum(terms.values())`` exactly; the env reports every term in ``info``.
"""

from __future__ import annotations

import numpy as np

from quad_uneven_env.config import RewardWeights

REWARD_TERMS: tuple[str, ...] = ("forward_progress", "stability", "torque", "energy", "alive", "fall")


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
