"""The input of one gait-cycle plan (:class:`Scenario`) and the paper's §6 scenario."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

import numpy as np

from planners.footholds import FootholdLimits
from planners.gait import PAPER_DURATIONS, SWING_ORDERS, validate_durations
from planners.robot_geometry import RobotGeometry, robot_geometry
from planners.types import HeightMap
from quad_uneven_env.fields import excerpt
from quad_uneven_env.robot.description import RobotDescription


def _vec3(value: Any, field: str) -> np.ndarray:
    v = np.asarray(value, dtype=float)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise ValueError(f"{field} must be 3 finite numbers, got {excerpt(value)}")
    return v


def _boundary(value: Mapping[str, Any] | None, field: str) -> np.ndarray | None:
    """{'pos', 'vel', 'acc'} -> (3, 3) rows position (m), velocity (m/s), acceleration (m/s^2)."""
    if value is None:
        return None
    if not isinstance(value, Mapping) or "pos" not in value:
        raise ValueError(
            f"{field} must be a dict with 'pos' (and optional 'vel', 'acc') 3-vectors, got {excerpt(value)}"
        )
    unknown = set(value) - {"pos", "vel", "acc"}
    if unknown:
        raise ValueError(f"{field}: unknown key(s) {excerpt(sorted(unknown, key=str))}; allowed: pos, vel, acc")
    return np.stack([_vec3(value.get(k, np.zeros(3)), f"{field}.{k}") for k in ("pos", "vel", "acc")])


def _feet(value: Any, field: str) -> np.ndarray:
    a = np.asarray(value, dtype=float)
    if a.shape != (4, 3) or not np.all(np.isfinite(a)):
        raise ValueError(
            f"{field} must be a finite 4 x 3 array (legs LF, RF, LH, RH; x, y, z in m), got shape {a.shape}"
        )
    return a


BODY_PITCH_MODES: tuple[str, ...] = ("level", "terrain")
"""Allowed values of ``Scenario.body_pitch``."""


@dataclasses.dataclass(frozen=True)
class Scenario:
    """One gait cycle to plan (SI units, world frame = MuJoCo's, legs LF, RF, LH, RH).

    Footholds are points ON the terrain surface; the foot site (sphere centre) of a foot resting
    there is ``foothold + foot_radius * normal``.
    """

    terrain: str | Mapping[str, Any] | HeightMap
    """terrain spec (str or dict, as the environment accepts) or a height map (e.g. a ``HeightField``)."""
    feet_start: np.ndarray
    """(4, 3) current footholds (m), points on the terrain surface."""
    cog_start: Mapping[str, Any]
    """COG at the start: {'pos', 'vel', 'acc'} 3-vectors (m, m/s, m/s^2); whole-robot COG."""
    footholds: np.ndarray | None = None
    """(4, 3) target footholds on the surface (m), or None to choose them on the terrain."""
    cog_goal: Mapping[str, Any] | None = None
    """COG at the end of the cycle, or None: above the target footholds' centroid, at rest."""
    durations: tuple[float, ...] = PAPER_DURATIONS
    """7 phase durations (s)."""
    mass: float | None = None
    """robot mass (kg) in the stability index; None: the robot's total mass."""
    epsilon: float = 0.1
    """stability margin (N m)."""
    clearance: float = 0.05
    """swing clearance (m) of the foot sphere above the terrain."""
    terrain_seed: int = 0
    """seed of the generator used when ``terrain`` is a spec."""
    cog_height: float = 0.36
    """desired COG height (m) above the mean height of the footholds at each junction."""
    stride: tuple[float, float] = (0.2, 0.0)
    """nominal (dx, dy) (m, world) of the body per cycle when footholds are chosen automatically."""
    weights: tuple[float, float, float] = (1.0, 1.0, 1.0)
    """COG cost weights W (x, y, z) (1/m^2)."""
    smoothing: float = 1e-2
    """weight of the integrated squared COG acceleration (s^3/m^2)."""
    robot: RobotDescription | RobotGeometry | None = None
    """the robot: its description or its planning view; None: the paper's Table-1 robot
    (configs/robot/paper.yaml)."""
    method: str = "sqp"
    """COG solver: 'sqp', 'slsqp' or 'slsqp-fd'."""
    body_pitch: str = "level"
    """base orientation: 'level' (identity, the paper) or 'terrain' (pitch from ``pitch_start`` to the
    slope of the target footholds, :mod:`planners.pitch`)."""
    pitch_start: float = 0.0
    """base pitch (rad, about world y, positive nose down) at the start; used with ``body_pitch='terrain'``."""
    yaw_start: float = 0.0
    """base yaw (rad, about world z, counter-clockwise from above) at the start; 0 with ``turn`` 0: the
    paper's unturned body, exactly."""
    turn: float = 0.0
    """rad, in (-pi/2, pi/2): the body's yaw change over the cycle (a commanded yaw rate times the cycle's
    duration); the nominal footholds are the hips turned by ``yaw_start + turn`` about the goal COG and the
    base yaw follows a smoothstep from ``yaw_start`` (:class:`planners.pitch.BodyPitch`)."""
    swing_order: str = "right_first"
    """lifting order (:data:`planners.gait.SWING_ORDERS`): "right_first" (RH, RF, LH, LF: the paper) or
    "left_first" (its mirror image, for a body moving to the left)."""
    foothold_limits: FootholdLimits | None = None
    """acceptance limits and cost weights of the automatic foothold search; None: the defaults."""

    def __post_init__(self) -> None:
        _feet(self.feet_start, "feet_start")
        if self.footholds is not None:
            _feet(self.footholds, "footholds")
        _boundary(self.cog_start, "cog_start")
        _boundary(self.cog_goal, "cog_goal")
        validate_durations(self.durations)
        if self.mass is not None and not self.mass > 0.0:
            raise ValueError(f"mass must be > 0 kg or None, got {self.mass}")
        if not (np.isfinite(self.epsilon) and self.epsilon >= 0.0):
            raise ValueError(f"epsilon must be a finite number >= 0 (N m), got {self.epsilon}")
        if not (np.isfinite(self.clearance) and self.clearance >= 0.0):
            raise ValueError(f"clearance must be a finite number >= 0 (m), got {self.clearance}")
        if not 0.0 < self.cog_height < 1.0:
            raise ValueError(f"cog_height must be in (0, 1) m, got {self.cog_height}")
        if self.swing_order not in SWING_ORDERS:
            raise ValueError(f"swing_order must be one of {list(SWING_ORDERS)}, got {excerpt(self.swing_order)}")
        if self.body_pitch not in BODY_PITCH_MODES:
            raise ValueError(f"body_pitch must be one of {list(BODY_PITCH_MODES)}, got {excerpt(self.body_pitch)}")
        if not (np.isfinite(self.pitch_start) and abs(self.pitch_start) < 0.5 * np.pi):
            raise ValueError(f"pitch_start must be a finite angle in (-pi/2, pi/2) rad, got {self.pitch_start}")
        if not np.isfinite(self.yaw_start):
            raise ValueError(f"yaw_start must be a finite angle (rad), got {self.yaw_start}")
        if not (np.isfinite(self.turn) and abs(self.turn) < 0.5 * np.pi):
            raise ValueError(f"turn must be a finite angle in (-pi/2, pi/2) rad, got {self.turn}")
        if self.foothold_limits is not None and not isinstance(self.foothold_limits, FootholdLimits):
            raise ValueError(f"foothold_limits must be a FootholdLimits or None, got {excerpt(self.foothold_limits)}")

    def robot_geometry(self) -> RobotGeometry:
        """The planners' view of the robot (:mod:`planners.robot_geometry`; the paper's Table-1 robot unless
        given)."""
        return robot_geometry(self.robot)

    def height_map(self) -> HeightMap:
        """The terrain as a height map (generated from the spec with ``terrain_seed``)."""
        if hasattr(self.terrain, "height") and hasattr(self.terrain, "normal"):
            return self.terrain  # type: ignore[return-value]
        from quad_uneven_env.terrain import Terrain, parse_terrain_spec

        return Terrain(parse_terrain_spec(self.terrain)).generate(np.random.default_rng(self.terrain_seed))

    def start_boundary(self) -> np.ndarray:
        """(3, 3) start position, velocity, acceleration of the COG."""
        return _boundary(self.cog_start, "cog_start")  # type: ignore[return-value]

    def goal_boundary(self) -> np.ndarray | None:
        """(3, 3) goal position, velocity, acceleration, or None (automatic)."""
        return _boundary(self.cog_goal, "cog_goal")


def paper_scenario() -> Scenario:
    """The paper's §6 scenario: Table 1 robot, COG (0.01, 0, 0.544) -> (0.21, 0, 0.5743), 6.1 s cycle.

    The terrain is the ``paper`` kind, our reconstruction of the (missing) Fig. 3: raised ground
    at 0.12 m and non-coplanar blocks under the start and target footholds (``PAPER_BLOCKS``,
    tops 0.16-0.23 m, each leg moves 0.2 m forward; y equal at start and target as in the
    paper). Footholds are given, as by the paper's expert user. Zero velocity and acceleration
    at both ends, epsilon = 0.1 N m, 5 cm swing clearance. ``cog_height`` 0.368 m matches the
    paper's start/end COG heights over the mean foothold height (0.369 and 0.367 m).
    """
    from quad_uneven_env.terrain import PAPER_BLOCKS

    zero = (0.0, 0.0, 0.0)
    return Scenario(
        terrain="paper",
        feet_start=np.array(PAPER_BLOCKS["start"]),
        footholds=np.array(PAPER_BLOCKS["target"]),
        cog_start={"pos": (0.01, 0.0, 0.544), "vel": zero, "acc": zero},
        cog_goal={"pos": (0.21, 0.0, 0.5743), "vel": zero, "acc": zero},
        durations=PAPER_DURATIONS,
        mass=None,
        epsilon=0.1,
        clearance=0.05,
        cog_height=0.368,
    )
