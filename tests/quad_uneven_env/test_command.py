"""QuadUneven-v0(command=...): validation, the observation field, info, resampling, seeding, tracking rewards."""

from __future__ import annotations

import math
import warnings

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import quad_uneven_env  # noqa: F401
from quad_uneven_env.command import CommandConfig, CommandSchedule, load_command
from quad_uneven_env.config import RewardWeights
from quad_uneven_env.rewards import COMMAND_REWARD_TERMS, REWARD_TERMS, command_reward_terms

RANGES = {"vx": [-0.2, 0.2], "vy": [-0.1, 0.1], "yaw_rate": [-0.3, 0.3]}


def make(**kwargs):
    kwargs.setdefault("terrain", "flat")
    return gym.make("QuadUneven-v0", **kwargs)


def rollout(env, seed, steps, actions_seed=5):
    """Observations, rewards and infos of ``steps`` random-action steps after ``reset(seed)``."""
    rng = np.random.default_rng(actions_seed)
    obs, info = env.reset(seed=seed)
    out = [(obs, 0.0, info)]
    for _ in range(steps):
        obs, rew, term, trunc, info = env.step(rng.uniform(-0.3, 0.3, 12).astype(np.float32))
        out.append((obs, rew, info))
        if term or trunc:
            obs, info = env.reset()
            out.append((obs, 0.0, info))
    return out


# ---------------------------------------------------------------------------- config
def test_fixed_and_ranged_configs():
    fixed = load_command({"vx": 0.1})
    assert not fixed.drawn and fixed.fixed.tolist() == [0.1, 0.0, 0.0]
    drawn = load_command({"ranges": RANGES, "resample_interval": 5})
    assert drawn.drawn and drawn.ranges.vy == (-0.1, 0.1) and drawn.resample_interval == 5.0
    mixed = load_command({"vx": 0.05, "ranges": {"yaw_rate": [-0.3, 0.3]}})
    assert mixed.ranges.vx is None and mixed.vx == 0.05
    assert load_command(None) is None and load_command(fixed) is fixed


@pytest.mark.parametrize(
    ("raw", "match"),
    [
        ({"vx": 3.0}, r"command\.vx must be a number in \[-1, 1\] \(m/s\), got 3\.0"),
        ({"vx": True}, r"command\.vx must be a number"),
        ({"yaw_rate": float("nan")}, r"command\.yaw_rate must be a number in \[-2, 2\]"),
        (
            {"speed": 0.1},
            r"command: unknown field\(s\) \['speed'\]; allowed: \['heading', 'heading_gain', 'heading_max_yaw_rate', "
            r"'ranges', 'resample_interval'",
        ),
        (
            {"ranges": {"vz": [0, 1]}},
            r"command\.ranges: unknown field\(s\) \['vz'\]; allowed: \['heading', 'vx', 'vy', 'yaw_rate'\]",
        ),
        ({"ranges": {"vx": [0.2, -0.2]}}, r"command\.ranges\.vx must be null or a \[low, high\] pair with low <= high"),
        ({"ranges": {"vy": [0.0, 2.0]}}, r"command\.ranges\.vy must be .* in \[-1, 1\]"),
        (
            {"ranges": [0.1, 0.2]},
            r"command\.ranges must be a mapping with keys from \['vx', 'vy', 'yaw_rate', 'heading'\]",
        ),
        (
            {"resample_interval": 0.0},
            r"command\.resample_interval must be a number in \(0, inf\) or null \(s\), got 0\.0",
        ),
        ({"vx": 0.1, "ranges": {"vx": [0, 0.2]}}, r"command\.vx must not be given with command\.ranges\.vx"),
        ([0.1, 0.0, 0.0], r"command must be None or a mapping"),
    ],
)
def test_bad_commands_name_the_field(raw, match):
    with pytest.raises(ValueError, match=match):
        make(command=raw)


def test_tracking_weights_need_a_command():
    with pytest.raises(ValueError, match=r"reward_weights\.command_tracking_lin must be 0 without a command"):
        make(reward_weights={"command_tracking_lin": 1.0})
    with pytest.raises(ValueError, match=r"reward_weights\.command_sigma_yaw must be a number in \(0, 10\]"):
        make(command={"vx": 0.1}, reward_weights={"command_sigma_yaw": 0.0})


