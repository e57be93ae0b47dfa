"""Planning time per gait cycle of the expert under commands with and without a yaw rate.

For each command: ``QuadUneven-v0(terrain=rough 5 cm, command=...)`` with the expert, walked for ``--cycles``
gait cycles per seed; printed: the median and 95th percentile over the successful plans of the COG solve
time (``plan.stats["cog_solve_time"]``) and of the whole cycle plan (``plan.stats["total_time"]``: footholds,
COG path, swings), in ms. Timings on a shared machine are noisy: compare the rows of one run.

Usage: ``python benchmarks/command_planning_time.py [--seeds 2] [--cycles 6]
[--durations 0.35,0.35,0.35,0.1,0.35,0.35,0.35] [--commands="0.1,0,0 0,0,0.3 0.1,0,0.2"]``
(commands: space-separated ``vx,vy,yaw_rate`` triples, m/s, m/s, rad/s).
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np

import quad_uneven_env  # noqa: F401
from agents.expert import ExpertConfig, attach_expert

TERRAIN = {"kind": "rough", "amplitude": 0.05, "x_start": -7.0, "length": 14.0, "width": 8.0, "spawn_radius": 0.4}
"""The command suite's terrain (configs/suites/command.yaml)."""


def plan_times(command: dict, seed: int, cycles: int, config: ExpertConfig) -> tuple[list[float], list[float]]:
    """COG solve and whole-plan times (ms) of every successful plan of one episode."""
    env = gym.make("QuadUneven-v0", terrain=TERRAIN, command=command, max_episode_steps=10**7)
    expert = attach_expert(env, config)
    env.reset(seed=seed)
    for _ in range(round(cycles * sum(config.durations) / env.unwrapped.dt)):
        _, _, term, _, _ = env.step(expert.predict(None)[0])
        if term:
            break
    plans = [p for _, p in expert.plans if hasattr(p, "stats")]
    env.close()
    return [1e3 * p.stats["cog_solve_time"] for p in plans], [1e3 * p.stats["total_time"] for p in plans]


def main(argv: list[str] | None = None) -> None:
    """Print one line per command."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=2)
    parser.add_argument("--cycles", type=int, default=6)
    parser.add_argument("--durations", default=None, help="the expert's 7 phase durations (s), comma-separated")
    parser.add_argument("--commands", default="0.1,0,0 0,0.1,0 0,0,0.3 0,0,-0.3 0.1,0,0.2 0.1,0.05,-0.3")
    args = parser.parse_args(argv)
    config = (
        ExpertConfig()
        if args.durations is None
        else ExpertConfig(durations=tuple(map(float, args.durations.split(","))))
    )
    print(f"durations {config.durations}, {args.seeds} seeds x {args.cycles} cycles")
    print("   vx    vy  yaw_rate | plans | COG ms median  p95 | cycle ms median  p95")
    for triple in args.commands.split():
        vx, vy, wz = map(float, triple.split(","))
        cog, total = [], []
        for seed in range(args.seeds):
            c, t = plan_times({"vx": vx, "vy": vy, "yaw_rate": wz}, seed, args.cycles, config)
            cog += c
            total += t
        print(
            f"{vx:5.2f} {vy:5.2f} {wz:9.2f} | {len(cog):5d} | {np.median(cog):13.1f} {np.percentile(cog, 95):4.1f} | "
            f"{np.median(total):15.1f} {np.percentile(total, 95):4.1f}",
            flush=True,
        )


if __name__ == "__main__":
    main()
