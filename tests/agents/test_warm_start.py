"""How a SAC residual run starts: --init-from (a warm start takes the saved weights, optimizers, temperature and
statistics), and the untrained actor's exploration std."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch
import yaml
from stable_baselines3.common.vec_env import DummyVecEnv

from agents.cli import main
from agents.rl.config import TrainConfigError, default_config_path, load_train_config

TINY_SAC = {
    "timesteps": 64,
    "n_envs": 1,
    "max_episode_steps": 40,
    "eval_freq": 0,
    "checkpoint_freq": 0,
    "hyperparams": {"buffer_size": 1000, "batch_size": 16, "learning_starts": 0, "ent_coef": "auto_0.1"},
    "policy_kwargs": {"net_arch": [16]},
}
"""Overrides of the shipped SAC config for a run of a few seconds."""


def write_config(path: Path, **changes) -> Path:
    """The shipped SAC config with :data:`TINY_SAC` and ``changes``, written to ``path``."""
    path.write_text(yaml.safe_dump({**yaml.safe_load(default_config_path("sac").read_text()), **TINY_SAC, **changes}))
    return path


@pytest.fixture(scope="module")
def saved_run(tmp_path_factory) -> Path:
    """A tiny SAC residual run of 64 steps (weights, temperature and statistics moved from their start)."""
    from agents.rl.training import train

    tmp = tmp_path_factory.mktemp("warm")
    train(load_train_config(write_config(tmp / "c.yaml")), tmp / "saved", progress=False)
    return tmp / "saved"


def _state(model) -> dict[str, np.ndarray]:
    return {
        f"{module}.{name}": value.detach().numpy().copy()
        for module, sd in model.get_parameters().items()
        if module == "policy"
        for name, value in sd.items()
    }


def test_warm_start_takes_the_saved_weights_temperature_optimizer_and_statistics(saved_run, tmp_path):
    from stable_baselines3.common.save_util import load_from_zip_file

    from agents.rl.normalization import ObsNormalization
    from agents.rl.training import _make_model, _metadata
    from agents.rl.vec_env import build_vec_env, normalize
    from agents.rl.warm_start import check_init_model, warm_start

    cfg = load_train_config(write_config(tmp_path / "c.yaml", init_from=str(saved_run), seed=3))
    path, steps = check_init_model(cfg.init_from, _metadata(cfg, "paper"))
    assert path == saved_run / "model.zip" and steps == 64
    _, params, variables = load_from_zip_file(path, device="cpu", load_data=False)
    saved_stats = ObsNormalization.load(saved_run / "model_obs_norm.npz")
    venv = normalize(build_vec_env(cfg, 1, cfg.seed, None, vec_env="dummy"), cfg, training=True)
    try:
        model = _make_model(cfg, venv)
        fresh = _state(model)
        saved = {f"policy.{k}": v.numpy() for k, v in params["policy"].items()}
        assert fresh.keys() == saved.keys()
        assert any(not np.array_equal(fresh[k], saved[k]) for k in saved)  # the test can fail
        assert model.log_ent_coef.item() != pytest.approx(variables["log_ent_coef"].item(), abs=1e-9)

        warm_start(model, path, steps)

        for key, value in _state(model).items():
            np.testing.assert_array_equal(value, saved[key], err_msg=key)
        assert model.log_ent_coef.item() == variables["log_ent_coef"].item()
        moments = model.actor.optimizer.state_dict()["state"]
        saved_moments = params["actor.optimizer"]["state"]
        assert moments.keys() == saved_moments.keys() and moments
        for k in moments:
            assert torch.equal(moments[k]["exp_avg"], saved_moments[k]["exp_avg"])
        rms = model.get_vec_normalize_env().obs_rms
        np.testing.assert_array_equal(rms.mean, saved_stats.mean)
        np.testing.assert_array_equal(rms.var, saved_stats.var)
        assert rms.count == 64.0
    finally:
        venv.close()


def test_a_warm_started_run_trains_and_records_its_origin(saved_run, tmp_path):
    out = tmp_path / "continued"
    cfg = write_config(tmp_path / "c.yaml", timesteps=16, seed=3)
    rc = main(["train", "--config", str(cfg), "--init-from", str(saved_run), "--out", str(out), "--no-progress"])
    assert rc == 0
    assert json.loads((out / "rl_meta.json").read_text())["init_from"] == str(saved_run)
    summary = json.loads((out / "train_summary.json").read_text())
    assert summary["init_timesteps"] == 64 and summary["timesteps"] == 16


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"residual_scale": 0.2}, "residual_scale"),
        ({"expert": {"adaptation": "knee"}}, "expert"),
        ({"expert_features": False}, "expert_features"),
        ({"policy_kwargs": {"net_arch": [8]}}, "does not fit"),
    ],
)
def test_a_model_of_another_env_or_network_is_refused_naming_the_field(saved_run, tmp_path, changes, message):
    from agents.rl.training import train

    cfg = load_train_config(write_config(tmp_path / "c.yaml", init_from=str(saved_run), **changes))
    with pytest.raises(TrainConfigError, match=rf"^init_from: .*{message}"):
        train(cfg, tmp_path / "out", progress=False)


def test_bad_init_from_exits_2_with_one_line(saved_run, tmp_path, capsys):
    cfg = str(write_config(tmp_path / "c.yaml"))
    for init, out in ((tmp_path / "nothing", tmp_path / "a"), (saved_run, saved_run)):
        argv = ["--config", cfg, "--init-from", str(init), "--out", str(out), "--overwrite", "--no-progress"]
        rc = main(["train", *argv])
        err = capsys.readouterr().err.strip()
        assert rc == 2 and err.count("\n") == 0 and "init_from" in err, err
    assert (saved_run / "model.zip").is_file()  # --out holding the model: refused before anything is deleted


def test_a_from_scratch_model_continues_too(tmp_path):
    """residual: false records env_kwargs with the joint_pd action mode: the check compares what a new run of
    the same config would record, not the config's own env_kwargs."""
    from agents.rl.training import train

    scratch = {"residual": False, "expert_features": False, "residual_legs": "all", "residual_basis": "torque_limit",
               "residual_scale": 0.1, "timesteps": 16}  # fmt: skip
    train(load_train_config(write_config(tmp_path / "a.yaml", **scratch)), tmp_path / "a", progress=False)
    cfg = load_train_config(write_config(tmp_path / "b.yaml", **scratch, init_from=str(tmp_path / "a")))
    summary = train(cfg, tmp_path / "b", progress=False)
    assert summary["init_timesteps"] == 16 and summary["timesteps"] == 16