# ---------------------------------------------------------------------------- the default is unchanged
def test_without_command_nothing_changes_and_the_command_perturbs_nothing_else():
    """command=None is the old env exactly; a command (tracking weights 0) only appends its field and keys."""
    plain = rollout(make(terrain="rough"), seed=11, steps=60)
    none = rollout(make(terrain="rough", command=None), seed=11, steps=60)
    commanded_env = make(terrain="rough", command={"ranges": RANGES, "resample_interval": 0.2})
    commanded = rollout(commanded_env, seed=11, steps=60)
    n = plain[0][0].shape[0]
    assert commanded[0][0].shape[0] == n + 3
    assert commanded_env.unwrapped.observation_structure["command"] == slice(n, n + 3)
    for (o1, r1, i1), (o2, r2, i2), (o3, r3, i3) in zip(plain, none, commanded, strict=True):
        assert o1.tobytes() == o2.tobytes() == o3[:n].tobytes()
        assert r1 == r2 == r3
        assert set(i2) == set(i1) and "command" not in i1 and set(i3) == set(i1) | {"command"}
        assert list(i3["reward_terms"]) == [*REWARD_TERMS, *COMMAND_REWARD_TERMS]
        assert list(i1["reward_terms"]) == list(REWARD_TERMS)
        for key in i1:
            if key == "reward_terms":
                assert {k: i3[key][k] for k in REWARD_TERMS} == i1[key]
            else:
                np.testing.assert_array_equal(np.asarray(i1[key]), np.asarray(i3[key]), err_msg=key)


def test_randomized_world_is_the_same_with_a_command():
    a = make(terrain="rough", randomization="mild")
    b = make(terrain="rough", randomization="mild", command={"ranges": RANGES})
    for seed in (3, None, None):
        _, ia = a.reset(seed=seed)
        _, ib = b.reset(seed=seed)
        assert ia["randomization"] == ib["randomization"]


# ---------------------------------------------------------------------------- observation and info
def test_fixed_command_in_observation_and_info():
    env = make(command={"vx": 0.1, "vy": -0.05, "yaw_rate": 0.2})
    sl = env.unwrapped.observation_structure["command"]
    obs, info = env.reset(seed=0)
    for _ in range(3):
        np.testing.assert_array_equal(obs[sl], np.float32([0.1, -0.05, 0.2]))
        assert info["command"].shape == (3,) and info["command"].dtype == np.float64
        np.testing.assert_array_equal(info["command"], [0.1, -0.05, 0.2])
        obs, _, _, _, info = env.step(np.zeros(12, np.float32))
    assert env.observation_space.contains(obs)
    info["command"][:] = 9.0  # a copy: the env's command is untouched
    np.testing.assert_array_equal(env.unwrapped.command, [0.1, -0.05, 0.2])


def test_gymnasium_env_checker_with_a_drawn_command():
    from gymnasium.utils.env_checker import check_env

    env = make(terrain="rough", command={"ranges": RANGES, "resample_interval": 0.1})
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env.unwrapped, skip_render_check=True)


def test_make_vec_stacks_the_command_through_autoresets():
    envs = gym.make_vec(
        "QuadUneven-v0",
        num_envs=2,
        vectorization_mode="sync",
        terrain="rough",
        max_episode_steps=12,
        command={"ranges": RANGES, "resample_interval": 0.1},
    )
    try:
        obs, infos = envs.reset(seed=4)
        sl = envs.unwrapped.envs[0].unwrapped.observation_structure["command"]
        rng = np.random.default_rng(2)
        dones, seen = 0, set()
        for _ in range(30):
            assert infos["command"].shape == (2, 3) and infos["command"].dtype == np.float64
            np.testing.assert_allclose(obs[:, sl], infos["command"], atol=1e-7)
            seen.update(map(tuple, infos["command"].tolist()))
            obs, _, term, trunc, infos = envs.step(rng.uniform(-0.3, 0.3, (2, 12)).astype(np.float32))
            dones += int((term | trunc).sum())
        assert dones >= 4 and len(seen) > 10
        for c in seen:
            assert -0.2 <= c[0] <= 0.2 and -0.1 <= c[1] <= 0.1 and -0.3 <= c[2] <= 0.3
    finally:
        envs.close()


