"""Speed of the residual env while the agent explores: env steps/s at several residual noise levels.

One process, the training world of a training config (default ``configs/rl/ppo_residual_adaptive.yaml``,
the shipped residual agent's: extreme randomization on its terrain mix, stance-gated residual as a gain on the
expert's torque, expert features on), the same seeds for every row. Each row steps
QuadUnevenResidual-v0 with Gaussian residual actions of the given std around 0 (clipped to [-1, 1]; PPO's
exploration noise with ``log_std_init`` = ln(std) around the untrained agent), resets included, and reports
env steps/s and the ratio to the noise-free row measured in the same run, and the falls. The reference row,
std 0, is the untrained agent (the expert alone).

Usage: ``python benchmarks/residual_exploration.py [--steps 1500] [--stds 0,0.08,0.2,0.37] [--config YAML]``
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from agents.rl.config import load_train_config
from agents.rl.vec_env import make_train_env


def _rate(cfg, std: float, steps: int, seed: int) -> dict[str, float]:
    env = make_train_env(
        cfg.terrain, cfg.max_episode_steps, dict(cfg.env_kwargs), cfg.randomization, cfg.residual_config()
    )
    rng = np.random.default_rng(seed)
    env.reset(seed=seed)
    for _ in range(20):  # compile the kernels of this process before timing
        env.step(np.zeros(12, dtype=np.float32))
    env.reset(seed=seed)
    falls = episodes = 0
    t0 = time.perf_counter()
    for _ in range(steps):
        action = np.clip(rng.normal(0.0, std, 12), -1.0, 1.0).astype(np.float32)
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            falls += int(terminated)
            episodes += 1
            env.reset()
    wall = time.perf_counter() - t0
    env.close()
    return {"steps_per_s": steps / wall, "falls": falls, "episodes": episodes}


def main(argv: list[str] | None = None) -> None:
    """Measure every noise level and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=1500, help="control steps per row (20 ms each)")
    parser.add_argument("--stds", default="0,0.08,0.2,0.37", help="comma-separated residual noise stds")
    parser.add_argument("--config", default="configs/rl/ppo_residual_adaptive.yaml")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    cfg = load_train_config(args.config)
    stds = [float(s) for s in args.stds.split(",")]
    _rate(cfg, 0.1, 1000, args.seed + 1)  # compile every terrain's kernels in this process first (not timed)
    rows = [(std, _rate(cfg, std, args.steps, args.seed)) for std in stds]
    ref = next((r for s, r in rows if s == 0.0), rows[0][1])["steps_per_s"]
    gain = cfg.residual_basis == "expert_torque"
    print(f"residual env, {args.config}: {args.steps} steps per row, one process, mean action 0")
    unit = "x the expert's torque" if gain else "N m"
    print(f"| noise std | residual noise std ({unit}) | env steps/s | ratio to std 0 | falls / episodes ended |")
    print("|---|---|---|---|---|")
    for std, r in rows:
        noise = std * cfg.residual_scale * (1.0 if gain else 120.0)
        rate = r["steps_per_s"]
        print(f"| {std:g} | {noise:.2f} | {rate:.0f} | {rate / ref:.2f} | {r['falls']} / {r['episodes']} |")


if __name__ == "__main__":
    main()
