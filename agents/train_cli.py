"""The ``quad-uneven train`` subcommand: options, config loading, error reporting (training: :mod:`agents.train`).

Kept free of Stable-Baselines3, torch and the expert's compiled kernels, so building the command-line
parser stays fast for the other subcommands.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from agents.train_config import ALGOS, TrainConfigError, load_train_config

__all__ = ["add_train_parser", "run_train_command"]


def add_train_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register the ``train`` subcommand on ``sub`` (its handler is in ``func``)."""
    p = sub.add_parser(
        "train",
        help="train a residual RL agent (SB3 PPO or SAC) on top of the scripted expert",
        description="Train a residual agent on QuadUnevenResidual-v0 (expert torques + residual_scale x action x "
        "torque limit). Writes DIR/model.zip, DIR/rl_meta.json, DIR/learning_curve.png and more (docs/rl.md). "
        "Options override single fields of the config (default configs/rl/ALGO_residual.yaml). Exit code 2 on "
        "an invalid option or config.",
    )
    p.add_argument("--algo", choices=ALGOS, default=None, help="SB3 algorithm (default: the config's, else ppo)")
    p.add_argument("--terrain", default=None, help="terrain kind, preset or YAML path (default: the config's)")
    p.add_argument("--timesteps", type=int, default=None, help="total env steps over all envs")
    p.add_argument("--out", type=Path, required=True, help="output directory DIR")
    p.add_argument("--seed", type=int, default=None, help="seed of the model and envs (default: the config's)")
    p.add_argument("--n-envs", type=int, default=None, help="parallel envs (default: the config's)")
    p.add_argument("--residual-scale", type=float, default=None, help="residual torque per unit action / limit")
    p.add_argument(
        "--time-limit-min", type=float, default=None, help="stop (and save) after this many minutes of training"
    )
    p.add_argument("--config", default=None, help="training config YAML (default configs/rl/ALGO_residual.yaml)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=run_train_command)
    return p


def run_train_command(args: argparse.Namespace) -> int:
    """Handler of ``quad-uneven train``: 0 on success, 2 on an invalid option or config."""
    overrides = {
        "algo": args.algo,
        "terrain": args.terrain,
        "timesteps": args.timesteps,
        "seed": args.seed,
        "n_envs": args.n_envs,
        "residual_scale": args.residual_scale,
        "time_limit_min": args.time_limit_min,
    }
    try:
        cfg = load_train_config(args.config, overrides)
        from agents.train import train  # deferred: SB3, torch and the expert's kernels

        summary = train(cfg, args.out, progress=not args.no_progress)
    except TrainConfigError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    for key in ("timesteps", "wall_time", "steps_per_s", "episodes", "mean_return", "mean_stability_index",
                "mean_distance", "fall_rate"):  # fmt: skip
        value = summary[key]
        print(f"{key:22s} {round(value, 3) if isinstance(value, float) else value}")
    print(f"model: {Path(summary['model']).resolve()}")
    print(f"learning curve: {(Path(args.out) / 'learning_curve.png').resolve()}")
    return 0
