"""The env's arguments as one frozen config, and the action map that turns an action into the actuators' command."""

from __future__ import annotations

import dataclasses
import inspect

import gymnasium as gym
import numpy as np
import pytest

import quad_uneven_env  # noqa: F401
from quad_uneven_env.actuation import ActionMap
from quad_uneven_env.config import RewardWeights, TerminationLimits
from quad_uneven_env.env import QuadUnevenEnv
from quad_uneven_env.env_config import EnvConfig, arguments_table, default_base_height_limits, default_pd_gains
from quad_uneven_env.fields import params_of
from quad_uneven_env.robot.description import load_robot


def test_the_env_takes_the_configs_fields_and_a_controller_as_its_arguments():
    fields = dataclasses.fields(EnvConfig)
    params = inspect.signature(QuadUnevenEnv).parameters
    assert list(params) == ["controller"] + [f.name for f in fields]
    for f in fields:
        assert params[f.name].default == f.default


def test_the_config_holds_the_arguments_checked_and_loaded():
    cfg = EnvConfig(terrain="flat", reward_weights={"alive": 2.0}, frame_skip=np.int64(4), timestep=np.float32(0.001))
    assert cfg.robot is load_robot("paper") and cfg.terrain.kind == "flat"
    assert cfg.reward_weights == RewardWeights(alive=2.0)
    assert type(cfg.frame_skip) is int and cfg.frame_skip == 4 and type(cfg.timestep) is float
    assert cfg.height_scan is not None and cfg.randomization is None and cfg.command is None
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.frame_skip = 5


def test_robot_dependent_defaults_come_from_the_robot():
    """None for the PD gains and unset base-height limits are the robot's (the paper robot's: 100 N m/rad,
    3 N m s/rad, 0.12 and 1 m; another robot's scaled from them); given values win."""
    cfg = EnvConfig()
    assert (cfg.pd_kp, cfg.pd_kd) == default_pd_gains(cfg.robot) == (100.0, 3.0)
    assert default_base_height_limits(cfg.robot) == (0.12, 1.0)
    assert cfg.termination == TerminationLimits(min_base_height=0.12, max_base_height=1.0)
    given = EnvConfig(pd_kp=50, termination={"max_base_height": 0.8})
    assert given.pd_kp == 50.0 and given.pd_kd == 3.0
    assert (given.termination.min_base_height, given.termination.max_base_height) == (0.12, 0.8)
    other = EnvConfig(robot="go1")
    lo, hi = default_base_height_limits(other.robot)
    assert (other.pd_kp, other.pd_kd) == default_pd_gains(other.robot) != (100.0, 3.0)
    assert (other.termination.min_base_height, other.termination.max_base_height) == (lo, hi) != (0.12, 1.0)


def test_a_config_can_be_rebuilt_from_its_own_fields():
    cfg = EnvConfig(terrain={"kind": "stairs"}, randomization="mild", command={"vx": 0.2})
    again = dataclasses.replace(cfg, frame_skip=5)
    assert again.frame_skip == 5 and again.robot is cfg.robot and again.randomization == cfg.randomization
    assert again.terrain == cfg.terrain and again.command == cfg.command


def test_the_env_keeps_its_config_and_reads_its_arguments_from_it():
    env = gym.make("QuadUneven-v0", terrain="flat", frame_skip=5, action_mode="joint_pd", pd_kd=2.0).unwrapped
    assert env.config.frame_skip == env.frame_skip == 5 and env.config.pd_kd == 2.0
    assert env.action_mode == "joint_pd" and env.robot is env.config.robot
    assert env.dt == pytest.approx(5 * 0.002)


def test_the_arguments_table_has_one_row_per_scalar_argument():
    rows = arguments_table().splitlines()[2:]
    assert [r.split("|")[1].strip() for r in rows] == [f"``{p.name}``" for p in params_of(EnvConfig)]
    assert "| ``pd_kp`` | ``None`` | number in (0, 100000] | N m/rad |" in arguments_table()


def test_an_unknown_argument_is_refused_naming_it():
    with pytest.raises(TypeError, match="unexpected keyword argument 'speed'"):
        gym.make("QuadUneven-v0", speed=1.0)


LIMIT = np.array([30.0, 60.0, 90.0] * 4)
LO, HI = np.full(12, -0.5), np.full(12, 0.5)


def test_torque_mode_commands_action_times_the_limit():
    out = np.empty(12)
    a = np.linspace(-1.0, 1.0, 12)
    ActionMap("torque", LIMIT, LO, HI, 0.3).ctrl_into(a, out)
    assert out[0] == -30.0 and out[-1] == 90.0
    np.testing.assert_allclose(out, [a[i] * LIMIT[i] for i in range(12)], rtol=0, atol=1e-12)


def test_joint_pd_mode_commands_the_standing_pose_plus_the_scaled_action_within_the_ranges():
    m = ActionMap("joint_pd", LIMIT, LO, HI, 0.3)
    m.home_joints = np.full(12, 0.4)
    out = np.empty(12)
    a = np.zeros(12)
    a[0], a[1], a[2] = 1.0, -1.0, 0.5  # 0.4 + 0.3 = 0.7 -> 0.5 (range); 0.4 - 0.3 = 0.1; 0.4 + 0.15 = 0.55 -> 0.5
    m.ctrl_into(a, out)
    np.testing.assert_allclose(out[:3], [0.5, 0.1, 0.5], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(out[3:], 0.4)
