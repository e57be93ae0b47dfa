"""A model knows its robot: ``rl_meta.json`` names it, and evaluate, export and train --init-from refuse another."""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path

import pytest

from agents.cli import main
from agents.rl.config import TrainConfigError, load_train_config
from agents.rl.model_io import model_robot, read_metadata

ROOT = Path(__file__).resolve().parents[2]
RESIDUAL = ROOT / "models" / "ppo_residual_adaptive" / "model.zip"
DISTILLED = ROOT / "models" / "distilled" / "model.zip"


def _one_line_error(capsys, rc: int) -> str:
    err = capsys.readouterr().err.strip()
    assert rc == 2 and err.count("\n") == 0 and err.startswith("error: "), err
    return err


def test_a_model_without_the_field_was_trained_on_its_env_kwargs_robot_else_the_papers():
    assert model_robot({"robot": "go1", "env_kwargs": {}}) == "go1"
    assert model_robot({"env_kwargs": {"robot": "configs/robot/hyq.yaml"}}) == "hyq"
    assert model_robot({"env_kwargs": {}}) == "paper"
    for model in (RESIDUAL, DISTILLED, ROOT / "models" / "ppo_scratch" / "model.zip"):
        meta = read_metadata(model)
        assert "robot" not in meta and "robot" not in meta["env_kwargs"] and model_robot(meta) == "paper"


@pytest.mark.parametrize(("model", "robot"), [(RESIDUAL, "go1"), (DISTILLED, "hyq")])
def test_evaluate_refuses_a_model_on_another_robot(tmp_path, capsys, model, robot):
    argv = ["evaluate", "--policy", str(model), "--suite", "smoke", "--episodes", "1", "--robot", robot]
    rc = main([*argv, "--out", str(tmp_path / "out"), "--no-progress"])
    err = _one_line_error(capsys, rc)
    assert f"robot must be 'paper', the robot {model} was trained on, got '{robot}'" in err
    assert not (tmp_path / "out" / "episodes").exists() or not any((tmp_path / "out" / "episodes").iterdir())


def test_export_refuses_metadata_whose_robot_is_not_its_envs(tmp_path, capsys):
    """The exported graph is traced in the model's env; metadata naming another robot than its env_kwargs build is
    refused (and the robot the policy acts for travels in the ONNX metadata, tests/agents/test_model_files.py)."""
    folder = tmp_path / "model"
    shutil.copytree(DISTILLED.parent, folder)
    meta = json.loads((folder / "rl_meta.json").read_text())
    (folder / "rl_meta.json").write_text(json.dumps({**meta, "robot": "go1"}))
    rc = main(["export", "--policy", str(folder / "model.zip"), "--out", str(tmp_path / "p.onnx")])
    err = _one_line_error(capsys, rc)
    assert "robot must be 'go1'" in err and "got 'paper'" in err
    assert not (tmp_path / "p.onnx").exists()


def test_train_init_from_refuses_a_model_of_another_robot(tmp_path, capsys):
    config = ROOT / "configs" / "rl" / "ppo_from_distilled.yaml"  # init_from: models/distilled (the paper's robot)
    out = tmp_path / "run"
    argv = ["train", "--config", str(config), "--robot", "go1", "--out", str(out), "--no-progress"]
    rc = main(argv)
    err = _one_line_error(capsys, rc)
    assert "init_from:" in err and "robot='paper', the config has robot='go1'" in err
    assert not out.exists()


def test_train_init_from_takes_a_model_of_the_same_robot_named_explicitly():
    """``--robot paper`` puts ``robot: paper`` into env_kwargs; the model's metadata names no robot (the paper's):
    the same robot, so no refusal (env_kwargs are compared without ``robot``)."""
    from agents.rl.training import _metadata
    from agents.rl.warm_start import check_init_model

    cfg = load_train_config(ROOT / "configs" / "rl" / "ppo_from_distilled.yaml")
    cfg = dataclasses.replace(cfg, init_from=str(ROOT / "models" / "distilled"))
    explicit = dataclasses.replace(cfg, env_kwargs={**cfg.env_kwargs, "robot": "paper"})
    path, _ = check_init_model(explicit.init_from, _metadata(explicit, "paper"))
    assert path == DISTILLED
    with pytest.raises(TrainConfigError, match=r"^init_from: .*robot='paper', the config has robot='hyq'"):
        hyq = dataclasses.replace(cfg, env_kwargs={**cfg.env_kwargs, "robot": "hyq"})
        check_init_model(hyq.init_from, _metadata(hyq, "hyq"))
