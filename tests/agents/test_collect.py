"""quad-uneven collect: the expert's episodes as a Minari dataset (shapes, actions from the applied torques,
determinism, resume, loading and the recovered env) and the command's errors."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import yaml

import quad_uneven_env  # noqa: F401  (registers QuadUneven-v0)
from agents.cli import main

minari = pytest.importorskip("minari", reason="the 'datasets' extra (Minari) is not installed")

import agents.datasets.run as collect_module  # noqa: E402
from agents.datasets import (  # noqa: E402
    CollectInterrupted,
    TorqueRecorder,
    TorqueReplay,
    collect,
    episode_env,
    episode_metadata,
    load_collected,
    recorded_action,
)
from agents.datasets.recorder import info_fields  # noqa: E402

TIME_LIMIT = 1.0  # s: 50 control steps per episode


def write_suite(path: Path, **overrides) -> Path:
    """The smoke suite's flat and rough entries with a 1 s time limit (two terrains, one seed each with
    --episodes 1; the rough entry has a second seed)."""
    raw = yaml.safe_load(Path("configs/suites/smoke.yaml").read_text())
    raw.update(name="smoke-short", time_limit=TIME_LIMIT, terrains=raw["terrains"][:2])
    raw["terrains"][1]["seeds"] = [0, 1]
    raw.update(overrides)
    path.write_text(yaml.safe_dump(raw))
    return path


def episodes_of(dataset) -> list:
    return [dataset[i] for i in range(dataset.total_episodes)]


def flat_infos(infos: dict, prefix: str = "") -> dict[str, np.ndarray]:
    out = {}
    for k, v in infos.items():
        if isinstance(v, dict):
            out.update(flat_infos(v, f"{prefix}{k}/"))
        else:
            out[prefix + k] = np.asarray(v)
    return out


def assert_same_episodes(a, b) -> None:
    assert a.total_episodes == b.total_episodes
    for ea, eb in zip(episodes_of(a), episodes_of(b), strict=True):
        for name in ("observations", "actions", "rewards", "terminations", "truncations"):
            np.testing.assert_array_equal(getattr(ea, name), getattr(eb, name), err_msg=name)
        ia, ib = flat_infos(ea.infos), flat_infos(eb.infos)
        assert ia.keys() == ib.keys()
        for k in ia:
            np.testing.assert_array_equal(ia[k], ib[k], err_msg=k)


@pytest.fixture(scope="module")
def collected(tmp_path_factory):
    """One collection through the CLI: the two entries, --episodes 1 (2 episodes of 50 steps)."""
    root = tmp_path_factory.mktemp("collect")
    suite = write_suite(root / "suite.yaml")
    out = root / "out"
    code = main(["collect", "--policy", "expert", "--suite", str(suite), "--out", str(out), "--episodes", "1",
                 "--no-progress"])  # fmt: skip
    assert code == 0
    return suite, out


def test_the_dataset_loads_with_minari_and_has_the_documented_fields(collected, monkeypatch):
    _, out = collected
    summary = json.loads((out / "collect.json").read_text())
    assert summary["dataset_id"] == "quad-uneven-smoke-short-expert-v0"
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(out))
    dataset = minari.load_dataset(summary["dataset_id"])
    assert dataset.total_episodes == 2 and dataset.total_steps == summary["steps"] == 100
    assert not list(out.glob("episodes/*.npz"))  # the arrays live in the dataset only
    u = gym.make("QuadUneven-v0", terrain="flat").unwrapped
    fs = u.frame_skip
    for ep in episodes_of(dataset):
        n = len(ep)
        assert n == round(TIME_LIMIT / u.dt)
        assert ep.observations.shape == (n + 1, *u.observation_space.shape) and ep.observations.dtype == np.float32
        assert ep.actions.shape == (n, 12) and ep.actions.dtype == np.float32
        assert all(dataset.action_space.contains(a) for a in ep.actions)
        assert np.abs(ep.actions).mean() > 0.01  # the expert's torques, not the zero action it passes to step
        assert ep.rewards.shape == ep.terminations.shape == ep.truncations.shape == (n,)
        # the episode ran into the suite's time limit: truncated at its last step only
        assert ep.truncations[-1] and not ep.truncations[:-1].any() and not ep.terminations.any()
        infos = ep.infos
        assert sorted(infos) == sorted(info_fields(command=False))
        shapes = {
            "torques": (fs, 12), "edge_moments": (4,), "contact_forces": (4, 3), "foot_contact": (4,),
            "planned_stance": (4,), "joint_reference": (12,), "joint_velocity_reference": (12,), "gait_phase": (),
            "stability_index": (), "cog": (3,), "feet_pos": (4, 3), "time": (),
        }  # fmt: skip
        for k, shape in shapes.items():
            assert infos[k].shape == (n + 1, *shape), k
        assert infos["torques"].dtype == np.float64 and infos["planned_stance"].dtype == bool
        assert set(infos["reward_terms"]) >= {"forward_progress", "stability"}
        assert all(v.shape == (n + 1,) for v in infos["reward_terms"].values())
        np.testing.assert_allclose(np.diff(infos["time"]), u.dt, atol=1e-9)
        assert ((infos["gait_phase"] >= 0) & (infos["gait_phase"] <= 1)).all()
        assert np.abs(infos["torques"][1:]).max() <= u.idx.torque_limit.max()


def test_the_infos_torques_average_to_the_recorded_action(collected):
    _, out = collected
    dataset = load_collected(out)
    limit = gym.make("QuadUneven-v0", terrain="flat").unwrapped.idx.torque_limit
    for ep in episodes_of(dataset):
        torques = ep.infos["torques"]
        assert not torques[0].any()  # the reset: no physics step yet
        np.testing.assert_allclose(torques[1:].mean(axis=1) / limit, ep.actions, atol=1e-6)


def test_the_observed_previous_action_is_the_recorded_action(collected):
    """What the plain env shows a policy that took the recorded actions (the expert itself passes zeros)."""
    _, out = collected
    ep = load_collected(out)[0]
    sl = gym.make("QuadUneven-v0", terrain="flat").unwrapped.observation_structure["prev_action"]
    assert not ep.observations[0, sl].any()
    np.testing.assert_array_equal(ep.observations[1:, sl], ep.actions)


def test_episode_metadata_rebuilds_each_episodes_env(collected):
    _, out = collected
    dataset = load_collected(out)
    kinds = []
    for i, ep in enumerate(episodes_of(dataset)):
        meta = episode_metadata(dataset, i)
        kinds.append(meta["terrain_kind"])
        assert meta["seed"] == 0 and meta["entry"] == i and meta["suite"] == "smoke-short"
        assert meta["terrain"]["kind"] == meta["env_kwargs"]["terrain"]["kind"] == meta["terrain_kind"]
        assert meta["end_reason"] == "time_limit" and meta["randomization"] is None and meta["command"] is None
        env = episode_env(dataset, i)
        obs, _ = env.reset(seed=meta["seed"])
        np.testing.assert_array_equal(obs, ep.observations[0])  # the same terrain and spawn
        assert env.spec.max_episode_steps == len(ep)
    assert kinds == ["flat", "rough"]


def test_recover_environment_is_the_first_episodes_env_and_steps(collected):
    _, out = collected
    dataset = load_collected(out)
    env = dataset.recover_environment()
    meta = episode_metadata(dataset, 0)
    assert env.spec.id == "QuadUneven-v0"
    assert {**env.spec.kwargs, "max_episode_steps": env.spec.max_episode_steps} == meta["env_kwargs"]
    assert env.unwrapped.action_mode == "torque" and env.unwrapped.controller is None
    obs, _ = env.reset(seed=meta["seed"])
    ep = dataset[0]
    np.testing.assert_array_equal(obs, ep.observations[0])
    obs, reward, terminated, _, _ = env.step(ep.actions[0])
    assert obs.shape == ep.observations.shape[1:] and np.isfinite(reward) and not terminated


def test_replaying_the_physics_rate_torques_reproduces_the_episode(collected):
    """The infos' torques are exactly what was applied: replayed at physics rate they walk the same trajectory."""
    _, out = collected
    dataset = load_collected(out)
    ep = dataset[1]  # rough terrain
    env = episode_env(dataset, 1)
    env.unwrapped.set_controller(TorqueReplay(ep.infos["torques"][1:]))
    obs, _ = env.reset(seed=episode_metadata(dataset, 1)["seed"])
    for t, action in enumerate(ep.actions):
        obs, reward, *_ = env.step(action)  # the action is ignored under a controller, but shows in prev_action
        np.testing.assert_array_equal(obs, ep.observations[t + 1], err_msg=f"step {t}")
        assert reward == ep.rewards[t]


