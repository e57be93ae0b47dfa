"""Foothold selection: flat, edge-free, reachable spots with the shank clear; stepping stones, not holes."""

from __future__ import annotations

import numpy as np
import pytest

from planners.footholds import SHANK_RADIUS_SCALE, FootholdLimits, choose_footholds, foothold_costs, shank_clearance
from planners.terrain_query import BlockTerrain, capsule_clearance
from planners.types import FootholdError, PlanningError
from quad_uneven_env.terrain import Terrain, parse_terrain_spec

FEET = np.array([[0.25, 0.185, 0.0], [0.25, -0.185, 0.0], [-0.25, 0.185, 0.0], [-0.25, -0.185, 0.0]])


def test_flat_ground_gives_nominal_footholds(paper_robot):
    out = choose_footholds(
        BlockTerrain(0.05),
        paper_robot,
        FEET + np.array([0, 0, 0.05]),
        np.array([0, 0, 0.41]),
        np.array([0.2, 0.0]),
        0.36,
    )
    nominal = paper_robot.hip_positions_B[:, :2] + [0.2, 0.0]
    np.testing.assert_allclose(out[:, :2], nominal, atol=1e-9)
    np.testing.assert_allclose(out[:, 2], 0.05)


def test_avoids_step_edge(paper_robot):
    # A 10 cm step edge right at the LF/RF nominal x (0.45): chosen footholds keep 4.5 cm away from it.
    terrain = BlockTerrain(0.0, blocks=np.array([[0.45, 2.0, -1.0, 1.0, 0.1]]))
    out = choose_footholds(terrain, paper_robot, FEET, np.array([0, 0, 0.36]), np.array([0.2, 0.0]), 0.36)
    for i in (0, 1):
        assert abs(out[i, 0] - 0.45) >= FootholdLimits().edge_radius - 1e-9
        assert out[i, 2] == pytest.approx(terrain.height(out[i, 0], out[i, 1]))


def test_stepping_stones_footholds_on_stones(paper_robot, rng):
    spec = parse_terrain_spec("stepping_stones")
    hf = Terrain(spec).generate(np.random.default_rng(3))
    base = np.array([1.0, 0.0])
    feet = np.column_stack([paper_robot.hip_positions_B[:, :2] + base, np.zeros(4)])
    feet[:, 2] = hf.height(feet[:, 0], feet[:, 1])
    out = choose_footholds(
        hf, paper_robot, feet, np.array([1.0, 0.0, feet[:, 2].mean() + 0.36]), base + np.array([0.2, 0.0]), 0.36
    )
    s = hf.patch_stats(out[:, 0], out[:, 1], FootholdLimits().edge_radius)
    assert np.all(s.height_max - s.height_min <= 1e-9)  # flat stone tops: no edge or hole under the foot
    np.testing.assert_allclose(out[:, 2], hf.height(out[:, 0], out[:, 1]))


def test_no_foothold_raises_naming_leg(paper_robot):
    # Washboard of 10 cm ridges every 4 cm: no flat spot anywhere.
    blocks = np.array([[x, x + 0.02, -1.0, 1.0, 0.1] for x in np.arange(-1.0, 1.0, 0.04)])
    with pytest.raises(PlanningError, match=r"LF"):
        choose_footholds(
            BlockTerrain(0.0, blocks=blocks), paper_robot, FEET, np.array([0, 0, 0.4]), np.array([0.2, 0.0]), 0.36
        )


