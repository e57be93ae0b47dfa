"""Commands and waypoints in the evaluation: suite fields, tracking metrics, the waypoint follower, the report."""

from __future__ import annotations

import json
import math

import gymnasium as gym
import numpy as np
import pytest

import quad_uneven_env  # noqa: F401
from agents.evaluation import evaluate
from agents.evaluation.metrics import COMMAND_METRICS, command_metrics, commanded_path
from agents.evaluation.suites import SuiteError, load_suite, suite_from_dict
from agents.waypoints import WaypointConfig, WaypointFollower, load_waypoints


def suite(**entry) -> dict:
    return {"name": "t", "goal_distance": 1.0, "time_limit": 5.0, "terrains": [{"kind": "flat", "seeds": [0], **entry}]}


# ------------------------------------------------------------------ suite fields
def test_entries_keep_their_command_and_waypoints_and_skip_the_goal_check():
    raw = suite(command={"vx": 0.1, "yaw_rate": 0.2})
    raw["goal_distance"] = 50.0  # beyond the grid: fine for a commanded entry (it walks for the time limit)
    entry = suite_from_dict(raw).terrains[0]
    assert entry.command == {"vx": 0.1, "yaw_rate": 0.2} and entry.waypoints is None
    assert entry.label == "flat cmd(vx=0.1, yaw_rate=0.2)"
    entry = suite_from_dict(suite(waypoints={"points": [[1, 0], [2, 0.5]], "radius": 0.2})).terrains[0]
    assert entry.waypoints == {"points": [[1, 0], [2, 0.5]], "radius": 0.2}
    assert entry.label == "flat 2 waypoints"


@pytest.mark.parametrize(
    ("entry", "expected"),
    [
        ({"command": {"vx": 2.0}}, "terrains[0].command.vx must be a number in [-1, 1] (m/s), got 2.0"),
        ({"command": {"speed": 1}}, "terrains[0].command: unknown field(s) ['speed']"),
        ({"command": [0.1, 0.0]}, "terrains[0].command must be None or a mapping"),
        ({"waypoints": {"points": []}}, "terrains[0].waypoints.points must be a non-empty list of finite [x, y]"),
        ({"waypoints": {"points": [[1, "a"]]}}, "terrains[0].waypoints.points must be"),
        ({"waypoints": {"points": [[1, 0]], "radius": 0}}, "terrains[0].waypoints.radius must be a number in (0, 2]"),
        ({"waypoints": {"points": [[1, 0]], "heading": "up"}}, "terrains[0].waypoints.heading must be one of"),
        ({"waypoints": {"points": [[1, 0]], "pace": 1}}, "terrains[0].waypoints: unknown field(s) ['pace']"),
        (
            {"waypoints": {"points": [[1, 0], [1, 1.3]]}},
            "terrains[0].waypoints.points[1] = [1, 1.3] m is off the terrain",
        ),
    ],
)
def test_bad_command_or_waypoints_name_the_field(entry, expected):
    with pytest.raises(SuiteError) as err:
        suite_from_dict(suite(**entry))
    assert expected in str(err.value)


def test_shipped_command_and_course_suites_match_the_issue():
    cmd = load_suite("command")
    commands = [np.array([e.command.get(a, 0.0) for a in ("vx", "vy", "yaw_rate")]) for e in cmd.terrains]
    assert all(e.kind == "rough" and e.params["amplitude"] == 0.05 and len(e.seeds) >= 10 for e in cmd.terrains)
    c = np.array(commands)
    assert c[:, 0].min() == -0.2 and c[:, 0].max() == 0.2 and np.abs(c[:, 1]).max() == 0.1
    assert c[:, 2].min() == -0.3 and c[:, 2].max() == 0.3
    course = load_suite("course")
    assert all(e.waypoints is not None and len(e.seeds) >= 10 for e in course.terrains)
    assert {e.kind for e in course.terrains} == {"rough", "stairs", "slope"}


