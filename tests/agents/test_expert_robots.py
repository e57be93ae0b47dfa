"""The expert on the URDF robots (HyQ, ANYmal C, Go1, Solo12): its settings scaled from the robot, and it walks."""

from __future__ import annotations

import dataclasses
import math

import gymnasium as gym
import numpy as np
import pytest

from agents.expert import ExpertConfig, attach_expert
from agents.expert.config import motor_load
from planners.robot_geometry import robot_geometry
from quad_uneven_env.robot.description import load_robot

URDF_ROBOTS = ("anymal_c", "go1", "hyq", "solo12")


def test_the_paper_robot_gets_the_defaults():
    paper = load_robot("paper")
    assert ExpertConfig.for_robot(paper) == ExpertConfig()
    assert ExpertConfig.for_robot(paper, {"stride": 0.2}) == ExpertConfig(stride=0.2)


@pytest.mark.parametrize(
    ("name", "load", "friction"),
    [
        ("paper", 1.717, 0.25),
        ("go1", 2.310, 0.25),
        ("solo12", 2.948, 0.25),
        ("hyq", 3.950, 0.5),
        ("anymal_c", 4.166, 0.5),
    ],
)
def test_the_cones_are_narrow_only_where_the_motors_hold_the_robot_easily(name, load, friction):
    """The paper robot: 50 kg x 9.81 m/s^2 x 0.42 m / 120 N m = 1.717 (below 3.5: cones of 0.25; Go1: 13.1 kg,
    0.426 m, 23.7 N m: 2.31); HyQ's and ANYmal C's weakest hip-flexion or knee motors work harder and keep 0.5."""
    robot = load_robot(name)
    assert motor_load(robot) == pytest.approx(load, abs=1e-3)
    assert ExpertConfig.for_robot(robot).friction == friction


@pytest.mark.parametrize("name", URDF_ROBOTS)
def test_settings_scale_with_the_robot(name):
    """Lengths ~ leg length s, times ~ sqrt(s) (equal Froude number), margin ~ mass x s, gains ~ 1/s, 1/sqrt(s)."""
    desc = load_robot(name)
    s, m = desc.leg_length / 0.42, desc.total_mass / 50.0
    base, cfg = ExpertConfig(), ExpertConfig.for_robot(desc)
    assert robot_geometry(desc).scale == pytest.approx(s)
    assert np.allclose(cfg.durations, np.array(base.durations) * math.sqrt(s), atol=0.005)
    assert np.allclose(np.array(cfg.durations) / 0.01, np.round(np.array(cfg.durations) / 0.01))  # 10 ms multiples
    assert cfg.stride == pytest.approx(0.33 * s) and cfg.clearance == pytest.approx(0.05 * s)
    assert cfg.epsilon == pytest.approx(20.0 * m * s)
    assert cfg.gains.kp_pos == pytest.approx(400.0 / s) and cfg.gains.kd_joint == pytest.approx(60.0 / math.sqrt(s))
    assert cfg.foothold_scale == pytest.approx(s)
    # the COG walks a little below its standing height (the paper robot's ratio, 0.33 / 0.349)
    assert 0.85 * desc.standing_height < cfg.cog_height < desc.standing_height


def test_the_robot_yaml_and_the_caller_override_the_scaled_settings():
    desc = dataclasses.replace(load_robot("go1"))
    object.__setattr__(desc, "gait", dataclasses.replace(desc.gait, cycle_time=2.0, body_height=0.25, gain_scale=2.0))
    cfg = ExpertConfig.for_robot(desc)
    assert sum(cfg.durations) == pytest.approx(2.0, abs=0.03) and cfg.cog_height == 0.25
    assert cfg.gains.kp_pos == pytest.approx(2.0 * ExpertConfig.for_robot(load_robot("go1")).gains.kp_pos)
    given = ExpertConfig.for_robot(desc, {"cog_height": 0.22, "gains": {"kp_joint": 500.0}})
    assert given.cog_height == 0.22 and given.gains.kp_joint == 500.0 and given.gains.kp_pos == cfg.gains.kp_pos
    with pytest.raises(ValueError, match=r"expert_config: unknown field\(s\) \['stryde'\]"):
        ExpertConfig.for_robot(desc, {"stryde": 0.1})