def test_shank_clearance_flat_stance_versus_shank_on_a_nosing(paper_robot):
    flat = BlockTerrain(0.0)
    r = paper_robot.foot_radius
    for leg, hip_x in (("LF", 0.25), ("LH", -0.25)):
        hip = np.array([hip_x, 0.185, 0.33])  # nominal stance: the foot under the hip
        gap = shank_clearance(flat, paper_robot, leg, np.array([[hip_x, 0.185, r]]), hip, np.eye(3))
        assert gap[0] > 0.01
    # The stairs-down failure: hind foot 2.5 cm behind a 8 cm drop, hip only 0.13 m above the foot
    # and 0.1 m ahead: the forward knee dips below the foot and the shank rests on the nosing.
    stair = BlockTerrain(-0.08, blocks=np.array([[-2.0, 0.6, -1.0, 1.0, 0.0]]))
    site = np.array([[0.575, 0.198, r]])
    low = shank_clearance(stair, paper_robot, "LH", site, np.array([0.679, 0.198, 0.15]), np.eye(3))
    high = shank_clearance(stair, paper_robot, "LH", site, np.array([0.679, 0.198, 0.30]), np.eye(3))
    assert low[0] < -0.001 and FootholdLimits().shank_clearance < high[0]
    # On a plane the gap is exact: a shank parallel to a 15 deg slope, its axis 3 cm above it.
    slope = BlockTerrain(0.0, slope=(np.tan(np.deg2rad(15.0)), 0.0))
    axis = np.array([np.cos(np.deg2rad(15.0)), 0.0, np.sin(np.deg2rad(15.0))])
    n = np.array([-axis[2], 0.0, axis[0]])
    a = 0.03 * n
    assert capsule_clearance(slope, a, a + 0.2 * axis, 0.0175)[0] == pytest.approx(0.0125, abs=1e-6)


@pytest.mark.parametrize("pitch_start", [None, 0.0])
def test_front_foot_kept_off_the_nosing_when_stepping_down(paper_robot, pitch_start):
    # 8 cm drop at x = 0.5, the front nominal footholds 8 cm past it: the backward-bent front
    # shank would rest on the edge above the foot; the chosen footholds keep it clear.
    terrain = BlockTerrain(-0.08, blocks=np.array([[-2.0, 0.5, -1.0, 1.0, 0.0]]))
    args = (terrain, paper_robot, FEET, np.array([0.0, 0.0, 0.33]), np.array([0.33, 0.0]), 0.33)
    free = choose_footholds(
        *args, pitch_start=pitch_start, limits=FootholdLimits(shank_clearance=-1.0, w_edge=0.0, w_shank=0.0)
    )
    out = choose_footholds(*args, pitch_start=pitch_start)
    np.testing.assert_allclose(free[:2, 0], 0.58)  # nominal: under the hips at the end of the cycle
    assert np.all(out[:2, 2] == -0.08) and np.all(out[:2, 0] > free[:2, 0] + 0.01)  # further from the edge
    np.testing.assert_allclose(out[2:], free[2:])  # hind feet on the flat upper level: unchanged


def test_shank_geometry_matches_the_mujoco_model(paper_robot):
    import mujoco

    from quad_uneven_env.robot import robot_mjcf

    m = mujoco.MjModel.from_xml_string(robot_mjcf(paper_robot))
    for leg in ("LF", "RH"):
        radius, half_length = m.geom(f"{leg}_shank_geom").size[:2]
        assert radius == pytest.approx(SHANK_RADIUS_SCALE * paper_robot.link_radius)
        # The capsule runs from the knee to foot_radius short of the foot point (where shank_clearance starts it).
        assert 2 * half_length == pytest.approx(paper_robot.two_link.shank - paper_robot.foot_radius)


def _slope_field(angle_deg: float):
    """The env's ``slope`` terrain (a HeightField): flat, a ramp of ``angle_deg`` from x = 0.62 m to 2.12 m, ..."""
    spec = parse_terrain_spec({"kind": "slope", "angle_deg": angle_deg, "ramp_length": 1.5, "plateau_length": 1.0})
    return Terrain(spec).generate(np.random.default_rng(0))