# ---------------------------------------------------------------------------- resampling and seeding
def test_resample_interval():
    """Control steps of 0.02 s, interval 0.1 s: new draws after steps 5, 10, 15, ... and never between."""
    env = make(command={"ranges": RANGES, "resample_interval": 0.1})
    _, info = env.reset(seed=1)
    history = [info["command"]]
    for _ in range(20):
        history.append(env.step(np.zeros(12, np.float32))[4]["command"])
    changed = [k for k in range(1, 21) if not np.array_equal(history[k], history[k - 1])]
    assert changed == [5, 10, 15, 20]


def test_drawn_once_without_interval_and_fixed_axes_stay():
    env = make(command={"vx": 0.07, "ranges": {"yaw_rate": [-0.3, 0.3]}, "resample_interval": None})
    _, info = env.reset(seed=2)
    first = info["command"]
    assert first[0] == 0.07 and first[1] == 0.0 and first[2] != 0.0
    for _ in range(30):
        np.testing.assert_array_equal(env.step(np.zeros(12, np.float32))[4]["command"], first)
    second = env.reset()[1]["command"]
    assert second[0] == 0.07 and second[2] != first[2]  # a new episode draws again


def test_same_seed_same_commands_different_seed_different_commands():
    cfg = {"ranges": RANGES, "resample_interval": 0.1}

    def commands(seed):
        env = make(command=cfg)
        _, info = env.reset(seed=seed)
        out = [info["command"]]
        out += [env.step(np.zeros(12, np.float32))[4]["command"] for _ in range(12)]
        out.append(env.reset()[1]["command"])
        return np.array(out)

    np.testing.assert_array_equal(commands(5), commands(5))
    assert not np.array_equal(commands(5)[0], commands(6)[0])


def test_schedule_skips_missed_resample_times():
    """A control period longer than the interval draws once per step, and the next time stays on the grid."""
    s = CommandSchedule(CommandConfig(ranges=load_command({"ranges": {"vx": [0, 1]}}).ranges, resample_interval=1.0))
    s.reset(np.random.default_rng(0))
    assert not s.update(0.99)
    assert s.update(3.5)  # 1, 2 and 3 s passed: one draw, the next at 4 s
    assert not s.update(3.99) and s.update(4.0)


# ---------------------------------------------------------------------------- tracking rewards
def test_tracking_terms_against_a_hand_computation():
    w = RewardWeights(command_tracking_lin=2.0, command_tracking_yaw=0.5, command_sigma_lin=0.1, command_sigma_yaw=0.2)
    terms = command_reward_terms(w, np.array([0.13, -0.04]), 0.1, np.array([0.1, 0.0, 0.3]))
    # |v - v_cmd|^2 = 0.03^2 + 0.04^2 = 0.0025 -> 2 exp(-0.25); (0.1 - 0.3)^2 = 0.04 -> 0.5 exp(-1)
    assert terms["command_tracking_lin"] == pytest.approx(2.0 * math.exp(-0.25), rel=1e-12)
    assert terms["command_tracking_yaw"] == pytest.approx(0.5 * math.exp(-1.0), rel=1e-12)


def test_env_tracking_terms_use_the_trunk_velocity_in_the_yaw_aligned_frame():
    weights = {"command_tracking_lin": 1.0, "command_tracking_yaw": 1.0}
    env = make(terrain="rough", command={"ranges": RANGES, "resample_interval": 0.06}, reward_weights=weights)
    base = env.unwrapped
    _, info = env.reset(seed=9)
    rng = np.random.default_rng(0)
    for _ in range(15):
        before = info["command"]
        _, reward, term, _, info = env.step(rng.uniform(-0.3, 0.3, 12).astype(np.float32))
        q, v = base.data.qpos, base.data.qvel
        w, x, y, z = q[3:7]
        yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))  # heading of the trunk's x axis
        vx_h = math.cos(yaw) * v[0] + math.sin(yaw) * v[1]
        vy_h = -math.sin(yaw) * v[0] + math.cos(yaw) * v[1]
        R = np.empty(9)
        mujoco.mju_quat2Mat(R, q[3:7])
        yaw_rate = (R.reshape(3, 3) @ v[3:6])[2]
        lin = math.exp(-((vx_h - before[0]) ** 2 + (vy_h - before[1]) ** 2) / 0.1**2)
        ang = math.exp(-((yaw_rate - before[2]) ** 2) / 0.2**2)
        terms = info["reward_terms"]
        assert terms["command_tracking_lin"] == pytest.approx(lin, rel=1e-9, abs=1e-12)
        assert terms["command_tracking_yaw"] == pytest.approx(ang, rel=1e-9, abs=1e-12)
        assert reward == pytest.approx(sum(terms.values()), rel=1e-12)
        if term:
            break


