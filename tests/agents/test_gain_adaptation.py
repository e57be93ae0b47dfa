"""The adaptive knee gains: the law by hand, its fixed point on a synthetic knee, and in the residual env."""

from __future__ import annotations

import types

import gymnasium as gym
import numpy as np
import pytest

from agents.rl import gain_adaptation as GA
from agents.rl.config import TrainConfigError, load_train_config
from agents.rl.residual_env import ResidualController, make_residual_env

KNEES = [2, 5, 8, 11]


def test_one_update_by_hand_moves_only_the_knees():
    law = GA.KneeGainAdaptation(period=0.02)
    e = np.linspace(-0.1, 0.1, 12)
    u = np.linspace(0.5, -0.5, 12)
    law.update(e, u, time_since_reset=1.0)
    w = 0.02 / GA.CORRELATION_TIME
    a, b = w * u[KNEES] ** 2, w * u[KNEES] * e[KNEES]
    expected = np.clip(1.0 + GA.ADAPTATION_RATE * 0.02 * b / (a + GA.EPS), *GA.GAIN_BOUNDS)
    np.testing.assert_allclose(law.gain[KNEES], expected, rtol=1e-14)
    assert np.all(np.delete(law.gain, KNEES) == 1.0)
    assert np.all(law.gain[KNEES] != 1.0)


def test_no_update_while_the_robot_settles_and_reset_forgets():
    law = GA.KneeGainAdaptation(period=0.02)
    law.update(np.full(12, 0.2), np.full(12, 0.5), time_since_reset=GA.START_TIME - 0.01)
    assert np.all(law.gain == 1.0)
    for _ in range(400):
        law.update(np.full(12, 0.2), np.full(12, 0.5), time_since_reset=5.0)
    assert np.all(law.gain[KNEES] == GA.GAIN_BOUNDS[1])  # a persistent sag saturates at the weakest motor's 2.0
    law.reset()
    assert np.all(law.gain == 1.0)
    for _ in range(400):
        law.update(np.full(12, -0.2), np.full(12, 0.5), time_since_reset=5.0)  # overshoot: the knee is too strong
    assert np.all(law.gain[KNEES] == GA.GAIN_BOUNDS[0])


@pytest.mark.parametrize("strength", [0.5, 0.7, 1.0, 1.3])
def test_a_knee_at_strength_s_settles_near_one_over_s(strength):
    """A synthetic knee whose sag follows its unmet load, e = c (1 - s g) u, with a load that changes sign and
    size over a gait cycle: the gain settles at 1/s (the fixed point of the law) within a few seconds."""
    law = GA.KneeGainAdaptation(period=0.02)
    for k in range(1000):  # 20 s
        u = np.full(12, 0.4 * np.sin(2 * np.pi * k * 0.02 / 1.1) + 0.2)
        e = 3.0 * (1.0 - strength * law.gain) * u  # 3 rad per unit of unmet load: the fit of docs/rl.md, run 7
        law.update(e, u, time_since_reset=k * 0.02)
    np.testing.assert_allclose(law.gain[KNEES], 1.0 / strength, rtol=0.02)


def test_bad_arguments_are_named():
    with pytest.raises(ValueError, match="period"):
        GA.KneeGainAdaptation(period=0.0)
    with pytest.raises(ValueError, match=r"gain_adaptation must be one of \['none', 'knee', 'learned'\]"):
        GA.check_gain_adaptation("hip")
    with pytest.raises(ValueError, match="gain_adaptation must be one of"):
        make_residual_env(terrain="flat", gain_adaptation=None)
    with pytest.raises(TrainConfigError, match="gain_adaptation"):
        load_train_config(None, {"gain_adaptation": "hips"})
    with pytest.raises(TrainConfigError, match="gain_adaptation 'none'"):
        load_train_config(None, {"residual": False, "expert_features": False, "gain_adaptation": "knee"})


class _PlannedExpert:
    """A stub expert with a plan: fixed torques, planned joint angles ``q_ref`` (rad)."""

    def __init__(self, tau: np.ndarray, q_ref: np.ndarray) -> None:
        self.tau, self.q_ref = tau, q_ref

    def reset(self, model, data, terrain) -> None:
        pass

    def planned_now(self, t: float):
        return types.SimpleNamespace(q_joints=self.q_ref), 0.0

    def __call__(self, model, data, action) -> np.ndarray:
        return self.tau.copy()


