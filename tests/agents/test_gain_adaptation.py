"""The expert's adaptive gains: the knee law by hand, its fixed point on a synthetic knee, the schedule that applies
a law to the torques, ``ExpertConfig(adaptation=...)`` in the env (its call and its fast lane), under the residual,
and in a model folder."""

from __future__ import annotations

import types

import gymnasium as gym
import numpy as np
import pytest

import quad_uneven_env  # noqa: F401  (registers QuadUneven-v0)
from agents.control.adaptation import ADAPTATIONS, AdaptiveGains, make_adaptation
from agents.control.adaptation import knee as GA
from agents.control.adaptation.learned import LearnedGainAdaptation, estimator_digest
from agents.expert import ExpertConfig, attach_expert
from agents.rl.config import TrainConfigError, load_train_config
from agents.rl.residual_env import make_residual_env

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
        e = 3.0 * (1.0 - strength * law.gain) * u  # 3 rad per unit of unmet load: the fit of docs/rl.md
        law.update(e, u, time_since_reset=k * 0.02)
    np.testing.assert_allclose(law.gain[KNEES], 1.0 / strength, rtol=0.02)


def test_bad_arguments_are_named():
    with pytest.raises(ValueError, match="period"):
        GA.KneeGainAdaptation(period=0.0)
    assert ADAPTATIONS == ("none", "knee", "learned")
    for bad in ("hip", None, 1, "Knee"):
        with pytest.raises(ValueError, match=r"^ExpertConfig\.adaptation must be one of \['none', 'knee', 'learned'\]"):
            ExpertConfig(adaptation=bad)
    with pytest.raises(ValueError, match=r"^adaptation must be one of \['none', 'knee', 'learned'\], got 'hip'"):
        make_adaptation("hip", 0.02, np.ones(12))
    assert make_adaptation("none", 0.02, np.ones(12)) is None
    with pytest.raises(ValueError, match=r"^ResidualConfig\.expert\.adaptation must be one of"):
        make_residual_env(terrain="flat", expert={"adaptation": None})
    with pytest.raises(TrainConfigError, match=r"^expert\.adaptation must be one of \['none', 'knee', 'learned'\]"):
        load_train_config(None, {"expert": {"adaptation": "hips"}})
    with pytest.raises(TrainConfigError, match=r"^expert: unknown field\(s\) \['adaption'\]"):
        load_train_config(None, {"expert": {"adaption": "knee"}})
    with pytest.raises(TrainConfigError, match=r"expert \{\}"):
        load_train_config(None, {"residual": False, "expert_features": False, "expert": {"adaptation": "knee"}})
    for removed in ("gain_adaptation", "adaptation_features"):
        with pytest.raises(TrainConfigError, match=rf"^{removed}: unknown field"):
            load_train_config(None, {removed: "knee"})


class _Law:
    """A law that records what it is fed and moves its gains by a known amount at every update."""

    def __init__(self, period: float) -> None:
        self.period = period
        self.gain = np.ones(12)
        self.fed: list[tuple[np.ndarray, np.ndarray, float]] = []

    def reset(self) -> None:
        self.gain[:] = 1.0
        self.fed = []

    def update(self, joint_pos_error: np.ndarray, load: np.ndarray, time_since_reset: float) -> None:
        self.fed.append((joint_pos_error.copy(), load.copy(), time_since_reset))
        self.gain += 0.01 * np.arange(12)


def test_the_gains_update_at_each_control_steps_first_physics_step_and_scale_the_torques():
    """:class:`AdaptiveGains` over 40 control steps of 10 physics steps (2 ms) after a reset at t = 0.3 s: the
    law is fed planned minus measured angles and torque / limit at t = 0.3 + k 0.02 s (k >= 1), and every physics
    step returns the torques times the gains of that moment."""
    limit = np.linspace(40.0, 150.0, 12)
    law = _Law(0.02)
    gains = AdaptiveGains(law, limit)
    q_ref, q = np.full(12, 0.05), np.linspace(-0.1, 0.1, 12)
    planned = []

    def planned_now(t):
        planned.append(t)
        return types.SimpleNamespace(q_joints=q_ref), 0.0

    gains.reset(0.3)
    tau = np.linspace(-60.0, 60.0, 12)
    expected_gain = np.ones(12)
    for n in range(1, 401):
        t = 0.3 + n * 0.002
        if n % 10 == 0:  # a control step's first physics step: the law moves first
            expected_gain += 0.01 * np.arange(12)
        np.testing.assert_array_equal(gains.apply(tau, t, q, planned_now), tau * expected_gain)
    assert len(law.fed) == 40 and planned == pytest.approx([0.3 + 0.02 * k for k in range(1, 41)])
    np.testing.assert_array_equal(law.fed[0][0], q_ref - q)
    np.testing.assert_array_equal(law.fed[0][1], tau / limit)
    assert [f[2] for f in law.fed] == pytest.approx([0.02 * k for k in range(1, 41)])
    gains.reset(0.0)
    assert law.fed == [] and np.all(gains.gain == 1.0)


