"""``quad-uneven distill --robot NAME --scale-terrain``: a tiny end-to-end distillation on Go1 (the suite scaled to
the robot as ``evaluate`` scales it, the teacher scaled to it, the robot recorded and enforced)."""

from __future__ import annotations

import json
import math

import pytest

import quad_uneven_env  # noqa: F401  (registers QuadUneven-v0)
from agents.cli import main
from agents.evaluation.policies import PolicyError
from agents.evaluation.run import evaluate
from agents.evaluation.suites import suite_from_dict
from agents.expert import ExpertConfig
from quad_uneven_env.env_config import default_pd_gains
from quad_uneven_env.robot.description import load_robot

pytest.importorskip("stable_baselines3")

SUITE = {
    "name": "tiny-scaled",
    "goal_distance": 5.0,
    "time_limit": 0.6,
    "terrains": [{"kind": "flat", "seeds": [0]}, {"kind": "rough", "params": {"amplitude": 0.04}, "seeds": [1]}],
}


@pytest.fixture(scope="module")
def go1_run(tmp_path_factory):
    root = tmp_path_factory.mktemp("distill_go1")
    (root / "suite.yaml").write_text(json.dumps(SUITE))
    argv = ["distill", "--suite", str(root / "suite.yaml"), "--out", str(root / "run"), "--robot", "go1",
            "--scale-terrain", "--dagger-rounds", "1", "--episodes", "1", "--epochs", "2"]  # fmt: skip
    assert main(argv) == 0
    return root


def test_a_go1_student_learns_on_the_scaled_suite_with_the_scaled_teacher(go1_run):
    from agents.rl.model_io import read_metadata

    go1 = load_robot("go1")
    factor = go1.length_ratio
    assert not math.isclose(factor, 1.0)
    meta = read_metadata(go1_run / "run" / "model.zip")
    assert meta["robot"] == "go1" and meta["env_kwargs"]["robot"] == "go1"
    teacher = ExpertConfig.for_robot(go1, {"recovery": False})
    assert meta["env_kwargs"]["gait_period"] == pytest.approx(sum(teacher.durations))
    # the robot's own servo (26.6 N m/rad, 0.80 N m s/rad for 13 kg), not the paper robot's 100 and 3
    assert (meta["env_kwargs"]["pd_kp"], meta["env_kwargs"]["pd_kd"]) == default_pd_gains(go1)
    assert meta["env_kwargs"]["pd_kp"] == pytest.approx(26.575, abs=1e-3)
    # the suite as evaluate --scale-terrain runs it: lengths x factor, time limit x sqrt(factor)
    assert meta["terrain"][1]["amplitude"] == pytest.approx(0.04 * factor)
    assert meta["max_episode_steps"] == round(0.6 * math.sqrt(factor) / 0.02)
    summary = json.loads((go1_run / "run" / "distill_summary.json").read_text())
    assert summary["rounds"][0]["steps"] == 2 * meta["max_episode_steps"]  # the expert walked both episodes out
    assert summary["rounds"][0]["falls"] == 0


def test_the_teacher_is_the_expert_scaled_to_the_robot():
    from agents.rl.distill import DistillConfig

    go1 = DistillConfig(env_kwargs={"robot": "go1"}).expert_config()
    assert go1 == ExpertConfig.for_robot(load_robot("go1"), {"recovery": False})
    assert go1.stride != ExpertConfig().stride and go1.recovery is False  # scaled, with the overrides on top
    assert DistillConfig().expert_config() == ExpertConfig(recovery=False)  # the paper robot: the defaults


def test_the_go1_student_runs_on_go1_and_is_refused_on_another_robot(go1_run, tmp_path):
    model = str(go1_run / "run" / "model.zip")
    suite = suite_from_dict({**SUITE, "time_limit": 0.1}, source="test")
    res = evaluate(suite, model, tmp_path / "go1", env_kwargs={"robot": "go1"}, progress=False)
    assert [e["error"] for e in res["episodes"]] == [None, None]
    with pytest.raises(PolicyError, match="robot must be 'go1'"):
        evaluate(suite, model, tmp_path / "paper", env_kwargs={"robot": "paper"}, progress=False)


def test_robot_options_errors_are_one_line_with_exit_code_2(tmp_path, capsys):
    cases = [
        (["--robot", "go1", "--env-kwargs", '{"robot": "hyq"}'], "differ: give one"),
        (["--robot", "no_such_robot"], "distill.env_kwargs.robot"),
        (["--env-kwargs", '{"action_mode": "torque"}'], "distill.env_kwargs must not set ['action_mode']"),
    ]
    for extra, says in cases:
        rc = main(["distill", "--suite", "smoke", "--out", str(tmp_path / "o"), *extra])
        err = capsys.readouterr().err
        assert rc == 2 and says in err, (extra, err)
        assert not (tmp_path / "o").exists()
