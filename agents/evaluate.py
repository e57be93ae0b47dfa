"""``quad-uneven evaluate``: run a policy over a terrain suite, write results.json, report.md, plots, videos.

Typical use::

    quad-uneven evaluate --policy expert --suite rough --out out/eval/rough --workers 2

Python API: :func:`evaluate` (returns the results dict) and :func:`make_policy` (re-exported from
:mod:`agents.evaluate_policies`). Formats and definitions: docs/evaluation.md.
"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import json
import multiprocessing
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from tqdm.auto import tqdm

from agents.evaluate_episode import EpisodeResult, EvalConfig, make_env, run_task
from agents.evaluate_metrics import json_safe, summarize
from agents.evaluate_policies import SB3_ALGOS, PolicyError, make_policy, policy_kind
from agents.evaluate_report import write_report
from agents.evaluate_targets import check_targets
from agents.suites import EpisodeTask, Suite, SuiteError, episode_tasks, load_suite, suite_names

__all__ = ["add_evaluate_parser", "evaluate", "make_policy", "run_evaluate_command"]


def _run_all(tasks: list[EpisodeTask], cfg: EvalConfig, workers: int, progress: bool) -> list[EpisodeResult]:
    """Run every task, in ``workers`` spawned processes if > 1; results in task order."""
    results: list[EpisodeResult | None] = [None] * len(tasks)
    bar = tqdm(total=len(tasks), desc="episodes", unit="ep", disable=not progress)
    if workers <= 1:
        for t in tasks:
            results[t.index] = run_task(t, cfg)
            bar.update(1)
    else:
        ctx = multiprocessing.get_context("spawn")  # MuJoCo (and its GL contexts) + fork is fragile
        pool = cf.ProcessPoolExecutor(max_workers=workers, mp_context=ctx)
        try:
            futures = {pool.submit(run_task, t, cfg): t.index for t in tasks}
            for fut in cf.as_completed(futures):
                results[futures[fut]] = fut.result()
                bar.update(1)
        except BaseException:  # an error or Ctrl-C: do not wait for the queued episodes
            pool.shutdown(wait=False, cancel_futures=True)
            bar.close()
            raise
        pool.shutdown()
    bar.close()
    return results  # type: ignore[return-value]


def _preflight(task: EpisodeTask, cfg: EvalConfig) -> None:
    """Build the first episode's env and policy here, so bad env kwargs or policies fail before any worker starts."""
    env = make_env(task, cfg)
    try:
        make_policy(cfg.policy, env, cfg.algo)
    finally:
        env.close()


def _save_traces(episodes: list[EpisodeResult], out: Path) -> None:
    folder = out / "traces"
    folder.mkdir(exist_ok=True)
    for e in episodes:
        np.savez_compressed(folder / f"ep{e.record['index']:03d}.npz", **e.trace)


def evaluate(
    suite: Suite | str | Path,
    policy: str,
    out: str | Path,
    episodes: int | None = None,
    seed: int = 0,
    workers: int = 1,
    video: bool = False,
    algo: str = "ppo",
    env_kwargs: Mapping[str, Any] | None = None,
    progress: bool = True,
) -> dict[str, Any]:
    """Run ``policy`` on every (terrain entry, seed) of ``suite``; write ``out/results.json``, ``report.md``, PNGs.

    :param suite: a :class:`Suite`, a shipped suite name or a suite YAML path.
    :param policy: ``"zero"``, ``"expert"`` or the path of an SB3 model ``.zip`` (loaded with ``algo``).
    :param episodes: at most this many seeds per terrain entry (None: all).
    :param seed: offset added to every seed of the suite.
    :param workers: episodes run in this many spawned processes (1: in this process).
    :param video: MP4 of the first episode of each terrain entry in ``out/videos/``.
    :param env_kwargs: extra QuadUneven-v0 arguments (override the policy's own).
    :return: the results.json content.
    :raises SuiteError: on an invalid suite; ``PolicyError`` on an unusable policy; ValueError on bad arguments.
    """
    if not isinstance(suite, Suite):
        suite = load_suite(suite)
    policy_kind(policy)
    if algo not in SB3_ALGOS:
        raise PolicyError(f"algo must be one of {list(SB3_ALGOS)}, got {algo!r}")
    if workers < 1:
        raise ValueError(f"workers must be an integer >= 1, got {workers}")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    tasks = episode_tasks(suite, episodes, seed)
    cfg = EvalConfig(
        policy=str(policy),
        goal_distance=suite.goal_distance,
        time_limit=suite.time_limit,
        algo=algo,
        env_kwargs=dict(env_kwargs or {}),
        video_dir=str(out / "videos") if video else None,
    )
    _preflight(tasks[0], cfg)
    runs = _run_all(tasks, cfg, min(workers, len(tasks)), progress)
    records = [json_safe(r.record) for r in runs]
    labels = [e.label for e in suite.terrains]
    summary = json_safe(summarize(records, labels))
    results = {
        "suite": suite.name,
        "policy": str(policy),
        "episodes": records,
        "summary": summary,
        "targets": json_safe(check_targets(suite.terrains, summary["by_entry"], suite.goal_distance)),
        "meta": json_safe(
            {
                "suite_file": suite.source,
                "goal_distance": suite.goal_distance,
                "time_limit": suite.time_limit,
                "episodes_per_entry": episodes,
                "seed_offset": seed,
                "workers": workers,
                "algo": algo if policy_kind(policy) == "sb3" else None,
                "env_kwargs": dict(env_kwargs or {}),
                "entries": labels,
            }
        ),
    }
    (out / "results.json").write_text(json.dumps(results, indent=2, allow_nan=False))
    _save_traces(runs, out)
    write_report(results, runs, labels, out)
    return results


