"""Model folders are data: loading them runs no code from the files; exported ONNX equals SB3's predict."""

from __future__ import annotations

import base64
import json
import pickle
import zipfile
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import quad_uneven_env  # noqa: F401
from agents.rl.model_io import ModelError, load_sb3_model, load_sb3_policy, write_metadata
from agents.rl.normalization import ObsNormalization


class _Boom:
    """Unpickling this sets a flag: proof that a loader ran code from a file."""

    def __reduce__(self):
        return (exec, ("import builtins; builtins.QUAD_UNEVEN_PWNED = True",))


def _model_folder(tmp_path, algo: str, rng: np.random.Generator, residual: bool = False):
    """An untrained SB3 model on QuadUneven-v0 with random weights and random observation statistics."""
    import stable_baselines3
    import torch

    env = gym.make("QuadUneven-v0", terrain="flat")
    cls = getattr(stable_baselines3, algo.upper())
    kw = {"n_steps": 64, "batch_size": 32} if algo == "ppo" else {"learning_starts": 10, "buffer_size": 100}
    model = cls("MlpPolicy", env, policy_kwargs={"net_arch": [32, 32]}, device="cpu", seed=0, **kw)
    with torch.no_grad():  # non-trivial outputs: the default init gives a near-zero mean action
        for p in model.policy.parameters():
            p.add_(0.3 * torch.randn_like(p))
    model.save(tmp_path / "model.zip")
    n = env.observation_space.shape[0]
    norm = ObsNormalization(rng.normal(0, 0.3, n), rng.uniform(0.01, 2.0, n), 1e-8, 10.0)
    norm.save(tmp_path / "model_obs_norm.npz")
    meta = {"algo": algo, "residual": residual, "normalize_obs": True, "env_kwargs": {"terrain": "flat"}}
    if residual:
        meta["residual_scale"] = 0.1
    write_metadata(tmp_path, meta)
    return tmp_path / "model.zip", env, norm


def _recorded_observations(env, n: int = 200) -> np.ndarray:
    rng = np.random.default_rng(4)
    obs, _ = env.reset(seed=4)
    out = []
    for _ in range(n):
        out.append(obs)
        obs, _, term, trunc, _ = env.step(rng.uniform(-1, 1, 12).astype(np.float32))
        if term or trunc:
            obs, _ = env.reset()
    return np.array(out, dtype=np.float32)


@pytest.mark.parametrize("algo", ["ppo", "sac"])
def test_onnx_export_matches_predict(tmp_path, algo, capfd, recwarn):
    import onnx
    import onnxruntime as ort

    from agents.cli import main

    path, env, _ = _model_folder(tmp_path, algo, np.random.default_rng(0))
    capfd.readouterr()
    recwarn.clear()
    assert main(["export", "--policy", str(path), "--out", str(tmp_path / "p.onnx")]) == 0
    printed = capfd.readouterr()
    assert "torchvision" not in printed.err and "Warning" not in printed.err, printed.err  # no third-party notes
    assert not [w for w in recwarn if issubclass(w.category, FutureWarning | DeprecationWarning)]
    policy = load_sb3_policy(path, gym.make("QuadUneven-v0", terrain="flat"), algo)
    obs = _recorded_observations(env)
    want = np.array([policy.predict(o)[0] for o in obs])
    assert np.abs(want).max() > 0.05, "a degenerate policy would not test the graph"
    session = ort.InferenceSession(str(tmp_path / "p.onnx"), providers=["CPUExecutionProvider"])
    got = session.run(None, {"obs": obs})[0]
    # float32 both ways; folding 1 / std (std down to 0.01 here) into the first layer scales its rounding.
    np.testing.assert_allclose(got, want, rtol=0, atol=5e-5)
    props = {p.key: p.value for p in onnx.load(str(tmp_path / "p.onnx")).metadata_props}
    layout = json.loads(props["observation_layout"])
    assert layout["stability_index"] == [38, 39] and props["observation_normalization"] == "folded"
    assert props["algo"] == algo and json.loads(props["action_low"]) == [-1.0] * 12


@pytest.mark.parametrize("algo", ["ppo", "sac"])
def test_the_algorithm_is_read_from_the_model_folder(tmp_path, algo):
    """``quad-uneven evaluate --policy DIR/model.zip`` without --algo loads the class rl_meta.json records."""
    from agents.evaluation.policies import PolicyError, make_policy, model_algo

    path, _, _ = _model_folder(tmp_path, algo, np.random.default_rng(2))
    assert model_algo(path) == algo and model_algo(path, "ppo") == "ppo"
    policy = make_policy(str(path), gym.make("QuadUneven-v0", terrain="flat"))
    assert type(policy.model).__name__ == algo.upper()
    if algo == "sac":  # evaluate() resolves it too, and records the class it used
        from agents.evaluation.run import evaluate
        from agents.evaluation.suites import suite_from_dict

        suite = suite_from_dict(
            {"name": "t", "goal_distance": 5.0, "time_limit": 0.1, "terrains": [{"kind": "flat", "seeds": [0]}]},
            source="test",
        )
        meta = json.loads((tmp_path / "rl_meta.json").read_text())
        (tmp_path / "rl_meta.json").write_text(json.dumps({**meta, "env_kwargs": {}}))  # the suite sets the terrain
        res = evaluate(suite, str(path), tmp_path / "eval", progress=False)
        assert res["meta"]["algo"] == "sac" and res["episodes"][0]["error"] is None
    (tmp_path / "rl_meta.json").unlink()
    assert model_algo(path) == "ppo"  # a folder without metadata (an older run): PPO, as before
    with pytest.raises(PolicyError, match="algo must be one of"):
        model_algo(path, "dqn")


