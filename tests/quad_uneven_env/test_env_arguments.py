"""Every QuadUneven-v0 argument is checked at make time by type and range; the error names it and what it allows."""

from __future__ import annotations

import inspect

import gymnasium as gym
import numpy as np
import pytest

import quad_uneven_env  # noqa: F401
from quad_uneven_env.config import MAX_SCAN_POINTS
from quad_uneven_env.env import QuadUnevenEnv
from quad_uneven_env.env_config import EnvConfig
from quad_uneven_env.fields import params_of


def make(**kwargs):
    kwargs.setdefault("terrain", "flat")
    return gym.make("QuadUneven-v0", **kwargs)


BAD = [
    # (argument, value, text the message must hold)
    ("frame_skip", True, "frame_skip must be an integer in [1, 1000], got True of type bool"),
    ("frame_skip", 0, "frame_skip must be an integer in [1, 1000]"),
    ("frame_skip", 2.5, "frame_skip must be an integer"),
    ("frame_skip", "10", "frame_skip must be an integer in [1, 1000], got '10' of type str"),
    ("frame_skip", 10_000, "frame_skip must be an integer in [1, 1000]"),
    ("timestep", "abc", "timestep must be a number in (0, 0.002] (s), got 'abc' of type str"),
    ("timestep", True, "timestep must be a number in (0, 0.002] (s), got True of type bool"),
    ("timestep", 0.0, "timestep must be a number in (0, 0.002] (s)"),
    ("timestep", 0.01, "timestep must be a number in (0, 0.002] (s)"),
    ("timestep", float("nan"), "timestep must be a number in (0, 0.002] (s)"),
    ("gait_period", None, "gait_period must be a number in (0, 1000] (s), got None of type NoneType"),
    ("gait_period", 0.0, "gait_period must be a number in (0, 1000] (s)"),
    ("gait_period", float("inf"), "gait_period must be a number in (0, 1000] (s)"),
    ("pd_kp", [1, 2], "pd_kp must be a number in (0, 100000] (N m/rad), got [1, 2] of type list"),
    ("pd_kp", 0.0, "pd_kp must be a number in (0, 100000]"),
    ("pd_kd", -1.0, "pd_kd must be a number in [0, 10000] (N m s/rad)"),
    ("pd_kd", False, "pd_kd must be a number in [0, 10000] (N m s/rad), got False of type bool"),
    ("pd_action_scale", 0.0, "pd_action_scale must be a number in (0, 3.14159] (rad)"),
    ("reset_noise_scale", -0.1, "reset_noise_scale must be a number in [0, 1] (rad, rad/s)"),
    ("reset_noise_scale", 5.0, "reset_noise_scale must be a number in [0, 1]"),
    ("action_mode", "velocity", "action_mode must be one of ['torque', 'joint_pd'], got 'velocity'"),
    ("action_mode", None, "action_mode must be one of ['torque', 'joint_pd'], got None"),
    ("render_mode", "window", "render_mode must be one of ['human', 'rgb_array', 'depth_array'] or null"),
    ("render_mode", 1, "render_mode must be one of"),
    ("width", 0, "width must be an integer in [1, 4096] (px)"),
    ("width", True, "width must be an integer in [1, 4096] (px), got True of type bool"),
    ("height", 5000, "height must be an integer in [1, 4096] (px)"),
    ("height", "480", "height must be an integer in [1, 4096] (px), got '480' of type str"),
    ("episode_step_cap", 0, "episode_step_cap must be an integer in [1, 1e+09]"),
    ("episode_step_cap", True, "episode_step_cap must be an integer in [1, 1e+09], got True of type bool"),
    ("episode_step_cap", 1.5, "episode_step_cap must be an integer"),
    ("robot", 5, "robot must be a config name or a .yaml path, got 5 of type int"),
    ("robot", None, "robot must be a config name or a .yaml path, got None"),
    ("controller", 5, "controller must be None or a callable"),
    ("terrain", 5, "terrain spec must be None, a kind name"),
    ("reward_weights", {"alive": "abc"}, "reward_weights.alive must be a number in (-inf, inf), got 'abc' of type str"),
    ("reward_weights", {"alive": True}, "reward_weights.alive must be a number in (-inf, inf), got True of type bool"),
    ("reward_weights", {"stability_scale": 0}, "reward_weights.stability_scale must be a number in (0, 1] (m), got 0"),
    ("reward_weights", {"speed": 1.0}, "reward_weights: unknown field(s) ['speed']"),
    ("reward_weights", "fast", "reward_weights must be a mapping"),
    ("termination", {"max_tilt_deg": 360}, "termination.max_tilt_deg must be a number in (0, 180] (deg), got 360"),
    ("termination", {"max_tilt_deg": 1e9}, "termination.max_tilt_deg must be a number in (0, 180] (deg)"),
    (
        "termination",
        {"min_base_height": 0.5, "max_base_height": 0.3},
        "termination.min_base_height must be < max_base_height=0.3, got 0.5",
    ),
    ("termination", {"trunk_contact": "false"}, "termination.trunk_contact must be true or false, got 'false'"),
    ("termination", {"min_base_height": None}, "termination.min_base_height must be a number in [0, 2] (m)"),
    ("height_scan", {"resolution": 0}, "height_scan.resolution must be a number in [0.005, 1] (m), got 0"),
    ("randomization", {"friction": [0.8, 0.4]}, "randomization.friction must be null or a [low, high] pair"),
    ("randomization", "nonsense", "randomization: unknown randomization config 'nonsense'"),
    ("randomization", {"bogus": 1}, "randomization: unknown field(s) ['bogus']"),
    ("command", {"vx": 5.0}, "command.vx must be a number in [-1, 1] (m/s), got 5.0"),
    ("command", "fast", "command must be None or a mapping"),
    ("course_frame", 1, "course_frame must be true or false, got 1 of type int"),
    ("course_frame", "yes", "course_frame must be true or false, got 'yes' of type str"),
    ("proprio_history", -1, "proprio_history must be an integer in [0, 50] (control steps), got -1"),
    ("proprio_history", 51, "proprio_history must be an integer in [0, 50] (control steps), got 51"),
    ("proprio_history", True, "proprio_history must be an integer in [0, 50] (control steps), got True of type bool"),
    ("height_scan", {"size_x": "1"}, "height_scan.size_x must be a number in [0, 10] (m), got '1' of type str"),
    (
        "height_scan",
        {"size_x": 10.0, "size_y": 10.0, "resolution": 0.1},
        f"height_scan.resolution must give at most {MAX_SCAN_POINTS} points, got 101 x 101",
    ),
]


