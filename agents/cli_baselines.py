"""The ``quad-uneven baselines`` subcommand: its parser and handler (the work is
:func:`agents.evaluation.baselines.baselines`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from agents.cli_backend import add_backend_arguments, backend_options
from agents.interrupts import sigterm_as_keyboard_interrupt

__all__ = ["add_baselines_parser", "run_baselines_command"]


def add_baselines_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register the ``baselines`` subcommand on ``sub`` (its handler is in ``func``)."""
    p = sub.add_parser(
        "baselines",
        help="evaluate several policies on the same episodes of several suites; write one markdown table",
        description="Run 'quad-uneven evaluate' for every policy on every suite (DIR/runs/POLICY/SUITE/; a rerun "
        "resumes them) and write DIR/baselines.md (rows policies, columns suites: episodes that reached the goal / "
        "episodes; then one table per suite by entry) and DIR/baselines.json (docs/results.md#baselines). Exit code "
        "2 on an invalid policy, suite or option; 130 when interrupted (rerun the same command to continue).",
    )
    p.add_argument(
        "--policies",
        required=True,
        help="comma-separated rows: 'zero', 'expert', 'expert:ADAPTATION' (e.g. expert:learned), SB3 model .zip "
        "paths or exported .onnx paths, e.g. 'zero,expert,expert:learned,models/distilled/model.zip'",
    )
    p.add_argument(
        "--suites",
        required=True,
        help="comma-separated columns: shipped suite names or suite .yaml paths, each optionally @ROBOT to run it on "
        "that robot at its scale (as evaluate --robot ROBOT --scale-terrain), e.g. 'targets,robust_hard,targets@go1'",
    )
    p.add_argument("--out", type=Path, required=True, help="output directory DIR")
    p.add_argument("--episodes", type=int, default=None, help="at most N seeds per terrain entry (default: all)")
    p.add_argument("--seed", type=int, default=0, help="offset added to every seed of the suites (default 0)")
    add_backend_arguments(p)
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=run_baselines_command)
    return p


def run_baselines_command(args: argparse.Namespace) -> int:
    """Handler of ``quad-uneven baselines``: 0 on success, 2 on an invalid policy, suite or option."""
    from agents.evaluation.baselines import baselines

    if args.episodes is not None and args.episodes < 1:
        raise ValueError(f"--episodes must be >= 1, got {args.episodes}")
    backend = backend_options(args)
    policies = [p for p in args.policies.split(",") if p.strip()]
    suites = [s for s in args.suites.split(",") if s.strip()]
    with sigterm_as_keyboard_interrupt():
        baselines(
            policies, suites, args.out, episodes=args.episodes, seed=args.seed, progress=not args.no_progress,
            **backend,
        )  # fmt: skip
    print(f"table written to {(Path(args.out) / 'baselines.md').resolve()}")
    return 0
