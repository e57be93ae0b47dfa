"""The robustness command: a sweep of one factor through the evaluation machinery, its JSON and curves."""

from __future__ import annotations

import json

import numpy as np
import pytest

from agents.cli import main
from agents.evaluation.robustness import FACTORS, robustness_sweep


@pytest.mark.slow  # ~40 s: two evaluations of the expert (most of it compiling the controller's kernels)
def test_robustness_command_on_a_tiny_sweep(tmp_path, capsys):
    code = main(["robustness", "--factor", "friction", "--values", "1.0,0.5", "--seeds", "1", "--goal", "0.2",
                 "--out", str(tmp_path), "--no-progress"])  # fmt: skip
    assert code == 0
    summary = json.loads((tmp_path / "robustness_friction.json").read_text())
    assert [p["value"] for p in summary["points"]] == [1.0, 0.5]
    for p in summary["points"]:
        assert p["episodes"] == 1 and p["errors"] == 0 and 0.0 <= p["success_rate"] <= 1.0
        assert p["randomization"] == {"friction": [p["value"], p["value"]]}
    # one evaluation with an entry per value, each episode recorded with its world and the expert's model
    results = json.loads((tmp_path / "friction" / "results.json").read_text())
    assert results["meta"]["randomization"] == [{"friction": [1.0, 1.0]}, {"friction": [0.5, 0.5]}]
    assert [e["randomization"]["friction"] for e in results["episodes"]] == [1.0, 0.5]
    assert {e["expert_model"] for e in results["episodes"]} == {"nominal"}
    assert summary["expert_model"] == ["nominal"]
    assert (tmp_path / "robustness_friction.png").stat().st_size > 1000
    assert "friction      0.5: success" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--factor", "push", "--values", "a,b"], "--values must be comma-separated finite numbers"),
        (["--factor", "push", "--values", "1,nan"], "'nan' is not"),
        (["--factor", "push", "--policy", "zero", "--model", "oracle"], "--model is the expert's model"),
        (["--factor", "push", "--seeds", "0"], "seeds must be an integer >= 1"),
        (["--factor", "latency", "--workers", "0"], "--workers must be >= 1"),
    ],
)
def test_robustness_command_rejects_bad_input(tmp_path, capsys, argv, message):
    assert main(["robustness", *argv, "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1


def test_robustness_command_rejects_an_unknown_factor(tmp_path, capsys):
    assert main(["robustness", "--factor", "gravity", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: argument --factor: invalid choice") and err.count("\n") == 1


def test_every_factor_fixes_one_randomization_value():
    from quad_uneven_env.randomization import load_randomization

    for f in FACTORS.values():
        for v in f.values:
            load_randomization(f.randomization(v))  # valid for the env
    with pytest.raises(ValueError, match="factor must be one of"):
        robustness_sweep("gravity", "unused")


def test_torque_peak_fractions_by_hand():
    from agents.evaluation.metrics import torque_peak_fractions

    limit = np.tile([10.0, 20.0, 40.0], 4)
    peak = np.zeros(12)
    peak[[0, 4, 11]] = [5.0, -20.0, 14.0]  # LF HAA half its limit, RF HFE at its limit, RH KFE 14 of 40
    strength = np.ones(12)
    strength[11] = 0.5  # RH KFE has 20 N m: 14 is 0.7 of it
    strength[4] = 1.3  # a strong motor still saturates at its limit
    assert torque_peak_fractions(peak, limit, strength) == pytest.approx({"HAA": 0.5, "HFE": 1.0, "KFE": 0.7})


@pytest.mark.slow  # ~15 s: the sweep on Go1 at its scale, on stairs
def test_robustness_sweep_on_another_robot_runs_at_its_scale(tmp_path):
    from agents.evaluation.run import robot_scale

    code = main(["robustness", "--factor", "motor_strength", "--values", "1.0,0.6", "--seeds", "1", "--goal", "0.2",
                 "--robot", "go1", "--terrain", "stairs_up", "--expert-config", '{"adaptation": "knee"}',
                 "--out", str(tmp_path), "--no-progress"])  # fmt: skip
    assert code == 0
    summary = json.loads((tmp_path / "robustness_motor_strength.json").read_text())
    assert summary["robot"] == "go1" and summary["terrain"]["kind"] == "stairs"
    assert summary["expert_config"] == {"adaptation": "knee"}
    assert [p["randomization"] for p in summary["points"]] == [
        {"scale": "robot", "motor_strength": [1.0, 1.0]},
        {"scale": "robot", "motor_strength": [0.6, 0.6]},
    ]
    results = json.loads((tmp_path / "motor_strength" / "results.json").read_text())
    assert results["meta"]["goal_distance"] == pytest.approx(0.2 * robot_scale("go1"))
    assert results["meta"]["entries"][0].startswith(f"stairs(length={8 * robot_scale('go1'):g}")
    weak = next(e for e in results["episodes"] if e["entry"] == 1)
    assert weak["randomization"]["motor_strength_LF_HFE"] == 0.6
    for e in results["episodes"]:
        assert set(e["torque_peak_fraction"]) == {"HAA", "HFE", "KFE"}
        assert all(0.0 < f <= 1.0 + 1e-9 for f in e["torque_peak_fraction"].values())
