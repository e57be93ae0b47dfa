"""The commanded planar base velocity of ``QuadUneven-v0(command=...)``: its config and its per-episode schedule.

A command is (vx, vy, yaw_rate): m/s, m/s, rad/s of the trunk in the *yaw-aligned base frame* (x along the
trunk's heading projected on the horizontal plane, z up). Each axis is either fixed (``vx``, ``vy``,
``yaw_rate``) or drawn uniformly from its ``ranges`` entry at every reset and again every
``resample_interval`` seconds of episode time (legged_gym's scheme). Draws come from a generator the env
hands down (a child of ``env.np_random``), so the same seed gives the same commands.

**Heading mode** (legged_gym's ``heading_command``): with ``heading`` (fixed) or ``ranges.heading`` (drawn),
the command names a world heading instead of a yaw rate, and the yaw rate (the third component, in the
observation and ``info`` as always) is computed at every control step from the measured trunk heading:
``clip(heading_gain * wrap(heading - yaw), -heading_max_yaw_rate, heading_max_yaw_rate)``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from quad_uneven_env.fields import check_fields, excerpt, from_mapping, param, params_of
from quad_uneven_env.spatial import wrap_angle

COMMAND_AXES: tuple[str, ...] = ("vx", "vy", "yaw_rate")
"""The command's components, in the order of the observation field and ``info["command"]``."""

_RANGED_AXES: tuple[str, ...] = (*COMMAND_AXES, "heading")

MAX_LIN = 1.0
"""m/s: bound of a commanded linear velocity component (fixed value or range end)."""

MAX_YAW_RATE = 2.0
"""rad/s: bound of a commanded yaw rate."""


@dataclasses.dataclass(frozen=True)
class CommandRanges:
    """Uniform ranges the drawn axes come from; None: the axis keeps its fixed value."""

    vx: tuple[float, float] | None = param(None, "m/s", "forward velocity", kind="range", lo=-MAX_LIN, hi=MAX_LIN)
    """m/s, within [-1, 1]: forward (+) or backward (-) velocity along the heading."""
    vy: tuple[float, float] | None = param(None, "m/s", "lateral velocity", kind="range", lo=-MAX_LIN, hi=MAX_LIN)
    """m/s, within [-1, 1]: velocity to the left (+) or right (-) of the heading."""
    yaw_rate: tuple[float, float] | None = param(
        None, "rad/s", "yaw rate", kind="range", lo=-MAX_YAW_RATE, hi=MAX_YAW_RATE
    )
    """rad/s, within [-2, 2]: turning rate about world z (+: counter-clockwise seen from above)."""
    heading: tuple[float, float] | None = param(
        None, "rad", "world heading (heading mode)", kind="range", lo=-math.pi, hi=math.pi
    )
    """rad, within [-pi, pi]: the heading to turn to and hold (world frame, 0 = +x); sets heading mode."""

    def __post_init__(self) -> None:
        check_fields(self)


