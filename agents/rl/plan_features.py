"""What the plan-level agent sees of the expert's own estimates: its plan's margins, its friction and strength
estimates and the settings of the cycle it planned.

:data:`PLAN_FEATURE_FIELDS` is the layout (data, like :func:`quad_uneven_env.observations.observation_fields`);
:func:`plan_features` fills it from an :class:`~agents.expert.ExpertPolicy` and the last plan action. Every entry is
clipped to its bounds (a non-finite one reads 0).
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

from agents.rl.plan_config import PLAN_ACTION_SIZE
from quad_uneven_env import constants as C
from quad_uneven_env.observations import STABILITY_CLIP, ObsField, observation_structure

GRAVITY = 9.81
"""m/s^2: normalises the planned stability margin (N m) by the planned mass's weight."""

PLAN_FEATURE_FIELDS: tuple[ObsField, ...] = (
    ObsField("plan_action", PLAN_ACTION_SIZE, -1.0, 1.0, "-", "the plan action of the current cycle's settings"),
    ObsField("plan_hold", 1, 0.0, 1.0, "-", "1 if no plan was feasible and the expert stands still this cycle"),
    ObsField(
        "plan_min_stability",
        1,
        -STABILITY_CLIP,
        STABILITY_CLIP,
        "m",
        "the current plan's smallest stability index / (m g) over its cycle (0 while standing still)",
    ),
    ObsField("plan_min_clearance", 1, -0.1, 0.3, "m", "the current plan's smallest swing clearance (0 standing)"),
    ObsField("expert_friction", 1, 0.0, 2.0, "-", "the friction coefficient the expert's cones assume now"),
    ObsField("expert_strength_gain", C.N_JOINTS, 0.0, 3.0, "-", "the adaptive gain per joint on its torques"),
    ObsField("expert_failures", 1, 0.0, 50.0, "-", "entries in the expert's failure log this episode"),
)
"""The plan features, in order (appended to the env's observation and the expert features by the plan env)."""

PLAN_FEATURE_SIZE = sum(f.size for f in PLAN_FEATURE_FIELDS)
"""Length of the plan feature vector."""

_LOW = np.concatenate([np.full(f.size, f.low) for f in PLAN_FEATURE_FIELDS])
_HIGH = np.concatenate([np.full(f.size, f.high) for f in PLAN_FEATURE_FIELDS])
_SLICES = observation_structure(PLAN_FEATURE_FIELDS)


def plan_features(expert, action: np.ndarray) -> np.ndarray:
    """The plan features (:data:`PLAN_FEATURE_FIELDS`) of ``expert`` now.

    :param expert: an :class:`agents.expert.ExpertPolicy` that has been reset with its env.
    :param action: (5,) the plan action the current cycle's settings came from.
    :return: (PLAN_FEATURE_SIZE,) float32, clipped to the field bounds.
    """
    out = np.zeros(PLAN_FEATURE_SIZE)
    out[_SLICES["plan_action"]] = action
    plan = expert.planner.current
    stats = getattr(plan, "stats", None)
    if stats is None:
        out[_SLICES["plan_hold"]] = 1.0
    else:
        out[_SLICES["plan_min_stability"]] = float(stats.get("min_stability", 0.0)) / (plan.mass * GRAVITY)
        out[_SLICES["plan_min_clearance"]] = float(stats.get("min_clearance", 0.0))
    out[_SLICES["expert_friction"]] = expert.assumed_friction
    gain = getattr(expert.adaptation, "gain", None)
    out[_SLICES["expert_strength_gain"]] = 1.0 if gain is None else gain
    out[_SLICES["expert_failures"]] = len(expert.failure_log)
    np.nan_to_num(out, copy=False, nan=0.0)
    np.clip(out, _LOW, _HIGH, out=out)
    return out.astype(np.float32)


def augmented_plan_space(env_space: spaces.Box) -> spaces.Box:
    """``env_space`` with the plan features appended."""
    low, high = np.concatenate([env_space.low, _LOW]), np.concatenate([env_space.high, _HIGH])
    return spaces.Box(low.astype(np.float32), high.astype(np.float32))


__all__ = ["PLAN_FEATURE_FIELDS", "PLAN_FEATURE_SIZE", "augmented_plan_space", "plan_features"]