OBS_DIM = 30


class _Box(gym.Env):
    """Spaces only: the model is built, never stepped."""

    observation_space = gym.spaces.Box(-10.0, 10.0, (OBS_DIM,), np.float32)
    action_space = gym.spaces.Box(-1.0, 1.0, (12,), np.float32)

    def reset(self, seed=None, options=None):
        return np.zeros(OBS_DIM, np.float32), {}

    def step(self, action):
        return np.zeros(OBS_DIM, np.float32), 0.0, False, False, {}


def _std(tmp_path, **changes) -> np.ndarray:
    """The untrained actor's std per action on 500 standard-normal (normalized) observations."""
    from agents.rl.training import _make_model

    model = _make_model(load_train_config(write_config(tmp_path / "c.yaml", **changes)), DummyVecEnv([_Box]))
    with torch.no_grad():
        _, log_std, _ = model.actor.get_action_dist_params(
            torch.randn(500, OBS_DIM, generator=torch.Generator().manual_seed(0))
        )
    return log_std.exp().numpy()


def test_sb3_sac_ignores_log_std_init(tmp_path):
    """With policy_kwargs.log_std_init -2.3 (std 0.1) SB3's SAC actor starts with a random log-std layer, a std
    near 1 that varies with the state; the config warns."""
    with pytest.warns(UserWarning, match=r"^policy_kwargs.log_std_init has no effect on SAC without use_sde"):
        std = _std(tmp_path, policy_kwargs={"net_arch": [16], "log_std_init": -2.3})
    assert np.median(std) > 0.5 and std.std() > 1e-3


