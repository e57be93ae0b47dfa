"""The residual env's settings: :class:`ResidualConfig` (what one unit of residual action does, where, on top of
which expert, what the agent sees) and the readers of its parts as a training config or ``rl_meta.json`` gives them.

A module of its own so that the training config (:mod:`agents.rl.config`), the residual env
(:mod:`agents.rl.residual_env`) and the model reader (:mod:`agents.rl.model_io`) share it without importing each
other.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

from agents.control.controller import Gains
from agents.expert.config import ExpertConfig
from quad_uneven_env.fields import check_fields, excerpt, from_mapping, param

RESIDUAL_LEGS = ("all", "stance")
"""Which legs take the residual: every leg, or only those whose foot touches the ground (per physics step)."""

RESIDUAL_BASES = ("torque_limit", "expert_torque")
"""What one unit of residual action is: a fraction of the motor's torque limit (additive), or of the expert's
own torque at that physics step (a gain on the expert: ``tau = tau_expert x (1 + residual_scale x action)``)."""

DEFAULT_RESIDUAL_SCALE = 0.1
"""Default residual torque as a fraction of the torque limit (0.1 x 120 N m = 12 N m per joint)."""


def check_residual_legs(residual_legs: Any) -> str:
    """``residual_legs`` if it is one of :data:`RESIDUAL_LEGS`.

    :raises ValueError: naming ``residual_legs`` and its allowed values otherwise.
    """
    if not isinstance(residual_legs, str) or residual_legs not in RESIDUAL_LEGS:
        raise ValueError(f"residual_legs must be one of {list(RESIDUAL_LEGS)}, got {excerpt(residual_legs)}")
    return residual_legs


def check_residual_basis(residual_basis: Any) -> str:
    """``residual_basis`` if it is one of :data:`RESIDUAL_BASES`.

    :raises ValueError: naming ``residual_basis`` and its allowed values otherwise.
    """
    if not isinstance(residual_basis, str) or residual_basis not in RESIDUAL_BASES:
        raise ValueError(f"residual_basis must be one of {list(RESIDUAL_BASES)}, got {excerpt(residual_basis)}")
    return residual_basis


def check_residual_scale(residual_scale: Any) -> float:
    """``residual_scale`` as a float in (0, 1].

    :raises ValueError: naming ``residual_scale`` otherwise.
    """
    try:
        value = float(residual_scale)
    except (TypeError, ValueError):
        value = float("nan")
    if isinstance(residual_scale, bool) or not (0.0 < value <= 1.0):
        raise ValueError(
            f"residual_scale must be a number in (0, 1] (of the torque limit), got {excerpt(residual_scale)}"
        )
    return value


def expert_config(raw: Mapping[str, Any] | ExpertConfig | None, where: str = "expert") -> ExpertConfig:
    """An :class:`ExpertConfig` from a mapping of its fields (``gains`` a mapping of :class:`Gains` fields,
    ``durations`` a list), as a training config or ``rl_meta.json`` says it; an ExpertConfig is returned as is.

    :raises ValueError: naming ``where.field`` and its allowed values.
    """
    if raw is None or isinstance(raw, ExpertConfig):
        return ExpertConfig() if raw is None else raw
    values = dict(raw) if isinstance(raw, Mapping) else raw
    if isinstance(values, dict):
        if isinstance(values.get("gains"), Mapping):
            values["gains"] = from_mapping(Gains, values["gains"], f"{where}.gains")
        if isinstance(values.get("durations"), list):
            values["durations"] = tuple(values["durations"])
    return from_mapping(ExpertConfig, values, where)


def expert_overrides(config: ExpertConfig) -> dict[str, Any]:
    """The fields of ``config`` that differ from :class:`ExpertConfig`'s defaults, as JSON values (a mapping for
    ``gains``, a list for ``durations``): what ``rl_meta.json`` records, and :func:`expert_config` reads back."""
    default = ExpertConfig()
    out: dict[str, Any] = {}
    for f in dataclasses.fields(ExpertConfig):
        value = getattr(config, f.name)
        if value == getattr(default, f.name):
            continue
        if isinstance(value, Gains):
            value = {g.name: getattr(value, g.name) for g in dataclasses.fields(Gains)}
        elif isinstance(value, tuple):
            value = list(value)
        out[f.name] = value
    return out


@dataclasses.dataclass(frozen=True)
class ResidualConfig:
    """The residual env's settings (SI units): what one unit of action does, where, on top of which expert, and
    what the agent sees. Frozen; bad values raise ``ValueError`` naming ``ResidualConfig.field``."""

    residual_scale: float = param(DEFAULT_RESIDUAL_SCALE, "of the torque limit", lo=0.0, hi=1.0, lo_open=True)
    """residual per unit action as a fraction of the torque limit (``torque_limit`` basis) or of the expert's
    torque (``expert_torque`` basis), in (0, 1]."""
    residual_legs: str = param("all", kind="choice", choices=RESIDUAL_LEGS)
    """``all``: every leg takes the residual; ``stance``: only a leg whose foot touches the ground, at each
    physics step (the residual then cannot move a swinging foot)."""
    residual_basis: str = param("torque_limit", kind="choice", choices=RESIDUAL_BASES)
    """``torque_limit``: residual = scale x action x the motor limit; ``expert_torque``: scale x action x the
    expert's own torque (per joint and physics step: a gain on the expert)."""
    expert_features: bool = param(True, kind="bool")
    """append the expert features (:mod:`agents.rl.expert_features`) to the observation."""
    residual_penalty: float = param(0.0, "per mean(action^2)", lo=0.0)
    """>= 0: subtracted from the reward per unit of mean(action^2) over the 12 joints; 0 keeps the env's."""
    expert: ExpertConfig = dataclasses.field(default_factory=ExpertConfig)
    """the expert under the residual (its ``adaptation``: adaptive gains on its torques)."""

    def __post_init__(self) -> None:
        check_fields(self)
        if not isinstance(self.expert, ExpertConfig):
            raise ValueError(f"ResidualConfig.expert must be an ExpertConfig, got {excerpt(self.expert)}")

    def to_dict(self) -> dict[str, Any]:
        """JSON values of every field; ``expert`` as its fields that differ from the defaults
        (:func:`expert_overrides`)."""
        out = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name != "expert"}
        return {**out, "expert": expert_overrides(self.expert)}

    @classmethod
    def from_dict(cls, raw: Mapping[str, Any], where: str = "ResidualConfig") -> ResidualConfig:
        """A config from a mapping of its fields (``expert`` a mapping of :class:`ExpertConfig` fields; missing
        fields take their defaults), the inverse of :meth:`to_dict`.

        :raises ValueError: naming ``where.field`` (or ``where.expert.field``) and its allowed values.
        """
        if not isinstance(raw, Mapping):
            raise ValueError(f"{where} must be a mapping of ResidualConfig fields, got {excerpt(raw)}")
        values = dict(raw)
        if "expert" in values:
            values["expert"] = expert_config(values["expert"], f"{where}.expert" if where else "expert")
        return from_mapping(cls, values, where)


def split_config(cls: type, config: Any, kwargs: dict[str, Any], what: str) -> Any:
    """The ``cls`` settings of an env factory: ``config`` (an instance, a mapping of its fields, or None), or the
    fields of ``cls`` popped from ``kwargs`` (the rest are the base env's arguments).

    :raises ValueError: when both ``config`` and such fields are given, or on a bad field (named).
    """
    names = {f.name for f in dataclasses.fields(cls)}
    fields = {k: kwargs.pop(k) for k in list(kwargs) if k in names}
    if fields and config is not None:
        raise ValueError(f"give the {what} in config or as keywords, not both: got config and {sorted(fields)}")
    return config if isinstance(config, cls) else cls.from_dict(fields if config is None else config)


__all__ = [
    "DEFAULT_RESIDUAL_SCALE",
    "RESIDUAL_BASES",
    "RESIDUAL_LEGS",
    "ResidualConfig",
    "check_residual_basis",
    "check_residual_legs",
    "check_residual_scale",
    "expert_config",
    "expert_overrides",
    "split_config",
]
