"""quad-uneven select: the candidates of a run, the ranking, the copy of the chosen snapshot, reuse and resume."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml

from agents.cli import main
from agents.rl.config import default_config_path, load_train_config

TINY_PPO = {
    "timesteps": 64,
    "n_envs": 1,
    "max_episode_steps": 40,
    "eval_freq": 0,
    "checkpoint_freq": 32,
    "hyperparams": {"n_steps": 32, "batch_size": 16, "n_epochs": 1},
    "policy_kwargs": {"net_arch": [16], "log_std_init": -2.5},
}
"""Overrides of the shipped PPO config for a run of a few seconds with checkpoints at 32 and 64 steps."""

SUITE = {
    "name": "validation",
    "goal_distance": 5.0,
    "time_limit": 0.3,
    "terrains": [{"kind": "rough", "params": {"amplitude": 0.03}, "seeds": [0]}],
}


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory) -> Path:
    """A tiny PPO residual run: checkpoints/model_32_steps.zip, model_64_steps.zip and model.zip."""
    from agents.rl.training import train

    tmp = tmp_path_factory.mktemp("select")
    config = tmp / "c.yaml"
    config.write_text(yaml.safe_dump({**yaml.safe_load(default_config_path("ppo").read_text()), **TINY_PPO}))
    train(load_train_config(config), tmp / "run", progress=False)
    return tmp / "run"


def test_candidates_are_the_checkpoints_by_steps_then_the_final_model(tiny_run):
    from agents.rl.selection import find_candidates

    found = find_candidates(tiny_run)
    assert [(c["name"], c["steps"]) for c in found] == [("model_32_steps", 32), ("model_64_steps", 64), ("final", 64)]


def test_rank_key_orders_successes_then_falls_then_steps():
    from agents.rl.selection import rank_key

    rows = [
        {"name": "a", "successes": 5, "falls": 1, "steps": 300},
        {"name": "b", "successes": 6, "falls": 4, "steps": 100},
        {"name": "c", "successes": 5, "falls": 0, "steps": 100},
        {"name": "d", "successes": 5, "falls": 0, "steps": 200},
        {"name": "e", "successes": 5, "falls": 0, "steps": None},
    ]
    assert [r["name"] for r in sorted(rows, key=rank_key)] == ["b", "d", "c", "e", "a"]


def test_the_best_candidate_is_copied_with_its_own_statistics(tiny_run, tmp_path, monkeypatch):
    """Evaluation results stubbed per model: the middle checkpoint wins on falls, and OUT/selected holds its
    weights and its statistics, not the final model's."""
    import agents.rl.selection as selection

    outcome = {"model_32_steps.zip": (3, 0), "model_64_steps.zip": (3, 2), "model.zip": (2, 0)}

    def fake_evaluate(suite, policy, out, **kwargs):
        out.mkdir(parents=True, exist_ok=True)
        successes, falls = outcome[Path(policy).name]
        overall = {"successes": successes, "episodes": 4, "falls": falls, "mean_stability_index": 10.0}
        return {"summary": {"overall": overall}}

    monkeypatch.setattr(selection, "evaluate", fake_evaluate)
    result = selection.select_checkpoint(tiny_run, "smoke", seed=200, out=tmp_path / "sel", progress=False)
    assert result["selected"] == "model_32_steps"
    assert [c["rank"] for c in result["candidates"]] == [1, 2, 3]  # successes before falls
    chosen = tiny_run / "checkpoints"
    selected = tmp_path / "sel" / "selected"
    assert (selected / "model.zip").read_bytes() == (chosen / "model_32_steps.zip").read_bytes()
    assert (selected / "model_obs_norm.npz").read_bytes() == (chosen / "model_obs_norm_32_steps.npz").read_bytes()
    assert (selected / "model_obs_norm.npz").read_bytes() != (tiny_run / "model_obs_norm.npz").read_bytes()
    assert json.loads((selected / "rl_meta.json").read_text()) == json.loads((tiny_run / "rl_meta.json").read_text())
    assert (selected / "train_config.json").is_file() and (selected / "selection.json").is_file()
    table = (tmp_path / "sel" / "selection.md").read_text()
    assert "Selected: **model_32_steps**" in table and "| final | 64 | 2/4 | 0 |" in table
    assert (tmp_path / "sel" / "selection.png").stat().st_size > 0