# ------------------------------------------------------------------ metrics
def test_command_metrics_hand_case_straight():
    """0.08 m/s along +x under a 0.1 m/s command, turning at 0.1 rad/s under 0.15 rad/s: errors 0.02 m/s, 0.05 rad/s."""
    dt, n = 0.02, 500
    t = dt * np.arange(n + 1)
    xy = np.column_stack([0.08 * t, np.zeros(n + 1)])
    yaw = np.zeros(n + 1)
    m = command_metrics(dt, xy, yaw, np.tile([0.1, 0.0, 0.0], (n, 1)))
    assert m["velocity_error"] == pytest.approx(0.02)
    assert m["velocity_error_window"] == pytest.approx(0.02)
    assert m["velocity_rmse"] == pytest.approx(0.02)
    assert m["yaw_rate_error"] == pytest.approx(0.0) and m["heading_error"] == pytest.approx(0.0)
    m = command_metrics(dt, np.zeros((n + 1, 2)), 0.1 * t, np.tile([0.0, 0.0, 0.15], (n, 1)))
    assert m["yaw_rate_error"] == pytest.approx(0.05)
    assert m["heading_error"] == pytest.approx(math.sqrt(np.mean((0.05 * t[1:]) ** 2)))
    assert m["velocity_error"] == 0.0
    assert command_metrics(dt, xy[:1], yaw[:1], np.zeros((0, 3))) == dict.fromkeys(COMMAND_METRICS)


def test_command_metrics_of_an_exact_arc_are_near_zero():
    """Walking the commanded circle exactly (v = 0.1 m/s, w = 0.3 rad/s): the errors are the integration's only."""
    dt, n, v, w = 0.02, 1000, 0.1, 0.3
    t = dt * np.arange(n + 1)
    yaw = w * t
    xy = np.column_stack([v / w * np.sin(yaw), v / w * (1.0 - np.cos(yaw))])
    m = command_metrics(dt, xy, yaw, np.tile([v, 0.0, w], (n, 1)))
    assert m["velocity_error"] < 2e-3 and m["velocity_rmse"] < 2e-3
    assert m["yaw_rate_error"] == pytest.approx(0.0, abs=1e-12) and m["heading_error"] == pytest.approx(0.0, abs=1e-12)
    path, heading = commanded_path(dt, xy[0], yaw, np.tile([v, 0.0, w], (n, 1)))
    assert np.abs(path - xy).max() < 0.01 and heading[-1] == pytest.approx(yaw[-1])


# ------------------------------------------------------------------ the follower
def test_follower_turns_towards_the_waypoint_then_walks_to_it():
    f = WaypointFollower(load_waypoints({"points": [[0.0, -1.0], [1.0, -1.0]], "radius": 0.3}))
    f.reset(0.0)
    cmd = f.update(np.array([0.0, 0.0]), 0.0)  # waypoint straight to the right: turn clockwise in place
    assert cmd[0] == pytest.approx(0.0, abs=1e-12) and cmd[1] == 0.0 and cmd[2] == pytest.approx(-0.3)
    cmd = f.update(np.array([0.0, 0.0]), -math.pi / 2)  # facing it: walk forwards
    np.testing.assert_allclose(cmd, [0.1, 0.0, 0.0], atol=1e-12)
    cmd = f.update(np.array([0.0, -0.8]), -math.pi / 2)  # within the radius: on to the next, to the left
    assert f.reached == 1 and cmd[2] > 0.0
    assert f.update(np.array([0.9, -1.1]), 0.0) == pytest.approx(np.zeros(3)) and f.done


def test_follower_holding_its_heading_steps_sideways():
    f = WaypointFollower(WaypointConfig(points=((0.0, 2.0),), heading="hold", max_lateral=0.08))
    f.reset(0.0)
    np.testing.assert_allclose(f.update(np.zeros(2), 0.0), [0.0, 0.08, 0.0], atol=1e-12)
    cmd = f.update(np.zeros(2), 0.3)  # turned off the start heading: steer back, the waypoint is now ahead-left
    assert cmd[2] == pytest.approx(-0.1) and cmd[0] > 0.0


def test_set_command_reaches_the_observation_and_is_checked():
    env = gym.make("QuadUneven-v0", terrain="flat", command={})
    u = env.unwrapped
    env.reset(seed=0)
    u.set_command(np.array([0.1, -0.05, 0.2]))
    np.testing.assert_allclose(u.command, [0.1, -0.05, 0.2])
    obs, _, _, _, info = env.step(np.zeros(12))
    np.testing.assert_allclose(info["command"], [0.1, -0.05, 0.2])
    np.testing.assert_allclose(obs[u.observation_structure["command"]], [0.1, -0.05, 0.2], rtol=1e-6)
    with pytest.raises(ValueError, match=r"command must be 3 finite numbers"):
        u.set_command(np.array([0.0, 0.0, 3.0]))
    env.reset(seed=0)
    np.testing.assert_allclose(u.command, 0.0)  # a reset restores the configured command
    plain = gym.make("QuadUneven-v0", terrain="flat")
    plain.reset(seed=0)
    with pytest.raises(ValueError, match="set_command needs an env made with a command"):
        plain.unwrapped.set_command(np.zeros(3))


