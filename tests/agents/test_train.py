"""quad-uneven train: config validation, bad options named, a tiny PPO run that evaluate can load."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from agents.cli import main
from agents.rl.config import TrainConfigError, default_config_path, load_train_config

TINY = {
    "timesteps": 64,
    "n_envs": 1,
    "max_episode_steps": 40,
    "eval_freq": 32,
    "eval_episodes": 1,
    "checkpoint_freq": 32,
    "hyperparams": {"n_steps": 32, "batch_size": 16, "n_epochs": 1},
    "policy_kwargs": {"net_arch": [16], "log_std_init": -2.5},
}
"""Overrides of the shipped PPO config for a run of a few seconds (episodes of 40 steps = 0.8 s)."""


def write_config(path: Path, **changes) -> Path:
    raw = yaml.safe_load(default_config_path("ppo").read_text())
    raw.update(TINY)
    raw.update(changes)
    path.write_text(yaml.safe_dump(raw))
    return path


@pytest.mark.parametrize("algo", ["ppo", "sac"])
def test_shipped_configs_are_valid(algo):
    cfg = load_train_config(None, {"algo": algo})
    # a small residual: at most 0.2 of the motor limit added, or a gain of 1 +- 0.5 on the expert's torque
    limit = 0.2 if cfg.residual_basis == "torque_limit" else 0.5
    assert cfg.algo == algo and 0 < cfg.residual_scale <= limit
    assert load_train_config(default_config_path(algo)).to_dict() == cfg.to_dict()


@pytest.mark.parametrize(
    ("argv", "field"),
    [
        (["--timesteps", "0"], "timesteps"),
        (["--n-envs", "0"], "n_envs"),
        (["--seed", "-1"], "seed"),
        (["--terrain", "lava"], "terrain"),
        (["--terrain", "rough", "lava"], "terrain[1]"),
        (["--randomization", "stormy"], "randomization"),
        (["--residual-scale", "2"], "residual_scale"),
        (["--time-limit-min", "-1"], "time_limit_min"),
        (["--algo", "sac", "--config", str(default_config_path("ppo"))], "algo"),
    ],
)
def test_bad_train_options_exit_2_naming_the_field(tmp_path, capsys, argv, field):
    rc = main(["train", "--out", str(tmp_path / "run"), "--no-progress", *argv])
    err = capsys.readouterr().err
    assert rc == 2
    assert err.startswith(f"error: {field}")
    assert not (tmp_path / "run").exists()  # rejected before anything is written


def test_argparse_rejects_unknown_algo_and_non_integer_timesteps(tmp_path, capsys):
    for argv, name in ((["--algo", "dqn"], "--algo"), (["--timesteps", "many"], "--timesteps")):
        assert main(["train", "--out", str(tmp_path), *argv]) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"error: argument {name}") and err.count("\n") == 1


@pytest.mark.parametrize(
    ("changes", "field"),
    [
        ({"bogus": 1}, "bogus"),
        ({"env_kwargs": {"terrain": "flat"}}, "env_kwargs"),
        ({"hyperparams": {"seed": 3}}, "hyperparams"),
        ({"normalize_obs": "yes"}, "normalize_obs"),
        ({"vec_env": "threads"}, "vec_env"),
        ({"eval_episodes": 0}, "eval_episodes"),
        ({"residual": False}, "residual"),  # expert_features still on
        ({"residual": "no"}, "residual"),
        ({"residual_legs": "swing"}, "residual_legs"),
        ({"residual": False, "expert_features": False, "residual_legs": "stance"}, "residual"),
        ({"residual_basis": "gain"}, "residual_basis"),
        ({"residual": False, "expert_features": False, "residual_basis": "expert_torque"}, "residual"),
        ({"initial_action": 0.2}, "initial_action"),  # not a field
    ],
)
def test_bad_config_fields_are_named(tmp_path, changes, field):
    with pytest.raises(TrainConfigError, match=f"^{field}"):
        load_train_config(write_config(tmp_path / "c.yaml", **changes))


def test_unknown_hyperparameter_is_named(tmp_path):
    with pytest.raises(TrainConfigError, match=r"^hyperparams\.n_stepz: not an SB3 PPO argument"):
        load_train_config(write_config(tmp_path / "c.yaml", hyperparams={"n_stepz": 8}))


def test_episode_stats_wrapper_on_a_stub_env():
    import gymnasium as gym

    from agents.rl.vec_env import EPISODE_KEYS, EpisodeStats

    class Stub(gym.Env):
        observation_space = gym.spaces.Box(-1, 1, (1,))
        action_space = gym.spaces.Box(-1, 1, (1,))
        index = (10.0, -math.inf, 20.0, -3.0)

        def reset(self, *, seed=None, options=None):
            self.t = 0
            return np.zeros(1, np.float32), {}

        def step(self, action):
            i = self.index[self.t]
            self.t += 1
            end = self.t == len(self.index)
            info = {"stability_index": i, "distance": 0.1 * self.t, "diverged": end}
            return np.zeros(1, np.float32), 0.0, end, False, info

    env = EpisodeStats(Stub())
    for _ in range(2):  # statistics restart at every reset
        env.reset()
        infos = [env.step(np.zeros(1))[4] for _ in range(4)]
        assert not any(k in infos[0] for k in EPISODE_KEYS)
        last = infos[-1]
        assert last["ep_stability_mean"] == pytest.approx(9.0)  # the -inf step (< 3 feet) is left out
        assert last["ep_stability_min"] == -3.0
        assert last["ep_distance"] == pytest.approx(0.4)
        assert last["ep_diverged"] == 1 and last["ep_fell"] == 1


def test_tiny_ppo_run_saves_a_model_that_evaluate_runs_with_the_expert(tmp_path, capsys):
    from agents.evaluation.run import evaluate
    from agents.evaluation.suites import suite_from_dict
    from agents.rl.learning_curve import read_monitor

    run = tmp_path / "run"
    tb = tmp_path / "tb"
    rc = main(["train", "--config", str(write_config(tmp_path / "c.yaml")), "--out", str(run), "--no-progress",
               "--tensorboard", str(tb)])  # fmt: skip
    assert rc == 0, capsys.readouterr().err
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    events = EventAccumulator(str(next(tb.iterdir()))).Reload()
    scalars = set(events.Tags()["scalars"])
    assert {"episode/stability_mean", "episode/distance", "episode/fall_rate", "episode/residual_torque"} <= scalars
    assert "train/value_loss" in scalars  # SB3's own
    for name in ("model.zip", "model_obs_norm.npz", "rl_meta.json", "learning_curve.png", "train_config.json"):
        assert (run / name).is_file(), name
    assert (run / "eval" / "evaluations.npz").is_file()
    assert sorted(p.name for p in (run / "checkpoints").glob("*.zip")) == ["model_32_steps.zip", "model_64_steps.zip"]
    assert (run / "checkpoints" / "model_obs_norm_32_steps.npz").is_file() and (
        run / "best" / "best_model_obs_norm.npz"
    ).is_file()
    assert not list(run.rglob("*.pkl")), "a training run writes no pickles"
    meta = json.loads((run / "rl_meta.json").read_text())
    assert meta["residual"] is True and meta["algo"] == "ppo" and meta["residual_scale"] == 0.1
    summary = json.loads((run / "train_summary.json").read_text())
    assert summary["timesteps"] == 64 and summary["episodes"] == 1  # 64 steps: one 40-step episode ended
    mon = read_monitor(run / "monitor")
    assert mon["l"].tolist() == [40.0]
    assert np.isfinite(mon["ep_stability_mean"]).all() and np.isfinite(mon["ep_distance"]).all()

    suite = suite_from_dict(
        {"name": "t", "goal_distance": 5.0, "time_limit": 0.4, "terrains": [{"kind": "rough", "seeds": [0]}]},
        source="test",
    )
    for model in (run / "model.zip", run / "checkpoints" / "model_32_steps.zip", run / "best" / "best_model.zip"):
        res = evaluate(suite, str(model), tmp_path / f"eval_{model.stem}", progress=False)
        e = res["episodes"][0]
        assert e["error"] is None and e["sim_time"] == pytest.approx(0.4)
        assert e["planner_calls"] >= 1  # the expert is in the loop
        assert e["mean_residual_torque"] is not None and 0.0 <= e["mean_residual_torque"] <= 12.0

    rc = main(["evaluate", "--policy", str(run / "model.zip"), "--algo", "sac", "--suite", "smoke",
               "--out", str(tmp_path / "e2"), "--no-progress"])  # fmt: skip
    assert rc == 2 and "algo" in capsys.readouterr().err


def test_tiny_run_from_scratch_evaluates_on_the_plain_env(tmp_path):
    """residual: false trains on QuadUneven-v0 in joint_pd mode: no expert in the loop at training or in
    evaluate, and the recorded env_kwargs rebuild that env; the shipped config is valid."""
    from agents.evaluation.run import evaluate
    from agents.evaluation.suites import suite_from_dict
    from agents.rl.training import train

    shipped = load_train_config(Path("configs/rl/ppo_scratch.yaml"))
    assert shipped.residual is False and shipped.time_limit_min == 35
    cfg = load_train_config(
        write_config(tmp_path / "c.yaml", residual=False, expert_features=False, residual_penalty=0.0)
    )
    train(cfg, tmp_path / "run", progress=False)
    meta = json.loads((tmp_path / "run" / "rl_meta.json").read_text())
    assert meta["residual"] is False and meta["env_id"] == "QuadUneven-v0"
    assert meta["env_kwargs"] == {"action_mode": "joint_pd"}
    suite = suite_from_dict(
        {"name": "t", "goal_distance": 5.0, "time_limit": 0.4, "terrains": [{"kind": "rough", "seeds": [0]}]},
        source="test",
    )
    e = evaluate(suite, str(tmp_path / "run" / "model.zip"), tmp_path / "eval", progress=False)["episodes"][0]
    assert e["error"] is None and e["planner_calls"] is None and e["mean_residual_torque"] is None


def test_residual_policy_runs_in_its_training_env_and_normalizes(tmp_path):
    """The model's env, rebuilt from rl_meta.json, has the training's residual controller; the policy acts on
    normalised observations of it."""
    import gymnasium as gym

    from agents.evaluation.policies import make_policy, make_policy_env
    from agents.rl.model_io import SB3Policy
    from agents.rl.residual_env import ResidualController
    from agents.rl.training import train

    cfg = load_train_config(
        write_config(
            tmp_path / "c.yaml",
            timesteps=32,
            eval_freq=0,
            checkpoint_freq=0,
            residual_legs="stance",
            residual_basis="expert_torque",
        )
    )
    train(cfg, tmp_path / "run", progress=False)
    path = str(tmp_path / "run" / "model.zip")
    meta_path = tmp_path / "run" / "rl_meta.json"
    meta = json.loads(meta_path.read_text())
    assert (meta["residual_legs"], meta["residual_basis"]) == ("stance", "expert_torque")
    assert meta["robot"] == "paper" and meta["residual_penalty"] == 0.0
    env = make_policy_env(path, terrain="flat")
    policy = make_policy(path, env)
    assert isinstance(policy, SB3Policy) and isinstance(env.unwrapped.controller, ResidualController)
    assert env.unwrapped.controller.residual_legs == "stance"  # the evaluation applies the training's gate
    assert env.unwrapped.controller.residual_basis == "expert_torque"
    assert policy.obs_normalizer is not None and policy.expert is env.unwrapped.controller.expert
    obs, _ = env.reset(seed=0)
    action, _ = policy.predict(obs)
    assert action.shape == (12,) and np.all(np.abs(action) <= 1)
    from agents.evaluation.policies import PolicyError

    meta_path.write_text(meta_path.read_text().replace('"residual_legs": "stance"', '"residual_legs": "swing"'))
    with pytest.raises(PolicyError, match="residual_legs must be one of"):
        make_policy(path, gym.make("QuadUneven-v0", terrain="flat"))
    with pytest.raises(PolicyError, match="residual_legs must be one of"):
        make_policy_env(path)
    meta_path.write_text(meta_path.read_text().replace('"residual_legs": "swing"', '"residual_legs": "stance"'))
    meta_path.write_text(meta_path.read_text().replace('"expert_torque"', '"gain"'))
    with pytest.raises(PolicyError, match="residual_basis must be one of"):
        make_policy(path, gym.make("QuadUneven-v0", terrain="flat"))
    meta_path.write_text(meta_path.read_text().replace('"gain"', '"expert_torque"'))
    (tmp_path / "run" / "model_obs_norm.npz").unlink()

    with pytest.raises(PolicyError, match=r"obs_norm\.npz is missing"):
        make_policy(path, make_policy_env(path, terrain="flat"))


def test_wall_clock_limit_stops_training_and_still_saves(tmp_path):
    from agents.rl.training import train

    cfg = load_train_config(
        write_config(tmp_path / "c.yaml", timesteps=10_000, time_limit_min=1e-9, eval_freq=0, checkpoint_freq=0)
    )
    summary = train(cfg, tmp_path / "run", progress=False)
    assert summary["time_limit_reached"] is True and summary["timesteps"] < 10_000
    assert (tmp_path / "run" / "model.zip").is_file()


@pytest.mark.parametrize(("algo", "sde"), [("PPO", False), ("SAC", False), ("SAC", True)])
def test_untrained_agent_commands_zero(algo, sde):
    """The mean-action layer starts at zero: the untrained deterministic agent commands 0 on every joint (the
    expert), through SAC's tanh squashing and its gSDE head too."""
    import gymnasium as gym
    import stable_baselines3

    from agents.rl.training import _zero_mean_action

    env = gym.wrappers.RescaleAction(gym.make("Pendulum-v1"), -1.0, 1.0)
    kwargs = {"use_sde": True} if sde else {}
    model = getattr(stable_baselines3, algo)(
        "MlpPolicy", env, policy_kwargs={"net_arch": [8]}, device="cpu", seed=0, **kwargs
    )
    obs = np.stack([env.observation_space.sample() for _ in range(5)])
    assert np.abs(model.predict(obs, deterministic=True)[0]).max() > 0  # not so by SB3's own init
    _zero_mean_action(model)
    np.testing.assert_array_equal(model.predict(obs, deterministic=True)[0], 0.0)


