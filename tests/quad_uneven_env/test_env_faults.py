"""Faults inside a control step end the episode with a reason, never an exception, and undo the step."""

from __future__ import annotations

import os
import subprocess
import sys

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import quad_uneven_env  # noqa: F401


def make(**kwargs):
    kwargs.setdefault("terrain", "flat")
    return gym.make("QuadUneven-v0", **kwargs)


def hold(model, data, action):
    """A controller that works: a PD hold of the joints, 12 finite torques."""
    return -50.0 * data.qvel[6:]


def snapshot(d: mujoco.MjData) -> dict[str, np.ndarray]:
    return {"time": np.array(d.time), "qpos": d.qpos.copy(), "qvel": d.qvel.copy(), "ctrl": d.ctrl.copy()}


def assert_same_state(d: mujoco.MjData, before: dict[str, np.ndarray]) -> None:
    now = snapshot(d)
    for key, value in before.items():
        np.testing.assert_array_equal(now[key], value, err_msg=key)


class FailOnCall:
    """Works for ``n_good`` calls, then fails with ``failure`` (a callable returning the bad value or raising)."""

    def __init__(self, n_good: int, failure):
        self.n_good, self.failure, self.calls = n_good, failure, 0

    def __call__(self, model, data, action):
        self.calls += 1
        if self.calls > self.n_good:
            return self.failure()
        return hold(model, data, action)


def _raise(exc):
    def f():
        raise exc

    return f


class Weird:
    def __array__(self, *args, **kwargs):
        raise RuntimeError("no array here")


FAILURES = {
    "RuntimeError": (_raise(RuntimeError("boom")), "raised RuntimeError: boom"),
    "KeyError": (_raise(KeyError("HAA")), "raised KeyError"),
    "ZeroDivisionError": (_raise(ZeroDivisionError("division by zero")), "raised ZeroDivisionError"),
    "LinAlgError": (_raise(np.linalg.LinAlgError("Singular matrix")), "raised LinAlgError"),
    "custom Exception": (_raise(type("PlannerGaveUp", (Exception,), {})("no plan")), "raised PlannerGaveUp"),
    "string": (lambda: "torques", "returned 'torques' of type str"),
    "dict": (lambda: {"LF_HAA": 1.0}, "of type dict"),
    "None": (lambda: None, "returned None of type NoneType"),
    "wrong shape": (lambda: np.zeros(3), "an array of shape (3,)"),
    "column": (lambda: np.zeros((12, 1)), "an array of shape (12, 1)"),
    "short list": (lambda: [0.0] * 11, "of type list"),
    "ragged list": (lambda: [[0.0], [0.0, 1.0]], "of type list"),
    "bools": (lambda: np.ones(12, dtype=bool), "dtype bool"),
    "complex": (lambda: np.ones(12, dtype=complex), "dtype complex128"),
    "strings in a list": (lambda: ["1"] * 12, "of type list"),
    "bad __array__": (lambda: Weird(), "of type Weird"),
    "NaN": (lambda: np.full(12, np.nan), "non-finite torques"),
    "Inf in float32": (lambda: np.r_[np.zeros(11), np.inf].astype(np.float32), "non-finite torques"),
}


@pytest.mark.parametrize("name", list(FAILURES))
@pytest.mark.parametrize("n_good", [0, 4])  # fails on the first physics step, or in the middle of the control step
def test_controller_failure_ends_the_episode_and_undoes_the_step(name, n_good):
    failure, expected = FAILURES[name]
    env = make(controller=hold)
    u = env.unwrapped
    env.reset(seed=0)
    obs1, *_ = env.step(np.zeros(12))  # one good control step: t = 0.02 s
    before = snapshot(u.data)
    u.set_controller(FailOnCall(n_good, failure))
    obs, reward, terminated, truncated, info = env.step(np.zeros(12))  # never raises
    assert terminated and not truncated and info["diverged"]
    assert info["termination_reason"].startswith("diverged: controller") and expected in info["termination_reason"]
    assert np.isfinite(reward) and reward < 0 and np.isfinite(obs).all()
    # None of the control step happened: state and time as before it; the observation is that state's.
    assert_same_state(u.data, before)
    np.testing.assert_array_equal(obs, obs1)
    # The next (good) control step is a whole one: it ends at t = 0.04 s.
    u.set_controller(hold)
    env.step(np.zeros(12))
    assert u.data.time == pytest.approx(2 * u.dt, abs=1e-12)


def test_an_undone_step_leaves_nothing_behind():
    """Good, failed, good gives bit for bit the trajectory of good, good (warm start and all)."""

    def run(with_failure: bool) -> np.ndarray:
        env = make(terrain="rough", controller=hold)
        u = env.unwrapped
        env.reset(seed=4)
        env.step(np.full(12, 0.1))
        if with_failure:
            u.set_controller(FailOnCall(7, _raise(RuntimeError("late failure"))))
            assert env.step(np.full(12, 0.3))[4]["diverged"]
            u.set_controller(hold)
        for _ in range(5):
            obs, *_ = env.step(np.full(12, 0.2))
        return np.concatenate([obs, u.data.qpos, u.data.qvel, [u.data.time]])

    np.testing.assert_array_equal(run(True), run(False))


