"""Terrain suites: the shipped files, validation errors naming the field, episode expansion."""

from __future__ import annotations

import pytest
import yaml

from agents.evaluation.suites import SuiteError, episode_tasks, load_suite, suite_from_dict, suite_names
from quad_uneven_env.terrain import parse_terrain_spec

REQUIRED = ("flat", "rough", "slopes", "stairs", "stepping_stones", "paper", "mixed", "smoke")
TARGET_SUITES = ("flat", "rough", "slopes", "stairs", "stepping_stones", "paper", "targets")


def valid() -> dict:
    return {
        "name": "t",
        "goal_distance": 1.0,
        "time_limit": 5.0,
        "terrains": [
            {"kind": "flat", "seeds": [0]},
            {"kind": "rough", "params": {"amplitude": 0.04, "wavelength": 0.6}, "seeds": [0, 1]},
        ],
    }


def test_shipped_suites_exist_and_load():
    names = suite_names()
    for n in REQUIRED:
        assert n in names
    for n in names:
        s = load_suite(n)
        assert s.name and s.goal_distance > 0 and s.time_limit > 0 and s.terrains


@pytest.mark.parametrize("name", TARGET_SUITES)
def test_target_suites_have_ten_seeds_and_a_5m_goal(name):
    s = load_suite(name)
    assert s.goal_distance == 5.0
    assert all(len(e.seeds) >= 10 for e in s.terrains)


def test_target_suites_match_the_issue_targets():
    rough = load_suite("rough").terrains[0]
    assert parse_terrain_spec(rough.spec).params["amplitude"] == 0.04
    slope = load_suite("slopes").terrains[0]
    assert slope.kind == "slope" and parse_terrain_spec(slope.spec).params["angle_deg"] == 10
    stairs = load_suite("stairs").terrains
    assert {parse_terrain_spec(e.spec).params["direction"] for e in stairs} == {"up", "down"}
    assert all(parse_terrain_spec(e.spec).params["riser"] == 0.08 for e in stairs)
    kinds = {e.kind for e in load_suite("targets").terrains}
    assert kinds == {"flat", "rough", "slope", "stairs", "stepping_stones"}
    assert len({e.kind for e in load_suite("mixed").terrains}) >= 4


@pytest.mark.parametrize(("name", "preset"), [("robust", "mild"), ("robust_hard", "hard")])
def test_robust_suites_randomize_rough_and_stairs_with_ten_seeds(name, preset):
    s = load_suite(name)
    assert all(e.randomization == preset and len(e.seeds) >= 10 for e in s.terrains)
    params = [(e.kind, parse_terrain_spec(e.spec).params) for e in s.terrains]
    assert any(k == "rough" and p["amplitude"] == 0.05 for k, p in params)
    assert {p["direction"] for k, p in params if k == "stairs" and p["riser"] == 0.08} == {"up", "down"}


def test_smoke_suite_is_short():
    s = load_suite("smoke")
    assert s.goal_distance <= 1.0 and all(len(e.seeds) == 1 for e in s.terrains)


def test_valid_suite_round_trip(tmp_path):
    path = tmp_path / "s.yaml"
    path.write_text(yaml.safe_dump(valid()))
    s = load_suite(path)
    assert s.source == str(path)
    assert [e.kind for e in s.terrains] == ["flat", "rough"]
    assert s.terrains[1].seeds == (0, 1)
    assert s.terrains[0].params == {}
    assert s.terrains[1].spec == {"kind": "rough", "amplitude": 0.04, "wavelength": 0.6}


def _mutate(path, value):
    raw = valid()
    target = raw
    for key in path[:-1]:
        target = target[key]
    if value is KeyError:
        del target[path[-1]]
    else:
        target[path[-1]] = value
    return raw


