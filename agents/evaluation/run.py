"""Run a policy over a terrain suite (``quad-uneven evaluate``): results.json, report.md, plots, videos.

Typical use::

    quad-uneven evaluate --policy expert --suite rough --out out/eval/rough --workers 2

Python API: :func:`evaluate` (returns the results dict) and :func:`make_policy` (re-exported from
:mod:`agents.evaluation.policies`). Formats and definitions: docs/evaluation.md.
"""

from __future__ import annotations

import concurrent.futures as cf
import json
import multiprocessing
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from tqdm.auto import tqdm

from agents.evaluation.episode import EpisodeResult, EvalConfig, make_env, run_task
from agents.evaluation.metrics import factor_summary, json_safe, summarize
from agents.evaluation.policies import SB3_ALGOS, PolicyError, make_policy, policy_kind
from agents.evaluation.report import write_report
from agents.evaluation.suites import EpisodeTask, Suite, episode_tasks, load_suite
from agents.evaluation.targets import check_targets

__all__ = ["evaluate", "make_policy"]


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


def _preflight(tasks: list[EpisodeTask], cfg: EvalConfig) -> None:
    """Build the first episode's env and policy, and every entry's env, here: bad env kwargs, randomization
    (e.g. a latency beyond the control period) or policies fail before any worker starts."""
    env = make_env(tasks[0], cfg)
    try:
        make_policy(cfg.policy, env, cfg.algo, cfg.expert_config)
    finally:
        env.close()
    for t in tasks[1:]:
        if t.first_of_entry and t.randomization is not None:
            make_env(t, cfg).close()


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
    expert_config: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """Run ``policy`` on every (terrain entry, seed) of ``suite``; write ``out/results.json``, ``report.md``, PNGs.

    :param suite: a :class:`Suite`, a shipped suite name or a suite YAML path.
    :param policy: ``"zero"``, ``"expert"`` or the path of an SB3 model ``.zip`` (loaded with ``algo``).
    :param episodes: at most this many seeds per terrain entry (None: all).
    :param seed: offset added to every seed of the suite.
    :param workers: episodes run in this many spawned processes (1: in this process).
    :param video: MP4 of the first episode of each terrain entry in ``out/videos/``.
    :param env_kwargs: extra QuadUneven-v0 arguments (override the policy's own).
    :param expert_config: fields of :class:`agents.expert.ExpertConfig` for ``policy="expert"``, e.g.
        ``{"model": "oracle"}`` (None: the defaults; a residual model keeps the expert of its training).
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
        expert_config=dict(expert_config or {}),
    )
    _preflight(tasks, cfg)
    runs = _run_all(tasks, cfg, min(workers, len(tasks)), progress)
    records = [json_safe(r.record) for r in runs]
    labels = [e.label for e in suite.terrains]
    summary = json_safe({**summarize(records, labels), "by_factor": factor_summary(records)})
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
                "expert_config": dict(expert_config or {}),
                "expert_model": sorted({str(r["expert_model"]) for r in records if r.get("expert_model")}) or None,
                "entries": labels,
                "randomization": [e.randomization for e in suite.terrains],
            }
        ),
    }
    (out / "results.json").write_text(json.dumps(results, indent=2, allow_nan=False))
    _save_traces(runs, out)
    write_report(results, runs, labels, out)
    return results
