"""quad-uneven evaluate: metrics on hand-computed cases, end-to-end runs through the CLI, parallel == serial."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

import agents.evaluation.episode as evaluate_episode
from agents.cli import main
from agents.evaluation.episode import EvalConfig, run_task
from agents.evaluation.metrics import (
    cost_of_transport,
    group_summary,
    json_safe,
    reason_category,
    stability_metrics,
    timing_metrics,
)
from agents.evaluation.policies import PolicyError, make_policy, make_policy_env
from agents.evaluation.run import evaluate
from agents.evaluation.suites import EpisodeTask

ISSUE_FIELDS = (
    "terrain",
    "params",
    "seed",
    "success",
    "distance",
    "sim_time",
    "mean_speed",
    "min_stability_index",
    "mean_stability_index",
    "time_index_negative",
    "cost_of_transport",
    "fall_reason",
    "planner_ms_median",
    "planner_ms_p95",
)
WALL_CLOCK_FIELDS = ("wall_time", "realtime_factor", "planner_ms_median", "planner_ms_p95")


def strict_json(path: Path):
    def no_constant(name):
        raise ValueError(f"invalid JSON constant {name}")

    return json.loads(path.read_text(), parse_constant=no_constant)


def write_suite(path: Path, **overrides) -> Path:
    raw = {
        "name": "tiny",
        "goal_distance": 0.5,
        "time_limit": 2.0,
        "terrains": [
            {"kind": "flat", "seeds": [0]},
            {"kind": "rough", "params": {"amplitude": 0.04, "wavelength": 0.6}, "seeds": [3]},
        ],
    }
    raw.update(overrides)
    path.write_text(yaml.safe_dump(raw))
    return path


# ------------------------------------------------------------------ metrics on hand-computed cases
def test_stability_metrics_hand_case():
    m = stability_metrics(np.array([1.0, -np.inf, -2.0, 3.0, 0.0]), dt=0.02)
    assert m["min_stability_index"] == -2.0
    assert m["mean_stability_index"] == pytest.approx(0.5)  # (1 - 2 + 3 + 0) / 4, -inf left out
    assert m["time_index_negative"] == pytest.approx(0.04)  # -inf and -2 count, 0 does not
    assert m["time_fewer_than_3_feet"] == pytest.approx(0.02)
    assert m["fraction_index_nonnegative"] == pytest.approx(0.6)
    none = stability_metrics(np.array([-np.inf, -np.inf]), dt=0.01)
    assert none["min_stability_index"] is None and none["time_index_negative"] == pytest.approx(0.02)


def test_cost_of_transport_hand_case():
    assert cost_of_transport(490.5, 50.0, 9.81, 1.0) == pytest.approx(1.0)
    assert cost_of_transport(981.0, 50.0, 9.81, 4.0) == pytest.approx(0.5)
    assert cost_of_transport(10.0, 50.0, 9.81, 0.0) is None
    assert cost_of_transport(10.0, 50.0, 9.81, -0.1) is None


def test_timing_metrics():
    t = timing_metrics(list(range(1, 101)))
    assert t["planner_ms_median"] == pytest.approx(50.5)
    assert t["planner_ms_p95"] == pytest.approx(95.05)
    assert timing_metrics(None) == {"planner_ms_median": None, "planner_ms_p95": None, "planner_calls": None}
    assert timing_metrics([])["planner_ms_median"] is None


def test_json_safe_has_no_nan_or_inf():
    data = {"a": np.float64("nan"), "b": [np.inf, np.int64(3), np.bool_(True)], "c": np.array([1.5, -np.inf])}
    out = json_safe(data)
    assert out == {"a": None, "b": [None, 3, True], "c": [1.5, None]}
    json.dumps(out, allow_nan=False)


def test_reason_category_and_group_summary():
    assert reason_category("fall: tilt 61.2 deg > 60.0 deg") == "fall: tilt # deg > # deg"
    base = {
        "success": True,
        "distance": 5.0,
        "mean_speed": 0.2,
        "sim_time": 25.0,
        "min_stability_index": 3.0,
        "mean_stability_index": 10.0,
        "time_index_negative": 0.0,
        "fraction_index_nonnegative": 1.0,
        "cost_of_transport": 1.0,
        "fall_reason": None,
        "end_reason": "goal",
        "planner_ms_median": 2.0,
        "planner_ms_p95": 4.0,
    }
    eps = [
        base,
        {**base, "fraction_index_nonnegative": 0.9, "min_stability_index": -1.0, "cost_of_transport": 3.0},
        {
            **base,
            "success": False,
            "distance": 2.0,
            "mean_speed": 0.1,
            "fall_reason": "fall: tilt 70.0 deg > 60.0 deg",
            "end_reason": "fall",
            "cost_of_transport": None,
        },
        {**base, "success": False, "distance": 1.0, "mean_speed": 0.05, "end_reason": "time_limit"},
    ]
    g = group_summary(eps)
    assert g["episodes"] == 4 and g["successes"] == 2 and g["success_rate"] == 0.5
    assert g["mean_distance"] == pytest.approx(13.0 / 4)
    assert g["mean_speed_success"] == pytest.approx(0.2)
    assert g["min_stability_index"] == -1.0
    assert g["mean_cost_of_transport"] == pytest.approx(5.0 / 3)
    assert g["successes_index_ok"] == 1
    assert g["end_reasons"] == {"fall: tilt # deg > # deg": 1, "time_limit": 1}


# ------------------------------------------------------------------ policies
def test_make_policy_errors_and_env_kwargs(tmp_path):
    assert make_policy_env("zero", terrain="flat").unwrapped.action_mode == "joint_pd"
    with pytest.raises(PolicyError, match="one of"):
        make_policy_env("random")
    with pytest.raises(PolicyError, match="does not exist"):
        make_policy(str(tmp_path / "missing.zip"), env=None)
    with pytest.raises(PolicyError, match="algo"):
        make_policy(str(tmp_path / "missing.zip"), env=None, algo="dqn")


def test_expert_policy_installs_its_controller():

    from agents.expert import ExpertPolicy

    env = make_policy_env("expert", terrain="flat")
    policy = make_policy("expert", env)
    assert isinstance(policy, ExpertPolicy)
    assert env.unwrapped.controller is policy


# ------------------------------------------------------------------ end to end
def test_cli_end_to_end_zero_policy(tmp_path, capsys):
    suite = write_suite(tmp_path / "tiny.yaml")
    out = tmp_path / "out"
    rc = main(["evaluate", "--policy", "zero", "--suite", str(suite), "--out", str(out), "--no-progress"])
    assert rc == 0
    printed = capsys.readouterr().out
    assert "report.md" in printed
    assert "target" not in printed  # flat and rough 4 cm, but one seed each and a 0.5 m goal: no target judged
    res = strict_json(out / "results.json")
    assert res["suite"] == "tiny" and res["policy"] == "zero"
    assert res["targets"] == [] and res["command_targets"] == []
    assert [(e["terrain"], e["seed"]) for e in res["episodes"]] == [("flat", 0), ("rough", 3)]
    for e in res["episodes"]:
        for field in ISSUE_FIELDS:
            assert field in e, field
        # The zero action in joint_pd mode stands still: time limit, no fall, no success.
        assert e["success"] is False and e["fall_reason"] is None and e["end_reason"] == "time_limit"
        assert e["sim_time"] == pytest.approx(2.0)
        assert abs(e["distance"]) < 0.05
        assert e["mean_speed"] == pytest.approx(e["distance"] / e["sim_time"])
        assert e["min_stability_index"] > 0 and e["mean_stability_index"] >= e["min_stability_index"]
        assert e["planner_ms_median"] is None and e["failure_log"] is None
        assert e["end_stance"] == ["LF", "RF", "LH", "RH"]  # standing: all four feet down
        # The recorded traces agree with the record (distance = COG x travelled since reset).
        tr = np.load(out / "traces" / f"ep{e['index']:03d}.npz")
        assert tr["time"][-1] == pytest.approx(e["sim_time"])
        assert tr["cog"][-1, 0] - tr["cog"][0, 0] == pytest.approx(e["distance"], abs=1e-5)
        steps = np.isfinite(tr["index"][1:])
        assert float(tr["index"][1:][steps].min()) == pytest.approx(e["min_stability_index"])
        neg = np.count_nonzero(~(tr["index"][1:] >= 0)) * 0.02
        assert e["time_index_negative"] == pytest.approx(neg)
    assert set(res["summary"]["by_kind"]) == {"flat", "rough"}
    assert res["summary"]["by_kind"]["rough"]["success_rate"] == 0.0
    report = (out / "report.md").read_text()
    assert "## By terrain kind" in report and "| rough |" in report
    for png in ("distance.png", "stability.png", "paths_entry0.png", "paths_entry1.png"):
        assert (out / png).stat().st_size > 10_000, png
        assert f"]({png})" in report


class LeanForward:
    """Joint-PD action bending every hip forward: the trunk slides ~0.15 m along +x without stepping."""

    def predict(self, observation, state=None, episode_start=None, deterministic=True):
        a = np.zeros(12, dtype=np.float32)
        a[1::3] = 0.3
        return a, state


def test_goal_ends_the_episode_as_a_success(monkeypatch):
    monkeypatch.setattr(evaluate_episode, "make_policy", lambda *args, **kwargs: LeanForward())
    task = EpisodeTask(0, 0, "flat", {}, 0, True)
    res = run_task(task, EvalConfig("zero", goal_distance=0.05, time_limit=2.0))
    r = res.record
    assert r["success"] is True and r["end_reason"] == "goal" and r["fall_reason"] is None
    assert 0.05 <= r["distance"] < 0.08
    assert r["sim_time"] < 1.0  # stopped at the goal, not at the time limit
    assert r["cost_of_transport"] is not None and r["cost_of_transport"] > 0
    assert res.terrain is not None and res.terrain["heights"].ndim == 2


def test_a_fall_is_recorded_with_its_reason():
    # Zero torques (torque mode, no controller): the robot collapses.
    task = EpisodeTask(0, 0, "flat", {}, 0, False)
    cfg = EvalConfig("zero", goal_distance=1.0, time_limit=3.0, env_kwargs={"action_mode": "torque"})
    r = run_task(task, cfg).record
    assert r["success"] is False and r["end_reason"] == "fall"
    assert r["fall_reason"].startswith("fall:")
    assert r["sim_time"] < 3.0
    assert r["end_position"][2] < 0.3
    assert set(r["end_stance"]) <= {"LF", "RF", "LH", "RH"}


def test_policy_exception_does_not_crash_the_evaluation(monkeypatch):
    class Broken:
        def predict(self, observation, state=None, episode_start=None, deterministic=True):
            raise RuntimeError("boom")

    monkeypatch.setattr(evaluate_episode, "make_policy", lambda *args, **kwargs: Broken())
    r = run_task(EpisodeTask(0, 0, "flat", {}, 0, False), EvalConfig("zero", 1.0, 1.0)).record
    assert r["end_reason"] == "error" and "boom" in r["fall_reason"] and r["success"] is False


@pytest.mark.parametrize(
    ("mutation", "field"),
    [
        ({"surprise": 1}, "surprise"),
        ({"terrains": [{"kind": "lava", "seeds": [0]}]}, "terrains[0].kind"),
        ({"terrains": [{"kind": "rough", "params": {"amplitude": -1}, "seeds": [0]}]}, "terrains[0].params.amplitude"),
        ({"terrains": [{"kind": "flat", "seeds": []}]}, "terrains[0].seeds"),
    ],
)
def test_cli_invalid_suite_exits_nonzero_naming_the_field(tmp_path, capsys, mutation, field):
    suite = write_suite(tmp_path / "bad.yaml", **mutation)
    rc = main(["evaluate", "--policy", "zero", "--suite", str(suite), "--out", str(tmp_path / "o"), "--no-progress"])
    assert rc != 0
    assert field in capsys.readouterr().err
    assert not (tmp_path / "o" / "results.json").exists()


def test_cli_unknown_policy_exits_nonzero(tmp_path, capsys):
    suite = write_suite(tmp_path / "s.yaml")
    rc = main(["evaluate", "--policy", "magic", "--suite", str(suite), "--out", str(tmp_path / "o"), "--no-progress"])
    assert rc != 0 and "policy" in capsys.readouterr().err


def test_workers_two_equals_workers_one(tmp_path):
    suite = write_suite(tmp_path / "s.yaml", time_limit=1.0)
    one = evaluate(suite, "zero", tmp_path / "w1", workers=1, progress=False)
    two = evaluate(suite, "zero", tmp_path / "w2", workers=2, progress=False)

    def strip(eps):
        return [{k: v for k, v in e.items() if k not in WALL_CLOCK_FIELDS} for e in eps]

    assert strip(one["episodes"]) == strip(two["episodes"])
    assert [e["index"] for e in two["episodes"]] == [0, 1]


def test_episodes_cap_and_seed_offset(tmp_path):
    suite = write_suite(
        tmp_path / "s.yaml",
        time_limit=0.2,
        terrains=[{"kind": "rough", "seeds": [0, 1, 2]}, {"kind": "flat", "seeds": [5]}],
    )
    res = evaluate(suite, "zero", tmp_path / "o", episodes=2, seed=10, progress=False)
    assert [(e["terrain"], e["seed"]) for e in res["episodes"]] == [("rough", 10), ("rough", 11), ("flat", 15)]
    # Different seeds give different rough terrains, hence different measurements.
    assert res["episodes"][0]["mean_stability_index"] != res["episodes"][1]["mean_stability_index"]


def test_sb3_model_zip_runs(tmp_path):
    import gymnasium as gym
    from stable_baselines3 import PPO

    env = gym.make("QuadUneven-v0", terrain="flat", action_mode="joint_pd")
    model = PPO("MlpPolicy", env, n_steps=8, batch_size=8, policy_kwargs={"net_arch": [8]}, device="cpu", seed=0)
    path = tmp_path / "agent.zip"
    model.save(path)
    suite = write_suite(tmp_path / "s.yaml", time_limit=0.2, terrains=[{"kind": "flat", "seeds": [0]}])
    res = evaluate(suite, str(path), tmp_path / "o", env_kwargs={"action_mode": "joint_pd"}, progress=False)
    e = res["episodes"][0]
    assert e["sim_time"] == pytest.approx(0.2) and math.isfinite(e["distance"])
    assert res["meta"]["algo"] == "ppo"


@pytest.mark.slow
def test_video_of_the_first_episode_per_entry(tmp_path):
    import imageio.v3 as iio

    suite = write_suite(tmp_path / "s.yaml", time_limit=1.0, terrains=[{"kind": "flat", "seeds": [0, 1]}])
    res = evaluate(suite, "zero", tmp_path / "o", video=True, progress=False)
    videos = sorted((tmp_path / "o" / "videos").glob("*.mp4"))
    assert [v.name for v in videos] == [res["episodes"][0]["video"]]
    assert res["episodes"][1]["video"] is None
    frames = list(iio.imiter(videos[0]))
    assert len(frames) == pytest.approx(26, abs=1)  # 1 s at 25 fps, plus the reset frame
    assert frames[0].shape == (360, 480, 3)


def test_targets_apply_to_matching_entries_only():
    from agents.evaluation.suites import TerrainEntry
    from agents.evaluation.targets import check_targets

    entries = [
        TerrainEntry("rough", {"amplitude": 0.04}, tuple(range(10))),
        TerrainEntry("rough", {"amplitude": 0.08}, tuple(range(10))),
        TerrainEntry("stairs", {"direction": "down"}, tuple(range(10))),  # default riser 0.08
    ]
    group = {"episodes": 10, "successes": 10, "success_rate": 1.0, "mean_speed_success": 0.12, "successes_index_ok": 10}
    by_entry = [
        {"entry": 0, **group},
        {"entry": 1, **group},
        {"entry": 2, **group, "successes": 8, "success_rate": 0.8, "successes_index_ok": 7},
    ]
    rows = check_targets(entries, by_entry, goal_distance=5.0)
    assert [(r["target"], r["entry"]) for r in rows] == [("rough 4 cm", 0), ("stairs 8 cm down", 2)]
    assert rows[0]["passed"] is True and rows[0]["why_not"] is None
    assert rows[1]["passed"] is False
    assert "success rate 80% < 90%" in rows[1]["why_not"] and "1 success(es)" in rows[1]["why_not"]
    slow = check_targets(entries[:1], [{**by_entry[0], "mean_speed_success": 0.05}], goal_distance=5.0)
    assert slow[0]["passed"] is False and "mean speed" in slow[0]["why_not"]
    few = check_targets(entries[:1], [{**by_entry[0], "episodes": 3, "successes": 3, "successes_index_ok": 3}], 5.0)
    assert few[0]["passed"] is False and few[0]["why_not"] == "3 < 10 episodes"  # --episodes 3 on a target entry
    assert check_targets(entries[:1], by_entry[:1], goal_distance=1.0) == []  # a short walk judges no target
    one_seed = [TerrainEntry("rough", {"amplitude": 0.04}, (0,))]
    assert check_targets(one_seed, [{**by_entry[0], "episodes": 1}], goal_distance=5.0) == []
    randomized = [TerrainEntry("rough", {"amplitude": 0.04}, tuple(range(10)), "mild")]
    assert check_targets(randomized, by_entry[:1], goal_distance=5.0) == []  # the targets are nominal-world ones


def test_the_smoke_suite_judges_no_target_and_the_targets_suite_all_of_them():
    """Perfect results on every entry: the targets suite passes its six targets; smoke (1 m, one seed) has none."""
    from agents.evaluation.suites import load_suite
    from agents.evaluation.targets import TARGETS, check_targets

    def perfect(suite):
        n = len(suite.terrains[0].seeds)
        group = {"episodes": n, "successes": n, "successes_index_ok": n, "success_rate": 1.0, "mean_speed_success": 0.2}
        return [{"entry": i, **group} for i in range(len(suite.terrains))]

    targets = load_suite("targets")
    rows = check_targets(targets.terrains, perfect(targets), targets.goal_distance)
    assert sorted(r["target"] for r in rows) == sorted(t.name for t in TARGETS) and all(r["passed"] for r in rows)
    smoke = load_suite("smoke")
    assert check_targets(smoke.terrains, perfect(smoke), smoke.goal_distance) == []


@pytest.mark.parametrize("factor", [0.773, 1.551, 1.657])
def test_a_suite_scaled_to_a_robot_judges_every_target_at_its_scale(factor):
    """``targets`` magnified by a robot's factor: every target judged on its scaled entry (riser 8 cm x factor, goal
    5 m x factor), the speed targets x sqrt(factor); the unscaled suite's entries judged at that factor match none."""
    from agents.evaluation.suites import load_suite, scale_suite
    from agents.evaluation.targets import TARGETS, check_targets

    suite = load_suite("targets")
    scaled = scale_suite(suite, factor)
    assert scaled.length_scale == factor
    n = len(suite.terrains[0].seeds)
    group = {"episodes": n, "successes": n, "successes_index_ok": n, "success_rate": 1.0}
    slow = 0.1 * factor**0.5 * 0.99  # just under the flat target's scaled 0.1 m/s
    by_entry = [{"entry": i, **group, "mean_speed_success": slow} for i in range(len(scaled.terrains))]
    rows = check_targets(scaled.terrains, by_entry, scaled.goal_distance, scaled.length_scale)
    assert sorted(r["target"] for r in rows) == sorted(t.name for t in TARGETS)
    speed_rows = {r["target"]: r for r in rows if r["required_speed"] is not None}
    assert set(speed_rows) == {"flat", "rough 4 cm"}
    assert all(r["required_speed"] == pytest.approx(0.1 * factor**0.5) and not r["passed"] for r in speed_rows.values())
    assert all(r["passed"] for r in rows if r["required_speed"] is None)
    unscaled_rows = check_targets(suite.terrains, by_entry, suite.goal_distance * factor, factor)
    assert sorted(r["target"] for r in unscaled_rows) == ["flat", "slope 10°", "stepping stones"]  # no length
    if factor > 1.0:  # a goal short of 5 m x factor judges nothing
        assert check_targets(scaled.terrains, by_entry, suite.goal_distance, factor) == []


