"""quad-uneven sweep: the sweep file checked at the boundary, a tiny sweep on local Ray equal to plain training."""

from __future__ import annotations

import csv
import json
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from agents.cli import main
from agents.rl.sweep import SweepError, load_sweep, plot_sweep, sweep_from_dict, write_summary_table
from quad_uneven_env.config import CONFIG_DIR

EXAMPLE = CONFIG_DIR / "sweeps" / "example.yaml"

TINY_TRAIN = {
    "algo": "ppo",
    "terrain": "rough",
    "timesteps": 2048,
    "n_envs": 1,
    "max_episode_steps": 200,
    "eval_freq": 0,
    "checkpoint_freq": 0,
    "hyperparams": {"n_steps": 256, "batch_size": 64, "n_epochs": 1},
    "policy_kwargs": {"net_arch": [16], "log_std_init": -2.5},
}
"""A PPO run of 8 updates of 256 steps on one env (a few seconds)."""


def tiny_sweep(**changes) -> dict:
    raw = {"name": "tiny", "base": dict(TINY_TRAIN), "grid": {"seed": [0, 1]}, "evaluation": {"suite": "smoke"}}
    raw.update(changes)
    return {k: v for k, v in raw.items() if v is not None}  # grid=None: no grid


# ------------------------------------------------------------------------------ the sweep file
def test_the_example_sweep_is_valid():
    sweep = load_sweep(EXAMPLE)
    assert sweep.swept == ("seed", "residual_scale")
    assert [r.params for r in sweep.runs] == [
        {"seed": s, "residual_scale": r} for s in (0, 1) for r in (0.05, 0.1)
    ]  # the product, the last key fastest
    assert len({r.name for r in sweep.runs}) == 4
    assert all(r.config.terrain == "rough" and r.config.n_envs == 1 for r in sweep.runs)
    assert sweep.evaluation.suite == "rough"


def test_grid_runs_get_the_base_and_their_values():
    sweep = sweep_from_dict(tiny_sweep(grid={"residual_scale": [0.05, 0.2], "randomization": ["mild", None]}))
    cfgs = [r.config for r in sweep.runs]
    assert [(c.residual_scale, c.randomization) for c in cfgs] == [
        (0.05, "mild"), (0.05, None), (0.2, "mild"), (0.2, None)
    ]  # fmt: skip
    assert all(c.timesteps == 2048 and c.hyperparams["n_steps"] == 256 for c in cfgs)
    assert sweep.runs[1].name == "residual_scale=0.05_randomization=none"


def test_a_runs_list_names_its_runs():
    sac = {"algo": "sac", "hyperparams": {"batch_size": 64, "learning_starts": 0}}  # SAC's own arguments
    sweep = sweep_from_dict(tiny_sweep(grid=None, runs=[{"name": "a", "seed": 3}, sac]))
    assert [r.name for r in sweep.runs] == ["a", "run001"]
    assert sweep.runs[1].config.algo == "sac" and sweep.swept == ("seed", "algo", "hyperparams")
    with pytest.raises(SweepError, match=r"^runs\[0\]: hyperparams\.n_epochs: not an SB3 SAC argument"):
        sweep_from_dict(tiny_sweep(grid=None, runs=[{"algo": "sac"}]))  # the base's PPO arguments


@pytest.mark.parametrize(
    ("changes", "field"),
    [
        ({"bogus": 1}, "bogus"),
        ({"grid": {"seed": [0, -1]}}, "grid.seed[1]"),
        ({"grid": {"seed": []}}, "grid.seed"),
        ({"grid": {"sed": [0]}}, "grid.sed: unknown"),
        ({"grid": {"residual_scale": [0.1, 5.0]}}, "grid.residual_scale[1]"),
        ({"grid": {"terrain": ["rough", "lava"]}}, "grid.terrain[1]"),
        ({"base": {"n_envs": 0}}, "base"),
        ({"base": {"algo": "dqn"}}, "base"),
        ({"runs": [{"seed": 0}]}, "grid or runs"),
        ({"grid": None, "runs": [{"name": "x"}, {"name": "x"}]}, "runs[1].name"),
        ({"grid": None, "runs": [{"name": "a/b"}]}, "runs[0].name"),
        ({"grid": None, "runs": [{"seed": 1.5}]}, "runs[0]"),
        ({"evaluation": {"suite": "nope"}}, "evaluation.suite"),
        ({"evaluation": {}}, "evaluation.suite"),
        ({"evaluation": {"suite": "smoke", "episodes": 0}}, "evaluation.episodes"),
        ({"evaluation": {"suite": "smoke", "workers": 2}}, "evaluation"),
        ({"cpus_per_run": 0}, "cpus_per_run"),
    ],
)
def test_bad_sweep_files_name_the_field(changes, field):
    raw = tiny_sweep(**changes)
    with pytest.raises(SweepError) as exc:
        sweep_from_dict(raw)
    assert str(exc.value).startswith(field), str(exc.value)


def test_cli_bad_sweep_file_exits_2_with_one_line(tmp_path, capsys):
    path = tmp_path / "s.yaml"
    path.write_text(yaml.safe_dump(tiny_sweep(grid={"seed": [0, -1]})))
    rc = main(["sweep", "--config", str(path), "--out", str(tmp_path / "o"), "--no-progress"])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and err.startswith("error: grid.seed[1]")
    assert not (tmp_path / "o").exists()
    rc = main(["sweep", "--config", str(tmp_path / "missing.yaml"), "--out", str(tmp_path / "o")])
    assert rc == 2 and "--config" in capsys.readouterr().err


