"""The env's boundary: arrays of the wrong kind are refused naming the argument, a controller cannot change the
step's action or smuggle bad torques through its fast lane, and what it changes in the model ends with the
episode."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import quad_uneven_env  # noqa: F401
from quad_uneven_env.env import QuadUnevenEnv


class _Hold:
    """Zero torques through the call; ``mutate(model, data, action)`` runs first."""

    def __init__(self, mutate=None):
        self.mutate = mutate

    def __call__(self, model, data, action):
        if self.mutate is not None:
            self.mutate(model, data, action)
        return np.zeros(12)


class _Lane(_Hold):
    """A fast lane that writes ``value`` into the torques and returns ``result``."""

    def __init__(self, value, result=True):
        super().__init__()
        self.value, self.result = value, result

    def torques_into(self, model, data, action, out, limit):
        out[:] = self.value
        return self.result


@pytest.mark.parametrize(
    "action", [np.full(12, 0.1 + 0.1j), np.array(["0.1"] * 12), np.zeros(12, dtype=bool), np.array([None] * 12)]
)
def test_actions_of_another_kind_than_real_numbers_are_refused(action):
    env = gym.make("QuadUneven-v0", terrain="flat")
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"action must hold real numbers .*dtype"):
        env.step(action)


def test_integer_actions_are_numbers():
    env = gym.make("QuadUneven-v0", terrain="flat")
    env.reset(seed=0)
    env.step(np.zeros(12, dtype=np.int64))


def test_step_before_reset_is_refused():
    env = QuadUnevenEnv(terrain="flat")
    with pytest.raises(gym.error.ResetNeeded, match="reset before step"):
        env.step(np.zeros(12))


def test_a_controller_cannot_write_nan_into_the_action():
    def poison(model, data, action):
        action[:] = np.nan

    env = gym.make("QuadUneven-v0", terrain="flat", controller=_Hold(poison))
    env.reset(seed=0)
    obs, _, terminated, _, info = env.step(np.zeros(12, dtype=np.float32))
    assert terminated and info["diverged"] and "read-only" in info["termination_reason"]
    assert env.observation_space.contains(obs) and np.all(np.isfinite(obs))


@pytest.mark.parametrize(
    "value, result, reason",
    [
        (np.nan, True, "non-finite torques"),
        (np.inf, True, "non-finite torques"),
        (0.0, 1, "not True or False"),
        (0.0, "yes", "not True or False"),
    ],
)
def test_the_fast_lane_is_checked_like_the_call(value, result, reason):
    env = gym.make("QuadUneven-v0", terrain="flat", controller=_Lane(value, result))
    env.reset(seed=0)
    _, _, terminated, _, info = env.step(np.zeros(12, dtype=np.float32))
    assert terminated and info["diverged"] and reason in info["termination_reason"]


def test_the_fast_lane_torques_are_clipped_to_the_motors():
    env = gym.make("QuadUneven-v0", terrain="flat", controller=_Lane(1e4, np.bool_(True)))
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.zeros(12, dtype=np.float32))
    assert not info["diverged"]
    u = env.unwrapped
    np.testing.assert_array_equal(u.data.ctrl, u.idx.torque_limit)


def test_a_controller_hook_that_is_not_a_method_is_refused_at_make():
    controller = _Hold()
    controller.reset = "not callable"
    with pytest.raises(ValueError, match=r"controller\.reset must be a method"):
        gym.make("QuadUneven-v0", terrain="flat", controller=controller)


def test_what_a_controller_changes_in_the_model_ends_with_the_episode():
    def tamper(model, data, action):
        model.body_mass[1] = 1e9
        model.opt.timestep = 0.0

    env = gym.make("QuadUneven-v0", terrain="flat", randomization="hard")
    env.reset(seed=3)
    u = env.unwrapped
    mass, step = u.model.body_mass.copy(), u.model.opt.timestep
    first, _ = env.reset(seed=4)
    u.set_controller(_Hold(tamper))
    env.step(np.zeros(12, dtype=np.float32))
    assert u.model.body_mass[1] == 1e9 and u.model.opt.timestep == 0.0
    u.set_controller(None)
    again, _ = env.reset(seed=4)
    np.testing.assert_array_equal(again, first)
    assert u.model.opt.timestep == step
    env.reset(seed=3)
    np.testing.assert_array_equal(u.model.body_mass, mass)


def test_model_changes_made_before_the_first_reset_last_for_every_episode():
    env = gym.make("QuadUneven-v0", terrain="flat")
    env.unwrapped.model.geom_friction[:, 0] = 0.4
    for seed in (0, 1):
        env.reset(seed=seed)
        assert np.all(env.unwrapped.model.geom_friction[:, 0] == 0.4)


@pytest.mark.parametrize(
    "heights", [np.full((20, 20), 1 + 0j), np.full((20, 20), "0.0"), np.zeros((20, 20), dtype=bool)]
)
def test_heightmaps_of_another_kind_than_real_numbers_are_refused(heights):
    with pytest.raises(ValueError, match=r"heights must hold real numbers"):
        gym.make("QuadUneven-v0", terrain={"kind": "heightmap", "heights": heights})


def test_a_heightmap_placed_twice_is_refused():
    heights = np.zeros((40, 40))
    with pytest.raises(ValueError, match="origin and x_start both place the grid"):
        gym.make("QuadUneven-v0", terrain={"kind": "heightmap", "heights": heights, "origin": [-1, -1], "x_start": -1})
