"""The mirrored swing order: left legs first, for a body that moves to the left."""

from __future__ import annotations

import numpy as np
import pytest

import planners
from planners.gait import SWING_ORDERS, walk_cycle
from planners.terrain_query import BlockTerrain

MIRROR = {"LF": "RF", "RF": "LF", "LH": "RH", "RH": "LH", None: None}
FEET = np.array([[0.25, 0.185, 0], [0.25, -0.185, 0], [-0.25, 0.185, 0], [-0.25, -0.185, 0]])  # LF RF LH RH


def test_left_first_is_the_mirror_image_of_the_paper_order():
    right, left = walk_cycle(order="right_first"), walk_cycle(order="left_first")
    assert [p.swing_leg for p in left] == [MIRROR[p.swing_leg] for p in right]
    swap = [1, 0, 3, 2]  # leg order LF RF LH RH mirrored
    for a, b in zip(right, left, strict=True):
        assert (a.t_start, a.t_end) == (b.t_start, b.t_end)
        assert b.stance == tuple(np.array(a.stance)[swap]) and b.moved == tuple(np.array(a.moved)[swap])
    assert set(SWING_ORDERS) == {"right_first", "left_first"}


def test_bad_order_is_rejected():
    with pytest.raises(ValueError, match=r"order must be one of \['right_first', 'left_first'\], got 'x'"):
        walk_cycle(order="x")
    with pytest.raises(ValueError, match=r"swing_order must be one of \['right_first', 'left_first'\]"):
        planners.Scenario(terrain=BlockTerrain(0.0), feet_start=FEET, cog_start={"pos": (0, 0, 0.36)}, swing_order="x")


@pytest.mark.parametrize("dy", [0.31, -0.31])
def test_a_long_side_step_needs_the_legs_on_that_side_first(dy):
    """A 0.31 m side step on flat ground: planned with the legs on the side moved to lifted first; with the other
    order no stable COG path exists (the first-moved legs narrow the support towards the body)."""

    def plan(order):
        sc = planners.Scenario(
            terrain=BlockTerrain(0.0), feet_start=FEET, cog_start={"pos": (0, 0, 0.33)}, cog_height=0.33,
            durations=(0.5, 0.5, 0.5, 0.1, 0.5, 0.5, 0.5), epsilon=20.0, stride=(0.0, dy), swing_order=order,
        )  # fmt: skip
        return planners.plan_gait_cycle(sc)

    good, bad = ("left_first", "right_first") if dy > 0 else ("right_first", "left_first")
    p = plan(good)
    assert p.stats["min_stability"] >= 20.0 - 1e-6
    np.testing.assert_allclose(p.cog.position(np.array([p.duration]))[0, :2], [0.0, dy], atol=0.01)
    with pytest.raises(planners.PlanningError, match="stability moment"):
        plan(bad)
