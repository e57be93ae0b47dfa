"""Foothold selection: flat, edge-free, reachable spots; stepping stones, not holes."""

from __future__ import annotations

import numpy as np
import pytest

from planners.errors import PlanningError
from planners.footholds import FootholdLimits, choose_footholds
from planners.terrain_query import BlockTerrain
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
    assert np.all(s.height_max - s.height_min <= FootholdLimits().max_step + 1e-9)  # no edge or hole under the foot
    np.testing.assert_allclose(out[:, 2], hf.height(out[:, 0], out[:, 1]))


def test_no_foothold_raises_naming_leg(robot_cfg):
    # Washboard of 10 cm ridges every 4 cm: no flat spot anywhere.
    blocks = np.array([[x, x + 0.02, -1.0, 1.0, 0.1] for x in np.arange(-1.0, 1.0, 0.04)])
    with pytest.raises(PlanningError, match=r"LF"):
        choose_footholds(
            BlockTerrain(0.0, blocks=blocks), robot_cfg, FEET, np.array([0, 0, 0.4]), np.array([0.2, 0.0]), 0.36
        )
