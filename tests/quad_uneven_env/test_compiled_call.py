"""quad_uneven_env.compiled_call: a kernel's entry point gives the dispatcher's results; the callers that keep one
(the env's measurement, the controller's lane) give the same outputs as the dispatcher's call."""

from __future__ import annotations

import numba as nb
import numpy as np

from quad_uneven_env.compiled_call import entry_point


@nb.njit(cache=False)
def _axpy_into(a, x, y, out):  # pragma: no cover - compiled
    for i in range(x.shape[0]):
        out[i] = a * x[i] + y[i]
    return out.shape[0]


def test_entry_point_equals_the_dispatcher_call():
    x, y = np.arange(5.0), np.linspace(-1.0, 1.0, 5)
    out_d, out_e = np.empty(5), np.empty(5)
    args = (0.3, x, y, out_d)
    assert entry_point(_axpy_into, args) is None  # not compiled for these types yet
    n = _axpy_into(*args)
    entry = entry_point(_axpy_into, args)
    assert entry is not None
    assert entry(0.3, x, y, out_e) == n
    np.testing.assert_array_equal(out_e, out_d)


def test_entry_point_is_per_type():
    x = np.arange(4.0)
    _axpy_into(1.0, x, x, np.empty(4))
    assert entry_point(_axpy_into, (1.0, x.astype(np.float32), x, np.empty(4))) is None
    assert entry_point(_axpy_into, (1.0, x[::2], x[::2], np.empty(2))) is None  # another layout
    assert entry_point(len, (x,)) is None  # not a numba dispatcher
    assert entry_point(_axpy_into, (object(), x, x, x)) is None  # nothing numba can type


def test_measurement_through_its_entry_point_equals_the_dispatcher_call():
    """StepMeasurement.update calls the kernel's entry point from its second call on: every buffer equals what a
    fresh StepMeasurement (first call: the dispatcher) measures on the same state."""
    import gymnasium as gym

    from quad_uneven_env.measurement import StepMeasurement

    env = gym.make("QuadUneven-v0", terrain="rough").unwrapped
    env.reset(seed=3)
    rng = np.random.default_rng(0)
    for _ in range(30):
        env.step(rng.uniform(-0.3, 0.3, 12))
        live = env._meas
        assert live._call is not None
        fresh = StepMeasurement(
            env.model, env.data, env.idx, env.robot.foot_radius, env._scan_B, env._fields,
            env.observation_space.low, env.observation_space.high,
        )  # fmt: skip
        fresh.mass = live.mass
        fresh.update(env.terrain.heightfield, env._prev_action, env.gait_period)
        for name in ("obs", "foot_forces", "foot_contact", "foot_points", "cog", "cog_acc", "feet_pos", "heights"):
            np.testing.assert_array_equal(getattr(live, name), getattr(fresh, name), err_msg=name)
        assert live.index == fresh.index or (np.isinf(live.index) and live.index == fresh.index)


def test_argument_type_is_the_dispatchers_type():
    from quad_uneven_env.compiled_call import argument_type

    x = np.arange(4.0)
    _axpy_into(1.0, x, x, np.empty(4))
    assert argument_type(_axpy_into, x) == nb.typeof(x)
    assert argument_type(_axpy_into, x[::2]) != argument_type(_axpy_into, x)
    assert argument_type(len, x) is None
    assert argument_type(_axpy_into, object()) != nb.typeof(x)


def test_a_new_terrain_keeps_the_measurements_entry_point_and_its_outputs(monkeypatch):
    """A reset draws a new terrain (a new heights array): the measurement keeps its entry point (the array's type is
    the same) instead of resolving it again (~0.2 ms: numba types every array of its arguments), and still measures
    what a fresh dispatcher call measures there."""
    import gymnasium as gym

    from quad_uneven_env import measurement
    from quad_uneven_env.measurement import StepMeasurement

    env = gym.make("QuadUneven-v0", terrain="rough").unwrapped
    env.reset(seed=0)
    env.step(np.zeros(12))
    entry, flat = env._meas._call[0], env._meas._call[1]
    resolved = []
    monkeypatch.setattr(measurement, "entry_point", lambda *a: resolved.append(a) or entry_point(*a))
    for seed in (1, 2):
        env.reset(seed=seed)
        env.step(np.full(12, 0.1))
        live = env._meas
        assert live._call[1] is env.terrain.heightfield.kernel_args[0] and live._call[1] is not flat
        assert live._call[0] is entry
        fresh = StepMeasurement(
            env.model, env.data, env.idx, env.robot.foot_radius, env._scan_B, env._fields,
            env.observation_space.low, env.observation_space.high,
        )  # fmt: skip
        fresh.mass = live.mass
        assert not resolved  # (before the fresh one below, which resolves its own)
        fresh.update(env.terrain.heightfield, env._prev_action, env.gait_period)
        resolved.clear()
        for name in ("obs", "heights", "foot_forces", "cog"):
            np.testing.assert_array_equal(getattr(live, name), getattr(fresh, name), err_msg=name)