def test_select_evaluates_every_candidate_and_the_choice_reproduces(tiny_run, tmp_path, capsys):
    """End to end: every candidate's count is its evaluation's; the selected copy, evaluated again, walks its
    episode exactly as the candidate did; a second call reuses the finished evaluations and resumes a cut one."""
    from agents.evaluation.run import evaluate
    from agents.evaluation.suites import suite_from_dict

    suite_file = tmp_path / "validation.yaml"
    suite_file.write_text(yaml.safe_dump(SUITE))
    out = tmp_path / "sel"
    argv = ["select", "--run", str(tiny_run), "--suite", str(suite_file), "--seed", "200", "--out", str(out),
            "--no-progress"]  # fmt: skip
    assert main(argv) == 0, capsys.readouterr().err
    assert "selected:" in capsys.readouterr().out
    result = json.loads((out / "selection.json").read_text())
    for c in result["candidates"]:
        res = json.loads((Path(c["evaluation"]) / "results.json").read_text())
        assert res["policy"] == c["path"] and res["summary"]["overall"]["successes"] == c["successes"]
        assert res["episodes"][0]["seed"] == 200
    best = next(c for c in result["candidates"] if c["name"] == result["selected"])
    again = evaluate(suite_from_dict(SUITE, "test"), str(out / "selected" / "model.zip"), tmp_path / "again",
                     seed=200, progress=False)  # fmt: skip
    first = json.loads((Path(best["evaluation"]) / "results.json").read_text())["episodes"][0]
    assert again["episodes"][0]["distance"] == pytest.approx(first["distance"], abs=1e-9)

    records = {c["name"]: next((Path(c["evaluation"]) / "episodes").iterdir()) for c in result["candidates"]}
    kept = records["final"].stat().st_mtime_ns
    records["model_32_steps"].unlink()
    assert main(argv) == 0, capsys.readouterr().err
    assert records["model_32_steps"].is_file()  # the cut evaluation was resumed
    assert records["final"].stat().st_mtime_ns == kept  # a finished one is not run again
    assert json.loads((out / "selection.json").read_text())["selected"] == result["selected"]

    ref = tmp_path / "expert"  # the expert on the same episodes, listed beside the candidates
    expert = evaluate(suite_from_dict(SUITE, "test"), "expert", ref, seed=200, progress=False)
    assert main([*argv, "--reference", str(ref)]) == 0, capsys.readouterr().err
    listed = json.loads((out / "selection.json").read_text())["references"]
    assert [(r["policy"], r["successes"], r["falls"]) for r in listed] == [
        ("expert", expert["summary"]["overall"]["successes"], expert["summary"]["overall"]["falls"])
    ]
    assert "| reference: `expert` |" in (out / "selection.md").read_text()
    other_seeds = tmp_path / "expert_0"
    evaluate(suite_from_dict(SUITE, "test"), "expert", other_seeds, seed=0, progress=False)
    assert main([*argv, "--reference", str(other_seeds)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: reference") and "seed offset 0" in err and err.count("\n") == 1


@pytest.mark.parametrize(
    ("argv", "field"),
    [
        (["--run", "nowhere"], "nowhere' is not a folder"),  # named as an absolute path
        (["--workers", "0"], "--workers"),
        (["--episodes", "0"], "--episodes"),
        (["--suite", "lava"], "invalid suite 'lava'"),
    ],
)
def test_bad_select_options_exit_2_naming_the_field(tiny_run, tmp_path, capsys, argv, field):
    base = {"--run": str(tiny_run), "--suite": "smoke", "--seed": "200", "--out": str(tmp_path / "sel")}
    args = dict(base, **dict(zip(argv[::2], argv[1::2], strict=True)))
    rc = main(["select", "--no-progress", *[x for kv in args.items() for x in kv]])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and field in err, err
    assert not (tmp_path / "sel" / "evals").exists()


def test_a_run_without_models_is_refused(tmp_path, capsys):
    (tmp_path / "run" / "checkpoints").mkdir(parents=True)
    assert main(["select", "--run", str(tmp_path / "run"), "--suite", "smoke", "--seed", "200"]) == 2
    assert "holds no model.zip" in capsys.readouterr().err