def add_evaluate_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register the ``evaluate`` subcommand on ``sub`` (its handler is in ``func``)."""
    p = sub.add_parser(
        "evaluate",
        help="run a policy over a terrain suite and write results.json, report.md, plots (and videos)",
        description="Run a policy over every (terrain, seed) of a suite; write DIR/results.json, DIR/report.md, "
        "PNG plots and per-episode traces (DIR/traces/*.npz). Exit code 2 on an invalid suite or policy.",
    )
    p.add_argument("--policy", required=True, help="'zero', 'expert', or the path of an SB3 model .zip")
    p.add_argument("--suite", required=True, help=f"shipped suite name {suite_names()} or the path of a suite .yaml")
    p.add_argument("--out", type=Path, required=True, help="output directory DIR")
    p.add_argument("--episodes", type=int, default=None, help="at most N seeds per terrain entry (default: all)")
    p.add_argument("--seed", type=int, default=0, help="offset added to every seed of the suite (default 0)")
    p.add_argument("--workers", type=int, default=1, help="parallel episode processes (default 1)")
    p.add_argument(
        "--video",
        action="store_true",
        help="write an MP4 (DIR/videos/) for the first episode of each terrain entry only (MuJoCo offscreen)",
    )
    p.add_argument("--algo", choices=SB3_ALGOS, default="ppo", help="SB3 class of a model .zip (default ppo)")
    p.add_argument(
        "--env-kwargs", default="{}", help="JSON object of extra QuadUneven-v0 arguments, e.g. '{\"frame_skip\": 5}'"
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=run_evaluate_command)
    return p


def run_evaluate_command(args: argparse.Namespace) -> int:
    """Handler of ``quad-uneven evaluate``: 0 on success, 2 on an invalid suite, policy or argument."""
    try:
        env_kwargs = json.loads(args.env_kwargs)
        if not isinstance(env_kwargs, dict):
            raise ValueError(f"--env-kwargs must be a JSON object, got {args.env_kwargs!r}")
        if args.episodes is not None and args.episodes < 1:
            raise ValueError(f"--episodes must be >= 1, got {args.episodes}")
        if args.workers < 1:
            raise ValueError(f"--workers must be >= 1, got {args.workers}")
        suite = load_suite(args.suite)
        results = evaluate(
            suite,
            args.policy,
            args.out,
            episodes=args.episodes,
            seed=args.seed,
            workers=args.workers,
            video=args.video,
            algo=args.algo,
            env_kwargs=env_kwargs,
            progress=not args.no_progress,
        )
    except SuiteError as e:
        print(f"error: invalid suite {args.suite!r}: {e}", file=sys.stderr)
        return 2
    except (PolicyError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    for kind, g in results["summary"]["by_kind"].items():
        speed = g["mean_speed"]
        print(
            f"{kind:16s} success {g['successes']}/{g['episodes']}  mean distance {g['mean_distance']:.2f} m  "
            f"mean speed {speed if speed is None else round(speed, 3)} m/s"
        )
    for t in results["targets"]:
        verdict = "PASS" if t["passed"] else f"FAIL ({t['why_not']})"
        print(f"target {t['target']:18s} entry {t['entry']}: {verdict}")
    print(f"report written to {Path(args.out).resolve()}/report.md")
    return 0