@pytest.mark.parametrize("adaptation", ["knee", "learned"])
def test_the_adaptive_expert_walks_the_same_in_its_call_and_its_fast_lane(adaptation, monkeypatch):
    """An attached expert with ``adaptation``, in the extreme world: with its fast lane (``torques_into``, which
    answers every physics step) and with the lane removed (the call every physics step), the same motor commands,
    trajectory and gains bit for bit; the gains moved."""
    runs = []
    for lane in (True, False):
        env = gym.make("QuadUneven-v0", terrain="rough", randomization="extreme")
        expert = attach_expert(env, ExpertConfig(adaptation=adaptation))
        answers = []
        real = type(expert).torques_into

        def counted(self, *args, _real=real, _answers=answers, _on=lane):
            done = _real(self, *args) if _on else False
            _answers.append(done)
            return done

        monkeypatch.setattr(type(expert), "torques_into", counted)
        env.reset(seed=201)
        d = env.unwrapped.data
        trace = []
        for _ in range(120):
            _, _, terminated, _, _ = env.step(np.zeros(12, dtype=np.float32))
            trace.append((d.qpos.copy(), d.ctrl.copy(), expert.adaptation.gain.copy()))
            assert not terminated
        runs.append((trace, answers))
        monkeypatch.undo()
    (with_lane, answers), (without, _) = runs
    for (q1, u1, g1), (q2, u2, g2) in zip(with_lane, without, strict=True):
        np.testing.assert_array_equal(u1, u2)
        np.testing.assert_array_equal(q1, q2)
        np.testing.assert_array_equal(g1, g2)
    assert np.abs(with_lane[-1][2] - 1.0).max() > 0.05
    assert all(answers) and len(answers) == 120 * env.unwrapped.frame_skip


def test_the_gains_multiply_the_controllers_torques_before_the_motor_limit():
    """One physics step of an adaptive expert's call, by hand: the controller's torques (``last_torques``) times
    the gains the step ended with."""
    env = gym.make("QuadUneven-v0", terrain="flat", randomization="extreme")
    expert = attach_expert(env, ExpertConfig(adaptation="knee"))
    env.reset(seed=201)
    for _ in range(100):
        env.step(np.zeros(12, dtype=np.float32))
    base = env.unwrapped
    gain = expert.adaptation.gain
    assert np.abs(gain - 1.0).max() > 0.05
    tau = expert(base.model, base.data, np.zeros(12))
    np.testing.assert_array_equal(tau, expert.last_torques * gain)


@pytest.mark.filterwarnings("ignore:.*different from the unwrapped")
def test_the_knee_adaptation_compensates_a_weak_knee_and_the_residual_env_over_it_passes_both_checkers():
    """Extreme world: a knee gain of the adaptive expert moves towards the inverse of the drawn strength of its
    motor (the weakest knee gets the largest gain); the residual env over that expert passes Gymnasium's and SB3's
    checkers."""
    from gymnasium.utils.env_checker import check_env
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = gym.make("QuadUneven-v0", terrain="rough", randomization="extreme")
    expert = attach_expert(env, ExpertConfig(adaptation="knee"))
    env.reset(seed=201)  # knee strengths 0.83, 0.95, 1.30, 0.61 (LF RF LH RH)
    strength = env.unwrapped.episode_draw.motor_strength[KNEES]
    for _ in range(150):  # 3 s
        *_, terminated, _, _ = env.step(np.zeros(12, dtype=np.float32))
        assert not terminated
    gain = expert.adaptation.gain[KNEES]
    assert np.argmax(gain) == np.argmin(strength)
    assert gain[np.argmin(strength)] > 1.3
    residual = make_residual_env(
        terrain="rough", randomization="extreme", residual_scale=0.5, residual_legs="stance",
        residual_basis="expert_torque", expert=ExpertConfig(adaptation="knee"),
    )  # fmt: skip
    assert isinstance(residual.expert.adaptation.law, GA.KneeGainAdaptation)
    check_env(residual, skip_render_check=True)
    sb3_check_env(residual, warn=True)


@pytest.mark.parametrize("adaptation", ["knee", "learned"])
def test_zero_residual_over_an_adaptive_expert_is_that_expert(adaptation):
    """The residual env with zero action over ``ExpertConfig(adaptation=...)`` walks exactly as that expert
    attached alone (the residual acts on the adapted torques, so zero adds nothing), in the extreme world."""
    cfg = ExpertConfig(adaptation=adaptation)
    plain = gym.make("QuadUneven-v0", terrain="rough", randomization="extreme")
    expert = attach_expert(plain, cfg)
    residual = make_residual_env(
        terrain="rough", randomization="extreme", residual_scale=0.5, residual_legs="stance",
        residual_basis="expert_torque", expert=cfg,
    )  # fmt: skip
    plain.reset(seed=201)
    residual.reset(seed=201)
    for _ in range(100):
        plain.step(np.zeros(12, dtype=np.float32))
        residual.step(np.zeros(12, dtype=np.float32))
        np.testing.assert_array_equal(plain.unwrapped.data.qpos, residual.unwrapped.data.qpos)
        np.testing.assert_array_equal(plain.unwrapped.data.ctrl, residual.unwrapped.data.ctrl)
    np.testing.assert_array_equal(expert.adaptation.gain, residual.expert.adaptation.gain)
    assert np.abs(expert.adaptation.gain - 1.0).max() > 0.05