def test_a_mujoco_divergence_inside_the_controller_loop_is_undone():
    def blow_up(model, data, action):
        data.qvel[:] = 1e30  # the controller corrupts the state: MuJoCo flags it at the next physics step
        return np.zeros(12)

    env = make(controller=hold)
    u = env.unwrapped
    env.reset(seed=0)
    before = snapshot(u.data)
    u.set_controller(blow_up)
    _, reward, terminated, _, info = env.step(np.zeros(12))
    assert terminated and info["diverged"] and "MuJoCo reported a bad" in info["termination_reason"]
    assert np.isfinite(reward)
    assert_same_state(u.data, before)


def test_a_mujoco_divergence_without_a_controller_is_undone():
    env = make()
    u = env.unwrapped
    obs0, _ = env.reset(seed=0)
    u.data.ctrl[:] = 0.0
    u.model.opt.timestep = 1e3  # an absurd step: MuJoCo's state blows up within the control step
    before = snapshot(u.data)
    obs, reward, terminated, _, info = env.step(np.ones(12))
    assert terminated and info["diverged"] and np.isfinite(reward)
    assert_same_state(u.data, before)
    np.testing.assert_array_equal(obs, obs0)


def test_a_mujoco_error_is_a_divergence(monkeypatch):
    env = make()
    u = env.unwrapped
    env.reset(seed=0)
    before = snapshot(u.data)

    def fatal(*args):
        raise mujoco.FatalError("mj_stackAlloc: insufficient memory")

    monkeypatch.setattr(mujoco, "mj_step", fatal)
    _, reward, terminated, _, info = env.step(np.zeros(12))
    monkeypatch.undo()
    assert terminated and info["diverged"] and "FatalError" in info["termination_reason"]
    assert np.isfinite(reward)
    assert_same_state(u.data, before)


def test_a_measurement_error_is_a_divergence(monkeypatch):
    env = make()
    u = env.unwrapped
    env.reset(seed=0)

    def broken(*args):
        raise IndexError("index 7 is out of bounds")

    monkeypatch.setattr(u._meas, "update", broken)
    _, reward, terminated, _, info = env.step(np.zeros(12))
    assert terminated and info["diverged"] and "measurement failed (IndexError" in info["termination_reason"]
    assert np.isfinite(reward)


def test_keyboard_interrupt_in_a_controller_propagates_from_a_whole_step_state():
    env = make(controller=hold)
    u = env.unwrapped
    env.reset(seed=0)
    before = snapshot(u.data)
    u.set_controller(FailOnCall(3, _raise(KeyboardInterrupt())))
    with pytest.raises(KeyboardInterrupt):
        env.step(np.zeros(12))
    assert_same_state(u.data, before)


# ---------------------------------------------------------------------------- joint_pd and controllers
def test_joint_pd_refuses_a_physics_rate_controller():
    with pytest.raises(ValueError, match=r"controller must be None with action_mode='joint_pd'.*action_mode='torque'"):
        make(action_mode="joint_pd", controller=hold)
    env = make(action_mode="joint_pd")
    with pytest.raises(ValueError, match="controller must be None with action_mode='joint_pd'"):
        env.unwrapped.set_controller(hold)
    assert env.unwrapped.controller is None
    env.unwrapped.set_controller(None)  # removing one is fine


def test_torque_mode_applies_a_controllers_torques_as_torques():
    env = make(controller=lambda m, d, a: np.full(12, 50.0))
    env.reset(seed=0)
    env.step(np.zeros(12))
    u = env.unwrapped
    np.testing.assert_allclose(u.data.actuator_force, np.minimum(50.0, u.idx.torque_limit))


@pytest.mark.parametrize("bad", [5, "expert", np.zeros(12)])
def test_a_controller_must_be_callable(bad):
    with pytest.raises(ValueError, match="controller must be None or a callable"):
        make(controller=bad)
    env = make()
    with pytest.raises(ValueError, match="controller must be None or a callable"):
        env.unwrapped.set_controller(bad)


# ---------------------------------------------------------------------------- caps and early checks
def test_the_env_truncates_at_its_step_cap_whatever_the_time_limit():
    env = make(action_mode="joint_pd", episode_step_cap=3, max_episode_steps=10**12)
    env.reset(seed=0)
    flags = [env.step(np.zeros(12))[2:4] for _ in range(3)]
    assert flags == [(False, False), (False, False), (False, True)]
    env.reset(seed=0)  # a new episode, a new count
    *_, truncated, info = env.step(np.zeros(12))
    assert not truncated and info["termination_reason"] is None


