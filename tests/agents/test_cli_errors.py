"""Every bad input of every command: exit code 2 and one line on stderr naming the field, never a traceback.

One case per input a careless or hostile user gives: malformed YAML (suites, training configs,
terrain and robot files), env kwargs (not JSON, unknown, owned by the suite, bad values), demo
options, a robot file missing a joint, model files (corrupt, truncated, metadata without
``residual_scale``, another observation space) and output directories (a file, an earlier run's).
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import yaml

from agents.cli import main
from quad_uneven_env.config import CONFIG_DIR

ROOT = Path(__file__).resolve().parents[2]


@dataclass(frozen=True)
class Case:
    """One bad input: ``argv(tmp, models)`` builds the command line, ``fields`` must all be in the message."""

    argv: Callable[[Path, Path], list[str]]
    fields: tuple[str, ...]
    env_side: bool = False
    """the message comes from the environment's own validation of a value (see the test)."""


def suite_file(tmp: Path, **changes) -> Path:
    raw = {"name": "tiny", "goal_distance": 0.5, "time_limit": 0.1, "terrains": [{"kind": "flat", "seeds": [0, 1]}]}
    path = tmp / "suite.yaml"
    path.write_text(yaml.safe_dump({**raw, **changes}))
    return path


def text_file(tmp: Path, name: str, text: str) -> Path:
    path = tmp / name
    path.write_text(text)
    return path


def evaluate_argv(
    tmp: Path, *extra: str, policy: str = "zero", suite: Path | None = None, out: Path | None = None
) -> list[str]:
    suite, out = suite or suite_file(tmp), out or tmp / "out"
    return ["evaluate", "--policy", policy, "--suite", str(suite), "--out", str(out), "--no-progress", *extra]


def env_kwargs(tmp: Path, kwargs: str) -> list[str]:
    return evaluate_argv(tmp, "--env-kwargs", kwargs)


def robot_without(tmp: Path, table: str, joint: str) -> Path:
    raw = yaml.safe_load((CONFIG_DIR / "robot" / "paper.yaml").read_text())
    del raw[table][joint]
    path = tmp / "robot.yaml"
    path.write_text(yaml.safe_dump(raw))
    return path


def model_case(models: Path, tmp: Path, name: str, *extra: str) -> list[str]:
    return evaluate_argv(tmp, "--env-kwargs", '{"action_mode": "joint_pd"}', *extra, policy=str(models / name))


def non_empty(tmp: Path, name: str) -> Path:
    folder = tmp / "out"
    folder.mkdir(exist_ok=True)
    (folder / name).write_text("old")
    return folder


def a_file(tmp: Path) -> Path:
    return text_file(tmp, "not_a_dir", "x")


def resume_other_kwargs(tmp: Path) -> list[str]:
    """A finished run of the suite, then --resume with other env kwargs."""
    assert main(evaluate_argv(tmp)) == 0
    return evaluate_argv(tmp, "--resume", "--env-kwargs", '{"frame_skip": 5}')


MALFORMED = "name: x\ngoal_distance: [1\n"