class InstrumentedPolicy:
    """Stands still and exposes what the expert exposes: planner times, a failure log and a phase."""

    def __init__(self, env):
        self.action = np.zeros(env.action_space.shape, dtype=np.float32)
        self.planner_times_ms = [1.0, 2.0, 3.0, 10.0]
        self.failure_log = [f"t={k}: PlanningError: edge {k}" for k in range(3)]
        self.phase = "swing RF"

    def predict(self, observation, state=None, episode_start=None, deterministic=True):
        return self.action, state


def test_policy_timings_failure_log_and_phase_are_recorded(monkeypatch):
    monkeypatch.setattr(
        evaluate_episode,
        "make_policy",
        lambda name, env, *args, **kwargs: InstrumentedPolicy(env),
    )
    r = run_task(EpisodeTask(0, 0, "flat", {}, 0, False), EvalConfig("zero", 1.0, 0.1)).record
    assert r["planner_ms_median"] == pytest.approx(2.5)
    assert r["planner_ms_p95"] == pytest.approx(np.percentile([1.0, 2.0, 3.0, 10.0], 95))
    assert r["planner_calls"] == 4
    assert r["failure_log"] == [
        "t=0: PlanningError: edge 0",
        "t=1: PlanningError: edge 1",
        "t=2: PlanningError: edge 2",
    ]
    assert r["failure_count"] == 3 and r["end_phase"] == "swing RF"


