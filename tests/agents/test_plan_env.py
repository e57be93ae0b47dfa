"""QuadUnevenPlan-v0: a residual on the expert's plan, one step per gait cycle."""

from __future__ import annotations

import itertools

import gymnasium as gym
import numpy as np
import pytest

from agents.expert import ExpertConfig, attach_expert
from agents.rl.plan_config import PLAN_ACTIONS, PlanConfig, check_plan_action, cycle_config
from agents.rl.plan_env import PLAN_ENV_ID, PlanExpertEnv, make_plan_env
from agents.rl.plan_features import PLAN_FEATURE_FIELDS
from quad_uneven_env.env import QuadUnevenEnv


class Recorder(gym.Wrapper):
    """Records qpos and qvel after every control step."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.states: list[np.ndarray] = []

    def step(self, action):
        out = self.env.step(action)
        d = self.env.unwrapped.data
        self.states.append(np.concatenate([d.qpos, d.qvel]))
        return out


@pytest.mark.parametrize("randomization", [None, "hard"])
def test_zero_action_is_the_adaptive_expert_bit_for_bit(randomization):
    """Three cycles of the plan env with zero actions against the adaptive expert alone in QuadUneven-v0: the same
    qpos and qvel at every control step."""
    kwargs = {"terrain": "rough", "randomization": randomization}
    recorder = Recorder(QuadUnevenEnv(**kwargs))
    env = PlanExpertEnv(recorder, PlanConfig())
    assert env.expert.config.adaptation == "learned"
    env.reset(seed=5)
    steps = 0
    for _ in range(3):
        _, _, terminated, truncated, info = env.step(np.zeros(5, dtype=np.float32))
        steps += info["control_steps"]
        assert not (terminated or truncated)
    assert steps == len(recorder.states) > 300

    plain = QuadUnevenEnv(**kwargs)
    attach_expert(plain, ExpertConfig(adaptation="learned"))
    plain.reset(seed=5)
    zero = np.zeros(12)
    for k in range(steps):
        plain.step(zero)
        expected = np.concatenate([plain.data.qpos, plain.data.qvel])
        np.testing.assert_array_equal(recorder.states[k], expected, err_msg=f"control step {k}")


def test_one_step_is_one_gait_cycle_and_the_action_sets_the_plan():
    """From the second step on, the step's action plans the cycle the step walks: its epsilon and duration are the
    adjusted ones, and the step lasts that cycle."""
    env = make_plan_env(terrain="flat")
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.zeros(5))
    assert info["control_steps"] == 155  # 3.1 s at 50 Hz: the first cycle, planned at the reset
    action = np.array([0.0, 1.0, 1.0, 0.0, 0.0])  # cycle time x 1.3, epsilon x 1.5
    obs, _, _, _, info = env.step(action)
    plan = env.expert.planner.current
    assert plan.epsilon == pytest.approx(20.0 * 1.5)
    assert plan.duration == pytest.approx(0.65 * 6 + 0.13)
    # the step ends before the control step that reaches the cycle's end (7.13 s: inside [7.12, 7.14) s)
    assert info["control_steps"] == 201
    np.testing.assert_array_equal(info["plan_action"], action)
    np.testing.assert_array_equal(obs[env.observation_structure["plan_action"]], action.astype(np.float32))
    assert obs[env.observation_structure["plan_hold"]][0] == 0.0
    assert obs[env.observation_structure["plan_min_stability"]][0] > 0.0


def test_reward_is_the_sum_of_the_control_steps_terms():
    env = make_plan_env(terrain="rough")
    env.reset(seed=1)
    _, reward, _, _, info = env.step(np.full(5, 0.5))
    assert set(info["reward_terms"]) == {"forward_progress", "stability", "torque", "energy", "alive", "fall"}
    assert reward == pytest.approx(sum(info["reward_terms"].values()))
    assert info["reward_terms"]["alive"] == pytest.approx(info["control_steps"] * 0.5)


def test_cycle_config_against_hand_computed_settings():
    base = ExpertConfig()
    config = PlanConfig()
    assert cycle_config(base, np.zeros(5), config) is base
    adjusted = cycle_config(base, np.array([1.0, -1.0, -1.0, 1.0, -1.0]), config)
    assert adjusted.stride == pytest.approx(0.33 * 1.3)
    assert adjusted.durations == (0.35, 0.35, 0.35, 0.07, 0.35, 0.35, 0.35)
    assert adjusted.epsilon == pytest.approx(10.0)
    assert adjusted.cog_height == pytest.approx(0.37)
    assert adjusted.clearance == pytest.approx(0.02)
    # clipped into the planner's bounds: no negative clearance
    assert cycle_config(base, np.array([0, 0, 0, 0, -1.0]), PlanConfig(clearance_range=0.2)).clearance == 0.0
    assert [a.name for a in PLAN_ACTIONS] == ["stride", "cycle_time", "epsilon", "cog_height", "clearance"]


def test_observation_layout_covers_the_space():
    env = make_plan_env(terrain="flat")
    obs, info = env.reset(seed=0)
    ends = sorted((s.start, s.stop) for s in env.observation_structure.values())
    assert ends[0][0] == 0 and ends[-1][1] == env.observation_space.shape[0] == obs.shape[0]
    assert all(a[1] == b[0] for a, b in itertools.pairwise(ends))
    assert env.observation_structure["expert_failures"].stop == obs.shape[0]
    assert PLAN_FEATURE_FIELDS[0].name == "plan_action"
    assert info["control_steps"] == 0 and info["plan_action"].shape == (5,)
    strength = obs[env.observation_structure["expert_strength_gain"]]
    np.testing.assert_array_equal(strength, np.ones(12, dtype=np.float32))  # the learned gains start at 1


def test_truncated_after_max_control_steps():
    env = make_plan_env(terrain="flat", max_control_steps=200)
    env.reset(seed=0)
    _, _, _, truncated, info = env.step(np.zeros(5))
    assert not truncated and info["control_steps"] == 155
    _, _, _, truncated, info = env.step(np.zeros(5))
    assert truncated and info["control_steps"] == 45


def test_make_vec_stacks_the_infos_of_reset_and_step():
    envs = gym.make_vec(PLAN_ENV_ID, num_envs=2, vectorization_mode="sync", terrain="flat", max_control_steps=200)
    _, info = envs.reset(seed=[0, 1])
    assert info["plan_action"].shape == (2, 5) and info["control_steps"].tolist() == [0, 0]
    for _ in range(2):  # the second step truncates both episodes (200 control steps) and autoresets
        _, _, _, truncated, info = envs.step(np.zeros((2, 5), dtype=np.float32))
    assert truncated.all() and info["control_steps"].tolist() == [45, 45]
    assert info["reward_terms"]["forward_progress"].shape == (2,)
    envs.close()


@pytest.mark.filterwarnings("ignore:.*different from the unwrapped")
def test_gymnasium_env_checker():
    from gymnasium.utils.env_checker import check_env

    check_env(make_plan_env(terrain="rough", max_control_steps=400), skip_render_check=True)


def test_sb3_env_checker():
    from stable_baselines3.common.env_checker import check_env

    check_env(gym.make(PLAN_ENV_ID, terrain="rough", max_control_steps=400), warn=True)


def test_bad_input_is_named():
    with pytest.raises(ValueError, match=r"^PlanConfig\.stride_range must be"):
        PlanConfig(stride_range=2.0)
    with pytest.raises(ValueError, match=r"^PlanConfig\.expert\.adaptation must be one of"):
        PlanConfig.from_dict({"expert": {"adaptation": "hip"}})
    with pytest.raises(ValueError, match=r"^action must be 5 finite numbers"):
        check_plan_action([0.0, 1.0])
    with pytest.raises(ValueError, match=r"^action must be 5 finite numbers"):
        check_plan_action([0.0, np.nan, 0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="controller is not accepted"):
        make_plan_env(controller=lambda m, d, a: np.zeros(12))
    with pytest.raises(ValueError, match="not both"):
        make_plan_env(config=PlanConfig(), stride_range=0.1)
    with pytest.raises(ValueError, match=r"action_mode must be 'torque'"):
        PlanExpertEnv(QuadUnevenEnv(terrain="flat", action_mode="joint_pd"))