def test_sigterm_stops_training_and_still_saves(tmp_path, monkeypatch):
    import os
    import signal

    from agents.rl import training

    cfg = load_train_config(write_config(tmp_path / "c.yaml", timesteps=10_000, eval_freq=0, checkpoint_freq=0))
    original = training.ProgressCallback._on_step

    def step_then_terminate(self):
        if self.n_calls == 5:
            os.kill(os.getpid(), signal.SIGTERM)  # as `kill PID` would
        return original(self)

    monkeypatch.setattr(training.ProgressCallback, "_on_step", step_then_terminate)
    summary = training.train(cfg, tmp_path / "run", progress=False)
    assert summary["interrupted"] is True and summary["timesteps"] < 10_000
    assert (tmp_path / "run" / "model.zip").is_file() and (tmp_path / "run" / "model_obs_norm.npz").is_file()
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL  # the handler is removed after training


def test_a_non_empty_out_is_refused_and_overwrite_removes_the_old_run(tmp_path, capsys):
    run = tmp_path / "run"

    def argv(steps):
        config = write_config(tmp_path / f"c{steps}.yaml", timesteps=steps, eval_freq=0)
        return ["train", "--config", str(config), "--out", str(run), "--no-progress"]

    assert main(argv(64)) == 0
    old = sorted(p.name for p in (run / "checkpoints").glob("*.zip"))
    assert "model_64_steps.zip" in old
    (run / "notes.txt").write_text("mine")
    (run / "checkpoints" / "mine.zip").write_text("a user's file among the checkpoints")
    assert main(argv(32)) == 2
    err = capsys.readouterr().err
    assert "--out" in err and "checkpoints/" in err and "--overwrite" in err
    assert main([*argv(32), "--overwrite"]) == 0
    assert sorted(p.name for p in (run / "checkpoints").glob("*.zip")) == ["mine.zip", "model_32_steps.zip"]
    assert (run / "notes.txt").read_text() == "mine"