def test_pickled_statistics_are_refused_unless_allowed(tmp_path):
    import builtins

    path, env, _ = _model_folder(tmp_path, "ppo", np.random.default_rng(1))
    (tmp_path / "model_obs_norm.npz").unlink()
    (tmp_path / "model_vecnormalize.pkl").write_bytes(pickle.dumps(_Boom()))
    with pytest.raises(ModelError, match="pickle"):
        load_sb3_policy(path, env, "ppo")
    assert not getattr(builtins, "QUAD_UNEVEN_PWNED", False)


def test_a_crafted_pickle_inside_the_model_zip_is_not_run(tmp_path):
    import builtins

    path, env, _ = _model_folder(tmp_path, "ppo", np.random.default_rng(2))
    with zipfile.ZipFile(path) as z:
        files = {n: z.read(n) for n in z.namelist()}
    data = json.loads(files["data"])
    # where SB3 keeps its cloudpickled entries: a known key, and one this loader does not know
    payload = base64.b64encode(pickle.dumps(_Boom())).decode()
    data["lr_schedule"] = {":type:": "<class 'function'>", ":serialized:": payload}
    files["data"] = json.dumps(data).encode()
    with zipfile.ZipFile(path, "w") as z:
        for n, b in files.items():
            z.writestr(n, b)
    load_sb3_model(path, "ppo", env)  # the known key is replaced, not unpickled
    assert not getattr(builtins, "QUAD_UNEVEN_PWNED", False)
    data["my_hook"] = {":type:": "<class 'function'>", ":serialized:": payload}
    files["data"] = json.dumps(data).encode()
    with zipfile.ZipFile(path, "w") as z:
        for n, b in files.items():
            z.writestr(n, b)
    with pytest.raises(ModelError, match="my_hook"):
        load_sb3_model(path, "ppo", env)
    assert not getattr(builtins, "QUAD_UNEVEN_PWNED", False)


def test_a_model_for_another_observation_space_is_refused(tmp_path):
    path, _, _ = _model_folder(tmp_path, "ppo", np.random.default_rng(3))
    other = gym.make("QuadUneven-v0", terrain="flat", height_scan={"size_x": 0.4, "size_y": 0.4})
    with pytest.raises(ModelError, match="observation space of shape"):
        load_sb3_model(path, "ppo", other)


def test_statistics_round_trip_and_match_vecnormalize(tmp_path):
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    venv = VecNormalize(DummyVecEnv([lambda: gym.make("QuadUneven-v0", terrain="flat")]), norm_reward=False)
    venv.reset()
    rng = np.random.default_rng(5)
    for _ in range(30):
        venv.step(rng.uniform(-1, 1, (1, 12)).astype(np.float32))
    norm = ObsNormalization.load(ObsNormalization.from_vecnormalize(venv).save(tmp_path / "s.npz"))
    obs = venv.get_original_obs()
    np.testing.assert_array_equal(norm.normalize(obs), venv.normalize_obs(obs))
    (tmp_path / "bad.npz").write_bytes(b"not a zip")
    with pytest.raises(ValueError, match="unreadable"):
        ObsNormalization.load(tmp_path / "bad.npz")


def test_onnx_export_of_a_residual_model_with_expert_features(tmp_path):
    """The exported graph takes env observation + expert features, and equals the evaluation's predict."""
    import onnx
    import onnxruntime as ort

    from agents.evaluation.policies import make_policy, make_policy_env
    from agents.rl.expert_features import EXPERT_FEATURE_SIZE, expert_features
    from agents.rl.export import export_onnx
    from agents.rl.residual_env import RESIDUAL_ENV_ID

    path = _residual_model_folder(tmp_path)
    export_onnx(path, tmp_path / "p.onnx")
    props = {p.key: p.value for p in onnx.load(str(tmp_path / "p.onnx")).metadata_props}
    assert json.loads(props["residual_basis"]) == "expert_torque" and json.loads(props["residual_legs"]) == "all"
    assert props["env_id"] == RESIDUAL_ENV_ID and props["robot"] == "paper"
    layout = json.loads(props["observation_layout"])
    n_env = gym.make("QuadUneven-v0", terrain="flat").observation_space.shape[0]
    assert layout["expert_base_pos_error"][0] == n_env and layout["expert_torque"][1] == n_env + EXPERT_FEATURE_SIZE

    env = make_policy_env(str(path), terrain="flat")
    policy = make_policy(str(path), env)
    assert env.unwrapped.controller.residual_basis == "expert_torque"
    obs, _ = env.reset(seed=0)
    session = ort.InferenceSession(str(tmp_path / "p.onnx"), providers=["CPUExecutionProvider"])
    for _ in range(20):
        # the env's observation carries the expert features, as the expert reports them
        np.testing.assert_array_equal(obs[n_env:], expert_features(policy.expert, env.unwrapped.data))
        action, _ = policy.predict(obs)
        np.testing.assert_allclose(session.run(None, {"obs": obs[None].astype(np.float32)})[0][0], action, atol=1e-5)
        obs, *_ = env.step(action)
    assert np.abs(action).max() > 0.05


