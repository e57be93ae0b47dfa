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
    """Terrain lengths (defaults too) and the goal x s, time x sqrt(s); the goal leaves 1 m x s of the 8 m grid."""
    from agents.evaluation.suites import scale_suite

    suite = load_suite("targets")
    small = scale_suite(suite, 0.9)
    assert small.goal_distance == pytest.approx(4.5) and small.time_limit == pytest.approx(120.0 * 0.9**0.5)
    rough, slope, stairs = small.terrains[1], small.terrains[2], small.terrains[3]
    assert rough.params == {"amplitude": pytest.approx(0.036), "wavelength": pytest.approx(0.54)}
    assert slope.params["angle_deg"] == 10 and slope.params["ramp_length"] == pytest.approx(1.35)
    assert stairs.params["riser"] == pytest.approx(0.072) and stairs.params["n_steps"] == 5
    assert [e.seeds for e in small.terrains] == [e.seeds for e in suite.terrains]
    big = scale_suite(suite, 1.5)
    assert big.goal_distance == pytest.approx(5.0)  # 7.5 m does not fit: the grid's end (6.5 m) less 1 m x 1.5
    flat = scale_suite(suite_from_dict({**_suite_raw(), "terrains": [{"kind": "stairs", "seeds": [0]}]}), 2.0)
    assert flat.terrains[0].params["riser"] == pytest.approx(0.16)  # the default 0.08 m, scaled


def test_a_scaled_parameter_out_of_range_is_named():
    from agents.evaluation.suites import scale_suite

    with pytest.raises(SuiteError, match=r"scaled by 0\.700: terrains\[5\]\.params\.gap must be >= 2 \* cell_size"):
        scale_suite(load_suite("targets"), 0.7)


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