def test_the_controller_updates_once_per_control_step_and_scales_the_knees():
    limit = np.full(12, 120.0)
    tau = np.linspace(-60.0, 60.0, 12)
    expert = _PlannedExpert(tau, q_ref=np.full(12, 0.05))
    ctrl = ResidualController(expert, limit, 0.5, residual_basis="expert_torque", gain_adaptation="knee")
    data = types.SimpleNamespace(time=0.0, qpos=np.zeros(19))
    ctrl.reset(None, data, None)
    law = GA.KneeGainAdaptation(period=0.02)  # the reference, fed at each control step's first physics step
    action = np.linspace(1.0, -1.0, 12)
    for n in range(1, 401):  # 400 physics steps of 2 ms = 40 control steps (updates from 0.5 s on)
        data.time = n * 0.002
        if n % 10 == 0:
            law.update(np.full(12, 0.05), tau / limit, data.time)
        got = ctrl(None, data, action)
        np.testing.assert_allclose(got, np.clip(tau * law.gain * (1 + 0.5 * action), -limit, limit), atol=1e-12)
    assert np.all(law.gain[KNEES] != 1.0)
    with pytest.raises(ValueError, match="planned_now"):
        ResidualController(lambda m, d, a: tau, limit, gain_adaptation="knee")


@pytest.mark.filterwarnings("ignore:.*different from the unwrapped")
def test_the_adaptive_env_compensates_a_weak_knee_and_passes_both_checkers():
    """Extreme world, zero action: a knee gain moves towards the inverse of the drawn strength of its motor
    (the weakest knee gets the largest gain); the env passes Gymnasium's and SB3's checkers."""
    from gymnasium.utils.env_checker import check_env
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = make_residual_env(
        terrain="rough",
        randomization="extreme",
        residual_scale=0.5,
        residual_legs="stance",
        residual_basis="expert_torque",
        gain_adaptation="knee",
    )
    env.reset(seed=201)  # knee strengths 0.83, 0.95, 1.30, 0.61 (LF RF LH RH)
    strength = env.unwrapped.episode_draw.motor_strength[KNEES]
    for _ in range(150):  # 3 s
        *_, terminated, _, _ = env.step(np.zeros(12, dtype=np.float32))
        assert not terminated
    gain = env.unwrapped.controller.adaptation.gain[KNEES]
    assert np.argmax(gain) == np.argmin(strength)
    assert gain[np.argmin(strength)] > 1.3
    check_env(env, skip_render_check=True)
    sb3_check_env(env, warn=True)
    assert isinstance(gym.make("QuadUnevenResidual-v0", terrain="flat", gain_adaptation="knee"), gym.Env)


@pytest.mark.parametrize("adaptation", ["knee", "learned"])
def test_a_model_folder_brings_its_adaptation_to_evaluate_and_onnx(tmp_path, adaptation):
    """``gain_adaptation`` in rl_meta.json: the loader installs the same adaptive controller the training env had,
    the ONNX metadata names it, and an unknown value is refused by name."""
    import json

    import onnx
    import stable_baselines3

    from agents.evaluation.policies import make_policy, policy_env_kwargs
    from agents.rl.export import export_onnx
    from agents.rl.model_io import ModelError, read_metadata, write_metadata
    from agents.rl.residual_env import RESIDUAL_ENV_ID
    from agents.rl.strength_estimator import LearnedGainAdaptation, estimator_digest

    train_env = gym.make(RESIDUAL_ENV_ID, terrain="flat", gain_adaptation=adaptation)
    model = stable_baselines3.PPO("MlpPolicy", train_env, n_steps=64, batch_size=32, device="cpu", seed=0,
                                  policy_kwargs={"net_arch": [16]})  # fmt: skip
    model.save(tmp_path / "model.zip")
    meta = {"algo": "ppo", "residual": True, "residual_scale": 0.5, "expert_features": True,
            "normalize_obs": False, "env_kwargs": {"terrain": "flat"}, "residual_basis": "expert_torque",
            "gain_adaptation": adaptation}  # fmt: skip
    if adaptation == "learned":
        meta["strength_estimator_sha256"] = estimator_digest()
    write_metadata(tmp_path, meta)
    path = tmp_path / "model.zip"
    env = gym.make("QuadUneven-v0", **{**policy_env_kwargs(str(path)), "terrain": "flat"})
    make_policy(str(path), env)
    assert env.unwrapped.controller.gain_adaptation == adaptation
    kind = {"knee": GA.KneeGainAdaptation, "learned": LearnedGainAdaptation}[adaptation]
    assert isinstance(env.unwrapped.controller.adaptation, kind)
    export_onnx(path, tmp_path / "p.onnx")
    props = {p.key: p.value for p in onnx.load(str(tmp_path / "p.onnx")).metadata_props}
    assert json.loads(props["gain_adaptation"]) == adaptation
    if adaptation == "learned":  # a model made with another estimator is refused, not run with this one
        write_metadata(tmp_path, {**meta, "strength_estimator_sha256": "0" * 64})
        with pytest.raises(ModelError, match="strength_estimator_sha256 must be the sha256"):
            read_metadata(path)
    write_metadata(tmp_path, {**meta, "gain_adaptation": "hip"})
    with pytest.raises(ModelError, match=r"gain_adaptation must be one of \['none', 'knee', 'learned'\], got 'hip'"):
        read_metadata(path)