@pytest.mark.parametrize("name, value, message", BAD, ids=[f"{n}={v!r}" for n, v, _ in BAD])
def test_a_bad_argument_raises_at_make_naming_it(name, value, message):
    # gym.make itself fails on a render_mode that is not a string (AttributeError): build the class there.
    build = QuadUnevenEnv if name == "render_mode" and not isinstance(value, str) else make
    with pytest.raises(ValueError) as err:
        build(**{name: value})
    assert message in str(err.value)
    assert "\n" not in str(err.value)


def test_the_bad_argument_list_covers_every_scalar_argument():
    assert {q.name for q in params_of(EnvConfig)} <= {name for name, _, _ in BAD}
    assert set(inspect.signature(QuadUnevenEnv).parameters) == {name for name, _, _ in BAD}


@pytest.mark.parametrize(
    "kwargs",
    [
        {"frame_skip": 1},
        {"frame_skip": np.int64(2)},
        {"frame_skip": 2.0},  # an integral float is an integer
        {"timestep": 0.002, "frame_skip": 1000},
        {"timestep": np.float32(0.001)},
        {"pd_kd": 0, "reset_noise_scale": 0, "action_mode": "joint_pd"},
        {"width": 4096, "height": 1, "render_mode": "rgb_array"},
        {"episode_step_cap": 1},
        {"height_scan": {"size_x": 9.9, "size_y": 9.9, "resolution": 0.1}},  # 100 x 100 points: the cap exactly
        {"termination": {"max_tilt_deg": 180, "trunk_contact": np.bool_(False)}},
    ],
)
def test_boundary_values_are_accepted(kwargs):
    env = make(**kwargs)
    env.reset(seed=0)
    env.step(np.zeros(12))
    u = env.unwrapped
    assert isinstance(u.frame_skip, int) and isinstance(u.episode_step_cap, int)


def test_the_height_scan_cap_bounds_the_observation():
    u = make(height_scan={"size_x": 9.9, "size_y": 9.9, "resolution": 0.1}).unwrapped
    st = u.observation_structure["height_scan"]
    assert st.stop - st.start == MAX_SCAN_POINTS


def test_rendering_larger_than_the_default_offscreen_buffer():
    env = make(render_mode="rgb_array", width=1500, height=800)
    env.reset(seed=0)
    frame = env.render()
    env.close()
    assert frame.shape == (800, 1500, 3) and frame.std() > 1


@pytest.mark.parametrize("seed", [True, False, np.bool_(True), -1, 1.5, "1", [1]])
def test_reset_refuses_a_seed_that_is_not_a_non_negative_integer(seed):
    env = make()
    with pytest.raises(ValueError, match=r"seed must be None or an integer >= 0, got .* of type"):
        env.reset(seed=seed)


def test_a_numpy_integer_seed_is_the_same_seed():
    env = make(terrain="rough")
    a, _ = env.reset(seed=np.int64(3))
    ha = env.unwrapped.terrain.heightfield.heights.copy()
    b, _ = env.reset(seed=3)
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(ha, env.unwrapped.terrain.heightfield.heights)


def test_the_docstring_lists_every_scalar_argument():
    doc = QuadUnevenEnv.__doc__
    for q in params_of(EnvConfig):
        assert f"| ``{q.name}`` |" in doc and q.allowed() in doc
