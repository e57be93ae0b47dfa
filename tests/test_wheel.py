"""The package as a user installs it: ``python -m build`` gives an sdist and a wheel built from that sdist; the
wheel, installed outside the checkout, is used from another directory (the shipped configs are package data;
nothing is read from the repository)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tarfile
import zipfile
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
def dist(tmp_path_factory) -> Path:
    """``python -m build`` of this checkout (the sdist, then the wheel built from the unpacked sdist), with the
    build tools of the test's interpreter."""
    out = tmp_path_factory.mktemp("dist")
    build = [sys.executable, "-m", "build", "--no-isolation", "-o", str(out), str(ROOT)]
    result = subprocess.run(build, capture_output=True, text=True, cwd=out)
    assert result.returncode == 0, result.stdout[-2000:] + result.stderr[-2000:]
    return out


@pytest.fixture(scope="module")
def installed(dist, tmp_path_factory) -> Path:
    """The wheel installed (without its dependencies, which the test's interpreter has) into a fresh folder."""
    (wheel,) = dist.glob("quad_uneven-*.whl")
    site = tmp_path_factory.mktemp("site")
    subprocess.run(
        [sys.executable, "-m", "pip", "install", "--no-deps", "-q", "--target", str(site), str(wheel)],
        check=True,
        capture_output=True,
    )
    return site


def _shipped_configs() -> set[str]:
    return {p.relative_to(ROOT / "configs").as_posix() for p in (ROOT / "configs").rglob("*.yaml")}


def test_the_sdist_and_the_wheel_carry_everything_they_need(dist):
    (sdist,) = dist.glob("quad_uneven-*.tar.gz")
    with tarfile.open(sdist) as tar:
        names = {n.split("/", 1)[1] for n in tar.getnames() if "/" in n}
    for needed in ("pyproject.toml", "setup.py", "README.md", "LICENSE", "CHANGELOG.md", "CITATION.cff"):
        assert needed in names
    assert {f"configs/{c}" for c in _shipped_configs()} <= names
    assert "agents/control/adaptation/data/strength_estimator.npz" in names

    (wheel,) = dist.glob("quad_uneven-*.whl")
    with zipfile.ZipFile(wheel) as whl:
        files = set(whl.namelist())
        (metadata,) = (n for n in files if n.endswith(".dist-info/METADATA"))
        meta = whl.read(metadata).decode()
    assert {f"quad_uneven_env/configs/{c}" for c in _shipped_configs()} <= files
    assert {"quad_uneven_env/py.typed", "planners/py.typed", "agents/py.typed"} <= files
    assert "agents/control/adaptation/data/strength_estimator.npz" in files
    assert not any(n.startswith(("tests/", "models/", "docs/")) for n in files)
    assert "License-Expression: MIT" in meta
    assert "Requires-Dist: mujoco" in meta


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