@dataclasses.dataclass(frozen=True)
class CommandConfig:
    """``QuadUneven-v0``'s ``command`` argument: the commanded base velocity, fixed or drawn per episode.

    ``{"vx": 0.1}`` commands 0.1 m/s forward for the whole episode; ``{"ranges": {"vx": [-0.2, 0.2]},
    "resample_interval": 10.0}`` draws vx uniformly at every reset and every 10 s of episode time. An axis
    with a range is drawn, the others keep their fixed value (default 0); giving both for one axis is an error.
    """

    vx: float = param(0.0, "m/s", "fixed forward velocity", lo=-MAX_LIN, hi=MAX_LIN)
    """m/s, in [-1, 1]: forward (+) or backward (-) velocity along the heading (yaw-aligned base x)."""
    vy: float = param(0.0, "m/s", "fixed lateral velocity", lo=-MAX_LIN, hi=MAX_LIN)
    """m/s, in [-1, 1]: velocity to the left (+) of the heading (yaw-aligned base y)."""
    yaw_rate: float = param(0.0, "rad/s", "fixed yaw rate", lo=-MAX_YAW_RATE, hi=MAX_YAW_RATE)
    """rad/s, in [-2, 2]: turning rate about world z."""
    heading: float | None = param(None, "rad", "fixed world heading (heading mode)", lo=-math.pi, hi=math.pi,
                                  none_ok=True)  # fmt: skip
    """rad, in [-pi, pi], or None: the heading to turn to and hold (world frame, 0 = +x); sets heading mode,
    where the yaw rate is computed from it (module docstring) and ``yaw_rate`` must stay 0."""
    heading_gain: float = param(0.5, "1/s", "yaw rate per rad of heading error", lo=0.0, hi=10.0, lo_open=True)
    """1/s, in (0, 10]: heading mode's yaw rate per rad of heading error (legged_gym's 0.5)."""
    heading_max_yaw_rate: float = param(
        1.0, "rad/s", "bound of heading mode's yaw rate", lo=0.0, hi=MAX_YAW_RATE, lo_open=True
    )
    """rad/s, in (0, 2]: heading mode's yaw rate is clipped to +- this (legged_gym's 1)."""
    ranges: CommandRanges = dataclasses.field(default_factory=CommandRanges)
    """the drawn axes (see :class:`CommandRanges`); default: none, the command is fixed."""
    resample_interval: float | None = param(
        10.0, "s", "episode time between two draws", lo=0.0, lo_open=True, none_ok=True
    )
    """s, > 0, or None (drawn once, at reset): episode time between two draws of the ranged axes; the draw
    happens at the end of the first control step at or after each multiple of it."""

    def __post_init__(self) -> None:
        check_fields(self)
        if not isinstance(self.ranges, CommandRanges):
            raise ValueError(
                f"command.ranges must be a mapping with keys from {list(_RANGED_AXES)}, got {excerpt(self.ranges)}"
            )
        if self.heading is not None and self.ranges.heading is not None:
            raise ValueError(
                "CommandConfig.heading must not be given with command.ranges.heading: it is either fixed or drawn"
            )
        if self.heading_mode and (self.yaw_rate != 0.0 or self.ranges.yaw_rate is not None):
            raise ValueError(
                "CommandConfig.yaw_rate must be 0 and ranges.yaw_rate null in heading mode (heading given): the "
                "yaw rate is computed from the heading"
            )

    @property
    def heading_mode(self) -> bool:
        """The command names a heading (fixed or drawn); the yaw rate follows from it."""
        return self.heading is not None or self.ranges.heading is not None

    @property
    def drawn(self) -> bool:
        """Some axis is drawn from a range."""
        return any(getattr(self.ranges, a) is not None for a in _RANGED_AXES)

    @property
    def fixed(self) -> np.ndarray:
        """(3,) the fixed values (m/s, m/s, rad/s), in :data:`COMMAND_AXES` order."""
        return np.array([getattr(self, a) for a in COMMAND_AXES], dtype=np.float64)


def load_command(raw: Mapping[str, Any] | CommandConfig | None) -> CommandConfig | None:
    """The env's ``command`` argument as a :class:`CommandConfig` (None: no command).

    :raises ValueError: on a non-mapping, an unknown key, a bad value or an axis given both fixed and ranged,
        naming the field (``command.vx``, ``command.ranges.vy``, ...) and its allowed values.
    """
    if raw is None or isinstance(raw, CommandConfig):
        return raw
    names = [f.name for f in dataclasses.fields(CommandConfig)]
    if not isinstance(raw, Mapping):
        raise ValueError(f"command must be None or a mapping with keys from {sorted(names)}, got {excerpt(raw)}")
    values = dict(raw)
    ranges = values.pop("ranges", None)
    if ranges is not None and not isinstance(ranges, Mapping | CommandRanges):
        raise ValueError(f"command.ranges must be a mapping with keys from {list(_RANGED_AXES)}, got {excerpt(ranges)}")
    values["ranges"] = from_mapping(CommandRanges, ranges, "command.ranges")
    both = [a for a in _RANGED_AXES if a in raw and raw[a] is not None and getattr(values["ranges"], a) is not None]
    if both:
        raise ValueError(
            f"command.{both[0]} must not be given with command.ranges.{both[0]}: an axis is either fixed or drawn"
        )
    return from_mapping(CommandConfig, values, "command")