@pytest.mark.parametrize(
    ("path", "value", "expected"),
    [
        (("colour",), "red", "unknown field(s) ['colour']"),
        (("goal_distance",), KeyError, "missing field(s) ['goal_distance']"),
        (("goal_distance",), -1.0, "goal_distance must be a number in (0, 500] (m)"),
        (("time_limit",), True, "time_limit must be a number in (0, 3600] (s)"),
        (("time_limit",), float("nan"), "time_limit must be"),
        (("name",), "", "name must be a non-empty string"),
        (("terrains",), [], "terrains must be a non-empty list"),
        (("terrains", 1, "kind"), "rugh", "terrains[1].kind must be one of"),
        (("terrains", 1, "kind"), KeyError, "terrains[1].kind is required"),
        (("terrains", 1, "flavour"), 1, "terrains[1]: unknown field(s) ['flavour']"),
        (("terrains", 1, "params", "amplitude"), 5, "terrains[1].params.amplitude must be a number in [0, 0.3]"),
        (("terrains", 1, "params", "amplitude"), True, "terrains[1].params.amplitude"),
        (("terrains", 1, "params", "bumpiness"), 1, "terrains[1].params: unknown parameter(s) ['bumpiness']"),
        (("terrains", 1, "params"), [1], "terrains[1].params must be a mapping"),
        (("terrains", 0, "seeds"), [], "terrains[0].seeds must be a non-empty list"),
        (("terrains", 0, "seeds"), KeyError, "terrains[0].seeds is required"),
        (("terrains", 0, "seeds"), [0, -1], "terrains[0].seeds[1] must be an integer in [0, "),
        (("terrains", 0, "seeds"), [0, 1.5], "terrains[0].seeds[1] must be an integer in [0, "),
        (("terrains", 0, "seeds"), [True], "terrains[0].seeds[0] must be an integer in [0, "),
        (("terrains", 0, "seeds"), [3, 3], "terrains[0].seeds must not repeat a seed"),
        (("terrains", 0, "seeds"), 3, "terrains[0].seeds must be a non-empty list"),
        (("terrains", 0, "randomization"), "wild", "terrains[0].randomization: unknown randomization config 'wild'"),
        (("terrains", 0, "randomization"), {"friction": [1, 0]}, "terrains[0].randomization.friction must be"),
        (("terrains", 0, "randomization"), {"gravity": 1}, "terrains[0].randomization: unknown field(s) ['gravity']"),
        (("terrains", 0, "randomization"), 3, "terrains[0].randomization must be a preset name or a mapping"),
    ],
)
def test_invalid_suites_name_the_field(path, value, expected):
    with pytest.raises(SuiteError) as err:
        suite_from_dict(_mutate(path, value))
    assert expected in str(err.value)


def test_goal_beyond_the_terrain_is_rejected():
    raw = valid()
    raw["goal_distance"] = 6.3  # default grid: x in [-1.5, 6.5], the episode ends at x = 6.2
    with pytest.raises(SuiteError, match=r"goal_distance 6.3 m cannot be reached on terrains\[0\]"):
        suite_from_dict(raw)
    raw["terrains"] = [{"kind": "flat", "params": {"length": 10.0}, "seeds": [0]}]
    assert suite_from_dict(raw).goal_distance == 6.3


def test_unknown_suite_name_lists_the_shipped_ones():
    with pytest.raises(SuiteError, match="smoke"):
        load_suite("no_such_suite")


def test_top_level_must_be_a_mapping(tmp_path):
    path = tmp_path / "list.yaml"
    path.write_text("- 1\n- 2\n")
    with pytest.raises(SuiteError, match="mapping"):
        load_suite(path)


def test_episode_tasks_cap_offset_and_order():
    s = suite_from_dict(
        {
            "name": "t",
            "goal_distance": 1.0,
            "time_limit": 5.0,
            "terrains": [{"kind": "flat", "seeds": [4, 7, 9]}, {"kind": "rough", "seeds": [1, 2]}],
        }
    )
    all_tasks = episode_tasks(s)
    assert [(t.entry, t.seed) for t in all_tasks] == [(0, 4), (0, 7), (0, 9), (1, 1), (1, 2)]
    assert [t.index for t in all_tasks] == [0, 1, 2, 3, 4]
    assert [t.first_of_entry for t in all_tasks] == [True, False, False, True, False]
    capped = episode_tasks(s, episodes=2, seed_offset=100)
    assert [(t.kind, t.seed) for t in capped] == [("flat", 104), ("flat", 107), ("rough", 101), ("rough", 102)]
    with pytest.raises(ValueError, match="episodes"):
        episode_tasks(s, episodes=0)
    with pytest.raises(ValueError, match="negative"):
        episode_tasks(s, seed_offset=-2)