@pytest.mark.filterwarnings("ignore:.*different from the unwrapped")
def test_the_adapted_gains_in_the_observation_are_the_controllers_and_pass_both_checkers():
    """``adaptation_features``: the observation ends with the four knee gains the controller applies."""
    from gymnasium.utils.env_checker import check_env
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    from agents.rl.expert_features import EXPERT_FEATURE_SIZE

    kwargs = dict(terrain="rough", randomization="extreme", residual_scale=0.5, gain_adaptation="knee")
    plain = make_residual_env(**kwargs)
    env = make_residual_env(**kwargs, adaptation_features=True)
    obs, _ = env.reset(seed=201)
    plain_obs, _ = plain.reset(seed=201)
    assert obs.shape == (plain_obs.shape[0] + 4,) and env.observation_space.shape == obs.shape
    assert env.observation_space.shape[0] == env.unwrapped.observation_space.shape[0] + EXPERT_FEATURE_SIZE + 4
    np.testing.assert_array_equal(obs[-4:], 1.0)
    for _ in range(100):  # 2 s: the gains move from 1
        obs, *_ = env.step(np.zeros(12, dtype=np.float32))
        plain_obs, *_ = plain.step(np.zeros(12, dtype=np.float32))
    gain = env.unwrapped.controller.adaptation.gain[KNEES]
    assert np.abs(gain - 1.0).max() > 0.05
    np.testing.assert_array_equal(obs[-4:], gain.astype(np.float32))
    np.testing.assert_array_equal(obs[:-4], plain_obs)  # the rest is the observation without them
    check_env(env, skip_render_check=True)
    sb3_check_env(env, warn=True)


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"gain_adaptation": "none", "adaptation_features": True}, "adaptation_features"),
        ({"gain_adaptation": "knee", "expert_features": False, "adaptation_features": True}, "adaptation_features"),
        ({"gain_adaptation": "knee", "adaptation_features": "yes"}, "adaptation_features"),
    ],
)
def test_adaptation_features_without_the_adaptation_are_refused_by_name(kwargs, field):
    with pytest.raises(ValueError, match=rf"^{field}"):
        make_residual_env(terrain="flat", **kwargs)


def test_adaptation_features_in_a_config_need_the_knee_adaptation(tmp_path):
    import yaml

    from agents.rl.config import default_config_path

    raw = yaml.safe_load(default_config_path("ppo").read_text())
    path = tmp_path / "c.yaml"
    path.write_text(yaml.safe_dump({**raw, "adaptation_features": True, "gain_adaptation": "none"}))
    with pytest.raises(TrainConfigError, match=r"^adaptation_features: true needs .*gain_adaptation: knee"):
        load_train_config(path)
    path.write_text(yaml.safe_dump({**raw, "adaptation_features": True, "gain_adaptation": "knee"}))
    assert load_train_config(path).adaptation_features is True


