"""The shipped models (models/ppo_residual_adaptive, the PPO residual over the expert with the knee adaptation;
models/ppo_scratch, PPO from scratch; models/distilled, the expert distilled into a network policy): load as data,
run, match their configs, and carry a model card whose file list and sha256 match the folder and whose config (or
command) and Makefile target retrain it."""

from __future__ import annotations

import hashlib
import json
import re
from pathlib import Path

import numpy as np
import pytest

import quad_uneven_env  # noqa: F401  (registers QuadUneven-v0)
from agents.evaluation.policies import make_policy, make_policy_env
from agents.rl.config import load_train_config
from agents.rl.expert_features import EXPERT_FEATURE_SIZE
from agents.rl.model_io import SB3Policy, read_metadata
from agents.rl.residual_env import ResidualController

ROOT = Path(__file__).resolve().parents[2]
RESIDUAL_MODELS = {
    "ppo_residual_adaptive": ("extreme", "stance", "expert_torque"),
}
"""models/NAME (trained by configs/rl/NAME.yaml) -> (its randomization preset, residual_legs, residual_basis)."""

SHIPPED = {"ppo_residual_adaptive": "rl-baseline", "ppo_scratch": "rl-scratch"}
"""models/NAME (trained by configs/rl/NAME.yaml) -> the Makefile target that retrains it."""


DISTILLED = {"distilled": "distilled", "distilled_go1": "distilled-go1"}
"""models/NAME (trained by ``quad-uneven distill``, no config file) -> the Makefile target that retrains it."""


def test_models_holds_the_shipped_agents_only():
    assert sorted(p.name for p in (ROOT / "models").iterdir()) == sorted(SHIPPED | DISTILLED)


def _card_files_match(folder: Path, card: str) -> None:
    """Every file of ``folder`` but the card is listed in it with its sha256, and nothing else."""
    listed = dict(re.findall(r"^\| `([^`]+)` \| `([0-9a-f]{64})` \|", card, re.M))
    assert set(listed) == {p.name for p in folder.iterdir()} - {"README.md"}
    for file, digest in listed.items():
        assert hashlib.sha256((folder / file).read_bytes()).hexdigest() == digest, file


def _recipe(target: str) -> str:
    """The lines of a Makefile target, from its rule to the next blank line."""
    match = re.search(rf"^{re.escape(target)}:.*?(?=\n\n|\Z)", (ROOT / "Makefile").read_text(), re.M | re.S)
    assert match, f"no Makefile target {target}"
    return match.group(0)


@pytest.mark.parametrize("name", sorted(SHIPPED))
def test_the_shipped_model_has_a_card_with_its_files_config_and_target(name):
    """models/NAME/README.md lists every file of the folder with its sha256, and names the config and the Makefile
    target that retrains the model into this folder."""
    folder = ROOT / "models" / name
    card = (folder / "README.md").read_text()
    config, target = f"configs/rl/{name}.yaml", SHIPPED[name]
    assert config in card and f"make {target}" in card
    recipe = _recipe(target)
    assert f"--config {config}" in recipe and f"models/{name})" in recipe  # $(call ship,RUN,models/NAME)
    _card_files_match(folder, card)


@pytest.mark.parametrize("name", sorted(DISTILLED))
def test_the_distilled_model_has_a_card_with_its_files_command_and_target(name):
    """models/NAME/README.md lists every file of the folder with its sha256 and names the Makefile target, whose
    recipe runs the card's ``quad-uneven distill`` command and copies its files into this folder."""
    folder = ROOT / "models" / name
    card = (folder / "README.md").read_text()
    target = DISTILLED[name]
    assert f"make {target}" in card
    recipe = _recipe(target)
    command = re.search(r"`quad-uneven distill ([^`]+)`", card)
    assert command, "the card names no quad-uneven distill command"
    flags = command.group(1).replace(f"--out runs/{name}", "").split()
    run = " ".join(recipe.replace("\\\n", " ").split())
    assert "agents.cli distill" in run and all(f in run.split() for f in flags), flags
    assert f"models/{name}" in recipe
    _card_files_match(folder, card)
    summary = json.loads((folder / "distill_summary.json").read_text())
    assert summary["config"]["course_frame"] is True and summary["suite"].split(" (")[0] == "targets"


@pytest.mark.parametrize("name", sorted(RESIDUAL_MODELS))
def test_the_shipped_model_was_trained_with_the_shipped_config(name):
    """``make rl-baseline`` retrains it: its recorded config is the YAML's, field for field (fields added
    since the run was recorded take their defaults)."""
    from agents.rl.config import TrainConfig

    world, legs, basis = RESIDUAL_MODELS[name]
    model = ROOT / "models" / name / "model.zip"
    recorded = json.loads((model.parent / "train_config.json").read_text())
    shipped = json.loads(json.dumps(load_train_config(ROOT / f"configs/rl/{name}.yaml").to_dict()))
    defaults = json.loads(json.dumps(TrainConfig().to_dict()))
    assert {**{k: defaults[k] for k in shipped.keys() - recorded.keys()}, **recorded} == shipped
    meta = read_metadata(model)
    assert meta["residual"] and meta["expert_features"] and meta["randomization"] == world
    assert meta.get("residual_legs", "all") == legs
    assert meta.get("residual_basis", "torque_limit") == basis
    assert meta.get("expert", {}) == ({"adaptation": "knee", "friction": 0.5} if "_adaptive" in name else {})
    assert meta["algo"] == name.split("_")[0]
    assert not list(model.parent.glob("*.pkl"))


