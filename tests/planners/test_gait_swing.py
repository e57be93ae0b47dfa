"""Walk gait phases and clamped cubic swing splines (paper §4, §5)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy.interpolate import CubicSpline

from planners.gait import PAPER_DURATIONS, phase_index, walk_cycle
from planners.spline import ClampedCubicSpline
from planners.swing import plan_swing
from planners.terrain_query import BlockTerrain, sphere_clearance
from planners.types import PlanningError


def test_walk_cycle_matches_paper_sequence():
    phases = walk_cycle(PAPER_DURATIONS)
    assert [p.swing_leg for p in phases] == [None, "RH", "RF", None, "LH", "LF", None]
    assert phases[-1].t_end == pytest.approx(6.1)
    assert phases[3].duration == pytest.approx(0.1)
    for p in phases:
        assert sum(p.stance) == (4 if p.swing_leg is None else 3)
    # RH (index 3) in swing in phase 1; legs already moved in phase 4: RH and RF.
    assert phases[1].stance == (True, True, True, False)
    assert phases[4].moved == (False, True, False, True)
    for a, b in itertools.pairwise(phases):
        assert a.t_end == b.t_start
    idx = phase_index(phases, np.array([0.0, 0.99, 1.0, 3.05, 6.1, 7.0]))
    np.testing.assert_array_equal(idx, [0, 0, 1, 3, 6, 6])


@pytest.mark.parametrize("bad", [(1, 1, 1), (1, 1, 1, 0, 1, 1, 1), (1, 1, 1, np.nan, 1, 1, 1)])
def test_walk_cycle_rejects_bad_durations(bad):
    with pytest.raises(ValueError, match="durations"):
        walk_cycle(bad)


def test_clamped_spline_matches_scipy(rng):
    tau = np.sort(rng.uniform(0.0, 2.0, 6))
    pts = rng.normal(size=(6, 3))
    ours = ClampedCubicSpline(tau, pts)
    ref = CubicSpline(tau, pts, bc_type="clamped")
    t = np.linspace(tau[0], tau[-1], 301)
    for d in range(3):
        np.testing.assert_allclose(ours(t, d), ref(t, d), atol=1e-9)
    np.testing.assert_allclose(ours(tau[[0, -1]], 1), 0.0, atol=1e-12)
    # Outside the interval: holds the ends.
    np.testing.assert_allclose(ours(np.array([tau[0] - 1, tau[-1] + 1])), pts[[0, -1]])
    np.testing.assert_allclose(ours(np.array([tau[-1] + 1]), 2), 0.0)


def test_swing_clears_a_wall_and_reports_clearance():
    # A 12 cm wall between lift-off and touch-down.
    terrain = BlockTerrain(0.0, blocks=np.array([[0.08, 0.12, -1, 1, 0.12]]))
    r, c = 0.02, 0.05
    p0, p1 = np.array([0.0, 0.0, r]), np.array([0.2, 0.0, r])
    sw = plan_swing("LF", p0, p1, 1.0, 2.0, terrain, clearance=c, foot_radius=r)
    t = np.linspace(1.0, 2.0, 2001)
    gap = sphere_clearance(terrain, sw.position(t), r)
    inner = (t >= sw.spline.tau[1]) & (t <= sw.spline.tau[-2])
    assert gap[inner].min() >= c - 2e-3  # dense independent check (finer than the planner's)
    assert gap.min() >= -1e-9
    assert sw.min_clearance >= c
    np.testing.assert_allclose(sw.position(np.array([1.0, 2.0])), [p0, p1], atol=1e-12)
    np.testing.assert_allclose(sw.velocity(np.array([1.0, 2.0])), 0.0, atol=1e-12)


def test_swing_raises_knots_when_cubic_dips():
    # A thin spike right where a first guess would pass: the check must detect and lift.
    terrain = BlockTerrain(0.0, blocks=np.array([[0.035, 0.05, -1, 1, 0.08]]))
    sw = plan_swing("RH", np.array([0, 0, 0.02]), np.array([0.25, 0, 0.02]), 0.0, 1.0, terrain, 0.03, 0.02)
    t = np.linspace(0, 1, 4001)
    gap = sphere_clearance(terrain, sw.position(t), 0.02)
    assert gap.min() >= -1e-3


def test_swing_workspace_violation_names_leg():
    terrain = BlockTerrain(0.0)
    with pytest.raises(PlanningError, match=r"RF.*workspace"):
        plan_swing(
            "RF",
            np.array([0, 0, 0.02]),
            np.array([0.2, 0, 0.02]),
            0.0,
            1.0,
            terrain,
            0.05,
            0.02,
            hip_position=lambda t: np.tile([0.1, 0.0, 1.0], (len(t), 1)),
            reach=(0.1, 0.42),
        )


def _swing_with_range(limit: float):
    """A 1 m flat step whose joints (a stand-in for the IK) pass their range by ``x - limit`` rad, x the knot's
    forward position (m)."""

    def excess(t, sites):
        assert sites.shape[0] == len(t) == 1
        return sites[..., 0] - limit

    p0, p1 = np.array([0.0, 0.0, 0.02]), np.array([1.0, 0.0, 0.02])
    return plan_swing("RH", p0, p1, 0.0, 1.0, BlockTerrain(0.0), 0.05, 0.02, range_excess=excess)


def test_swing_moves_a_knot_past_its_joint_range_toward_the_middle():
    """The descent point (x = 0.96, 0.16 rad past) goes to the first candidate toward the middle that is
    RANGE_MARGIN inside (x = 0.709 of 0.96, 0.918, ..., 0.5); the lift point (inside) stays."""
    from planners.swing import RANGE_MARGIN, RANGE_STEPS

    knots = _swing_with_range(0.8).knots
    s = np.linspace(0.96, 0.5, RANGE_STEPS)
    first = s[np.flatnonzero(s - 0.8 <= -RANGE_MARGIN)[0]]
    assert knots[3, 0] == pytest.approx(first) and first == pytest.approx(0.709, abs=1e-3)
    assert knots[1, 0] == pytest.approx(0.04) and knots[2, 0] == pytest.approx(0.5)


def test_swing_leaves_knots_the_middle_cannot_bring_near_their_range():
    """x - 0.1: the descent point is 0.86 rad past its range, still 0.4 (> RANGE_TOLERANCE) at the middle: it
    stays; a point less than RANGE_SLACK past (x - 0.92 at 0.96) stays too."""
    assert _swing_with_range(0.1).knots[3, 0] == pytest.approx(0.96)
    assert _swing_with_range(0.92).knots[3, 0] == pytest.approx(0.96)
    assert _swing_with_range(0.89).knots[3, 0] < 0.96


@pytest.mark.parametrize("n_knots", [2, 3, 5])
def test_spline_evaluate_gives_the_floats_of_each_derivative_call(n_knots):
    """``ClampedCubicSpline.evaluate`` (one compiled pass) against ``spline(t, d)`` (numpy), bit for bit: inside,
    at the knots, at and beyond both ends."""
    rng = np.random.default_rng(n_knots)
    tau = np.cumsum(rng.uniform(0.05, 0.4, n_knots)) + 1.3
    spline = ClampedCubicSpline(tau, rng.normal(0.0, 0.2, (n_knots, 3)))
    t = np.concatenate([rng.uniform(tau[0] - 0.2, tau[-1] + 0.2, 400), tau, [tau[0] - 1e-12, tau[-1] + 1e-12]])
    pos, vel, acc = spline.evaluate(t)
    for d, got in enumerate((pos, vel, acc)):
        want = spline(t, d)
        assert got.shape == want.shape
        assert got.tobytes() == want.tobytes(), f"derivative {d}"
    one = spline.evaluate(float(tau[0]) + 0.01)
    assert [a.shape for a in one] == [(1, 3)] * 3