def test_edge_test_accepts_a_uniform_25_deg_slope_and_rejects_a_step_edge(paper_robot):
    lim = FootholdLimits()
    r = paper_robot.foot_radius
    x = np.linspace(1.0, 1.8, 9)  # on the ramp, away from its kinks
    y = np.zeros_like(x)
    for terrain in (_slope_field(25.0), BlockTerrain(0.0, slope=(np.tan(np.deg2rad(25.0)), 0.0))):
        _, tests = foothold_costs(terrain, x, y, np.array([1.4, 0.0]), r, lim)
        assert tests["slope"].all() and tests["edge"].all()
        # The raw height range in the edge disc would call it an edge:
        s = _slope_field(25.0).patch_stats(x, y, lim.edge_radius)
        assert np.all(s.height_max - s.height_min > 0.03)
    # A 4 cm step (stairs, a HeightField) and a 10 cm block edge (exact map): rejected within edge_radius of it.
    stairs = Terrain(parse_terrain_spec({"kind": "stairs", "direction": "up", "riser": 0.04, "tread": 0.3}))
    hf = stairs.generate(np.random.default_rng(0))
    edge_x = 0.62 + 0.3  # first step edge at x0 + tread (on the first node at or beyond it)
    near = np.array([edge_x - 0.02, edge_x, edge_x + 0.02])
    _, tests = foothold_costs(hf, near, np.zeros(3), np.array([edge_x, 0.0]), r, lim)
    assert not tests["edge"].any()
    far = np.array([edge_x - 0.12, edge_x + 0.12])
    _, tests = foothold_costs(hf, far, np.zeros(2), np.array([edge_x, 0.0]), r, lim)
    assert tests["edge"].all()
    block = BlockTerrain(0.0, blocks=np.array([[0.5, 2.0, -1.0, 1.0, 0.1]]))
    _, tests = foothold_costs(block, np.array([0.48, 0.52, 0.4, 0.6]), np.zeros(4), np.zeros(2), r, lim)
    np.testing.assert_array_equal(tests["edge"], [False, False, True, True])


def test_footholds_on_a_25_deg_slope(paper_robot):
    hf = _slope_field(25.0)
    base = np.array([1.3, 0.0])
    feet = np.column_stack([paper_robot.hip_positions_B[:, :2] + base, np.zeros(4)])
    feet[:, 2] = hf.height(feet[:, 0], feet[:, 1])
    cog = np.array([*base, feet[:, 2].mean() + 0.33])
    out = choose_footholds(
        hf, paper_robot, feet, cog, base + np.array([0.33, 0.0]), 0.33, pitch_start=np.deg2rad(-25.0)
    )
    nominal = paper_robot.hip_positions_B[:, :2] + base + [0.33, 0.0]
    assert np.all(np.linalg.norm(out[:, :2] - nominal, axis=1) <= 0.05)
    assert np.all((out[:, 0] > 0.62 + 0.045) & (out[:, 0] < 2.12 - 0.045))  # on the ramp
    np.testing.assert_allclose(out[:, 2], hf.height(out[:, 0], out[:, 1]))


def test_stone_beyond_the_inner_window_when_the_nominal_foothold_is_in_a_gap(paper_robot):
    # 30 cm deep pits 14 cm wide (x) centred on the nominal footholds, ground between them: nothing
    # acceptable within the inner window (0.1 m), the ground beyond the pit is.
    goal = np.array([0.2, 0.0])
    nominal = paper_robot.hip_positions_B[:, :2] + goal  # x = 0.45 (front), -0.05 (hind)
    ground = np.array([[-2.0, -0.12, -1.0, 1.0, 0.0], [0.02, 0.38, -1.0, 1.0, 0.0], [0.52, 2.0, -1.0, 1.0, 0.0]])
    terrain = BlockTerrain(-0.3, blocks=ground)
    args = (terrain, paper_robot, FEET, np.array([0.0, 0.0, 0.33]), goal, 0.33)
    with pytest.raises(PlanningError, match=r"for LF within 0.1 m .*failed test: hole"):
        choose_footholds(*args, limits=FootholdLimits(reach_window=0.1))
    out = choose_footholds(*args)
    np.testing.assert_allclose(out[:, 2], 0.0)
    dist = np.abs(out[:, 0] - nominal[:, 0])
    # beyond the inner window, and no further from the pit than the edge-nearness cost asks (clear_radius)
    assert np.all(dist > 0.1) and np.all(dist <= 0.07 + FootholdLimits().clear_radius + 0.01)
    np.testing.assert_allclose(out[:, 1], nominal[:, 1], atol=0.02)


