"""Collision-free swing-leg paths (paper §5): clamped cubic splines of the foot site over the terrain.

The foot site (the centre of the foot sphere of radius ``foot_radius``) goes from its lift-off
position (foothold + radius x normal) to its touch-down position through ``N - 2`` intermediate
points (eq. 29): a lift point just above the lift-off foothold, apex points above the highest
terrain between the footholds, a descent point just above the touch-down foothold, all
``clearance`` above the terrain and inside the leg's workspace along the planned hip path. The
dense path is then checked against the height field: a cubic between two safe knots can dip
into an obstacle, so the intermediate points are raised by the deficit and the spline re-solved.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np

from planners.spline import ClampedCubicSpline
from planners.terrain_query import max_height_in_disk, sphere_clearance
from planners.types import HeightMap, PlanningError

KNOT_TIME = (0.0, 0.2, 0.5, 0.8, 1.0)
"""Default knot times as fractions of the swing duration (N = 5)."""
KNOT_TRAVEL = (0.0, 0.04, 0.5, 0.96, 1.0)
"""Horizontal progress of each knot as a fraction of the lift-off -> touch-down step."""
CHECK_SAMPLES = 120
"""Dense samples per swing for the clearance check."""
RANGE_SLACK = 0.05
"""rad: a swing knot at most this past its leg's joint ranges is left where it is (as far as a moved knot is placed
inside them)."""
RANGE_MARGIN = 0.05
"""rad: how far inside its joint ranges a swing knot moved by the joint-range test is placed."""
RANGE_STEPS = 12
"""candidate positions tried per knot by the joint-range test, from the knot to the middle of the step."""
RANGE_TOLERANCE = 0.3
"""rad: a swing knot that no position toward the middle of the step brings within this of its joint ranges is
left where it is (a step far past a joint range is walked as planned, the joint stopping at its limit)."""


@dataclasses.dataclass(frozen=True)
class SwingPath:
    """Foot-site path of one swing leg in the world frame (m, s; absolute times)."""

    leg: str
    """leg name."""
    t_start: float
    """lift-off time (s)."""
    t_end: float
    """touch-down time (s)."""
    spline: ClampedCubicSpline
    """the clamped cubic spline of the foot site."""
    min_clearance: float
    """smallest sphere-terrain gap (m) between the first and last intermediate knots."""
    end_clearance: float
    """smallest sphere-terrain gap (m) near lift-off and touch-down, relative to resting on the foothold."""

    @property
    def knots(self) -> np.ndarray:
        """(N, 3) foot-site knots (m): lift-off, intermediate points, touch-down."""
        return self.spline.points

    def position(self, t: np.ndarray) -> np.ndarray:
        """Foot-site position (T, 3) in m at absolute times ``t`` (s)."""
        return self.spline(t, 0)

    def velocity(self, t: np.ndarray) -> np.ndarray:
        """Foot-site velocity (T, 3) in m/s."""
        return self.spline(t, 1)

    def acceleration(self, t: np.ndarray) -> np.ndarray:
        """Foot-site acceleration (T, 3) in m/s^2."""
        return self.spline(t, 2)


def _dense_clearance(
    spline: ClampedCubicSpline, terrain: HeightMap, radius: float, t_in: tuple[float, float], rest_gap: float
) -> tuple[float, float, np.ndarray, np.ndarray]:
    t = np.linspace(spline.tau[0], spline.tau[-1], CHECK_SAMPLES)
    gap = sphere_clearance(terrain, spline(t), radius)
    inner = (t >= t_in[0]) & (t <= t_in[1])
    return float(gap[inner].min()), float(gap[~inner].min() - rest_gap), t, gap


def _fit_joint_ranges(
    points: np.ndarray, tau: np.ndarray, p0: np.ndarray, p1: np.ndarray, range_excess: Callable
) -> None:
    """Move the lift and descent points (in place) toward the middle of the step where the leg's joints would
    pass their ranges there by more than :data:`RANGE_SLACK`: to the first of :data:`RANGE_STEPS` positions
    :data:`RANGE_MARGIN` inside them, else to the one least outside if that is within :data:`RANGE_TOLERANCE`.
    Other points are not moved."""
    step = p1[:2] - p0[:2]
    for k in (1, len(points) - 2):
        if range_excess(tau[k : k + 1], points[None, k : k + 1])[0, 0] <= RANGE_SLACK:
            continue
        s0 = float(KNOT_TRAVEL[k])
        s = np.linspace(s0, 0.5, RANGE_STEPS)
        cand = np.repeat(points[k][None], RANGE_STEPS, axis=0)
        cand[:, :2] = p0[:2] + s[:, None] * step
        over = range_excess(tau[k : k + 1], cand[None])[0]
        ok = np.flatnonzero(over <= -RANGE_MARGIN)
        j = int(ok[0]) if ok.size else int(np.argmin(over))
        if over[j] <= RANGE_TOLERANCE:
            points[k, :2] = cand[j, :2]


def plan_swing(
    leg: str,
    site_lift: np.ndarray,
    site_touch: np.ndarray,
    t_start: float,
    t_end: float,
    terrain: HeightMap,
    clearance: float,
    foot_radius: float,
    hip_position: Callable[[np.ndarray], np.ndarray] | None = None,
    reach: tuple[float, float] = (0.0, np.inf),
    max_raises: int = 6,
    range_excess: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
) -> SwingPath:
    """Plan the swing of ``leg``'s foot site from ``site_lift`` to ``site_touch`` (world, m).

    :param site_lift: foot-site position at lift-off (foothold + radius x normal) (m).
    :param site_touch: foot-site position at touch-down (m).
    :param t_start: lift-off time (s); ``t_end``: touch-down time (s).
    :param terrain: height map (world frame).
    :param clearance: required sphere-terrain gap (m) between the first and last intermediate points.
    :param foot_radius: foot sphere radius (m).
    :param hip_position: ``t (T,) -> (T, 3)`` planned hip position (m) for the workspace check (eq. 29).
    :param reach: (min, max) hip-to-foot-site distance (m) allowed at the intermediate points.
    :param range_excess: ``(t (K,), sites (K, M, 3)) -> (K, M)``: how far (rad) the leg's joints would pass their
        ranges with the foot site at ``sites[k, m]`` at time ``t[k]`` (<= 0: inside). The lift and descent points
        whose joints pass their ranges by more than :data:`RANGE_SLACK` are moved toward the middle of the step,
        :data:`RANGE_MARGIN` inside them or as far inside as the middle allows (not beyond
        :data:`RANGE_TOLERANCE`: else they stay); None: no joint-range test.
    :raises PlanningError: naming the leg when no collision-free reachable path is found.
    """
    p0, p1 = np.asarray(site_lift, dtype=float), np.asarray(site_touch, dtype=float)
    if not t_end > t_start:
        raise ValueError(f"swing of {leg}: t_end must be > t_start, got {t_start}, {t_end}")
    if clearance < 0.0:
        raise ValueError(f"clearance must be >= 0 m, got {clearance}")
    tau = t_start + (t_end - t_start) * np.asarray(KNOT_TIME)
    travel = np.asarray(KNOT_TRAVEL)
    xy = p0[:2] + travel[:, None] * (p1[:2] - p0[:2])
    # Highest terrain under the whole step (sphere footprint plus a margin), and near each end.
    line = p0[:2] + np.linspace(0.0, 1.0, 40)[:, None] * (p1[:2] - p0[:2])
    top = float(max_height_in_disk(terrain, line, foot_radius + 0.01).max())
    z_apex = max(top + foot_radius + clearance, max(p0[2], p1[2]) + clearance)
    z = np.array([p0[2], z_apex, z_apex, z_apex, p1[2]])
    points = np.column_stack([xy, z])
    # Resting on a slope, the conservative gap is already r (n_z - 1) < 0: ends are judged against it.
    rest_gap = float(min(0.0, sphere_clearance(terrain, np.stack([p0, p1]), foot_radius).min()))
    t_in = (float(tau[1]), float(tau[-2]))
    if range_excess is not None:
        _fit_joint_ranges(points, tau, p0, p1, range_excess)
    for _ in range(max_raises + 1):
        spline = ClampedCubicSpline(tau, points)
        inner, ends, _, _ = _dense_clearance(spline, terrain, foot_radius, t_in, rest_gap)
        deficit = max(clearance - inner, -ends)
        if deficit <= 1e-9:
            break
        points[1:-1, 2] += deficit + 0.005
        if range_excess is not None:
            _fit_joint_ranges(points, tau, p0, p1, range_excess)
    else:
        raise PlanningError(
            f"swing of {leg}: no collision-free path after {max_raises} raises: clearance {inner:.4f} m "
            f"between the intermediate points (need {clearance:.4f} m), {ends:.4f} m near the ends (need >= 0)"
        )
    if hip_position is not None:
        dist = np.linalg.norm(points[1:-1] - np.asarray(hip_position(tau[1:-1])), axis=1)
        bad = np.flatnonzero((dist < reach[0]) | (dist > reach[1]))
        if bad.size:
            k = int(bad[0])
            raise PlanningError(
                f"swing of {leg}: intermediate point {k + 1} at {points[k + 1].round(4).tolist()} is "
                f"{dist[k]:.4f} m from the hip, outside the workspace [{reach[0]:.4f}, {reach[1]:.4f}] m"
            )
    return SwingPath(leg, float(t_start), float(t_end), spline, inner, ends)