class CommandSchedule:
    """This episode's command: drawn at :meth:`reset`, re-drawn by :meth:`update` at ``resample_interval``.

    :param config: the command's config.
    """

    def __init__(self, config: CommandConfig) -> None:
        self.config = config
        self.value = config.fixed
        """(3,) the current command (m/s, m/s, rad/s), yaw-aligned base frame; updated in place."""
        self._ranged = [
            (k, getattr(config.ranges, a)) for k, a in enumerate(COMMAND_AXES) if getattr(config.ranges, a) is not None
        ]
        self.heading = math.nan if config.heading is None else config.heading
        """rad, world frame: heading mode's target (drawn with the ranged axes); NaN outside heading mode."""
        self._rng: np.random.Generator | None = None
        self._next = math.inf

    def reset(self, rng: np.random.Generator) -> None:
        """Start an episode (episode time 0): draw the ranged axes from ``rng``, which later draws also use."""
        self._rng = rng
        self.value[:] = self.config.fixed
        self._draw()
        interval = self.config.resample_interval
        self._next = interval if self.config.drawn and interval is not None else math.inf

    def steer(self, yaw: float) -> None:
        """Heading mode: set the yaw rate from the measured trunk heading ``yaw`` (rad); otherwise nothing."""
        if self.config.heading_mode:
            c = self.config
            rate = c.heading_gain * wrap_angle(self.heading - yaw)
            self.value[2] = min(max(rate, -c.heading_max_yaw_rate), c.heading_max_yaw_rate)

    def update(self, t: float) -> bool:
        """At episode time ``t`` (s): re-draw if a resample time has been reached; True if it did."""
        if t < self._next:
            return False
        self._draw()
        interval = self.config.resample_interval
        self._next += interval * (math.floor((t - self._next) / interval) + 1)  # type: ignore[operator]
        return True

    def set(self, value: np.ndarray) -> None:
        """Replace the current command by ``value`` (3,) (m/s, m/s, rad/s), checked against the bounds.

        :raises ValueError: naming ``command`` and the allowed values.
        """
        v = np.asarray(value, dtype=float)
        bounds = np.array([MAX_LIN, MAX_LIN, MAX_YAW_RATE])
        if v.shape != (3,) or not np.all(np.isfinite(v)) or np.any(np.abs(v) > bounds):
            raise ValueError(
                f"command must be 3 finite numbers (vx, vy in [-{MAX_LIN:g}, {MAX_LIN:g}] m/s, yaw_rate in "
                f"[-{MAX_YAW_RATE:g}, {MAX_YAW_RATE:g}] rad/s), got {excerpt(value)}"
            )
        self.value[:] = v

    def _draw(self) -> None:
        for k, (low, high) in self._ranged:
            self.value[k] = self._rng.uniform(low, high)  # type: ignore[union-attr]
        if self.config.ranges.heading is not None:  # drawn after the axes: their draws do not change with it
            self.heading = float(self._rng.uniform(*self.config.ranges.heading))  # type: ignore[union-attr]


def command_arguments_table() -> str:
    """Markdown table of the ``command`` fields (field, default, allowed, unit, meaning)."""
    rows = ["| field | default | allowed | unit | meaning |", "|---|---|---|---|---|"]
    for prefix, cls in (("", CommandConfig), ("ranges.", CommandRanges)):
        for q in params_of(cls):
            rows.append(f"| ``{prefix}{q.name}`` | ``{q.default!r}`` | {q.allowed()} | {q.unit} | {q.doc} |")
    return "\n".join(rows)


__all__ = [
    "COMMAND_AXES",
    "CommandConfig",
    "CommandRanges",
    "CommandSchedule",
    "load_command",
]