def test_cost_ordering_on_a_hand_made_height_map(paper_robot):
    # Flat ground at 0 and a 10 cm block from x = 0.3 on; a tilted plane.
    lim = FootholdLimits()
    r = paper_robot.foot_radius
    block = BlockTerrain(0.0, blocks=np.array([[0.3, 2.0, -1.0, 1.0, 0.1]]))
    nominal = np.array([0.1, 0.0])
    pts = np.array([[0.1, 0.0], [0.12, 0.0], [0.1, 0.05], [0.1, 0.15], [0.25, 0.0], [0.1, -0.15], [0.2, 0.0]])
    cost, tests = foothold_costs(block, pts[:, 0], pts[:, 1], nominal, r, lim)
    assert np.all(tests["edge"])
    # Flat and clear of the edge (>= clear_radius): the squared distance alone, nearer is cheaper.
    np.testing.assert_allclose(cost[[0, 1, 2, 3, 5, 6]], [0.0, 0.02**2, 0.05**2, 0.15**2, 0.15**2, 0.1**2], atol=1e-12)
    # 0.15 m from the nominal, 5 cm from the block edge (inside the clear disc) costs more than 0.15 m away
    # from it, by the edge-nearness term (the plane residual of that disc: the 10 cm of the block).
    assert cost[4] == pytest.approx(0.15**2 + lim.w_edge * 0.1)
    # A tilted plane: the slope term.
    tilted = BlockTerrain(0.0, slope=(np.tan(np.deg2rad(10.0)), 0.0))
    c_tilt, _ = foothold_costs(tilted, pts[:1, 0], pts[:1, 1], nominal, r, lim)
    assert c_tilt[0] == pytest.approx(lim.w_slope * np.deg2rad(10.0))


def test_failure_names_the_leg_and_the_first_failing_test(paper_robot):
    flat = BlockTerrain(0.0)
    # Body 0.9 m above the ground: nothing within reach.
    with pytest.raises(FootholdError, match=r"for LF within 0.25 m .*failed test: reach; of 2601 candidates") as err:
        choose_footholds(flat, paper_robot, FEET, np.array([0, 0, 0.9]), np.array([0.2, 0.0]), 0.9)
    assert err.value.failed_test == "reach" and isinstance(err.value, PlanningError)
    assert err.value.slope_blocked == 0  # flat: no slope limit would help
    # A 45 deg plane: too steep everywhere.
    steep = BlockTerrain(0.0, slope=(1.0, 0.0))
    with pytest.raises(FootholdError, match=r"for LF .*failed test: slope; of 2601 candidates, .*: 0 slope") as err:
        choose_footholds(steep, paper_robot, FEET, np.array([0, 0, 0.33]), np.array([0.2, 0.0]), 0.33)
    assert err.value.failed_test == "slope" and err.value.slope_blocked > 0  # reachable, only too steep
    # A 20 deg plane under a 15 deg limit: refused for the slope alone; a 25 deg limit gives the footholds.
    ramp = BlockTerrain(0.0, slope=(np.tan(np.deg2rad(20.0)), 0.0))
    args = (ramp, paper_robot, FEET, np.array([0, 0, 0.33]), np.array([0.2, 0.0]), 0.33)
    with pytest.raises(FootholdError, match=r"failed test: slope; .*; [1-9]\d* fail the slope test alone") as err:
        choose_footholds(*args, limits=FootholdLimits(max_slope=np.deg2rad(15.0)))
    assert err.value.slope_blocked > 0
    assert choose_footholds(*args, limits=FootholdLimits(max_slope=np.deg2rad(25.0))).shape == (4, 3)


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("ring", 0.0, r"FootholdLimits.ring must be a number in \(0, 1\] \(m\), got 0"),
        ("step", -0.01, r"FootholdLimits.step must be"),
        ("max_slope", float("nan"), r"FootholdLimits.max_slope must be"),
        ("w_edge", -1.0, r"FootholdLimits.w_edge must be"),
        ("window", 0.3, r"FootholdLimits.window must be <= reach_window"),
    ],
)
def test_bad_limits_name_the_field(field, value, message):
    with pytest.raises(ValueError, match=message):
        FootholdLimits(**{field: value})