@pytest.mark.parametrize("name", sorted(RESIDUAL_MODELS))
def test_the_shipped_model_drives_the_expert_in_a_randomized_world(name):
    world, legs, basis = RESIDUAL_MODELS[name]
    model = ROOT / "models" / name / "model.zip"
    env = make_policy_env(str(model), terrain="rough", randomization=world)  # the env of its training
    policy = make_policy(str(model), env)  # the safe loader: nothing unpickled
    assert isinstance(policy, SB3Policy) and isinstance(env.unwrapped.controller, ResidualController)
    assert env.spec.id == "QuadUnevenResidual-v0" and env.observation_space == policy.model.observation_space
    assert env.unwrapped.controller.residual_legs == legs
    assert env.unwrapped.controller.residual_basis == basis
    assert policy.expert is env.unwrapped.controller.expert
    assert policy.expert.config.adaptation == ("knee" if "_adaptive" in name else "none")
    assert type(policy.model).__name__ == name.split("_")[0].upper()  # the class rl_meta.json records
    assert policy.model.observation_space.shape == (env.unwrapped.observation_space.shape[0] + EXPERT_FEATURE_SIZE,)
    obs, _ = env.reset(seed=100)
    x0 = env.unwrapped.data.qpos[0]
    actions = []
    for _ in range(100):
        action, _ = policy.predict(obs)
        actions.append(action)
        obs, _, terminated, truncated, info = env.step(action)
        assert not (terminated or truncated), info["termination_reason"]
    actions = np.array(actions)
    assert np.all(np.abs(actions) <= 1.0) and np.abs(actions).max() > 0  # a residual, not the zero policy
    assert env.unwrapped.data.qpos[0] - x0 > 0.1  # it walks (2 s)


SCRATCH = ROOT / "models" / "ppo_scratch" / "model.zip"


@pytest.mark.parametrize(("name", "robot"), [("distilled", "paper"), ("distilled_go1", "go1")])
def test_the_distilled_model_walks_the_plain_env_straight(name, robot):
    """models/distilled(_go1): a joint_pd policy with the expert's gait clock, the course frame and a 21 x 13 height
    scan (0.05 m: 137 - 77 + 273 = 333 inputs), without the expert, on its robot; on flat ground it walks forward for
    6 s (0.3-0.9 m at its 0.1 m/s) and keeps to the centre line."""
    model = ROOT / "models" / name / "model.zip"
    meta = read_metadata(model)
    assert meta.get("robot", "paper") == robot  # a model without one acts for the paper robot
    assert meta["residual"] is False and meta["env_kwargs"]["course_frame"] is True
    assert meta["env_kwargs"]["action_mode"] == "joint_pd" and meta["env_kwargs"]["gait_period"] == pytest.approx(3.1)
    env = make_policy_env(str(model), terrain="flat")
    policy = make_policy(str(model), env)  # the safe loader: nothing unpickled
    assert isinstance(policy, SB3Policy) and env.unwrapped.controller is None
    assert meta["env_kwargs"]["height_scan"] == {"resolution": 0.05}
    assert policy.model.observation_space.shape == (333,)
    obs, _ = env.reset(seed=7)
    x0 = env.unwrapped.data.qpos[0]
    for _ in range(300):
        obs, _, terminated, truncated, info = env.step(policy.predict(obs)[0])
        assert not (terminated or truncated), info["termination_reason"]
    assert 0.3 < env.unwrapped.data.qpos[0] - x0 < 0.9
    assert abs(env.unwrapped.data.qpos[1]) < 0.1
    assert not list(model.parent.glob("*.pkl"))


def test_the_shipped_from_scratch_model_runs_on_the_plain_env():
    """models/ppo_scratch: recorded as a joint_pd policy without the expert; it moves forward fast."""
    meta = read_metadata(SCRATCH)
    assert meta["residual"] is False and meta["env_kwargs"] == {"action_mode": "joint_pd"}
    recorded = load_train_config(SCRATCH.parent / "train_config.json")
    assert recorded.residual is False and recorded.time_limit_min == 35
    assert recorded == load_train_config(ROOT / "configs/rl/ppo_scratch.yaml")  # make rl-scratch retrains it
    env = make_policy_env(str(SCRATCH), terrain="rough")
    policy = make_policy(str(SCRATCH), env)
    assert isinstance(policy, SB3Policy) and env.unwrapped.controller is None
    obs, _ = env.reset(seed=0)
    x0 = env.unwrapped.data.qpos[0]
    for _ in range(50):
        obs, _, terminated, truncated, _ = env.step(policy.predict(obs)[0])
        if terminated or truncated:
            break
    assert env.unwrapped.data.qpos[0] - x0 > 0.5  # 1 s: far beyond the expert's 0.1 m
    assert not list(SCRATCH.parent.glob("*.pkl"))