def test_the_same_command_twice_gives_identical_arrays_with_workers(collected, tmp_path):
    suite, out = collected
    collect(suite, tmp_path / "again", episodes=1, workers=2, progress=False)
    assert_same_episodes(load_collected(out), load_collected(tmp_path / "again"))


def test_an_interrupted_collection_leaves_no_dataset_and_resumes(collected, tmp_path, monkeypatch):
    suite, out = collected
    calls = []
    real = collect_module.collect_task

    def interrupted_after_one(task, cfg):
        calls.append(task.index)
        if len(calls) > 1:
            raise KeyboardInterrupt
        return real(task, cfg)

    monkeypatch.setattr(collect_module, "collect_task", interrupted_after_one)
    target = tmp_path / "resumed"
    with pytest.raises(CollectInterrupted, match="1 of 2 episodes finished"):
        collect(suite, target, episodes=1, progress=False)
    assert (target / "episodes" / "ep000.json").is_file() and not (target / "episodes" / "ep001.json").exists()
    assert not (target / "collect.json").exists() and not list(target.glob("quad-uneven-*"))
    assert not list(target.glob(".*.tmp"))
    with pytest.raises(FileNotFoundError, match="holds 0 finished datasets"):
        load_collected(target)

    calls.clear()
    monkeypatch.setattr(collect_module, "collect_task", lambda task, cfg: calls.append(task.index) or real(task, cfg))
    summary = collect(suite, target, episodes=1, progress=False, resume=True)
    assert calls == [1] and summary["resumed_episodes"] == 1
    assert_same_episodes(load_collected(out), load_collected(target))

    calls.clear()  # a finished collection: nothing is collected again
    collect(suite, target, episodes=1, progress=False, resume=True)
    assert calls == []
    assert_same_episodes(load_collected(out), load_collected(target))