def _residual_model_folder(tmp_path, **meta) -> Path:
    """An untrained residual PPO (expert features, ``expert_torque`` basis) with random weights, its metadata."""
    import stable_baselines3
    import torch

    from agents.rl.residual_env import RESIDUAL_ENV_ID

    train_env = gym.make(RESIDUAL_ENV_ID, terrain="flat", residual_basis="expert_torque")
    model = stable_baselines3.PPO("MlpPolicy", train_env, n_steps=64, batch_size=32, device="cpu", seed=0,
                                  policy_kwargs={"net_arch": [32, 32]})  # fmt: skip
    with torch.no_grad():
        for p in model.policy.parameters():
            p.add_(0.3 * torch.randn_like(p))
    model.save(tmp_path / "model.zip")
    write_metadata(tmp_path, {"algo": "ppo", "residual": True, "residual_scale": 0.1, "expert_features": True,
                              "normalize_obs": False, "env_kwargs": {"terrain": "flat"},
                              "residual_basis": "expert_torque", **meta})  # fmt: skip
    return tmp_path / "model.zip"


def test_a_residual_model_is_evaluated_in_the_env_it_was_trained_in(tmp_path):
    """The model's env, rebuilt from rl_meta.json, gives the observations of the training env
    (:func:`agents.rl.vec_env.make_train_env` with the run's residual config), bit for bit."""
    from agents.rl.model_io import make_model_env
    from agents.rl.residual_config import ResidualConfig
    from agents.rl.vec_env import make_train_env

    path = _residual_model_folder(tmp_path, residual_legs="stance")
    config = ResidualConfig(residual_scale=0.1, residual_legs="stance", residual_basis="expert_torque")
    trained_in = make_train_env("rough", 1000, {}, None, config)
    evaluated_in = make_model_env(path, terrain="rough", max_episode_steps=1000)
    rng = np.random.default_rng(3)
    obs_a, _ = trained_in.reset(seed=11)
    obs_b, _ = evaluated_in.reset(seed=11)
    np.testing.assert_array_equal(obs_a, obs_b)
    for _ in range(60):
        action = rng.uniform(-1, 1, 12).astype(np.float32)
        obs_a, reward_a, *_ = trained_in.step(action)
        obs_b, reward_b, *_ = evaluated_in.step(action)
        np.testing.assert_array_equal(obs_a, obs_b)
        assert reward_a == reward_b


def test_loading_a_model_never_installs_a_controller_on_the_callers_env(tmp_path):
    """A residual model given a plain QuadUneven-v0 env is refused, the env left as it was; an env with another
    residual, a plain model given a residual env and an env on another robot are refused by name."""
    from agents.rl.residual_env import RESIDUAL_ENV_ID

    path = _residual_model_folder(tmp_path)
    plain = gym.make("QuadUneven-v0", terrain="flat")
    with pytest.raises(ModelError, match=f"is a residual model: it runs in {RESIDUAL_ENV_ID}"):
        load_sb3_policy(path, plain, "ppo")
    assert plain.unwrapped.controller is None
    other = gym.make(RESIDUAL_ENV_ID, terrain="flat", residual_basis="torque_limit")
    controller = other.unwrapped.controller
    with pytest.raises(ModelError, match="trained with residual_basis='expert_torque', the env has residual_basis="):
        load_sb3_policy(path, other, "ppo")
    assert other.unwrapped.controller is controller
    go1 = gym.make(RESIDUAL_ENV_ID, terrain="flat", residual_basis="expert_torque", robot="go1")
    with pytest.raises(ModelError, match=r"^robot must be 'paper', the robot .* was trained on, got 'go1'"):
        load_sb3_policy(path, go1, "ppo")

    (tmp_path / "scratch").mkdir()
    scratch, _, _ = _model_folder(tmp_path / "scratch", "ppo", np.random.default_rng(0))
    with pytest.raises(ModelError, match="trained without the expert"):
        load_sb3_policy(scratch, gym.make(RESIDUAL_ENV_ID, terrain="flat"), "ppo")