# PPO from a saved policy: the action noise it starts with, fixed observation statistics, a critic warm-up.

TINY_PPO_SCRATCH = {
    "algo": "ppo",
    "residual": False,
    "expert_features": False,
    "residual_penalty": 0.0,
    "terrain": "flat",
    "timesteps": 64,
    "n_envs": 1,
    "vec_env": "dummy",
    "max_episode_steps": 40,
    "eval_freq": 0,
    "checkpoint_freq": 0,
    "hyperparams": {"n_steps": 32, "batch_size": 16, "n_epochs": 2, "learning_rate": 1e-3},
    "policy_kwargs": {"net_arch": [16], "log_std_init": -1.0},
}
"""A PPO-from-scratch run of a few seconds."""


def write_ppo_config(path: Path, **changes) -> Path:
    path.write_text(yaml.safe_dump({**TINY_PPO_SCRATCH, **changes}))
    return path


@pytest.fixture(scope="module")
def saved_ppo_run(tmp_path_factory) -> Path:
    """A tiny PPO-from-scratch run of 64 steps."""
    from agents.rl.training import train

    tmp = tmp_path_factory.mktemp("warm_ppo")
    train(load_train_config(write_ppo_config(tmp / "c.yaml")), tmp / "saved", progress=False)
    return tmp / "saved"


def _policy_params(path: Path) -> dict[str, np.ndarray]:
    from agents.rl.model_io import read_model_zip

    return {k: v.numpy().copy() for k, v in read_model_zip(path, where="test").params["policy"].items()}


ACTOR = ("mlp_extractor.policy_net.", "action_net.", "log_std")


def test_a_warm_start_with_the_actor_frozen_trains_only_the_critic_and_keeps_the_statistics(saved_ppo_run, tmp_path):
    """critic_warmup_steps over the whole run: the actor leaves as it came (with the log std it was given),
    the critic moved; freeze_obs_norm: the saved statistics come out unchanged."""
    from agents.rl.normalization import ObsNormalization
    from agents.rl.training import train

    cfg = write_ppo_config(
        tmp_path / "c.yaml",
        init_from=str(saved_ppo_run),
        init_log_std=-3.0,
        freeze_obs_norm=True,
        critic_warmup_steps=32,
        seed=5,
    )
    # a warm-up over the whole run, which the config check refuses (the actor would never train): the mechanism
    # itself is tested here
    train(dataclasses.replace(load_train_config(cfg), critic_warmup_steps=64), tmp_path / "out", progress=False)
    before, after = _policy_params(saved_ppo_run / "model.zip"), _policy_params(tmp_path / "out" / "model.zip")
    assert before.keys() == after.keys()
    for key in before:
        if key == "log_std":
            np.testing.assert_array_equal(after[key], np.full(12, -3.0, np.float32))
        elif key.startswith(ACTOR):
            np.testing.assert_array_equal(after[key], before[key], err_msg=key)
    assert any(
        not np.array_equal(after[k], before[k]) for k in before if k.startswith(("value_net", "mlp_extractor.value"))
    )
    saved, out = (
        ObsNormalization.load(saved_ppo_run / "model_obs_norm.npz"),
        ObsNormalization.load(tmp_path / "out" / "model_obs_norm.npz"),
    )
    np.testing.assert_array_equal(out.mean, saved.mean)
    np.testing.assert_array_equal(out.var, saved.var)