def test_the_step_cap_reason_is_reported():
    env = make(action_mode="joint_pd", episode_step_cap=1)
    env.reset(seed=0)
    *_, terminated, truncated, info = env.step(np.zeros(12))
    assert truncated and not terminated and info["termination_reason"].startswith("step cap: 1 control steps")


def test_human_rendering_without_a_display_warns_at_the_first_render_and_opens_no_window():
    """In a child process (GLFW would abort the whole process): make, reset, step and render work, one warning says
    why no window opens, GLFW is never imported, and Gymnasium's own checker passes with every declared mode."""
    code = (
        "import sys, warnings, numpy as np, gymnasium as gym, quad_uneven_env\n"
        "from gymnasium.utils.env_checker import check_env\n"
        "env = gym.make('QuadUneven-v0', terrain='flat', render_mode='human')\n"
        "env.reset(seed=0)\n"
        "with warnings.catch_warnings(record=True) as caught:\n"
        "    warnings.simplefilter('always')\n"
        "    env.step(np.zeros(12, dtype=np.float32)); env.step(np.zeros(12, dtype=np.float32))\n"
        "    print('render:', env.render())\n"
        "print('warnings:', [str(w.message) for w in caught])\n"
        "print('glfw loaded:', 'glfw' in sys.modules)\n"
        "check_env(gym.make('QuadUneven-v0', terrain='flat').unwrapped)\n"
        "print('checker passed')\n"
    )
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]
    assert "render: None" in out.stdout
    (warned,) = [line for line in out.stdout.splitlines() if line.startswith("warnings:")]
    assert warned.count("needs a display") == 1 and "rgb_array" in warned
    assert "glfw loaded: False" in out.stdout and "checker passed" in out.stdout


class _Laned:
    """A PD hold with a fast lane: every other physics step the lane writes the torques, 50 N m beyond the
    motors' limit so the env's clip shows; ``fail`` makes the lane raise or decline instead."""

    def __init__(self, fail: str = ""):
        self.fail, self.lane_steps, self.calls, self.seen = fail, 0, 0, 0

    def __call__(self, model, data, action):
        self.calls += 1
        return hold(model, data, action)

    def torques_into(self, model, data, action, out, limit):
        self.seen += 1
        if self.seen % 2 or self.fail == "decline":
            return False
        if self.fail == "raise":
            raise RuntimeError("lane bug")
        out[:] = np.clip(hold(model, data, None) + 50.0 * np.sign(hold(model, data, None)), -limit, limit)
        self.lane_steps += 1
        return True


def test_a_fast_lane_replaces_the_call_only_where_it_answers():
    """Where the lane returns True its torques are applied (clipped by it, as the protocol asks) and the call is
    not made; where it declines or raises the call runs, and the step is the one the call alone would give."""
    runs = {}
    for fail in ("", "decline", "raise"):
        ctrl = _Laned(fail)
        env = make(terrain="rough", controller=ctrl)
        env.reset(seed=0)
        d = env.unwrapped.data
        applied = []
        for _ in range(3):
            _, _, fell, _, info = env.step(np.zeros(12))
            assert not fell and info["termination_reason"] is None
            applied.append(d.ctrl.copy())
        runs[fail] = (np.array(applied), snapshot(d), ctrl)
    laned = runs[""][2]
    assert laned.lane_steps == 15 and laned.calls == 15 and laned.seen == 30
    assert np.abs(runs[""][0]).max() == pytest.approx(env.unwrapped.idx.torque_limit.max())
    for fail in ("decline", "raise"):
        assert runs[fail][2].calls == 30 and runs[fail][2].lane_steps == 0
        np.testing.assert_array_equal(runs[fail][0], runs["decline"][0])
    assert not np.array_equal(runs[""][0], runs["decline"][0])


def test_mujoco_warnings_go_to_the_logger_not_to_a_file_in_the_working_directory(tmp_path):
    """A diverging step (MuJoCo warns of a NaN) in a child process started in an empty folder: the warning reaches
    the "mujoco" logger, the episode ends as diverged, and no MUJOCO_LOG.TXT appears."""
    code = (
        "import logging, numpy as np, gymnasium as gym, quad_uneven_env\n"
        "records = []\n"
        "handler = type('H', (logging.Handler,), {'emit': lambda s, r: records.append(r)})()\n"
        "logging.getLogger('mujoco').addHandler(handler)\n"
        "logging.getLogger('mujoco').setLevel(logging.INFO)\n"
        "env = gym.make('QuadUneven-v0', terrain='flat')\n"
        "env.reset(seed=0)\n"
        "env.unwrapped.data.qvel[6] = 1e12\n"
        "obs, r, term, trunc, info = env.step(np.zeros(12, dtype=np.float32))\n"
        "print('diverged:', info['diverged'], 'logged:', len(records))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    assert "diverged: True logged:" in out.stdout and "logged: 0" not in out.stdout
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()