@pytest.mark.parametrize("adaptation", ["knee", "learned"])
def test_a_model_folder_brings_its_expert_to_evaluate_and_onnx(tmp_path, adaptation):
    """``expert: {adaptation: ...}`` in rl_meta.json: the model's env has the expert with that adaptation under
    the residual, the ONNX metadata records the expert config, and a bad value or a field this reader does not
    take is refused by name."""
    import json

    import onnx
    import stable_baselines3

    from agents.evaluation.policies import make_policy, make_policy_env
    from agents.rl.export import export_onnx
    from agents.rl.model_io import ModelError, read_metadata, write_metadata

    train_env = make_residual_env(terrain="flat", expert=ExpertConfig(adaptation=adaptation))
    model = stable_baselines3.PPO("MlpPolicy", train_env, n_steps=64, batch_size=32, device="cpu", seed=0,
                                  policy_kwargs={"net_arch": [16]})  # fmt: skip
    model.save(tmp_path / "model.zip")
    meta = {"algo": "ppo", "residual": True, "residual_scale": 0.5, "expert_features": True,
            "normalize_obs": False, "env_kwargs": {"terrain": "flat"}, "residual_basis": "expert_torque",
            "expert": {"adaptation": adaptation}}  # fmt: skip
    if adaptation == "learned":
        meta["strength_estimator_sha256"] = estimator_digest()
    write_metadata(tmp_path, meta)
    path = tmp_path / "model.zip"
    env = make_policy_env(str(path), terrain="flat")
    policy = make_policy(str(path), env)
    assert policy.expert is env.unwrapped.controller.expert
    assert policy.expert.config == ExpertConfig(adaptation=adaptation)
    kind = {"knee": GA.KneeGainAdaptation, "learned": LearnedGainAdaptation}[adaptation]
    assert isinstance(policy.expert.adaptation.law, kind)
    export_onnx(path, tmp_path / "p.onnx")
    props = {p.key: p.value for p in onnx.load(str(tmp_path / "p.onnx")).metadata_props}
    assert json.loads(props["expert"]) == {"adaptation": adaptation}
    if adaptation == "learned":  # a model made with another estimator is refused, not run with this one
        write_metadata(tmp_path, {**meta, "strength_estimator_sha256": "0" * 64})
        with pytest.raises(ModelError, match="strength_estimator_sha256 must be the sha256"):
            read_metadata(path)
    write_metadata(tmp_path, {**meta, "expert": {"adaptation": "hip"}})
    with pytest.raises(ModelError, match=r"expert\.adaptation must be one of \['none', 'knee', 'learned'\], got 'hip'"):
        read_metadata(path)
    write_metadata(tmp_path, {**meta, "expert": {}, "gain_adaptation": adaptation})
    with pytest.raises(ModelError, match=r"gain_adaptation must be absent or 'none'.*expert: \{adaptation"):
        read_metadata(path)
    write_metadata(tmp_path, {**meta, "adaptation_features": True})
    with pytest.raises(ModelError, match="adaptation_features must be absent or False"):
        read_metadata(path)


def test_a_training_run_records_its_expert_config_and_evaluate_rebuilds_it(tmp_path):
    """``quad-uneven train`` with ``expert: {adaptation: knee, friction: 0.6}``: rl_meta.json records those
    fields, and the loaded policy's expert has that config (the round trip of a model folder's expert)."""
    import json

    import yaml

    from agents.evaluation.policies import make_policy, make_policy_env
    from agents.rl.config import default_config_path
    from agents.rl.training import train

    raw = yaml.safe_load(default_config_path("ppo").read_text())
    raw.update(
        timesteps=32, n_envs=1, max_episode_steps=16, eval_freq=0, checkpoint_freq=0, terrain="flat",
        hyperparams={"n_steps": 32, "batch_size": 16, "n_epochs": 1}, policy_kwargs={"net_arch": [8]},
        expert={"adaptation": "knee", "friction": 0.6},
    )  # fmt: skip
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(raw))
    train(load_train_config(tmp_path / "c.yaml"), tmp_path / "run", progress=False)
    meta = json.loads((tmp_path / "run" / "rl_meta.json").read_text())
    assert meta["expert"] == {"friction": 0.6, "adaptation": "knee"}
    assert "strength_estimator_sha256" not in meta and "gain_adaptation" not in meta
    assert json.loads((tmp_path / "run" / "train_config.json").read_text())["expert"] == raw["expert"]
    path = str(tmp_path / "run" / "model.zip")
    env = make_policy_env(path, terrain="flat")
    policy = make_policy(path, env)
    assert policy.expert.config == ExpertConfig(adaptation="knee", friction=0.6)
    obs, _ = env.reset(seed=0)
    action, _ = policy.predict(obs)
    assert action.shape == (12,)
