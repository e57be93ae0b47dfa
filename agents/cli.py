"""The ``quad-uneven`` command line: demo (and, as they land, evaluate, paper, train)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np

import quad_uneven_env  # noqa: F401  (registers QuadUneven-v0)
from agents.evaluate import add_evaluate_parser
from agents.report import plot_forces_and_torques, plot_paths, plot_stability, write_frames
from agents.rollout import ZeroActionPolicy, run_episode


def demo(out: Path, terrain: str, seed: int, seconds: float) -> dict:
    """Stand the robot on the default rough terrain, write a report; return its summary."""
    out.mkdir(parents=True, exist_ok=True)
    env = gym.make(
        "QuadUneven-v0", terrain=terrain, action_mode="joint_pd", render_mode="rgb_array", width=480, height=360
    )
    steps = round(seconds / env.unwrapped.dt)
    rec = run_episode(
        env, ZeroActionPolicy(env.action_space), seed=seed, max_steps=steps, frame_every=max(1, steps // 4)
    )
    mass = env.unwrapped.idx.total_mass
    finite = rec.stability_index[np.isfinite(rec.stability_index)]
    summary = {
        "terrain": terrain,
        "seed": seed,
        "policy": "hold standing pose (joint_pd, zero action)",
        "sim_time_s": float(rec.time[-1]) if rec.time.size else 0.0,
        "termination_reason": rec.termination_reason,
        "min_stability_index_Nm": float(finite.min()) if finite.size else None,
        "mean_stability_index_Nm": float(finite.mean()) if finite.size else None,
        "time_with_fewer_than_3_feet_s": float((~np.isfinite(rec.stability_index)).sum() * env.unwrapped.dt),
    }
    plots = [
        plot_stability(rec, mass, out / "stability_index.png"),
        plot_paths(rec, out / "paths.png"),
        plot_forces_and_torques(rec, out / "forces_torques.png"),
    ]
    frames = write_frames(rec.frames, out)
    env.close()
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    lines = ["# quad-uneven demo", "", "| quantity | value |", "|---|---|"]
    lines += [f"| {k} | {v} |" for k, v in summary.items()]
    lines += ["", *[f"![{p.stem}]({p.name})" for p in plots + frames]]
    (out / "report.md").write_text("\n".join(lines) + "\n")
    return summary


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``quad-uneven``."""
    parser = argparse.ArgumentParser(prog="quad-uneven", description="Quadruped locomotion on uneven terrain")
    sub = parser.add_subparsers(dest="command", required=True)
    p_demo = sub.add_parser("demo", help="run the main job on the default terrain and write a report")
    p_demo.add_argument("--out", type=Path, default=Path("out/demo"), help="output directory")
    p_demo.add_argument("--terrain", default="rough", help="terrain kind (default: rough)")
    p_demo.add_argument("--seed", type=int, default=0)
    p_demo.add_argument("--seconds", type=float, default=4.0, help="simulated time (s)")
    add_evaluate_parser(sub)
    args = parser.parse_args(argv)
    if getattr(args, "func", None) is not None:
        return args.func(args)
    if args.command == "demo":
        summary = demo(args.out, args.terrain, args.seed, args.seconds)
        for k, v in summary.items():
            print(f"{k:32s} {v}")
        print(f"report written to {args.out.resolve()}/report.md")
    return 0


if __name__ == "__main__":
    sys.exit(main())
