"""The expert features of the residual observation, against an independent computation (scipy rotations)."""

from __future__ import annotations

import dataclasses

import gymnasium as gym
import mujoco
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from agents.rl.expert_features import (
    EXPERT_FEATURE_FIELDS,
    EXPERT_FEATURE_SIZE,
    expert_features,
)
from agents.rl.residual_env import RESIDUAL_ENV_ID
from quad_uneven_env.observations import observation_structure

SLICES = observation_structure(EXPERT_FEATURE_FIELDS)


def _reference_features(expert, data) -> dict[str, np.ndarray]:
    """The features computed again with scipy's rotations from the expert's plan (no clipping)."""
    ref, phase = expert.planned_now(float(data.time))
    q, v = data.qpos.copy(), data.qvel.copy()
    R_meas = Rotation.from_quat(q[3:7], scalar_first=True)
    yaw = R_meas.as_euler("ZYX")[0]
    R_yaw = Rotation.from_euler("z", yaw)
    R_ref = Rotation.from_quat(np.asarray(ref.quat_WB), scalar_first=True)
    return {
        "expert_base_pos_error": R_yaw.inv().apply(ref.p_base_W - q[:3]),
        "expert_base_vel_error": R_yaw.inv().apply(ref.v_base_W - v[:3]),
        "expert_base_rot_error": (R_meas.inv() * R_ref).as_rotvec(),
        "expert_joint_pos_error": ref.q_joints - q[7:],
        "expert_joint_vel_error": ref.qd_joints - v[6:],
        "expert_planned_stance": np.asarray(ref.stance, dtype=float),
        "expert_cycle_phase": np.array([np.sin(2 * np.pi * phase), np.cos(2 * np.pi * phase)]),
        "expert_base_acc_ref": R_yaw.inv().apply(ref.a_base_W),
        "expert_torque": expert.last_torques / expert.env.idx.torque_limit,
    }


def _check(features: np.ndarray, reference: dict[str, np.ndarray]) -> None:
    for f in EXPERT_FEATURE_FIELDS:
        want = np.clip(reference[f.name], f.low, f.high)
        np.testing.assert_allclose(features[SLICES[f.name]], want, atol=2e-5, rtol=1e-5, err_msg=f.name)


def test_layout_and_space():
    env = gym.make(RESIDUAL_ENV_ID, terrain="flat")
    plain = gym.make("QuadUneven-v0", terrain="flat", action_mode="torque")
    assert EXPERT_FEATURE_SIZE == sum(f.size for f in EXPERT_FEATURE_FIELDS) == 54
    assert env.observation_space.shape == (plain.observation_space.shape[0] + EXPERT_FEATURE_SIZE,)
    obs, _ = env.reset(seed=0)
    for _ in range(30):
        assert env.observation_space.contains(obs)
        obs, *_ = env.step(env.action_space.sample())
    no_features = gym.make(RESIDUAL_ENV_ID, terrain="flat", expert_features=False)
    assert no_features.observation_space == plain.observation_space
    with pytest.raises(ValueError, match="expert_features must be true or false"):
        gym.make(RESIDUAL_ENV_ID, terrain="flat", expert_features="yes")


def test_features_match_an_independent_computation_while_walking():
    """On rough terrain, along a walk with residual noise (the plan advances through several phases)."""
    env = gym.make(RESIDUAL_ENV_ID, terrain="rough")
    obs, _ = env.reset(seed=3)
    base = env.unwrapped
    expert = env.get_wrapper_attr("expert")
    n_env = base.observation_space.shape[0]
    rng = np.random.default_rng(0)
    stances = set()
    for step in range(120):
        if step % 10 == 0:
            _check(obs[n_env:], _reference_features(expert, base.data))
            stances.add(tuple(obs[n_env:][SLICES["expert_planned_stance"]]))
        obs, _, terminated, truncated, _ = env.step(rng.normal(0.0, 0.1, 12).astype(np.float32))
        assert not (terminated or truncated)
    assert len(stances) >= 2  # swing phases were visited, not only four-leg support


def test_frames_on_a_turned_and_shoved_robot():
    """A robot yawed by 120 deg and shoved: the errors are expressed in its yaw frame, not the world's."""
    env = gym.make(RESIDUAL_ENV_ID, terrain="flat")
    env.reset(seed=0)
    base, expert = env.unwrapped, env.get_wrapper_attr("expert")
    d = base.data
    yaw = Rotation.from_euler("z", np.deg2rad(120.0))
    d.qpos[3:7] = (yaw * Rotation.from_quat(d.qpos[3:7], scalar_first=True)).as_quat(scalar_first=True)
    d.qvel[0:3] += [0.3, -0.2, 0.05]
    mujoco.mj_forward(base.model, d)
    features = expert_features(expert, d)
    reference = _reference_features(expert, d)
    _check(features, reference)
    # the planned trunk faces +x, the robot 120 deg away: the rotation error is about -120 deg about z
    np.testing.assert_allclose(features[SLICES["expert_base_rot_error"]], [0.0, 0.0, -1.0], atol=0.05)
    # a world-frame shove of (0.3, -0.2) in the robot's yaw frame: rotated by -120 deg
    shove_Y = yaw.inv().apply([0.3, -0.2, 0.05])
    np.testing.assert_allclose(features[SLICES["expert_base_vel_error"]], -shove_Y, atol=0.02)


def test_the_documented_layout_is_the_code():
    from pathlib import Path

    from quad_uneven_env.observations import observation_table

    doc = (Path(__file__).resolve().parents[2] / "docs" / "rl.md").read_text()
    assert observation_table(EXPERT_FEATURE_FIELDS) in doc


def test_a_non_finite_plan_gives_finite_features(monkeypatch):
    """A plan with NaN and infinite entries (a singular whole-body reference): the NaN entries read 0, the
    infinite ones their bound, and every other entry is as computed from the finite plan."""
    env = gym.make(RESIDUAL_ENV_ID, terrain="flat")
    env.reset(seed=0)
    base, expert = env.unwrapped, env.get_wrapper_attr("expert")
    finite = expert_features(expert, base.data)
    ref, phase = expert.planned_now(float(base.data.time))
    q_bad = ref.q_joints.copy()
    q_bad[[0, 4]] = np.nan
    q_bad[7] = np.inf
    bad = dataclasses.replace(ref, p_base_W=np.full(3, np.nan), q_joints=q_bad)
    monkeypatch.setattr(expert, "planned_now", lambda t: (bad, phase))
    features = expert_features(expert, base.data)
    assert np.isfinite(features).all()
    pos, joints = SLICES["expert_base_pos_error"], SLICES["expert_joint_pos_error"]
    np.testing.assert_array_equal(features[pos], 0.0)
    assert features[joints][0] == features[joints][4] == 0.0
    assert features[joints][7] == EXPERT_FEATURE_FIELDS[3].high
    keep = np.ones(EXPERT_FEATURE_SIZE, dtype=bool)
    keep[pos] = False
    keep[np.arange(EXPERT_FEATURE_SIZE)[joints][[0, 4, 7]]] = False
    np.testing.assert_array_equal(features[keep], finite[keep])