def test_bad_env_kwargs_fail_before_any_episode(tmp_path, capsys):
    suite = write_suite(tmp_path / "s.yaml")
    argv = ["evaluate", "--policy", "zero", "--suite", str(suite), "--out", str(tmp_path / "o"), "--no-progress"]
    assert main([*argv, "--workers", "2", "--env-kwargs", '{"frame_skip": 0}']) == 2
    assert "frame_skip" in capsys.readouterr().err
    assert main([*argv, "--env-kwargs", "[1]"]) == 2
    assert "JSON object" in capsys.readouterr().err


def test_randomized_entries_record_their_draws_and_the_report_groups_by_factor(tmp_path):
    spec = {"friction": [0.4, 1.0], "payload_mass": [0.0, 10.0], "latency": [0.0, 0.004]}
    spec |= {"push_impulse": [5.0, 5.0], "push_interval": [0.5, 0.5], "push_duration": [0.1, 0.1]}
    suite = write_suite(
        tmp_path / "r.yaml",
        terrains=[
            {"kind": "flat", "seeds": [0]},
            {"kind": "flat", "randomization": spec, "seeds": [0, 1, 2, 3, 4, 5]},
        ],
    )
    res = evaluate(suite, "zero", tmp_path / "o", progress=False)
    nominal, *randomized = res["episodes"]
    assert nominal["randomization"] is None and nominal["factors"] is None and nominal["pushes"] is None
    frictions = [e["randomization"]["friction"] for e in randomized]
    assert all(0.4 <= f <= 1.0 for f in frictions) and len(set(frictions)) == 6
    for e in randomized:
        assert e["factors"]["total_mass"] == pytest.approx(50.0 + e["randomization"]["payload_mass"])
        assert e["factors"]["push_count"] == 3.0 and e["pushes"][0]["impulse"] == pytest.approx(5.0)  # 0.5, 1, 1.5 s
    rows = res["summary"]["by_factor"]
    assert {r["factor"] for r in rows} == {"friction", "payload_mass", "total_mass", "latency"}
    friction = [r for r in rows if r["factor"] == "friction"]
    bins = {0.35: "< 0.35", 0.45: "0.35-0.45", 0.6: "0.45-0.6", 0.8: "0.6-0.8", 1.0: "0.8-1", 2.0: ">= 1"}
    expected = {}
    for f in frictions:
        label = bins[min(edge for edge in bins if f < edge)]
        expected[label] = expected.get(label, 0) + 1
    assert {r["bin"]: r["episodes"] for r in friction} == expected
    assert res["meta"]["randomization"] == [None, spec]
    report = (tmp_path / "o" / "report.md").read_text()
    assert "## By randomization factor" in report and "| friction | " in report
    assert "+ randomization" in report  # the entry label


