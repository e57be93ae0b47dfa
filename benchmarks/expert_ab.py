"""Two commits' expert in one process, walking the same episode in lockstep: their wall time per physics step, paired.

On a shared machine one run's speed varies more than a change worth having (another process on the same cores,
frequency, caches), and separate processes alternated A B A B still see different moments. Here both commits'
packages are imported side by side (each one a ``git archive`` of the commit in a temporary directory, its
packages renamed ``a_*`` / ``b_*`` and its env registered as ``aQuadUneven-v0`` / ``bQuadUneven-v0``); both envs
walk from ``reset(seed=0)`` in turns of ``--chunk`` control steps, the order alternating, and each turn's wall
time per physics step is paired with the other commit's turn over the same stretch of the episode. The envs are
made anew for every repetition, in alternating order. End states are compared (the same floats unless a commit
changes the motion). An A/A run (``--a X --b X``) shows the method's own bias.

Usage: ``python benchmarks/expert_ab.py --a b3205d3 --b HEAD [--seconds 20] [--chunk 50] [--reps 4]``
"""

from __future__ import annotations

import argparse
import importlib
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

PACKAGES = ("quad_uneven_env", "planners", "agents")
ROOT = Path(__file__).resolve().parents[1]


def renamed_copy(commit: str, prefix: str, into: Path) -> Path:
    """``commit``'s tree under ``into``/``prefix`` with its packages renamed ``prefix_<package>``."""
    dst = into / prefix
    dst.mkdir()
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", commit], check=True, capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(dst)], input=archive, check=True)
    word = re.compile(r"\b(" + "|".join(PACKAGES) + r")\b")
    for pkg in PACKAGES:
        (dst / pkg).rename(dst / f"{prefix}_{pkg}")
    for pkg in PACKAGES:
        for path in (dst / f"{prefix}_{pkg}").rglob("*.py"):
            path.write_text(word.sub(lambda m: f"{prefix}_{m.group(1)}", path.read_text()))
    init = dst / f"{prefix}_quad_uneven_env" / "__init__.py"
    init.write_text(init.read_text().replace('ENV_ID = "QuadUneven-v0"', f'ENV_ID = "{prefix}QuadUneven-v0"'))
    return dst


def main(argv: list[str] | None = None) -> None:
    """Build both copies, walk them in lockstep, print the paired figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--a", default="HEAD~1", help="the first commit (the baseline)")
    parser.add_argument("--b", default="HEAD", help="the second commit")
    parser.add_argument("--seconds", type=float, default=20.0, help="simulated seconds per repetition")
    parser.add_argument("--chunk", type=int, default=50, help="control steps per turn")
    parser.add_argument("--reps", type=int, default=4, help="repetitions (envs made anew, order alternating)")
    args = parser.parse_args(argv)
    import gymnasium as gym

    with tempfile.TemporaryDirectory() as tmp:
        experts = {}
        for prefix, commit in (("a", args.a), ("b", args.b)):
            sys.path.insert(0, str(renamed_copy(commit, prefix, Path(tmp))))
            importlib.import_module(f"{prefix}_quad_uneven_env")
            experts[prefix] = importlib.import_module(f"{prefix}_agents.expert")

        def make(prefix: str):
            env = gym.make(f"{prefix}QuadUneven-v0", terrain="rough", max_episode_steps=10**7)
            policy = experts[prefix].attach_expert(env, experts[prefix].ExpertConfig())
            obs, _ = env.reset(seed=1)  # compile outside the timing
            for _ in range(5):
                obs, *_ = env.step(policy.predict(obs)[0])
            return env, policy

        times: dict[str, list[float]] = {"a": [], "b": []}
        for rep in range(args.reps):
            runs = {p: make(p) for p in (("a", "b") if rep % 2 == 0 else ("b", "a"))}
            obs = {p: runs[p][0].reset(seed=0)[0] for p in runs}
            n = int(args.seconds / runs["a"][0].unwrapped.dt)
            for start in range(0, n, args.chunk):
                for p in ("a", "b") if (start // args.chunk + rep) % 2 == 0 else ("b", "a"):
                    env, policy = runs[p]
                    u, o = env.unwrapped, obs[p]
                    s0 = u.data.time
                    t0 = time.perf_counter()
                    for _ in range(min(args.chunk, n - start)):
                        o, *_ = env.step(policy.predict(o)[0])
                    wall = time.perf_counter() - t0
                    obs[p] = o
                    times[p].append(wall / round((u.data.time - s0) / u.model.opt.timestep) * 1e6)
            same = np.array_equal(runs["a"][0].unwrapped.data.qpos, runs["b"][0].unwrapped.data.qpos)
            print(f"repetition {rep}: end states {'the same' if same else 'DIFFERENT'}", flush=True)
    a, b = np.array(times["a"]), np.array(times["b"])
    d = b - a
    print(f"{args.a} (a) against {args.b} (b): {len(d)} pairs of {args.chunk} control steps, us per physics step")
    for name, t in (("a", a), ("b", b)):
        p10, median = np.percentile(t, 10), np.median(t)
        print(f"  {name}: min {t.min():.1f}, p10 {p10:.1f}, median {median:.1f}, mean {t.mean():.1f}")
    print(
        f"  b - a: median {np.median(d):.2f}, mean {d.mean():.2f} +- {d.std() / np.sqrt(len(d)):.2f} (standard error); "
        f"b faster in {np.mean(d < 0) * 100:.0f} % of pairs"
    )


if __name__ == "__main__":
    main()