def test_without_ray_sweep_names_the_extra_and_exits_2(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` (and ray.tune) now raises ImportError
    rc = main(["sweep", "--config", str(EXAMPLE), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1
    assert err.startswith("error: sweep needs Ray") and 'pip install -e ".[distributed]"' in err
    assert not (tmp_path / "o").exists()


def test_summary_table_and_plot_from_a_hand_made_summary(tmp_path):
    def row(name, seed, scale, rate, index, error=None):
        return {
            "name": name,
            "params": {"seed": seed, "residual_scale": scale},
            "error": error,
            "train": {"timesteps": 100, "wall_time": 2.0, "mean_return": 1.5, "fall_rate": 0.0},
            "evaluation": {"episodes": 2, "successes": round(2 * rate), "success_rate": rate,
                           "mean_stability_index": index, "mean_distance": 1.0},
        }  # fmt: skip

    summary = {
        "sweep": "hand",
        "suite": "smoke",
        "swept": ["residual_scale", "seed"],
        "runs": [row("a", 0, 0.05, 1.0, 12.5), row("b", 0, 0.1, 0.5, 3.25), row("c", 1, 0.05, 0.0, None, "boom")],
    }
    for r in summary["runs"]:
        r["train"] |= {"steps_per_s": 50.0, "episodes": 3, "mean_stability_index": 4.0, "mean_distance": 0.2,
                       "interrupted": False}  # fmt: skip
    csv_path, md_path = write_summary_table(summary, tmp_path)
    lines = list(csv.DictReader(csv_path.open()))
    assert [(r["name"], r["residual_scale"], r["success_rate"], r["error"]) for r in lines] == [
        ("a", "0.05", "1.0", ""), ("b", "0.1", "0.5", ""), ("c", "0.05", "0.0", "boom")
    ]  # fmt: skip
    md = md_path.read_text()
    assert "| b | 0.1 | 0 | 100 | 2 | 1.5 | 0 | 1/2 | 3.25 | - |" in md
    assert plot_sweep(summary, tmp_path / "summary.png").stat().st_size > 1000


# -------------------------------------------------------------------------- a tiny sweep on Ray
def write_tiny_suite(path: Path) -> Path:
    """One 2 s episode on rough ground (goal 0.3 m)."""
    raw = {
        "name": "tiny",
        "goal_distance": 0.3,
        "time_limit": 2.0,
        "terrains": [{"kind": "rough", "params": {"amplitude": 0.04, "wavelength": 0.6}, "seeds": [0]}],
    }
    path.write_text(yaml.safe_dump(raw))
    return path


def _policy_weights(path: Path) -> list[np.ndarray]:
    from stable_baselines3 import PPO

    return [p.detach().numpy().copy() for p in PPO.load(path, device="cpu").policy.parameters()]


@pytest.mark.slow
def test_tiny_sweep_on_local_ray_equals_plain_training(tmp_path, capsys, local_ray):
    from agents.rl.training import train

    suite = write_tiny_suite(tmp_path / "suite.yaml")
    sweep_file = tmp_path / "sweep.yaml"
    sweep_file.write_text(yaml.safe_dump(tiny_sweep(evaluation={"suite": str(suite), "episodes": 1}, cpus_per_run=1)))
    rc = main(["sweep", "--config", str(sweep_file), "--out", str(tmp_path / "sweep"), "--no-progress"])
    assert rc == 0, capsys.readouterr().err
    out = tmp_path / "sweep"
    summary = json.loads((out / "summary.json").read_text())
    assert [r["name"] for r in summary["runs"]] == ["seed=0", "seed=1"] and summary["swept"] == ["seed"]
    for name in ("summary.md", "summary.csv", "summary.png", "sweep.json"):
        assert (out / name).is_file()
    for r in summary["runs"]:
        assert r["error"] is None and r["train"]["timesteps"] == 2048
        assert (out / "runs" / r["name"] / "model.zip").is_file()
        results = json.loads((out / "evals" / r["name"] / "results.json").read_text())
        assert results["meta"]["backend"] == "ray" and results["summary"]["overall"]["episodes"] == 1
        assert r["evaluation"]["mean_stability_index"] == results["summary"]["overall"]["mean_stability_index"]

    # A trial is exactly `quad-uneven train`: the same config trains the same model in this process.
    sweep = load_sweep(sweep_file)
    ref = train(sweep.runs[1].config, tmp_path / "ref", progress=False)
    got = json.loads((out / "runs" / "seed=1" / "train_summary.json").read_text())
    for key in ("timesteps", "episodes", "mean_return", "mean_stability_index", "mean_distance", "fall_rate"):
        assert got[key] == ref[key], key
    for a, b in zip(
        _policy_weights(out / "runs" / "seed=1" / "model.zip"),
        _policy_weights(tmp_path / "ref" / "model.zip"),
        strict=True,
    ):
        np.testing.assert_array_equal(a, b)
    assert summary["runs"][0]["train"]["mean_return"] != summary["runs"][1]["train"]["mean_return"]