@pytest.mark.filterwarnings("ignore:.*different from the unwrapped")
def test_evaluate_builds_the_training_observation_with_the_adapted_gains(tmp_path):
    """A model folder with ``adaptation_features``: the loaded policy sees, step for step, the observation the
    training env gives (the adapted gains included), and the ONNX layout names the gains' slice."""
    import json

    import onnx
    import stable_baselines3

    from agents.evaluation.policies import make_policy, policy_env_kwargs
    from agents.rl.export import export_onnx
    from agents.rl.model_io import ModelError, read_metadata, write_metadata

    kwargs = dict(terrain="flat", randomization="extreme", residual_scale=0.5, residual_basis="expert_torque")
    train_env = make_residual_env(**kwargs, gain_adaptation="knee", adaptation_features=True)
    model = stable_baselines3.PPO("MlpPolicy", train_env, n_steps=64, batch_size=32, device="cpu", seed=0,
                                  policy_kwargs={"net_arch": [16]})  # fmt: skip
    model.save(tmp_path / "model.zip")
    meta = {"algo": "ppo", "residual": True, "residual_scale": 0.5, "expert_features": True,
            "normalize_obs": False, "env_kwargs": {}, "residual_basis": "expert_torque",
            "gain_adaptation": "knee", "adaptation_features": True}  # fmt: skip
    write_metadata(tmp_path, meta)
    path = tmp_path / "model.zip"
    env = gym.make("QuadUneven-v0", **{**policy_env_kwargs(str(path)), "terrain": "flat", "randomization": "extreme"})
    policy = make_policy(str(path), env)
    seen = []
    predict = policy.model.predict
    policy.model.predict = lambda obs, **kw: (seen.append(np.array(obs)), predict(obs, **kw))[1]
    obs, _ = env.reset(seed=7)
    train_obs, _ = train_env.reset(seed=7)
    for _ in range(60):
        action, _ = policy.predict(obs)
        np.testing.assert_array_equal(seen[-1], train_obs)
        obs, *_ = env.step(action)
        train_obs, *_ = train_env.step(action)
    assert np.abs(seen[-1][-4:] - 1.0).max() > 0  # the gains moved, and both sides saw the same
    export_onnx(path, tmp_path / "p.onnx")
    props = {p.key: p.value for p in onnx.load(str(tmp_path / "p.onnx")).metadata_props}
    n = train_env.observation_space.shape[0]
    assert json.loads(props["observation_layout"])["adapted_knee_gain"] == [n - 4, n]
    assert json.loads(props["adaptation_features"]) is True
    write_metadata(tmp_path, {**meta, "gain_adaptation": "none"})
    with pytest.raises(ModelError, match=r"adaptation_features must be false, or true with gain_adaptation 'knee'"):
        read_metadata(path)


def test_a_training_run_with_adaptation_features_records_them_and_loads_for_evaluate(tmp_path):
    """``quad-uneven train`` writes ``adaptation_features`` into rl_meta.json, so the loaded policy's observation
    (env + expert features + the four gains) fits the trained network."""
    import json

    import yaml

    from agents.evaluation.policies import make_policy, policy_env_kwargs
    from agents.rl.config import default_config_path
    from agents.rl.training import train

    raw = yaml.safe_load(default_config_path("ppo").read_text())
    raw.update(
        timesteps=32, n_envs=1, max_episode_steps=16, eval_freq=0, checkpoint_freq=0, terrain="flat",
        hyperparams={"n_steps": 32, "batch_size": 16, "n_epochs": 1}, policy_kwargs={"net_arch": [8]},
        gain_adaptation="knee", adaptation_features=True,
    )  # fmt: skip
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(raw))
    train(load_train_config(tmp_path / "c.yaml"), tmp_path / "run", progress=False)
    assert json.loads((tmp_path / "run" / "rl_meta.json").read_text())["adaptation_features"] is True
    path = str(tmp_path / "run" / "model.zip")
    env = gym.make("QuadUneven-v0", **{**policy_env_kwargs(path), "terrain": "flat"})
    policy = make_policy(path, env)
    assert policy.adaptation is env.unwrapped.controller.adaptation
    obs, _ = env.reset(seed=0)
    action, _ = policy.predict(obs)
    assert action.shape == (12,)