CASES: dict[str, Case] = {
    # -- malformed YAML in every kind of file the commands read
    "suite yaml": Case(lambda t, m: evaluate_argv(t, suite=text_file(t, "s.yaml", MALFORMED)), ("s.yaml", "line 3")),
    "train config yaml": Case(
        lambda t, m: ["train", "--config", str(text_file(t, "c.yaml", MALFORMED)), "--out", str(t / "run")],
        ("c.yaml", "YAML"),
    ),
    "terrain yaml": Case(
        lambda t, m: ["train", "--terrain", str(text_file(t, "ter.yaml", "kind: rough\n  a: : 3\n")), "--out", str(t)],
        ("terrain", "ter.yaml", "line 2"),
    ),
    "robot yaml": Case(
        lambda t, m: env_kwargs(t, json.dumps({"robot": str(text_file(t, "r.yaml", "name: r\nbody: [\n"))})),
        ("r.yaml", "YAML"),
    ),
    "suite not a mapping": Case(lambda t, m: evaluate_argv(t, suite=text_file(t, "s.yaml", "- 1\n")), ("s.yaml",)),
    # -- --expert-config
    "expert config not JSON": Case(
        lambda t, m: evaluate_argv(t, "--expert-config", "{friction", policy="expert"), ("--expert-config", "JSON")
    ),
    "expert config unknown field": Case(
        lambda t, m: evaluate_argv(t, "--expert-config", '{"frictio": 1}', policy="expert"),
        ("expert_config", "frictio", "allowed"),
    ),
    "expert config bad value": Case(
        lambda t, m: evaluate_argv(t, "--expert-config", '{"friction": 5}', policy="expert"), ("friction",)
    ),
    "expert config without the expert": Case(
        lambda t, m: evaluate_argv(t, "--expert-config", '{"friction": 0.8}'), ("--expert-config", "--policy expert")
    ),
    # -- --env-kwargs
    "robot twice": Case(
        lambda t, m: evaluate_argv(t, "--robot", "go1", "--env-kwargs", '{"robot": "hyq"}'), ("--robot", "differ")
    ),
    "robot unknown, scaled": Case(lambda t, m: evaluate_argv(t, "--robot", "nosuch", "--scale-terrain"), ("nosuch",)),
    "env kwargs not JSON": Case(lambda t, m: env_kwargs(t, "{frame_skip: 5"), ("--env-kwargs", "JSON")),
    "env kwargs not an object": Case(lambda t, m: env_kwargs(t, "[1]"), ("--env-kwargs", "JSON object")),
    "env kwargs repeated key": Case(lambda t, m: env_kwargs(t, '{"frame_skip": 5, "frame_skip": 6}'), ("frame_skip",)),
    "env kwargs unknown key": Case(lambda t, m: env_kwargs(t, '{"surprise": 1}'), ("env_kwargs.surprise", "allowed")),
    "env kwargs terrain": Case(lambda t, m: env_kwargs(t, '{"terrain": "flat"}'), ("env_kwargs.terrain", "suite")),
    "env kwargs max_episode_steps": Case(
        lambda t, m: env_kwargs(t, '{"max_episode_steps": 5}'), ("env_kwargs.max_episode_steps", "time_limit")
    ),
    "env kwargs render_mode": Case(lambda t, m: env_kwargs(t, '{"render_mode": "human"}'), ("env_kwargs.render_mode",)),
    "env kwargs frame_skip 0": Case(lambda t, m: env_kwargs(t, '{"frame_skip": 0}'), ("frame_skip",)),
    "env kwargs action_mode": Case(lambda t, m: env_kwargs(t, '{"action_mode": "magic"}'), ("action_mode",)),
    "env kwargs timestep str": Case(lambda t, m: env_kwargs(t, '{"timestep": "abc"}'), ("timestep",), env_side=True),
    "env kwargs gait_period null": Case(
        lambda t, m: env_kwargs(t, '{"gait_period": null}'), ("gait_period",), env_side=True
    ),
    "env kwargs pd_kp list": Case(lambda t, m: env_kwargs(t, '{"pd_kp": [1, 2]}'), ("pd_kp",), env_side=True),
    "env kwargs reward weight str": Case(
        lambda t, m: env_kwargs(t, '{"reward_weights": {"alive": "abc"}}'), ("reward_weights.alive",), env_side=True
    ),
    "env kwargs unknown robot": Case(lambda t, m: env_kwargs(t, '{"robot": "nowhere"}'), ("robot", "nowhere")),
    # -- demo: every validation error of the suite it builds, named by the demo's own option
    "demo terrain": Case(
        lambda t, m: ["demo", "--terrain", "lava", "--out", str(t / "d"), "--no-video"], ("--terrain",)
    ),
    "demo distance negative": Case(
        lambda t, m: ["demo", "--distance", "-1", "--out", str(t / "d"), "--no-video"], ("--distance",)
    ),
    "demo distance unreachable": Case(
        lambda t, m: ["demo", "--distance", "100", "--out", str(t / "d"), "--no-video"], ("--distance", "6.20 m")
    ),
    "demo seed": Case(lambda t, m: ["demo", "--seed", "-1", "--out", str(t / "d"), "--no-video"], ("--seed",)),
    "demo out is a file": Case(lambda t, m: ["demo", "--out", str(a_file(t)), "--no-video"], ("--out", "not_a_dir")),
    # -- a robot file missing a joint
    "robot missing HAA range": Case(
        lambda t, m: env_kwargs(t, json.dumps({"robot": str(robot_without(t, "joint_range", "HAA"))})),
        ("robot robot.yaml.joint_range.HAA", "required"),
    ),
    "robot missing KFE limit": Case(
        lambda t, m: env_kwargs(t, json.dumps({"robot": str(robot_without(t, "torque_limit", "KFE"))})),
        ("robot robot.yaml.torque_limit.KFE", "required"),
    ),
    # -- model files
    "model zip corrupt": Case(lambda t, m: model_case(m, t, "corrupt.zip"), ("policy", "corrupt.zip")),
    "model zip truncated": Case(lambda t, m: model_case(m, t, "truncated.zip"), ("policy", "truncated.zip")),
    "model zip missing": Case(lambda t, m: model_case(m, t, "missing.zip"), ("policy", "missing.zip")),
    "metadata without residual_scale": Case(lambda t, m: model_case(m, t, "noscale/model.zip"), ("residual_scale",)),
    "metadata not JSON": Case(lambda t, m: model_case(m, t, "badmeta/model.zip"), ("rl_meta.json",)),
    "pickled statistics": Case(lambda t, m: model_case(m, t, "badnorm/model.zip"), ("vecnormalize", "--allow-pickle")),
    "pickled statistics corrupt": Case(
        lambda t, m: model_case(m, t, "badnorm/model.zip", "--allow-pickle"), ("model_vecnormalize.pkl",)
    ),
    "statistics npz truncated": Case(lambda t, m: model_case(m, t, "badnpz/model.zip"), ("model_obs_norm.npz",)),
    "model for another observation space": Case(
        lambda t, m: model_case(m, t, "pendulum.zip"), ("policy", "observation", "(3,)")
    ),
    "model for another observation space, pickled": Case(
        lambda t, m: model_case(m, t, "pendulum.zip", "--allow-pickle"), ("policy", "observation", "(3,)")
    ),
    "model for another height scan": Case(lambda t, m: model_case(m, t, "scan.zip"), ("policy", "observation")),
    "model with the wrong algo": Case(lambda t, m: model_case(m, t, "flat.zip", "--algo", "sac"), ("policy", "SAC")),
    # -- output directories, checked before any work
    "evaluate out is a file": Case(lambda t, m: evaluate_argv(t, out=a_file(t)), ("--out", "is a file")),
    "evaluate out not creatable": Case(lambda t, m: evaluate_argv(t, out=a_file(t) / "sub"), ("--out",)),
    "evaluate out holds an old run": Case(
        lambda t, m: (non_empty(t, "results.json"), evaluate_argv(t))[1], ("--out", "results.json", "--overwrite")
    ),
    "evaluate resume with other env kwargs": Case(lambda t, m: resume_other_kwargs(t), ("--resume", "env_kwargs")),
    "evaluate resume and overwrite": Case(lambda t, m: evaluate_argv(t, "--resume", "--overwrite"), ("--resume",)),
    "evaluate resume a foreign directory": Case(
        lambda t, m: (non_empty(t, "notes.txt"), evaluate_argv(t, "--resume"))[1], ("--resume", "run.json")
    ),
    "evaluate wall limit": Case(lambda t, m: evaluate_argv(t, "--episode-wall-limit", "0"), ("--episode-wall-limit",)),
    "evaluate episodes": Case(lambda t, m: evaluate_argv(t, "--episodes", "0"), ("--episodes",)),
    "paper out is a file": Case(lambda t, m: ["paper", "--out", str(a_file(t)), "--no-progress"], ("--out",)),
    "plan-paper out is a file": Case(lambda t, m: ["plan-paper", "--out", str(a_file(t))], ("--out",)),
    "export out is a directory": Case(
        lambda t, m: ["export", "--policy", str(m / "flat.zip"), "--out", str(t)], ("--out", "directory")
    ),
    "export out exists": Case(
        lambda t, m: ["export", "--policy", str(m / "flat.zip"), "--out", str(a_file(t))], ("--out", "--overwrite")
    ),
    "export out under a file": Case(
        lambda t, m: ["export", "--policy", str(m / "flat.zip"), "--out", str(a_file(t) / "p.onnx")], ("--out",)
    ),
    "train out is a file": Case(lambda t, m: ["train", "--out", str(a_file(t)), "--no-progress"], ("--out",)),
    "train out not empty": Case(
        lambda t, m: ["train", "--out", str(non_empty(t, "rl_meta.json")), "--no-progress"],
        ("--out", "rl_meta.json", "--overwrite"),
    ),
    "train expert config not JSON": Case(
        lambda t, m: ["train", "--expert-config", "{adaptation", "--out", str(t / "run")], ("--expert-config", "JSON")
    ),
    "train expert adaptation": Case(
        lambda t, m: ["train", "--expert-config", '{"adaptation": "hips"}', "--out", str(t / "run")],
        ("expert.adaptation", "'none', 'knee', 'learned'", "hips"),
    ),
    "evaluate expert adaptation": Case(
        lambda t, m: evaluate_argv(t, "--expert-config", '{"adaptation": "hips"}', policy="expert"),
        ("adaptation", "'none', 'knee', 'learned'", "hips"),
    ),
}