# ---------------------------------------------------------------------------- heading mode
@pytest.mark.parametrize(
    ("raw", "match"),
    [
        ({"heading": 0.5, "yaw_rate": 0.1}, r"command\.yaw_rate must be 0 and ranges\.yaw_rate null in heading mode"),
        ({"ranges": {"heading": [-1, 1], "yaw_rate": [-0.3, 0.3]}}, r"command\.yaw_rate must be 0 .* heading mode"),
        ({"heading": 0.5, "ranges": {"heading": [-1, 1]}}, r"command\.heading must not be given with command\.ranges"),
        ({"heading": 4.0}, r"command\.heading must be a number in \[-3\.14159, 3\.14159\] or null \(rad\), got 4\.0"),
        ({"heading": 0.5, "heading_gain": 0.0}, r"command\.heading_gain must be a number in \(0, 10\]"),
        ({"ranges": {"heading": [-4, 0]}}, r"command\.ranges\.heading must be null or a \[low, high\] pair"),
    ],
)
def test_bad_heading_commands_name_the_field(raw, match):
    with pytest.raises(ValueError, match=match):
        make(command=raw)


def _yaw(qpos) -> float:
    w, x, y, z = qpos[3:7]
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def test_heading_mode_yaw_rate_is_the_clipped_p_law_of_the_measured_heading():
    """Random torques spin the trunk; after every step the commanded yaw rate is legged_gym's
    clip(gain * wrap(heading - yaw), -max, max) of that step's measured heading (by hand from qpos), wrapping
    included (a heading of 3 rad against yaws near -3 rad turns the short way), and it is in the observation."""
    env = make(terrain="rough", command={"vx": 0.1, "heading": 3.0, "heading_gain": 2.0, "heading_max_yaw_rate": 1.5})
    u = env.unwrapped
    sl = u.observation_structure["command"]
    obs, info = env.reset(seed=1)
    rng = np.random.default_rng(0)
    clipped = seen = 0
    for _ in range(150):
        yaw = _yaw(u.data.qpos)
        err = (3.0 - yaw + math.pi) % (2 * math.pi) - math.pi
        expected = float(np.clip(2.0 * err, -1.5, 1.5))
        assert info["command"][2] == pytest.approx(expected, abs=1e-12)
        assert info["command"][0] == 0.1 and info["command_heading"] == 3.0
        np.testing.assert_allclose(obs[sl], info["command"], atol=1e-6)
        clipped += abs(expected) == 1.5
        seen += 1
        obs, _, term, trunc, info = env.step(rng.uniform(-1, 1, 12).astype(np.float32))
        if term or trunc:
            obs, info = env.reset()
    assert clipped > 0 and clipped < seen  # both regimes visited


def test_drawn_heading_is_seeded_and_stacked_by_make_vec():
    cfg = {"ranges": {"heading": [-1.0, 1.0], "vx": [0.0, 0.1]}, "resample_interval": 0.1}
    a, b = make(command=cfg), make(command=cfg)
    heads = []
    for seed in (3, 3, 4):
        _, info = a.reset(seed=seed)
        heads.append(info["command_heading"])
        _, info_b = b.reset(seed=seed)
        assert info_b["command_heading"] == info["command_heading"]
    assert heads[0] == heads[1] != heads[2] and all(-1.0 <= h <= 1.0 for h in heads)
    # the axes' draws are those of the same ranges without a heading
    c = make(command={"ranges": {"vx": [0.0, 0.1]}, "resample_interval": 0.1})
    assert c.reset(seed=3)[1]["command"][0] == a.reset(seed=3)[1]["command"][0]
    envs = gym.make_vec("QuadUneven-v0", num_envs=2, vectorization_mode="sync", terrain="flat", command=cfg)
    try:
        _, infos = envs.reset(seed=0)
        for _ in range(8):
            assert infos["command_heading"].shape == (2,) and np.all(np.abs(infos["command_heading"]) <= 1.0)
            _, _, _, _, infos = envs.step(np.zeros((2, 12), np.float32))
    finally:
        envs.close()
    assert "command_heading" not in make(command={"vx": 0.1}).reset(seed=0)[1]