def test_overwrite_refuses_an_older_run_without_a_manifest(tmp_path, capsys):
    run = tmp_path / "run"
    (run / "checkpoints").mkdir(parents=True)
    (run / "checkpoints" / "model_999_steps.zip").write_text("an older version's checkpoint")
    argv = ["train", "--config", str(write_config(tmp_path / "c.yaml", timesteps=32, eval_freq=0)), "--out", str(run)]
    assert main([*argv, "--no-progress", "--overwrite"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: --out {str(run)!r} holds outputs (checkpoints/)") and "manifest" in err
    assert (run / "checkpoints" / "model_999_steps.zip").is_file()


def _fake_run(folder: Path, returns: list[float], evals: list[float] | None) -> Path:
    """A train folder with one monitor CSV (episodes of 100 steps) and optionally an evaluations.npz."""
    (folder / "monitor").mkdir(parents=True)
    lines = ['#{"t_start": 0, "env_id": "None"}', "r,l,t,ep_stability_mean,ep_distance,ep_fell"]
    lines += [f"{r},100,{i + 1},10.0,{0.1 * i},{i % 2}" for i, r in enumerate(returns)]
    (folder / "monitor" / "0.monitor.csv").write_text("\n".join(lines) + "\n")
    if evals is not None:
        (folder / "eval").mkdir()
        steps = 100 * np.arange(1, len(evals) + 1)
        np.savez(folder / "eval" / "evaluations.npz", timesteps=steps, results=np.array(evals)[:, None],
                 ep_lengths=np.full((len(evals), 1), 100))  # fmt: skip
    return folder


def test_plot_curves_draws_each_runs_rolling_means_and_evaluations(tmp_path, monkeypatch, capsys):
    import agents.plotting
    from agents.rl.learning_curve import rolling_mean

    a = _fake_run(tmp_path / "a", [1.0, 2.0, 3.0, 4.0], [5.0, 6.0])
    b = _fake_run(tmp_path / "b", [10.0, 0.0, 10.0], None)
    figures = []
    real_save = agents.plotting.save
    monkeypatch.setattr(
        agents.plotting, "save", lambda fig, path, **kw: figures.append(fig) or real_save(fig, path, **kw)
    )
    out = tmp_path / "fig.png"
    assert main(["plot-curves", str(a), str(b), "--labels", "fine-tuned", "scratch", "--out", str(out)]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and str(out) in capsys.readouterr().out
    returns, distance, falls = figures[0].axes
    lines = {line.get_label(): line for line in returns.lines}
    assert set(lines) == {
        "fine-tuned (training, rolling 20)",
        "fine-tuned (evaluation)",
        "scratch (training, rolling 20)",
    }
    np.testing.assert_allclose(lines["fine-tuned (training, rolling 20)"].get_xdata(), [100, 200, 300, 400])
    np.testing.assert_allclose(lines["fine-tuned (training, rolling 20)"].get_ydata(), [1.0, 1.5, 2.0, 2.5])
    np.testing.assert_allclose(
        lines["scratch (training, rolling 20)"].get_ydata(), rolling_mean(np.array([10.0, 0, 10]))
    )
    np.testing.assert_allclose(lines["fine-tuned (evaluation)"].get_ydata(), [5.0, 6.0])
    np.testing.assert_allclose(distance.lines[0].get_ydata(), [0.0, 0.05, 0.1, 0.15])
    np.testing.assert_allclose(falls.lines[1].get_ydata(), [0.0, 0.5, 1 / 3])


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["EMPTY"], "error: RUN: "),
        (["A", "--labels", "x", "y"], "error: --labels: 2 labels for 1 runs"),
        (["A", "--out", "fig.pdf"], "error: --out must be a .png"),
    ],
)
def test_plot_curves_bad_input_exits_2_with_one_line(tmp_path, capsys, argv, message):
    (tmp_path / "EMPTY").mkdir()
    _fake_run(tmp_path / "A", [1.0], None)
    argv = [str(tmp_path / x) if x in ("EMPTY", "A") else x for x in argv]
    if "--out" not in argv:
        argv += ["--out", str(tmp_path / "fig.png")]
    assert main(["plot-curves", *argv]) == 2
    err = capsys.readouterr().err
    assert err.startswith(message) and err.count("\n") == 1
