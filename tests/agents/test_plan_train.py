"""quad-uneven train / evaluate with residual_level: plan (QuadUnevenPlan-v0)."""

from __future__ import annotations

import json
from pathlib import Path

import gymnasium as gym
import pytest
import yaml

from agents.cli import main
from agents.expert import ExpertConfig
from agents.rl.config import TrainConfigError, load_train_config
from agents.rl.model_io import ModelError, check_model_env, make_model_env, model_env_spec
from agents.rl.plan_config import PlanConfig
from agents.rl.plan_env import PLAN_ENV_ID, PlanExpertEnv

PLAN_CONFIG = Path("configs/rl/ppo_plan.yaml")

TINY = {
    "timesteps": 32,
    "n_envs": 1,
    "max_episode_steps": 400,
    "eval_freq": 16,
    "eval_episodes": 1,
    "checkpoint_freq": 16,
    "terrain": "rough",
    "randomization": None,
    "hyperparams": {"n_steps": 16, "batch_size": 8, "n_epochs": 1},
    "policy_kwargs": {"net_arch": [16], "log_std_init": -1.0},
}
"""Overrides of ppo_plan.yaml for a run of 32 gait cycles (episodes of 400 control steps: 3 cycles)."""


def write_config(path: Path, **changes) -> Path:
    raw = yaml.safe_load(PLAN_CONFIG.read_text())
    raw.update(TINY)
    raw.update(changes)
    path.write_text(yaml.safe_dump(raw))
    return path


def test_shipped_plan_config_is_valid_and_gives_the_adaptive_expert():
    cfg = load_train_config(PLAN_CONFIG)
    plan = cfg.env_config()
    assert isinstance(plan, PlanConfig)
    assert plan.expert.adaptation == "learned" and plan.max_control_steps == cfg.max_episode_steps == 1000
    assert plan.to_dict() == {**PlanConfig().to_dict(), **cfg.plan, "max_control_steps": 1000}


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"plan": {"stride_range": 5}}, r"^plan\.stride_range must be"),
        ({"plan": {"speed": 1}}, r"^plan"),
        ({"plan": {"expert": {}}}, r"^plan\.expert is not accepted"),
        ({"plan": {"max_control_steps": 10}}, r"^plan\.max_control_steps is not accepted"),
        ({"residual_level": "gait"}, r"^residual_level must be one of \['torque', 'plan'\]"),
        ({"residual_scale": 0.3}, r"^residual_scale applies to residual_level torque only"),
        ({"residual_legs": "stance"}, r"^residual_legs applies to residual_level torque only"),
        ({"expert_features": False}, r"^expert_features must be true with residual_level plan"),
        (
            {"residual": False, "expert": {}, "expert_features": False},
            r"^plan and residual_level: plan need residual: true",
        ),
    ],
)
def test_bad_plan_fields_are_named(tmp_path, changes, message):
    with pytest.raises(TrainConfigError, match=message):
        load_train_config(write_config(tmp_path / "c.yaml", **changes))


def test_plan_fields_need_the_plan_level(tmp_path):
    raw = yaml.safe_load(Path("configs/rl/ppo_residual.yaml").read_text())
    raw["plan"] = {"stride_range": 0.1}
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(raw))
    with pytest.raises(TrainConfigError, match=r"^plan and residual_level: plan need"):
        load_train_config(tmp_path / "c.yaml")


def test_model_env_spec_rebuilds_the_plan_env_and_refuses_another():
    meta = {
        "algo": "ppo",
        "residual": True,
        "residual_level": "plan",
        "plan": {"stride_range": 0.2},
        "expert": {"adaptation": "knee"},
        "env_id": PLAN_ENV_ID,
    }
    env_id, kwargs = model_env_spec(meta)
    assert env_id == PLAN_ENV_ID
    assert kwargs["config"] == PlanConfig(stride_range=0.2, expert=ExpertConfig(adaptation="knee"))
    env = gym.make(env_id, **kwargs, terrain="flat")
    wrapper = check_model_env(meta, env, Path("m.zip"))
    assert isinstance(wrapper, PlanExpertEnv) and wrapper.config.stride_range == 0.2
    other = gym.make(PLAN_ENV_ID, terrain="flat", config=PlanConfig(stride_range=0.1, expert=kwargs["config"].expert))
    with pytest.raises(ModelError, match=r"stride_range=0\.2, the env has stride_range=0\.1"):
        check_model_env(meta, other, Path("m.zip"))
    with pytest.raises(ModelError, match=r"it runs in QuadUnevenPlan-v0"):
        check_model_env(meta, gym.make("agents.rl:QuadUnevenResidual-v0", terrain="flat"), Path("m.zip"))


@pytest.mark.slow
def test_tiny_plan_run_trains_and_evaluates_through_the_cli(tmp_path, capsys):
    """A PPO run of 32 cycles on the plan level, then `quad-uneven evaluate --policy` on one episode of 8 s: the
    model runs in its own env (the plan env, rebuilt from rl_meta.json), truncated at the suite's time limit."""
    run = tmp_path / "run"
    rc = main(["train", "--config", str(write_config(tmp_path / "c.yaml")), "--out", str(run), "--no-progress"])
    assert rc == 0, capsys.readouterr().err
    meta = json.loads((run / "rl_meta.json").read_text())
    assert (
        meta["residual_level"] == "plan"
        and meta["env_id"] == PLAN_ENV_ID
        and meta["expert"] == {"adaptation": "learned"}
    )
    summary = json.loads((run / "train_summary.json").read_text())
    assert summary["timesteps"] == 32 and summary["episodes"] >= 8  # 3 cycles of 400 control steps each
    env = make_model_env(run / "model.zip", max_episode_steps=400)
    assert env.unwrapped.controller is env.get_wrapper_attr("expert")
    assert env.get_wrapper_attr("config").max_control_steps == 400

    suite = tmp_path / "suite.yaml"
    suite.write_text(
        yaml.safe_dump(
            {"name": "one", "goal_distance": 5.0, "time_limit": 8.0, "terrains": [{"kind": "flat", "seeds": [0]}]}
        )
    )
    out = tmp_path / "eval"
    rc = main(["evaluate", "--policy", str(run / "model.zip"), "--suite", str(suite), "--out", str(out),
               "--no-progress"])  # fmt: skip
    assert rc == 0, capsys.readouterr().err
    episode = json.loads((out / "results.json").read_text())["episodes"][0]
    assert episode["error"] is None and episode["end_reason"] == "time_limit"
    assert episode["sim_time"] == pytest.approx(8.0)  # 400 control steps: the plan env truncates at control steps
    assert episode["planner_calls"] >= 3  # the expert planned every cycle