def test_resume_refuses_another_collection_and_overwrite_starts_again(collected, capsys):
    suite, out = collected
    args = ["collect", "--policy", "expert", "--suite", str(suite), "--out", str(out), "--episodes", "1"]
    assert main([*args, "--resume", "--seed", "1", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: --resume: seed_offset differs") and err.count("\n") == 1
    assert main([*args, "--no-progress"]) == 2
    assert "is not empty" in capsys.readouterr().err


def test_recorded_action_is_the_mean_torque_over_the_limit():
    limit = np.full(12, 120.0)
    torques = np.outer(np.arange(10.0), np.ones(12)) * 12.0  # 0, 12, ..., 108 N m: mean 54 N m
    np.testing.assert_allclose(recorded_action(torques, limit), np.full(12, 0.45), rtol=1e-6)
    assert recorded_action(np.full((10, 12), 500.0), limit).max() == 1.0  # never outside the action space


class StepCounter:
    """A stand-in expert: at physics step k of the episode it commands k N m on every joint (its lane declines)."""

    def __init__(self) -> None:
        self.k = 0

    def reset(self, model, data, terrain) -> None:
        self.k = 0

    def __call__(self, model, data, action) -> np.ndarray:
        self.k += 1
        return np.full(12, float(self.k))

    def torques_into(self, model, data, action, out, limit) -> bool:
        return False


@pytest.mark.parametrize("latency_steps", [0, 2])
def test_the_torque_recorder_keeps_the_torques_applied_at_each_physics_step(latency_steps):
    """Commanded k N m at physics step k, applied ``latency_steps`` physics steps late (zero before the first)."""
    dt = 0.002
    randomization = {"latency": [latency_steps * dt, latency_steps * dt]} if latency_steps else None
    env = gym.make("QuadUneven-v0", terrain="flat", randomization=randomization)
    u = env.unwrapped
    recorder = TorqueRecorder(StepCounter(), u.frame_skip)
    u.set_controller(recorder)
    env.reset(seed=0)
    fs = u.frame_skip
    for step in range(2):
        env.step(np.zeros(12))
        commanded = np.arange(step * fs + 1, (step + 1) * fs + 1) - latency_steps
        expected = np.where(commanded > 0, commanded, 0.0)
        np.testing.assert_array_equal(recorder.end_step(u.data), np.outer(expected, np.ones(12)))


def test_cli_errors_are_one_line_with_exit_code_2(tmp_path, capsys):
    suite = write_suite(tmp_path / "suite.yaml")
    base = ["collect", "--suite", str(suite), "--out", str(tmp_path / "o"), "--no-progress"]
    cases = [
        (["--policy", "zero"], "--policy must be 'expert'"),
        (["--policy", "models/ppo_scratch/model.zip"], "--policy must be 'expert'"),
        (["--policy", "expert", "--suite", "nope"], "invalid suite 'nope'"),
        (["--policy", "expert", "--episodes", "0"], "--episodes must be >= 1"),
        (["--policy", "expert", "--workers", "0"], "--workers must be >= 1"),
        (["--policy", "expert", "--env-kwargs", '{"action_mode": "joint_pd"}'], "env_kwargs.action_mode must be"),
        (["--policy", "expert", "--env-kwargs", '{"terrain": "flat"}'], "env_kwargs.terrain is set by"),
        (["--policy", "expert", "--resume", "--overwrite"], "--resume and --overwrite exclude each other"),
    ]
    for extra, message in cases:
        assert main([*base, *extra]) == 2, extra
        err = capsys.readouterr().err
        assert err.startswith("error: ") and message in err and err.count("\n") == 1, (extra, err)
    assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())


def test_a_suite_mixing_command_and_plain_entries_is_refused(tmp_path, capsys):
    raw = yaml.safe_load(write_suite(tmp_path / "s.yaml").read_text())
    raw["terrains"][1]["command"] = {"vx": 0.1}
    suite = tmp_path / "mixed.yaml"
    suite.write_text(yaml.safe_dump(raw))
    code = main(["collect", "--policy", "expert", "--suite", str(suite), "--out", str(tmp_path / "o"), "--episodes",
                 "1", "--no-progress"])  # fmt: skip
    err = capsys.readouterr().err
    assert code == 2 and "one dataset holds one observation space" in err and err.count("\n") == 1
    assert not (tmp_path / "o" / "run.json").exists()


def test_without_minari_collect_names_the_extra(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "minari", None)  # import minari raises ImportError
    suite = write_suite(tmp_path / "suite.yaml")
    code = main(["collect", "--policy", "expert", "--suite", str(suite), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert code == 2 and "'datasets' extra" in err and 'pip install -e ".[datasets]"' in err
    assert not (tmp_path / "o").exists()


def test_overwrite_replaces_the_collection_and_keeps_the_users_files(tmp_path):
    suite, out = write_suite(tmp_path / "suite.yaml"), tmp_path / "out"
    args = [
        "collect",
        "--policy",
        "expert",
        "--suite",
        str(suite),
        "--out",
        str(out),
        "--episodes",
        "1",
        "--no-progress",
    ]
    assert main(args) == 0
    (out / "episodes" / "notes.txt").write_text("mine")
    (out / "plot.png").write_bytes(b"mine")
    assert main([*args, "--overwrite"]) == 0
    assert (out / "episodes" / "notes.txt").read_text() == "mine"
    assert (out / "plot.png").read_bytes() == b"mine"
    assert (out / "collect.json").is_file() and any(out.glob("quad-uneven-*/data/metadata.json"))
