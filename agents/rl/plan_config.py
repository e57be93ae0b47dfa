"""The plan-level residual's settings: :class:`PlanConfig`, and what one action does to the expert's plan.

One action of the plan env (:mod:`agents.rl.plan_env`) is a vector in [-1, 1]^5, one entry per decision of the
expert's cycle planner (:data:`PLAN_ACTIONS`, in order); :func:`cycle_config` turns it into the
:class:`~agents.expert.config.ExpertConfig` the next gait cycle is planned with. Every adjusted value stays inside
its field's bounds, so the planner still enforces every constraint (footholds, stability margin, reach) on the
adjusted settings. A zero action gives the expert's own settings exactly.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

import numpy as np

from agents.expert.config import ExpertConfig
from agents.rl.residual_config import expert_config, expert_overrides
from quad_uneven_env.fields import check_fields, excerpt, from_mapping, param


@dataclasses.dataclass(frozen=True)
class PlanAction:
    """One entry of the plan action: which planner setting it moves, how (``relative``: the setting times
    ``1 + range x action``; ``absolute``: plus ``range x action``, in the setting's unit) and by how much at most
    (the :class:`PlanConfig` field named ``range_field``)."""

    name: str
    setting: str
    relative: bool
    range_field: str
    description: str


PLAN_ACTIONS: tuple[PlanAction, ...] = (
    PlanAction("stride", "stride", True, "stride_range", "body advance per cycle (without a command)"),
    PlanAction("cycle_time", "durations", True, "cycle_time_range", "every phase of the cycle (10 ms grid)"),
    PlanAction("epsilon", "epsilon", True, "epsilon_range", "stability margin of the planned COG path"),
    PlanAction("cog_height", "cog_height", False, "cog_height_range", "COG height above the footholds (m)"),
    PlanAction("clearance", "clearance", False, "clearance_range", "swing clearance above the terrain (m)"),
)
"""The plan action's entries, in order."""

PLAN_ACTION_SIZE = len(PLAN_ACTIONS)
"""Length of the plan action."""

_BOUNDS: dict[str, tuple[float, float]] = {
    "stride": (1e-3, 1.0),
    "epsilon": (0.0, 1000.0),
    "cog_height": (0.05, 1.0),
    "clearance": (0.0, 0.3),
}
"""The ExpertConfig fields' bounds (an adjusted value is clipped into them)."""

PHASE_GRID = 0.01
"""s: an adjusted phase duration is rounded to two decimals, this grid (where the reference is a lookup of its
precomputed rows), and is at least this long."""


@dataclasses.dataclass(frozen=True)
class PlanConfig:
    """The plan env's settings: how far one unit of action moves each planner setting, the expert underneath,
    and the episode length. Frozen; bad values raise ``ValueError`` naming ``PlanConfig.field``."""

    stride_range: float = param(0.3, "of the stride", lo=0.0, hi=0.9)
    """stride x (1 + stride_range x action), in [0, 0.9]."""
    cycle_time_range: float = param(0.3, "of the cycle time", lo=0.0, hi=0.9)
    """every phase x (1 + cycle_time_range x action), rounded to 10 ms, in [0, 0.9]."""
    epsilon_range: float = param(0.5, "of epsilon", lo=0.0, hi=0.9)
    """epsilon x (1 + epsilon_range x action), in [0, 0.9]."""
    cog_height_range: float = param(0.04, "m", lo=0.0, hi=0.2)
    """m: cog_height + cog_height_range x action, in [0, 0.2]."""
    clearance_range: float = param(0.03, "m", lo=0.0, hi=0.2)
    """m: clearance + clearance_range x action (at least 0), in [0, 0.2]."""
    max_control_steps: int = param(1000, "control steps", kind="int", lo=1)
    """the episode is truncated after this many control steps of the env underneath (1000 = 20 s at 50 Hz)."""
    expert: ExpertConfig = dataclasses.field(default_factory=lambda: ExpertConfig(adaptation="learned"))
    """the expert whose plan is adjusted (default: the adaptive expert, ``adaptation="learned"``)."""

    def __post_init__(self) -> None:
        check_fields(self)
        if not isinstance(self.expert, ExpertConfig):
            raise ValueError(f"PlanConfig.expert must be an ExpertConfig, got {excerpt(self.expert)}")

    def to_dict(self) -> dict[str, Any]:
        """JSON values of every field; ``expert`` as its fields that differ from ExpertConfig's defaults."""
        out = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name != "expert"}
        return {**out, "expert": expert_overrides(self.expert)}

    @classmethod
    def from_dict(cls, raw: Mapping[str, Any], where: str = "PlanConfig") -> PlanConfig:
        """A config from a mapping of its fields (``expert`` a mapping of ExpertConfig fields; missing fields take
        their defaults; a missing ``expert`` is the adaptive expert), the inverse of :meth:`to_dict`.

        :raises ValueError: naming ``where.field`` and its allowed values.
        """
        if not isinstance(raw, Mapping):
            raise ValueError(f"{where} must be a mapping of PlanConfig fields, got {excerpt(raw)}")
        values = dict(raw)
        if "expert" in values:
            values["expert"] = expert_config(values["expert"], f"{where}.expert" if where else "expert")
        return from_mapping(cls, values, where)


def check_plan_action(action: Any) -> np.ndarray:
    """``action`` as a float64 (5,) array clipped to [-1, 1].

    :raises ValueError: naming ``action`` if it has another shape or a non-finite entry.
    """
    a = np.asarray(action, dtype=np.float64)
    if a.shape != (PLAN_ACTION_SIZE,) or not np.all(np.isfinite(a)):
        raise ValueError(f"action must be {PLAN_ACTION_SIZE} finite numbers, got {excerpt(action)}")
    return np.clip(a, -1.0, 1.0)


def cycle_config(base: ExpertConfig, action: np.ndarray, config: PlanConfig) -> ExpertConfig:
    """The settings one gait cycle is planned with: ``base`` with every :data:`PLAN_ACTIONS` entry applied.

    :param action: (5,) in [-1, 1] (:func:`check_plan_action`); 0 leaves a setting exactly as in ``base``.
    """
    changes: dict[str, Any] = {}
    for a, spec in zip(action, PLAN_ACTIONS, strict=True):
        if a == 0.0:
            continue
        step = float(a) * getattr(config, spec.range_field)
        value = getattr(base, spec.setting)
        if spec.setting == "durations":
            changes["durations"] = tuple(max(round(d * (1.0 + step), 2), PHASE_GRID) for d in value)
            continue
        lo, hi = _BOUNDS[spec.setting]
        changes[spec.setting] = min(max(value * (1.0 + step) if spec.relative else value + step, lo), hi)
    return dataclasses.replace(base, **changes) if changes else base


__all__ = [
    "PHASE_GRID",
    "PLAN_ACTIONS",
    "PLAN_ACTION_SIZE",
    "PlanAction",
    "PlanConfig",
    "check_plan_action",
    "cycle_config",
]
