"""The env's ``course_frame`` option: the trunk's heading and sideways offset on the course, appended to the
observation; the default observation unchanged."""

from __future__ import annotations

import math

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import quad_uneven_env  # noqa: F401  (registers QuadUneven-v0)
from quad_uneven_env.observations import COURSE_LATERAL_LIMIT
from quad_uneven_env.spatial import yaw_of_quat


def make(**kwargs):
    kwargs.setdefault("terrain", "rough")
    return gym.make("QuadUneven-v0", **kwargs)


def test_the_fields_are_appended_after_the_default_layout():
    env, default = make(course_frame=True), make()
    s = env.unwrapped.observation_structure
    assert default.observation_space.shape == (134,) and env.observation_space.shape == (137,)
    assert (s["course_heading"].start, s["course_heading"].stop) == (134, 136)
    assert (s["course_lateral"].start, s["course_lateral"].stop) == (136, 137)
    for name, sl in default.unwrapped.observation_structure.items():
        assert s[name] == sl
    np.testing.assert_array_equal(env.observation_space.low[:134], default.observation_space.low)
    np.testing.assert_array_equal(env.observation_space.low[134:], [-1, -1, -COURSE_LATERAL_LIMIT])
    np.testing.assert_array_equal(env.observation_space.high[134:], [1, 1, COURSE_LATERAL_LIMIT])


def test_the_default_observation_is_unchanged_bit_for_bit():
    """Without the option (default or False) the observation is that of the default env; with it the first 134
    entries are that observation too, along the same actions."""
    a, b, c = make(), make(course_frame=False), make(course_frame=True)
    assert a.observation_space == b.observation_space
    obs = [e.reset(seed=5)[0] for e in (a, b, c)]
    rng = np.random.default_rng(0)
    for _ in range(15):
        np.testing.assert_array_equal(obs[0], obs[1])
        np.testing.assert_array_equal(obs[0], obs[2][:134])
        action = rng.uniform(-0.3, 0.3, 12)
        obs = [e.step(action)[0] for e in (a, b, c)]


def test_hand_computed_heading_and_offset():
    """Trunk yawed by 0.3 rad about z (quaternion w = cos 0.15, z = sin 0.15) and moved to y = 0.25 m: the fields
    hold sin 0.3 = 0.29552, cos 0.3 = 0.95534 and 0.25 m; at y = -12.5 m the offset clips to -10 m."""
    env = make(course_frame=True, terrain="flat")
    env.reset(seed=0)
    u = env.unwrapped
    s = u.observation_structure
    u.data.qpos[1] = 0.25
    u.data.qpos[3:7] = (math.cos(0.15), 0.0, 0.0, math.sin(0.15))
    mujoco.mj_forward(u.model, u.data)
    obs = u._measure().obs
    np.testing.assert_allclose(obs[s["course_heading"]], [0.29552, 0.95534], atol=1e-5)
    assert obs[s["course_lateral"]][0] == pytest.approx(0.25)
    u.data.qpos[1] = -12.5
    mujoco.mj_forward(u.model, u.data)
    assert u._measure().obs[s["course_lateral"]][0] == -COURSE_LATERAL_LIMIT


def test_the_fields_follow_the_measured_pose_while_walking():
    """Along an episode the fields are the base quaternion's yaw (sin, cos) and the base's y (spawn at y = 0)."""
    env = make(course_frame=True)
    obs, _ = env.reset(seed=2)
    u = env.unwrapped
    s = u.observation_structure
    np.testing.assert_allclose(obs[s["course_heading"]], [0.0, 1.0], atol=1e-6)
    assert abs(obs[s["course_lateral"]][0]) < 1e-6
    rng = np.random.default_rng(1)
    moved = 0.0
    for _ in range(20):
        obs, *_ = env.step(rng.uniform(-0.5, 0.5, 12))
        yaw = yaw_of_quat(u.data.qpos[3:7])
        np.testing.assert_allclose(obs[s["course_heading"]], [math.sin(yaw), math.cos(yaw)], atol=1e-6)
        assert obs[s["course_lateral"]][0] == pytest.approx(u.data.qpos[1], abs=1e-6)
        moved = max(moved, abs(yaw))
    assert moved > 1e-4  # the random torques turned the trunk: the check above saw a nonzero yaw


def test_a_command_is_refused_with_course_frame():
    with pytest.raises(ValueError, match=r"^course_frame must be False with a command"):
        make(course_frame=True, command={"vx": 0.1})


def test_observation_noise_has_a_scale_for_each_field():
    """A noise scale per field: the heading's entries move by at most 0.05, the offset by at most 0.02 m."""
    noise = {"course_heading": 0.05, "course_lateral": 0.02}
    noisy, clean = make(course_frame=True, randomization={"observation_noise": noise}), make(course_frame=True)
    a, _ = noisy.reset(seed=3)
    b, _ = clean.reset(seed=3)
    d = np.abs(a.astype(np.float64) - b)
    assert d[:134].max() == 0.0
    assert 0 < d[134:136].max() <= 0.05 + 1e-6 and 0 < d[136] <= 0.02 + 1e-6