@pytest.fixture(scope="module")
def models(tmp_path_factory) -> Path:
    """Model files: a QuadUneven-v0 PPO (joint_pd), one for Pendulum, one for another height scan, broken ones."""
    import gymnasium as gym
    from stable_baselines3 import PPO

    folder = tmp_path_factory.mktemp("models")

    def save(env, name):
        PPO("MlpPolicy", env, n_steps=8, batch_size=8, policy_kwargs={"net_arch": [8]}, device="cpu").save(
            folder / name
        )

    save(gym.make("QuadUneven-v0", terrain="flat", action_mode="joint_pd"), "flat.zip")
    save(gym.make("Pendulum-v1"), "pendulum.zip")
    scan = {"size_x": 0.4, "size_y": 0.4, "resolution": 0.2}
    save(gym.make("QuadUneven-v0", terrain="flat", action_mode="joint_pd", height_scan=scan), "scan.zip")
    data = (folder / "flat.zip").read_bytes()
    (folder / "corrupt.zip").write_bytes(b"PK\x03\x04 this is not a model" * 20)
    (folder / "truncated.zip").write_bytes(data[: len(data) // 2])
    for sub, meta in (
        ("noscale", json.dumps({"format": "quad-uneven-rl/1", "algo": "ppo", "residual": True, "env_kwargs": {}})),
        ("badmeta", '{"format": "quad-uneven-rl/1", '),
        ("badnorm", json.dumps({"format": "quad-uneven-rl/1", "algo": "ppo", "residual": False})),
        ("badnpz", json.dumps({"format": "quad-uneven-rl/1", "algo": "ppo", "residual": False})),
    ):
        (folder / sub).mkdir()
        shutil.copy(folder / "flat.zip", folder / sub / "model.zip")
        (folder / sub / "rl_meta.json").write_text(meta)
    (folder / "badnorm" / "model_vecnormalize.pkl").write_bytes(b"\x80\x04truncated")
    np.savez(folder / "stats.npz", mean=np.zeros(3), var=np.ones(3), epsilon=1e-8, clip=10.0)
    stats = (folder / "stats.npz").read_bytes()
    (folder / "badnpz" / "model_obs_norm.npz").write_bytes(stats[: len(stats) // 2])
    return folder


@pytest.mark.parametrize("name", list(CASES))
def test_bad_input_exits_2_with_one_line_naming_the_field(name, tmp_path, models, capsys):
    case = CASES[name]
    argv = case.argv(tmp_path, models)
    capsys.readouterr()
    rc = main(argv)
    err = capsys.readouterr().err
    assert rc == 2, err
    assert "Traceback" not in err
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    missing = [f for f in case.fields if f not in lines[0]]
    assert not missing, lines[0]


def test_the_installed_entry_point_prints_no_traceback(tmp_path):
    """The same through a real process (``python -m agents.cli``): exit status 2, one line, no traceback."""
    bad = text_file(tmp_path, "s.yaml", MALFORMED)
    argv = ["evaluate", "--policy", "zero", "--suite", str(bad), "--out", str(tmp_path / "o"), "--no-progress"]
    proc = subprocess.run(
        [sys.executable, "-m", "agents.cli", *argv], capture_output=True, text=True, cwd=ROOT, timeout=300
    )
    assert proc.returncode == 2
    assert proc.stderr.count("\n") == 1 and "s.yaml" in proc.stderr and "Traceback" not in proc.stderr
    assert not (tmp_path / "o").exists()  # the suite is read before the output directory is made
