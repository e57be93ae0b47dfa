"""Foothold selection: flat, edge-free, reachable spots with the shank clear; stepping stones, not holes."""

from __future__ import annotations

import numpy as np
import pytest

from planners.footholds import SHANK_RADIUS_SCALE, FootholdLimits, choose_footholds, shank_clearance
from planners.terrain_query import BlockTerrain, capsule_clearance
from planners.types import PlanningError
from quad_uneven_env.robot.kinematics import hip_positions_B
from quad_uneven_env.terrain import Terrain, parse_terrain_spec

FEET = np.array([[0.25, 0.185, 0.0], [0.25, -0.185, 0.0], [-0.25, 0.185, 0.0], [-0.25, -0.185, 0.0]])


def test_flat_ground_gives_nominal_footholds(robot_cfg):
    out = choose_footholds(
        BlockTerrain(0.05), robot_cfg, FEET + np.array([0, 0, 0.05]), np.array([0, 0, 0.41]), np.array([0.2, 0.0]), 0.36
    )
    nominal = hip_positions_B(robot_cfg)[:, :2] + [0.2, 0.0]
    np.testing.assert_allclose(out[:, :2], nominal, atol=1e-9)
    np.testing.assert_allclose(out[:, 2], 0.05)


def test_avoids_step_edge(robot_cfg):
    # A 10 cm step edge right at the LF/RF nominal x (0.45): chosen footholds keep 4.5 cm away from it.
    terrain = BlockTerrain(0.0, blocks=np.array([[0.45, 2.0, -1.0, 1.0, 0.1]]))
    out = choose_footholds(terrain, robot_cfg, FEET, np.array([0, 0, 0.36]), np.array([0.2, 0.0]), 0.36)
    for i in (0, 1):
        assert abs(out[i, 0] - 0.45) >= FootholdLimits().edge_radius - 1e-9
        assert out[i, 2] == pytest.approx(terrain.height(out[i, 0], out[i, 1]))


def test_stepping_stones_footholds_on_stones(robot_cfg, rng):
    spec = parse_terrain_spec("stepping_stones")
    hf = Terrain(spec).generate(np.random.default_rng(3))
    base = np.array([1.0, 0.0])
    feet = np.column_stack([hip_positions_B(robot_cfg)[:, :2] + base, np.zeros(4)])
    feet[:, 2] = hf.height(feet[:, 0], feet[:, 1])
    out = choose_footholds(
        hf, robot_cfg, feet, np.array([1.0, 0.0, feet[:, 2].mean() + 0.36]), base + np.array([0.2, 0.0]), 0.36
    )
    s = hf.patch_stats(out[:, 0], out[:, 1], FootholdLimits().edge_radius)
    assert np.all(s.height_max - s.height_min <= 1e-9)  # flat stone tops: no edge or hole under the foot
    np.testing.assert_allclose(out[:, 2], hf.height(out[:, 0], out[:, 1]))


def test_no_foothold_raises_naming_leg(robot_cfg):
    # Washboard of 10 cm ridges every 4 cm: no flat spot anywhere.
    blocks = np.array([[x, x + 0.02, -1.0, 1.0, 0.1] for x in np.arange(-1.0, 1.0, 0.04)])
    with pytest.raises(PlanningError, match=r"LF"):
        choose_footholds(
            BlockTerrain(0.0, blocks=blocks), robot_cfg, FEET, np.array([0, 0, 0.4]), np.array([0.2, 0.0]), 0.36
        )


def test_shank_clearance_flat_stance_versus_shank_on_a_nosing(robot_cfg):
    flat = BlockTerrain(0.0)
    r = robot_cfg.foot_radius
    for leg, hip_x in (("LF", 0.25), ("LH", -0.25)):
        hip = np.array([hip_x, 0.185, 0.33])  # nominal stance: the foot under the hip
        gap = shank_clearance(flat, robot_cfg, leg, np.array([[hip_x, 0.185, r]]), hip, np.eye(3))
        assert gap[0] > 0.01
    # The stairs-down failure: hind foot 2.5 cm behind a 8 cm drop, hip only 0.13 m above the foot
    # and 0.1 m ahead: the forward knee dips below the foot and the shank rests on the nosing.
    stair = BlockTerrain(-0.08, blocks=np.array([[-2.0, 0.6, -1.0, 1.0, 0.0]]))
    site = np.array([[0.575, 0.198, r]])
    low = shank_clearance(stair, robot_cfg, "LH", site, np.array([0.679, 0.198, 0.15]), np.eye(3))
    high = shank_clearance(stair, robot_cfg, "LH", site, np.array([0.679, 0.198, 0.30]), np.eye(3))
    assert low[0] < -0.001 and FootholdLimits().shank_clearance < high[0]
    # On a plane the gap is exact: a shank parallel to a 15 deg slope, its axis 3 cm above it.
    slope = BlockTerrain(0.0, slope=(np.tan(np.deg2rad(15.0)), 0.0))
    axis = np.array([np.cos(np.deg2rad(15.0)), 0.0, np.sin(np.deg2rad(15.0))])
    n = np.array([-axis[2], 0.0, axis[0]])
    a = 0.03 * n
    assert capsule_clearance(slope, a, a + 0.2 * axis, 0.0175)[0] == pytest.approx(0.0125, abs=1e-6)


@pytest.mark.parametrize("pitch_start", [None, 0.0])
def test_front_foot_kept_off_the_nosing_when_stepping_down(robot_cfg, pitch_start):
    # 8 cm drop at x = 0.5, the front nominal footholds 8 cm past it: the backward-bent front
    # shank would rest on the edge above the foot; the chosen footholds keep it clear.
    terrain = BlockTerrain(-0.08, blocks=np.array([[-2.0, 0.5, -1.0, 1.0, 0.0]]))
    args = (terrain, robot_cfg, FEET, np.array([0.0, 0.0, 0.33]), np.array([0.33, 0.0]), 0.33)
    free = choose_footholds(
        *args, pitch_start=pitch_start, limits=FootholdLimits(shank_clearance=-np.inf, w_edge=0.0, w_shank=0.0)
    )
    out = choose_footholds(*args, pitch_start=pitch_start)
    np.testing.assert_allclose(free[:2, 0], 0.58)  # nominal: under the hips at the end of the cycle
    assert np.all(out[:2, 2] == -0.08) and np.all(out[:2, 0] > free[:2, 0] + 0.01)  # further from the edge
    np.testing.assert_allclose(out[2:], free[2:])  # hind feet on the flat upper level: unchanged


def test_shank_geometry_matches_the_mujoco_model(robot_cfg):
    import mujoco

    from quad_uneven_env.robot import robot_mjcf

    m = mujoco.MjModel.from_xml_string(robot_mjcf(robot_cfg))
    for leg in ("LF", "RH"):
        radius, half_length = m.geom(f"{leg}_shank_geom").size[:2]
        assert radius == pytest.approx(SHANK_RADIUS_SCALE * robot_cfg.link_radius)
        # The capsule runs from the knee to foot_radius short of the foot point (where shank_clearance starts it).
        assert 2 * half_length == pytest.approx(robot_cfg.shank.length - robot_cfg.foot_radius)
