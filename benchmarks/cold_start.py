"""Start-up cost of a new process: the wall time from starting Python to the first env step, to the first step of
the expert, and to the end of a one-episode evaluation, with the kernel cache off, empty and warm.

Usage: ``.venv/bin/python benchmarks/cold_start.py [--repeats 2]``

Every measurement is a fresh ``python`` process (what a CLI call, an evaluation worker, a vector-env copy or a Ray
task pays). Three cache states, each in a temporary ``QUAD_UNEVEN_CACHE_DIR``:

- ``off``: a folder that cannot be written, so every kernel compiles in the process (the cost without the cache);
- ``cold``: an empty folder (the first process after an install or an upgrade compiles and fills it);
- ``warm``: the folder the cold run filled.

Prints a Markdown table, then the ratios cold / off and warm / off measured in the same run. The target: warm, the
first expert step within 5 s of starting Python.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

PROBE = """
import json, sys, time
import gymnasium as gym
import numpy as np
import quad_uneven_env
from agents.expert import attach_expert

env = gym.make("QuadUneven-v0", terrain="rough")
env.reset(seed=0)
env.step(np.zeros(12, dtype=np.float32))
t_env = time.time()
env = gym.make("QuadUneven-v0", terrain="rough")
attach_expert(env)
env.reset(seed=0)
env.step(np.zeros(12, dtype=np.float32))
t_expert = time.time()
print(json.dumps({"env": t_env, "expert": t_expert}))
"""

SUITE = """name: one_episode
goal_distance: 0.5
time_limit: 10.0
terrains:
  - kind: rough
    params: {amplitude: 0.04, wavelength: 0.6}
    seeds: [0]
"""


def _env(cache: Path) -> dict[str, str]:
    return {**os.environ, "QUAD_UNEVEN_CACHE_DIR": str(cache), "PYTHONPATH": str(ROOT)}


def _first_steps(cache: Path) -> tuple[float, float]:
    """(s to the first env step, s to the first expert step), both from the moment the process is started."""
    start = time.time()
    out = subprocess.run([sys.executable, "-c", PROBE], env=_env(cache), capture_output=True, text=True, check=True)
    r = json.loads(out.stdout.strip().splitlines()[-1])
    return r["env"] - start, r["expert"] - start


def _evaluation(cache: Path, folder: Path) -> float:
    """s for ``quad-uneven evaluate`` of one episode, start to exit."""
    suite = folder / "one_episode.yaml"
    suite.write_text(SUITE)
    start = time.perf_counter()
    subprocess.run(
        [sys.executable, "-m", "agents.cli", "evaluate", "--policy", "expert", "--suite", str(suite), "--no-progress",
         "--out", str(folder / f"ev_{time.time_ns()}")],
        env=_env(cache), capture_output=True, text=True, check=True,
    )  # fmt: skip
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=2, help="warm measurements per row (default 2)")
    args = parser.parse_args()
    rows: dict[str, list[tuple[float, float, float]]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        blocked = folder / "a_file"
        blocked.write_text("")
        off = blocked / "cache"  # cannot be created: the cache is off
        cache = folder / "cache"
        rows["off"] = [(*_first_steps(off), _evaluation(off, folder))]
        first = _first_steps(cache)  # the empty cache is filled by this process
        rows["cold"] = [(*first, float("nan"))]
        rows["warm"] = [(*_first_steps(cache), _evaluation(cache, folder)) for _ in range(args.repeats)]
    print("| cache | first env step (s) | first expert step (s) | one-episode evaluation (s) |")
    print("|---|---|---|---|")
    best = {}
    for name, values in rows.items():
        best[name] = tuple(min(v[k] for v in values) for k in range(3))
        env_s, expert_s, eval_s = best[name]
        print(f"| {name} | {env_s:.1f} | {expert_s:.1f} | {eval_s:.1f} |")
    for name in ("cold", "warm"):
        ratios = ", ".join(
            f"{label} {best[name][k] / best['off'][k]:.2f} x"
            for k, label in enumerate(("env step", "expert step", "evaluation"))
            if best[name][k] == best[name][k]
        )
        print(f"{name} / off: {ratios}")
    print(f"target: warm, first expert step within 5 s: {best['warm'][1]:.1f} s")


if __name__ == "__main__":
    main()