def test_the_actor_thaws_after_the_warm_up_and_statistics_move_unless_frozen(saved_ppo_run, tmp_path):
    from agents.rl.normalization import ObsNormalization
    from agents.rl.training import train

    cfg = write_ppo_config(
        tmp_path / "c.yaml", init_from=str(saved_ppo_run), critic_warmup_steps=32, timesteps=96, seed=5
    )
    train(load_train_config(cfg), tmp_path / "out", progress=False)
    before, after = _policy_params(saved_ppo_run / "model.zip"), _policy_params(tmp_path / "out" / "model.zip")
    assert not np.array_equal(after["action_net.weight"], before["action_net.weight"])
    assert not np.array_equal(after["log_std"], before["log_std"])
    saved, out = (
        ObsNormalization.load(saved_ppo_run / "model_obs_norm.npz"),
        ObsNormalization.load(tmp_path / "out" / "model_obs_norm.npz"),
    )
    assert not np.array_equal(out.mean, saved.mean)


def test_critic_warmup_freezes_exactly_the_actor():
    """actor_parameters: the policy net, the action head and the log std; none of the critic's."""
    from stable_baselines3 import PPO

    from agents.rl.training import CriticWarmupCallback, actor_parameters

    env = gym.make("Pendulum-v1")
    model = PPO("MlpPolicy", env, policy_kwargs={"net_arch": [8]}, n_steps=16, batch_size=16, device="cpu")
    actor = {id(p) for p in actor_parameters(model)}
    names = {n for n, p in model.policy.named_parameters() if id(p) in actor}
    assert names == {
        "log_std",
        "mlp_extractor.policy_net.0.weight",
        "mlp_extractor.policy_net.0.bias",
        "action_net.weight",
        "action_net.bias",
    }
    callback = CriticWarmupCallback(32)
    callback.init_callback(model)
    callback.on_training_start({}, {})
    assert callback.frozen
    assert {n for n, p in model.policy.named_parameters() if not p.requires_grad} == names
    model.num_timesteps = 32
    callback.on_rollout_end()
    assert callback.frozen  # the update on steps 1-32 is still the critic's
    model.num_timesteps = 48
    callback.on_rollout_end()
    assert not callback.frozen and all(p.requires_grad for p in model.policy.parameters())
    env.close()


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"init_log_std": 5.0}, "^init_log_std must be"),
        ({"init_log_std": "small"}, "^init_log_std must be"),
        ({"critic_warmup_steps": -1}, "^critic_warmup_steps must be"),
        ({"freeze_obs_norm": True}, "^freeze_obs_norm .*needs init_from"),
        ({"freeze_obs_norm": True, "init_from": "x", "normalize_obs": False}, "^freeze_obs_norm .*normalize_obs"),
    ],
)
def test_bad_fine_tuning_options_are_named(tmp_path, changes, message):
    with pytest.raises(TrainConfigError, match=message):
        load_train_config(write_ppo_config(tmp_path / "c.yaml", **changes))


@pytest.mark.parametrize(
    ("changes", "field"),
    [({"init_log_std": -2.0}, "init_log_std"), ({"critic_warmup_steps": 8}, "critic_warmup_steps")],
)
def test_ppo_only_options_are_refused_for_sac(tmp_path, changes, field):
    with pytest.raises(TrainConfigError, match=rf"^{field} applies to PPO only"):
        load_train_config(write_config(tmp_path / "c.yaml", **changes))


def test_the_distilled_comparison_configs_differ_only_in_the_start():
    """configs/rl/ppo_from_distilled.yaml starts from models/distilled (its env checked as a warm start does);
    configs/rl/ppo_scratch_distilled_env.yaml is the same run from random weights."""
    from agents.rl.training import _metadata
    from agents.rl.warm_start import check_init_model

    fine = load_train_config(Path("configs/rl/ppo_from_distilled.yaml"))
    scratch = load_train_config(Path("configs/rl/ppo_scratch_distilled_env.yaml"))
    start = {"init_from", "init_log_std", "freeze_obs_norm", "critic_warmup_steps"}
    a, b = fine.to_dict(), scratch.to_dict()
    assert {k for k in a if a[k] != b[k]} == start
    assert scratch.init_from is None and fine.init_from == "models/distilled"
    path, _ = check_init_model(fine.init_from, _metadata(fine, "paper"))
    assert path == Path("models/distilled/model.zip")
    assert len(fine.terrain) == 6