def test_bad_randomization_of_a_later_entry_fails_before_any_episode(tmp_path, capsys):
    suite = write_suite(
        tmp_path / "s.yaml",
        terrains=[
            {"kind": "flat", "seeds": [0]},
            {"kind": "flat", "randomization": {"latency": [0, 0.05]}, "seeds": [0]},
        ],
    )
    argv = ["evaluate", "--policy", "zero", "--suite", str(suite), "--out", str(tmp_path / "o"), "--no-progress"]
    assert main(argv) == 2
    assert "randomization.latency" in capsys.readouterr().err


def test_factor_summary_groups_by_value_hand_case():
    from agents.evaluation.metrics import factor_summary

    def record(friction, latency, damping, pushes, success):
        base = {"success": success, "fall_reason": None if success else "fall: tilt 70 deg > 60 deg"}
        base |= {k: 1.0 for k in ("distance", "mean_speed", "sim_time", "min_stability_index")}
        base |= {k: 1.0 for k in ("mean_stability_index", "time_index_negative", "cost_of_transport")}
        base |= {"fraction_index_nonnegative": 1.0, "planner_ms_median": None, "planner_ms_p95": None}
        base |= {"end_reason": "goal" if success else "fall"}
        factors = {"friction": friction, "latency": latency, "payload_mass": 0.0, "joint_damping_mean": damping}
        return base | {"factors": factors | {"push_count": pushes}}

    # friction bins (edges 0.35, 0.45, 0.6, 0.8, 1.0): < 0.35 {0.3}, 0.35-0.45 {0.4, 0.35, 0.449},
    # 0.45-0.6 {0.45, 0.5}, 0.8-1 {0.9, 0.8}, >= 1 {1.2}; 0.6-0.8 is empty
    frictions = [0.9, 0.3, 0.5, 0.4, 0.8, 0.35, 0.449, 0.45, 1.2]
    success = [True, False, True, False, True, True, False, True, True]
    latencies = [0.0, 0.002, 0.004, 0.006, 0.008, 0.01, 0.0, 0.002, 0.004]  # edges 0.003, 0.007: 4, 3, 2
    dampings = [0.1, 0.9, 0.5, 0.3, 0.7, 0.2, 0.8, 0.4, 0.6]  # no edges: thirds by value
    records = [
        record(f, lat, dmp, float(k % 2), ok)
        for k, (f, lat, dmp, ok) in enumerate(zip(frictions, latencies, dampings, success, strict=True))
    ]
    records.append({**record(1.0, 0.0, 0.0, 0.0, True), "factors": None})  # a nominal episode: left out
    rows = factor_summary(records)
    assert {r["factor"] for r in rows} == {"friction", "latency", "joint_damping_mean", "push_count"}  # payload const
    friction = [
        (r["bin"], r["low"], r["high"], r["episodes"], r["successes"]) for r in rows if r["factor"] == "friction"
    ]
    assert friction == [
        ("< 0.35", 0.3, 0.3, 1, 0),
        ("0.35-0.45", 0.35, 0.449, 3, 1),
        ("0.45-0.6", 0.45, 0.5, 2, 2),
        ("0.8-1", 0.8, 0.9, 2, 2),
        (">= 1", 1.2, 1.2, 1, 1),
    ]
    latency = [(r["bin"], r["episodes"], r["successes"]) for r in rows if r["factor"] == "latency"]
    assert latency == [("< 0.003", 4, 2), ("0.003-0.007", 3, 2), (">= 0.007", 2, 2)]
    damping = [(r["bin"], r["low"], r["high"]) for r in rows if r["factor"] == "joint_damping_mean"]
    assert damping == [("thirds 1/3", 0.1, 0.3), ("thirds 2/3", 0.4, 0.6), ("thirds 3/3", 0.7, 0.9)]
    pushes = [(r["bin"], r["episodes"]) for r in rows if r["factor"] == "push_count"]
    assert pushes == [("0", 5), ("1", 4)]  # two distinct values: one group each
