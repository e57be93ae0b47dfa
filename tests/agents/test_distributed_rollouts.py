"""``collect`` and ``distill`` with ``--backend ray``: on a local Ray, the same dataset and the same student as with
local processes; their backend options' errors."""

from __future__ import annotations

import io
import zipfile
from pathlib import Path

import numpy as np
import pytest
import yaml

import quad_uneven_env  # noqa: F401  (registers QuadUneven-v0)
from agents.cli import main
from agents.evaluation.suites import suite_from_dict

TINY_DISTILL = {
    "name": "tiny",
    "goal_distance": 5.0,
    "time_limit": 0.6,
    "terrains": [{"kind": "flat", "seeds": [0]}, {"kind": "rough", "params": {"amplitude": 0.04}, "seeds": [1]}],
}
"""Two episodes of 30 control steps each."""


def policy_weights(path: Path) -> dict[str, np.ndarray]:
    import torch

    with zipfile.ZipFile(path) as z:
        state = torch.load(io.BytesIO(z.read("policy.pth")), weights_only=True)
    return {k: v.numpy() for k, v in state.items()}


def test_distill_on_ray_gives_the_student_of_local_rollouts(tmp_path, local_ray):
    pytest.importorskip("stable_baselines3")
    from agents.rl.distill import DistillConfig, distill

    suite = suite_from_dict(TINY_DISTILL, source="test")
    base = dict(dagger_rounds=1, episodes=1, epochs=2, net_arch=(16,), seed=3)
    local = distill(suite, tmp_path / "local", DistillConfig(**base), log=lambda _: None)
    on_ray = distill(suite, tmp_path / "ray", DistillConfig(**base, backend="ray"), log=lambda _: None)
    assert [r["round"] for r in on_ray["rounds"]] == [0, 1]
    assert on_ray["rounds"][1]["student_steps"] > 0  # the student's parameters travelled to the Ray workers
    for a, b in zip(local["rounds"], on_ray["rounds"], strict=True):
        for key in ("steps", "student_steps", "successes", "mean_distance", "loss", "label_rmse_on_policy"):
            assert a.get(key) == b.get(key), key
    wa, wb = policy_weights(tmp_path / "local" / "model.zip"), policy_weights(tmp_path / "ray" / "model.zip")
    assert wa.keys() == wb.keys() and all(np.array_equal(wa[k], wb[k]) for k in wa)
    assert on_ray["config"]["backend"] == "ray" and local["config"]["backend"] == "pool"


def test_collect_on_ray_gives_the_dataset_of_local_processes(tmp_path, local_ray):
    pytest.importorskip("minari", reason="the 'datasets' extra (Minari) is not installed")
    from agents.datasets import collect, load_collected

    raw = yaml.safe_load(Path("configs/suites/smoke.yaml").read_text())
    raw.update(name="smoke-short", time_limit=0.6, terrains=raw["terrains"][:2])
    suite = tmp_path / "suite.yaml"
    suite.write_text(yaml.safe_dump(raw))
    collect(suite, tmp_path / "local", episodes=1, progress=False)
    code = main(["collect", "--policy", "expert", "--suite", str(suite), "--out", str(tmp_path / "ray"), "--episodes",
                 "1", "--backend", "ray", "--no-progress"])  # fmt: skip
    assert code == 0
    a, b = load_collected(tmp_path / "local"), load_collected(tmp_path / "ray")
    assert a.total_episodes == b.total_episodes == 2
    for i in range(2):
        ea, eb = a[i], b[i]
        assert len(ea.actions) == 30
        for name in ("observations", "actions", "rewards", "terminations", "truncations"):
            np.testing.assert_array_equal(getattr(ea, name), getattr(eb, name), err_msg=name)
    assert not np.array_equal(a[0].observations[-1], a[1].observations[-1])  # two episodes, not one twice


@pytest.mark.parametrize("command", ["collect", "distill"])
@pytest.mark.parametrize(
    ("extra", "says"),
    [
        (["--address", "auto"], "--address and --ship-code need --backend ray"),
        (["--ship-code"], "--address and --ship-code need --backend ray"),
        (["--backend", "ray", "--address", "auto", "--workers", "2"], "drop --workers 2"),
        (["--workers", "0"], "--workers must be >= 1"),
        (["--backend", "spark"], "invalid choice"),
    ],
)
def test_backend_options_errors_are_one_line_with_exit_code_2(tmp_path, capsys, command, extra, says):
    policy = ["--policy", "expert"] if command == "collect" else []
    rc = main([command, *policy, "--suite", "smoke", "--out", str(tmp_path / "o"), *extra])
    err = capsys.readouterr().err
    assert rc == 2 and says in err, err
    assert not (tmp_path / "o").exists()