@pytest.mark.parametrize("name", URDF_ROBOTS)
def test_the_expert_walks_on_flat_ground(name):
    """8 s on flat ground (2.5-3 gait cycles): at least 1.3 strides forward, no fall, index >= 0 >= 99 % of the time."""
    env = gym.make("QuadUneven-v0", robot=name, terrain="flat")
    try:
        expert = attach_expert(env)
        obs, info = env.reset(seed=0)
        x0, index = info["cog"][0], []
        for _ in range(400):
            obs, _, terminated, truncated, info = env.step(expert.predict(obs)[0])
            index.append(info["stability_index"])
            assert not (terminated or truncated), info["termination_reason"]
        assert info["cog"][0] - x0 > 1.3 * expert.config.stride
        assert abs(info["cog"][1]) < 0.1
        assert np.mean(np.array(index) >= 0.0) >= 0.99
    finally:
        env.close()


def test_the_residual_env_scales_its_expert_to_the_robot():
    """The residual env's expert settings lie over the robot's scaled settings."""
    from agents.rl.residual_env import ResidualConfig

    config = ResidualConfig(expert=ExpertConfig(adaptation="knee"))
    go1 = gym.make("QuadUnevenResidual-v0", robot="go1", config=config)
    go1.reset(seed=0)
    expected = ExpertConfig.for_robot(load_robot("go1"), {"adaptation": "knee"})
    assert go1.unwrapped.controller.expert.config == expected
    assert expected.stride != ExpertConfig().stride  # scaled: not the paper robot's gait
    paper = gym.make("QuadUnevenResidual-v0", config=config)
    paper.reset(seed=0)
    assert paper.unwrapped.controller.expert.config == ExpertConfig(adaptation="knee")


def test_train_refuses_an_unknown_robot_before_writing(tmp_path, capsys):
    from agents.cli import main

    out = tmp_path / "run"
    assert main(["train", "--robot", "nosuch", "--timesteps", "16", "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: env_kwargs") and "nosuch" in err[0]
    assert not out.exists()


def test_the_expert_follows_a_command_on_a_urdf_robot():
    env = gym.make(
        "QuadUneven-v0",
        robot="go1",
        command={"ranges": {"vx": [0.05, 0.1], "yaw_rate": [-0.1, 0.1]}, "resample_interval": 5.0},
        max_episode_steps=400,
    )
    attach_expert(env)
    env.reset(seed=1)
    for _ in range(400):
        _, _, terminated, truncated, info = env.step(np.zeros(12, dtype=np.float32))
        assert not terminated
        if truncated:
            break
    assert info["distance"] > 0.5  # m in 8 s at 0.05-0.1 m/s commanded


def test_make_vec_runs_a_urdf_robot():
    venv = gym.make_vec("QuadUneven-v0", num_envs=2, vectorization_mode="sync", robot="solo12")
    obs, _ = venv.reset(seed=0)
    for _ in range(5):
        obs, _, terminated, _, _ = venv.step(np.zeros((2, 12), dtype=np.float32))
    assert obs.shape == (2, 134) and not terminated.any()
    assert venv.envs[0].unwrapped.robot.name == "solo12"


def test_an_evaluation_runs_the_suite_at_the_robot_scale(tmp_path):
    """A ``scale: leg_length`` suite on Solo12 (s = 0.3248 / 0.42): the episode's terrain is the written one with
    every length x s (the grid's 0.02 m cells are 1.55 cm), the goal is 1 m x s, the time limit 1 s x sqrt(s)."""
    from agents.evaluation.run import evaluate
    from agents.evaluation.suites import suite_from_dict

    s = load_robot("solo12").leg_length / 0.42
    raw = {"name": "stones", "scale": "leg_length", "goal_distance": 1.0, "time_limit": 1.0,
           "terrains": [{"kind": "stepping_stones", "params": {"gap": 0.05}, "seeds": [0]}]}  # fmt: skip
    res = evaluate(suite_from_dict(raw), "zero", tmp_path / "o", env_kwargs={"robot": "solo12"}, progress=False)
    params = res["episodes"][0]["params"]
    assert params["gap"] == pytest.approx(0.05 * s) and params["cell_size"] == pytest.approx(0.02 * s)
    assert params["length"] == pytest.approx(8.0 * s) and params["stone_size"] == pytest.approx(0.25 * s)
    assert res["meta"]["goal_distance"] == pytest.approx(s)
    assert res["meta"]["time_limit"] == pytest.approx(math.sqrt(s))
