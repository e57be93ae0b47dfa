"""Follow a list of waypoints by steering a velocity command (a small pure pursuit, outside the env).

:class:`WaypointFollower` turns the measured COG position and heading into the command ``(vx, vy, yaw_rate)``
(m/s, m/s, rad/s, yaw-aligned base frame) that walks to the next waypoint; the caller writes it into the env
(``QuadUneven-v0``'s :meth:`~quad_uneven_env.env.QuadUnevenEnv.set_command`), where the expert (or a learned
policy, through the observation's ``command`` field) follows it. A waypoint counts as reached once the COG
comes within ``radius`` of it (horizontal distance); they are taken in order.

Two ways of walking there (:attr:`WaypointConfig.heading`):

- ``"face"``: turn towards the waypoint and walk forwards: ``yaw_rate = clip(alpha / turn_time, +-max_yaw_rate)``
  for the bearing error ``alpha`` (rad, the waypoint's bearing minus the heading, wrapped to [-pi, pi]), and
  ``vx = speed * max(cos(alpha), 0)`` (no forward motion while the waypoint is behind: the robot turns in
  place first);
- ``"hold"``: keep the heading the episode started with (``yaw_rate`` steers back to it the same way) and
  walk straight at the waypoint, sideways or backwards as needed: ``(vx, vy) = speed * (unit bearing in the
  yaw-aligned frame)``, ``|vy|`` at most ``max_lateral`` (side-stepping along a slope).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from quad_uneven_env.fields import check_fields, excerpt, from_mapping, param
from quad_uneven_env.spatial import wrap_angle

HEADING_MODES: tuple[str, ...] = ("face", "hold")
"""Allowed values of :attr:`WaypointConfig.heading`."""


@dataclasses.dataclass(frozen=True)
class WaypointConfig:
    """Waypoints and how to walk them (SI units, world frame)."""

    points: tuple[tuple[float, float], ...] = ()
    """(x, y) m, world: the waypoints, in order (at least one)."""
    radius: float = param(0.3, "m", "distance at which a waypoint counts as reached", lo=0.0, hi=2.0, lo_open=True)
    """m, in (0, 2]: a waypoint is reached once the COG is within this horizontal distance of it."""
    speed: float = param(0.1, "m/s", "walking speed", lo=0.0, hi=1.0, lo_open=True)
    """m/s, in (0, 1]: commanded speed towards the waypoint."""
    heading: str = param("face", "-", "face the waypoint or hold the start heading", kind="choice",
                         choices=HEADING_MODES)  # fmt: skip
    """"face" (turn towards the waypoint, walk forwards) or "hold" (keep the start heading, walk sideways or
    backwards as needed); see the module docstring."""
    max_yaw_rate: float = param(0.3, "rad/s", "largest commanded yaw rate", lo=0.0, hi=2.0, lo_open=True)
    """rad/s, in (0, 2]: largest commanded yaw rate."""
    turn_time: float = param(3.0, "s", "time to close a heading error", lo=0.0, hi=60.0, lo_open=True)
    """s, in (0, 60]: the yaw rate is the heading error over this time (then clipped)."""
    max_lateral: float = param(0.1, "m/s", "largest commanded lateral speed", lo=0.0, hi=1.0)
    """m/s, in [0, 1]: largest |vy| with ``heading="hold"``."""

    def __post_init__(self) -> None:
        check_fields(self, "waypoints")
        pts = self.points
        bad = ValueError(f"waypoints.points must be a non-empty list of finite [x, y] pairs (m), got {excerpt(pts)}")
        if isinstance(pts, str | bytes | Mapping) or not isinstance(pts, Sequence) or len(pts) == 0:
            raise bad
        out = []
        for p in pts:
            if isinstance(p, str | bytes | Mapping) or not isinstance(p, Sequence) or len(p) != 2:
                raise bad
            if any(isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v) for v in p):
                raise bad
            out.append((float(p[0]), float(p[1])))
        object.__setattr__(self, "points", tuple(out))


def load_waypoints(raw: Mapping[str, Any] | WaypointConfig, where: str = "waypoints") -> WaypointConfig:
    """A :class:`WaypointConfig` from a mapping (``{"points": [[x, y], ...], "radius": ..., ...}``).

    :raises ValueError: naming the field (``waypoints.points``, ``waypoints.radius``, ...) and its allowed values.
    """
    try:
        return from_mapping(WaypointConfig, raw, where)
    except ValueError as err:
        msg = str(err)
        raise ValueError(msg if msg.startswith(where) else msg.replace("waypoints", where, 1)) from None


class WaypointFollower:
    """The command that walks to the waypoints of ``config`` in turn (see the module docstring).

    :param config: the waypoints and gains.
    """

    def __init__(self, config: WaypointConfig) -> None:
        self.config = config
        self.reached = 0
        """waypoints reached so far (in order)."""
        self._heading0 = 0.0

    @property
    def done(self) -> bool:
        """Every waypoint has been reached."""
        return self.reached >= len(self.config.points)

    def reset(self, yaw: float) -> None:
        """Start an episode whose trunk heading is ``yaw`` (rad, world z): no waypoint reached yet."""
        self.reached = 0
        self._heading0 = float(yaw)

    def update(self, xy: np.ndarray, yaw: float) -> np.ndarray:
        """The command (3,) (vx, vy m/s, yaw rate rad/s, yaw-aligned base frame) at COG ``xy`` (m, world) and
        heading ``yaw`` (rad); marks the waypoints reached first (zero command once all are)."""
        cfg = self.config
        x, y = float(xy[0]), float(xy[1])
        while not self.done:
            px, py = cfg.points[self.reached]
            if math.hypot(px - x, py - y) > cfg.radius:
                break
            self.reached += 1
        if self.done:
            return np.zeros(3)
        tx, ty = cfg.points[self.reached]
        bearing = math.atan2(ty - y, tx - x)
        if cfg.heading == "face":
            alpha = wrap_angle(bearing - yaw)
            vx, vy = cfg.speed * max(math.cos(alpha), 0.0), 0.0
        else:
            alpha = wrap_angle(self._heading0 - yaw)
            rel = wrap_angle(bearing - yaw)
            vx, vy = cfg.speed * math.cos(rel), cfg.speed * math.sin(rel)
            vy = max(-cfg.max_lateral, min(cfg.max_lateral, vy))
        rate = max(-cfg.max_yaw_rate, min(cfg.max_yaw_rate, alpha / cfg.turn_time))
        return np.array([vx, vy, rate])


__all__ = ["HEADING_MODES", "WaypointConfig", "WaypointFollower", "load_waypoints"]