# ------------------------------------------------------------------ end to end
def test_expert_evaluation_with_a_command_and_waypoints(tmp_path):
    """A turn in place (one 3.1 s cycle) and a 0.5 m waypoint on flat ground: records, summary, report, plot."""
    raw = {
        "name": "cmd",
        "goal_distance": 1.0,
        "time_limit": 9.3,
        "terrains": [
            {"kind": "flat", "command": {"yaw_rate": 0.3}, "seeds": [0]},
            {"kind": "flat", "waypoints": {"points": [[0.5, 0.0]], "radius": 0.25}, "seeds": [0]},
        ],
    }
    out = tmp_path / "out"
    res = evaluate(suite_from_dict(raw), "expert", out, progress=False)
    turn, walk = res["episodes"]
    assert turn["success"] and turn["end_reason"] == "time_limit" and turn["command"] == {"yaw_rate": 0.3}
    assert turn["yaw_rate_error"] < 0.01 and turn["velocity_error"] < 0.01
    assert walk["success"] and walk["end_reason"] == "waypoints" and walk["waypoints_reached"] == 1
    assert walk["waypoints_total"] == 1 and walk["sim_time"] < 9.0
    strict = json.loads((out / "results.json").read_text())
    for e in strict["episodes"]:
        assert all(k in e for k in (*COMMAND_METRICS, "command", "waypoints_reached", "waypoints_total"))
    assert strict["summary"]["by_entry"][0]["mean_yaw_rate_error"] == pytest.approx(turn["yaw_rate_error"])
    assert [t["target"] for t in strict["command_targets"]] == ["course (every waypoint reached)"]
    report = (out / "report.md").read_text()
    assert "## Command tracking" in report
    for png in ("command_entry0.png", "command_entry1.png"):
        assert (out / png).stat().st_size > 10_000 and f"]({png})" in report
    tr = np.load(out / "traces" / "ep001.npz")
    assert tr["command"].shape == (len(tr["time"]) - 1, 3) and tr["waypoints"].shape == (1, 2)


def test_goal_targets_skip_commanded_and_waypoint_entries_and_the_command_targets_pool_them():
    from agents.evaluation.targets import check_command_targets, check_targets

    raw = {
        "name": "t",
        "goal_distance": 5.0,
        "time_limit": 5.0,
        "terrains": [
            {"kind": "flat", "command": {"vx": 0.1}, "seeds": list(range(10))},
            {"kind": "rough", "params": {"amplitude": 0.05}, "command": {"yaw_rate": 0.3}, "seeds": list(range(10))},
            {"kind": "rough", "params": {"amplitude": 0.05}, "command": {"vx": -0.1}, "seeds": list(range(10))},
            {"kind": "flat", "waypoints": {"points": [[1, 0]]}, "seeds": list(range(10))},
        ],
    }
    entries = suite_from_dict(raw).terrains
    group = {"episodes": 10, "success_rate": 1.0, "mean_speed_success": 0.2, "successes_index_ok": 10, "successes": 10}
    assert check_targets(entries, [{"entry": i, **group} for i in range(4)], 5.0) == []

    def rec(entry, k, fell=False):
        return {"entry": entry, "success": not fell, "end_reason": "fall" if fell else "time_limit",
                "velocity_error": 0.01 * k, "yaw_rate_error": 0.001}  # fmt: skip

    records = [rec(e, k, fell=(e == 2 and k == 0)) for e in (0, 1, 2) for k in range(10)]
    records += [{"entry": 3, "success": k < 9, "end_reason": "waypoints"} for k in range(10)]
    commanded, course = check_command_targets(entries, records)
    assert commanded["entries"] == [1, 2] and commanded["episodes"] == 20  # flat is not rough 5 cm
    assert commanded["measured"]["no_fall_rate"] == pytest.approx(0.95)
    assert commanded["measured"]["velocity_error"] == pytest.approx(0.045)
    assert commanded["passed"] is False and "velocity_error 0.045 m/s > 0.03" in commanded["why_not"]
    assert course["measured"]["success_rate"] == pytest.approx(0.9) and course["passed"]