# ---------------------------------------------------------------------- suites at the robot's scale
def test_a_suite_scales_its_lengths_and_time_to_the_robot():
    """Terrain lengths (defaults and the shared grid parameters too) and the goal x s, time x sqrt(s)."""
    from agents.evaluation.suites import scale_suite

    suite = load_suite("targets")
    small = scale_suite(suite, 0.9)
    assert small.goal_distance == pytest.approx(4.5) and small.time_limit == pytest.approx(120.0 * 0.9**0.5)
    rough, slope, stairs = small.terrains[1], small.terrains[2], small.terrains[3]
    grid = {"length": 7.2, "width": 2.7, "cell_size": 0.018, "x_start": -1.35, "spawn_radius": 0.54}
    assert rough.params == pytest.approx({"amplitude": 0.036, "wavelength": 0.54, **grid})
    assert slope.params["angle_deg"] == 10 and slope.params["ramp_length"] == pytest.approx(1.35)
    assert stairs.params["riser"] == pytest.approx(0.072) and stairs.params["n_steps"] == 5
    assert [e.seeds for e in small.terrains] == [e.seeds for e in suite.terrains]
    flat = scale_suite(suite_from_dict({**_suite_raw(), "terrains": [{"kind": "stairs", "seeds": [0]}]}), 2.0)
    assert flat.terrains[0].params["riser"] == pytest.approx(0.16)  # the default 0.08 m, scaled
    assert flat.terrains[0].params["length"] == pytest.approx(16.0)  # the default 8 m grid, scaled


def test_a_suite_at_solo12_and_hyq_scale_is_the_paper_terrain_magnified():
    """Solo12 (s = 0.773): the stones' gap 0.05 x s = 0.0387 m stays above 2 cells (2 x 0.02 x s = 0.0309 m).
    HyQ (s = 0.696 / 0.42 = 1.657): the grid is 8 s = 13.26 m long, so the goal is 5 s = 8.29 m, uncapped."""
    import numpy as np

    from agents.evaluation.suites import scale_suite
    from quad_uneven_env.terrain import Terrain

    suite = load_suite("targets")
    solo = scale_suite(suite, 0.773)
    stones = solo.terrains[5].params
    assert stones["gap"] == pytest.approx(0.03865) and stones["cell_size"] == pytest.approx(0.01546)
    assert stones["stone_size"] == pytest.approx(0.19325) and solo.goal_distance == pytest.approx(3.865)
    s = 0.696 / 0.42
    hyq = scale_suite(suite, s)
    assert hyq.goal_distance == pytest.approx(5.0 * s) and hyq.goal_distance == pytest.approx(8.2857, abs=1e-4)
    assert hyq.terrains[0].params["length"] == pytest.approx(8.0 * s)
    # Node by node: the same grid shape, every height x s (the rough noise, the step and stone edges included).
    for scaled in (solo, hyq):
        f = scaled.goal_distance / suite.goal_distance
        for a, b in zip(suite.terrains, scaled.terrains, strict=True):
            ha = np.asarray(Terrain(a.spec).generate(np.random.default_rng(3)).heights)
            hb = np.asarray(Terrain(b.spec).generate(np.random.default_rng(3)).heights)
            assert ha.shape == hb.shape and np.ptp(ha) >= 0.0
            np.testing.assert_allclose(hb / f, ha, rtol=0, atol=1e-12, err_msg=a.label)


