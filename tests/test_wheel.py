"""The package as a user installs it: a wheel built from this checkout, installed outside it, used from another
directory (the shipped configs are package data; nothing is read from the repository)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

SMOKE = """
import json, sys
import gymnasium as gym
import numpy as np
import quad_uneven_env
from agents.expert import attach_expert
from quad_uneven_env.config import CONFIG_DIR

env = gym.make("QuadUneven-v0", terrain="stairs_up")
expert = attach_expert(env)
env.reset(seed=0)
for _ in range(10):
    obs, reward, terminated, truncated, info = env.step(np.zeros(12, dtype=np.float32))
print(json.dumps({"package": quad_uneven_env.__file__, "configs": str(CONFIG_DIR), "terminated": bool(terminated),
                  "x": float(info["distance"])}))
"""


@pytest.fixture(scope="module")
def installed(tmp_path_factory) -> Path:
    """A wheel of this checkout installed (without its dependencies, which the test's interpreter has) into a
    fresh folder."""
    work = tmp_path_factory.mktemp("wheel")
    build = [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", str(ROOT), "-w"]
    subprocess.run([*build, str(work / "dist")], check=True, capture_output=True, cwd=work)
    (wheel,) = (work / "dist").glob("quad_uneven-*.whl")
    site = work / "site"
    subprocess.run(
        [sys.executable, "-m", "pip", "install", "--no-deps", "-q", "--target", str(site), str(wheel)],
        check=True,
        capture_output=True,
    )
    return site


def _run(site: Path, cwd: Path, *args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(site)}
    env.pop("QUAD_UNEVEN_CONFIGS", None)
    return subprocess.run([sys.executable, *args], env=env, cwd=cwd, capture_output=True, text=True, timeout=900)


def test_the_installed_wheel_runs_the_env_the_expert_and_an_evaluation(installed, tmp_path):
    result = _run(installed, tmp_path, "-c", SMOKE)
    assert result.returncode == 0, result.stderr[-2000:]
    report = json.loads(result.stdout.strip().splitlines()[-1])
    assert Path(report["package"]).is_relative_to(installed)
    assert Path(report["configs"]).is_relative_to(installed)  # the package data, not the checkout's configs/
    assert not report["terminated"]

    out = tmp_path / "ev"
    cli = ["-m", "agents.cli", "evaluate", "--policy", "expert", "--suite", "smoke", "--episodes", "1"]
    result = _run(installed, tmp_path, *cli, "--out", str(out), "--no-progress")
    assert result.returncode == 0, result.stderr[-2000:]
    episodes = json.loads((out / "results.json").read_text())["episodes"]
    assert len(episodes) >= 1
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()