def test_scaling_by_one_changes_nothing():
    """The paper robot (s = 1): every shipped suite's terrains, goal and time limit stay as written."""
    import numpy as np

    from agents.evaluation.suites import scale_suite
    from quad_uneven_env.terrain import Terrain

    for name in suite_names():
        suite = load_suite(name)
        same = scale_suite(suite, 1.0)
        assert (same.goal_distance, same.time_limit) == (suite.goal_distance, suite.time_limit), name
        for a, b in zip(suite.terrains, same.terrains, strict=True):
            assert parse_terrain_spec(a.spec) == parse_terrain_spec(b.spec), f"{name}: {a.label}"
            ha = np.asarray(Terrain(a.spec).generate(np.random.default_rng(0)).heights)
            hb = np.asarray(Terrain(b.spec).generate(np.random.default_rng(0)).heights)
            assert np.array_equal(ha, hb), f"{name}: {a.label}"


def test_a_scaled_paper_terrain_moves_its_blocks():
    import numpy as np

    from agents.evaluation.suites import scale_suite
    from quad_uneven_env.terrain import PAPER_BLOCKS, Terrain

    big = scale_suite(load_suite("paper"), 1.5)
    p = big.terrains[0].params
    assert p["scale"] == pytest.approx(1.5) and p["base_height"] == pytest.approx(0.18)
    terrain = Terrain(big.terrains[0].spec)
    terrain.generate(np.random.default_rng(0))
    target = PAPER_BLOCKS["target"] * 1.5
    assert terrain.height(target[:, 0], target[:, 1]) == pytest.approx(target[:, 2], abs=1e-6)
    assert terrain.spawn_height == pytest.approx(0.19 * 1.5, abs=1e-6)


def test_a_scaled_heightmap_scales_its_heights_and_refuses_a_file(tmp_path):
    import numpy as np

    from agents.evaluation.suites import scale_suite

    heights = [[0.0] * 101 for _ in range(61)]  # 2 m x 1.2 m at 0.02 m
    heights[50][90] = 0.1
    given = {"heights": heights, "x_start": -0.8, "spawn_radius": 0.3}
    raw = {**_suite_raw(), "goal_distance": 0.5, "terrains": [{"kind": "heightmap", "params": given, "seeds": [0]}]}
    params = scale_suite(suite_from_dict(raw), 2.0).terrains[0].params
    assert params["heights"][50][90] == pytest.approx(0.2) and params["cell_size"] == pytest.approx(0.04)
    assert params["x_start"] == pytest.approx(-1.6) and params["spawn_radius"] == pytest.approx(0.6)
    assert "length" not in params
    raw["terrains"][0]["params"] = {"heights": heights, "origin": [-0.8, -0.6], "spawn_radius": 0.3}
    params = scale_suite(suite_from_dict(raw), 2.0).terrains[0].params
    assert params["origin"] == pytest.approx([-1.6, -1.2]) and "x_start" not in params
    np.save(tmp_path / "ground.npy", np.array(heights))
    raw["terrains"][0]["params"] = {**given, "heights": str(tmp_path / "ground.npy")}
    with pytest.raises(SuiteError, match=r"terrains\[0\]\.params\.heights cannot be scaled to the robot"):
        scale_suite(suite_from_dict(raw), 2.0)


def test_a_scaled_parameter_out_of_range_is_named():
    from agents.evaluation.suites import scale_suite

    with pytest.raises(SuiteError, match=r"scaled by 0\.200: terrains\[0\]\.params\.cell_size must be a number in"):
        scale_suite(load_suite("targets"), 0.2)
    with pytest.raises(SuiteError, match=r"scaled by 3\.500: terrains\[3\]\.params\.riser must be a number in"):
        scale_suite(load_suite("targets"), 3.5)


def test_a_suite_may_ask_to_be_scaled_to_the_robot():
    from agents.evaluation.run import robot_scale

    assert suite_from_dict({**_suite_raw(), "scale": "leg_length"}).scale == "leg_length"
    assert suite_from_dict(_suite_raw()).scale == "none"
    with pytest.raises(SuiteError, match=r"scale must be one of \['none', 'leg_length'\], got 'body'"):
        suite_from_dict({**_suite_raw(), "scale": "body"})
    assert robot_scale("paper") == 1.0
    assert robot_scale("hyq") == pytest.approx(0.696 / 0.42, abs=1e-3)


def _suite_raw() -> dict:
    return {"name": "s", "goal_distance": 1.0, "time_limit": 10.0, "terrains": [{"kind": "flat", "seeds": [0]}]}
