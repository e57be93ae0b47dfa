"""Run a policy over a terrain suite (``quad-uneven evaluate``): results.json, report.md, plots, videos.

Typical use::

    quad-uneven evaluate --policy expert --suite rough --out out/eval/rough --workers 2

Python API: :func:`evaluate` (returns the results dict) and :func:`make_policy` (re-exported from
:mod:`agents.evaluation.policies`). Formats and definitions: docs/evaluation.md.
"""

from __future__ import annotations

import dataclasses
import functools
import multiprocessing
import signal
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from tqdm.auto import tqdm

from agents.evaluation.episode import (
    DEFAULT_WALL_TIME_LIMIT,
    EnvArgumentError,
    EpisodeResult,
    EvalConfig,
    check_env_kwargs,
    make_env,
    run_task,
)
from agents.evaluation.machine import distinct_machines
from agents.evaluation.metrics import factor_summary, json_safe, summarize
from agents.evaluation.policies import SB3_ALGOS, PolicyError, make_policy, model_algo, policy_kind
from agents.evaluation.ray_backend import check_backend, run_on_ray
from agents.evaluation.report import write_report
from agents.evaluation.store import (
    RUN_FILE,
    check_resume,
    episode_files,
    load_records,
    load_results_for_report,
    open_output_dir,
    run_identity,
    start_run,
    write_episode,
)
from agents.evaluation.suites import EpisodeTask, Suite, episode_tasks, load_suite, scale_suite
from agents.evaluation.targets import check_command_targets, check_targets
from agents.outputs import OutputError, write_json_atomic
from quad_uneven_env.fields import excerpt

__all__ = [
    "EvaluationInterrupted",
    "evaluate",
    "make_policy",
    "preflight",
    "run_tasks",
    "suite_episodes",
    "write_results",
]


def _ignore_sigint() -> None:
    """Worker initializer: Ctrl-C is the parent's to handle (it keeps the finished episodes, then stops us)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def run_tasks(
    tasks: list[EpisodeTask],
    cfg: EvalConfig,
    workers: int,
    progress: bool,
    on_result: Callable[[Any], None],
    backend: str = "pool",
    address: str | None = None,
    ship_code: bool = False,
    runner: Callable[[EpisodeTask, EvalConfig], Any] | None = None,
) -> None:
    """Run every task, in ``workers`` spawned processes if > 1 (``backend="ray"``: as Ray tasks, see
    :func:`agents.evaluation.ray_backend.run_on_ray`), handing each result to ``on_result`` as it ends.

    :param runner: the episode function, ``runner(task, cfg)`` (default :func:`run_task`; a module-level function:
        the processes or Ray workers import it).

    An interrupt (Ctrl-C, or SIGTERM under :func:`agents.interrupts.sigterm_as_keyboard_interrupt`)
    stops the workers at once; the results already handed on are kept by the caller.
    """
    runner = runner or run_task
    bar = tqdm(total=len(tasks), desc="episodes", unit="ep", disable=not progress)
    try:
        if backend == "ray":

            def keep(result: EpisodeResult) -> None:
                on_result(result)
                bar.update(1)

            run_on_ray(tasks, cfg, keep, address=address, num_cpus=workers, ship_code=ship_code, runner=runner)
            return
        if workers <= 1:
            for t in tasks:
                on_result(runner(t, cfg))
                bar.update(1)
            return
        ctx = multiprocessing.get_context("spawn")  # MuJoCo (and its GL contexts) + fork is fragile
        pool = ctx.Pool(workers, initializer=_ignore_sigint)
        try:
            for result in pool.imap_unordered(functools.partial(runner, cfg=cfg), tasks, chunksize=1):
                on_result(result)
                bar.update(1)
        except BaseException:  # an error or an interrupt: do not wait for the running episodes
            pool.terminate()
            raise
        else:
            pool.close()
        finally:
            pool.join()
    finally:
        bar.close()


def preflight(tasks: list[EpisodeTask], cfg: EvalConfig) -> None:
    """Build the first episode's env and policy, and every randomized entry's env, here: bad env kwargs,
    randomization (e.g. a latency beyond the control period) or policies fail before any episode.

    :raises EnvArgumentError: if the environment rejects an argument (its ValueError or TypeError).
    :raises PolicyError: if the policy cannot be built for that env (missing or unreadable model, other spaces).
    """

    def build(task: EpisodeTask):
        try:
            return make_env(task, cfg)
        except PolicyError:  # the model's metadata: named by the policy's own message
            raise
        except (ValueError, TypeError) as err:
            msg = str(err).split(" was raised from the environment creator")[0]  # gymnasium's suffix repeats kwargs
            raise EnvArgumentError(msg if msg.startswith("env_kwargs") else f"env_kwargs: {msg}") from None

    env = build(tasks[0])
    try:
        make_policy(cfg.policy, env, cfg.algo, cfg.allow_pickle, cfg.expert_config)
    finally:
        env.close()
    for t in tasks[1:]:
        if t.first_of_entry and t.randomization is not None:
            build(t).close()


def _results(suite: Suite, policy: str, records: list[dict[str, Any]], meta: dict[str, Any]) -> dict[str, Any]:
    labels = [e.label for e in suite.terrains]
    summary = json_safe({**summarize(records, labels), "by_factor": factor_summary(records)})
    return {
        "suite": suite.name,
        "policy": str(policy),
        "episodes": records,
        "summary": summary,
        "targets": json_safe(
            check_targets(suite.terrains, summary["by_entry"], suite.goal_distance, suite.length_scale)
        ),
        "command_targets": json_safe(check_command_targets(suite.terrains, records)),
        "meta": json_safe(meta),
    }


def evaluate(
    suite: Suite | str | Path,
    policy: str,
    out: str | Path,
    episodes: int | None = None,
    seed: int = 0,
    workers: int = 1,
    video: bool = False,
    algo: str | None = None,
    env_kwargs: Mapping[str, Any] | None = None,
    progress: bool = True,
    resume: bool = False,
    overwrite: bool = False,
    wall_time_limit: float = DEFAULT_WALL_TIME_LIMIT,
    allow_pickle: bool = False,
    expert_config: Mapping[str, Any] | None = None,
    backend: str = "pool",
    address: str | None = None,
    ship_code: bool = False,
) -> dict[str, Any]:
    """Run ``policy`` on every (terrain entry, seed) of ``suite``; write ``out/results.json``, ``report.md``, PNGs.

    ``out`` is checked and created before the first episode; every episode's record is written as it
    finishes (``out/episodes/``), and results.json and the report are rebuilt from them at the end
    (docs/evaluation.md, "The output directory"). An interrupt keeps the finished episodes.

    :param suite: a :class:`Suite`, a shipped suite name or a suite YAML path; one with ``scale: leg_length`` is
        scaled to the robot of ``env_kwargs`` (:func:`~agents.evaluation.suites.scale_suite`).
    :param policy: ``"zero"``, ``"expert"`` or the path of an SB3 model ``.zip`` (loaded with ``algo``; None: the
        algorithm its ``rl_meta.json`` records, else ``"ppo"``).
    :param episodes: at most this many seeds per terrain entry (None: all).
    :param seed: offset added to every seed of the suite.
    :param workers: episodes run in this many spawned processes (1: in this process).
    :param video: MP4 of the first episode of each terrain entry in ``out/videos/``.
    :param env_kwargs: extra QuadUneven-v0 arguments (override the policy's own).
    :param resume: continue the run recorded in ``out`` (its finished episodes are kept, not run again).
    :param overwrite: delete an earlier run's outputs in ``out`` first (other files are kept).
    :param wall_time_limit: s of wall-clock time per episode before it is ended (``wall_time_limit``).
    :param allow_pickle: unpickle files of an SB3 model folder (trusted files only).
    :param expert_config: fields of :class:`agents.expert.ExpertConfig` for ``policy="expert"``, e.g.
        ``{"model": "oracle"}`` (None: the defaults; a residual model keeps the expert of its training).
    :param backend: ``"pool"`` (``workers`` processes on this machine) or ``"ray"``: one Ray task per episode on
        the running Ray session, else on the cluster at ``address``, else on a local Ray of ``workers`` CPUs.
    :param address: the Ray cluster to join (``backend="ray"`` only; None: the running session or a local Ray).
    :param ship_code: a Ray session started here uploads this source tree to the workers
        (:func:`agents.evaluation.ray_backend.code_runtime_env`); else they import their installed package.
    :return: the results.json content.
    :raises SuiteError: on an invalid suite; ``PolicyError`` on an unusable policy; ``EnvArgumentError`` on env
        arguments the environment rejects; ``OutputError`` on an unusable ``out`` (a file, an earlier run's
        files without ``resume``/``overwrite``, a run to resume that differs, results.json not writable).
    :raises ValueError: on other bad arguments.
    """
    if not isinstance(suite, Suite):
        suite = load_suite(suite)
    kind = policy_kind(policy)
    if kind == "sb3":
        algo = model_algo(policy, algo)
    elif algo is not None and algo not in SB3_ALGOS:
        raise PolicyError(f"algo must be one of {list(SB3_ALGOS)}, got {excerpt(algo)}")
    else:
        algo = "ppo"  # unused by a named policy
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers must be an integer >= 1, got {excerpt(workers)}")
    if isinstance(wall_time_limit, bool) or not (isinstance(wall_time_limit, int | float) and wall_time_limit > 0):
        raise ValueError(f"wall_time_limit must be a number > 0 (s), got {excerpt(wall_time_limit)}")
    check_backend(backend, address, ship_code)  # without Ray, fail before anything is written
    env_kwargs = check_env_kwargs(dict(env_kwargs or {}) if isinstance(env_kwargs, Mapping) else env_kwargs or {})
    suite, tasks = suite_episodes(suite, env_kwargs, episodes, seed)
    out = Path(out)
    with open_output_dir(out, resume=resume, overwrite=overwrite) as manifest:
        identity = run_identity(
            suite, str(policy), algo if kind == "sb3" else None, env_kwargs, episodes, seed, len(tasks), expert_config
        )
        resuming = resume and check_resume(out, identity)
        cfg = EvalConfig(
            policy=str(policy),
            goal_distance=suite.goal_distance,
            time_limit=suite.time_limit,
            algo=algo,
            env_kwargs=env_kwargs,
            video_dir=str(out / "videos") if video else None,
            wall_time_limit=float(wall_time_limit),
            allow_pickle=allow_pickle,
            expert_config=dict(expert_config or {}),
        )
        preflight(tasks, cfg)
        if not resuming:
            start_run(out, identity)
        done = load_records(out, tasks) if resuming else {}
        kept = [p for t in tasks if t.index in done for p in episode_files(out, t.index, t.first_of_entry)]
        manifest.add([out / RUN_FILE, *kept])  # a resumed run's (one an older version started has no manifest yet)
        todo = [t for t in tasks if t.index not in done]

        def keep(result: EpisodeResult) -> None:
            record = json_safe(result.record)
            try:
                write_episode(out, EpisodeResult(record, result.trace, result.terrain))
            except OSError as err:
                raise OutputError(f"--out {str(out)!r}: cannot write episode {record['index']} ({err})") from None
            index = int(record["index"])
            video = [out / "videos" / record["video"]] if record.get("video") else []
            manifest.add([*episode_files(out, index, result.terrain is not None), *video])
            done[int(record["index"])] = record

        try:
            n = workers if backend == "ray" else min(workers, max(1, len(todo)))
            run_tasks(todo, cfg, n, progress, keep, backend, address, ship_code)
        except KeyboardInterrupt:
            raise EvaluationInterrupted(out, len(done), len(tasks)) from None

        records = [done[t.index] for t in tasks]
        meta = {
            "suite_file": suite.source,
            "goal_distance": suite.goal_distance,
            "time_limit": suite.time_limit,
            "episodes_per_entry": episodes,
            "seed_offset": seed,
            "workers": workers,
            "backend": backend,
            "ray_address": address,
            "algo": algo if kind == "sb3" else None,
            "env_kwargs": env_kwargs,
            "entries": [e.label for e in suite.terrains],
            "randomization": [e.randomization for e in suite.terrains],
            "expert_config": dict(expert_config or {}),
            "expert_model": sorted({str(r["expert_model"]) for r in records if r.get("expert_model")}) or None,
            "wall_time_limit": float(wall_time_limit),
            "resumed_episodes": len(tasks) - len(todo),
            "machines": distinct_machines(records),
        }
        results = _results(suite, str(policy), records, meta)
        try:
            manifest.add([write_results(out, results)])
            write_report(results, load_results_for_report(out, records, tasks), meta["entries"], out)
        except OSError as err:
            raise OutputError(
                f"--out {str(out)!r}: cannot write results.json or report.md ({err}); the {len(records)} episode "
                f"records are kept in {out / 'episodes'} (fix the cause and rerun with --resume to rebuild them)"
            ) from None
        return results


class EvaluationInterrupted(KeyboardInterrupt):
    """An evaluation stopped by Ctrl-C or SIGTERM; its finished episodes are on disk (``--resume`` continues)."""

    def __init__(self, out: Path, finished: int, total: int, unwritten: str = "") -> None:
        """:param unwritten: what the run did not write because it was interrupted, e.g. ``"no dataset written"``."""
        note = f" ({unwritten})" if unwritten else ""
        super().__init__(
            f"interrupted: {finished} of {total} episodes finished and kept in {out / 'episodes'}{note}; "
            "rerun the same command with --resume to continue"
        )
        self.out, self.finished, self.total = out, finished, total


def write_results(out: Path, results: Mapping[str, Any]) -> Path:
    """Write ``out/results.json`` (strict JSON, atomically: a reader never sees half a file)."""
    return write_json_atomic(out / "results.json", dict(results))


def suite_episodes(
    suite: Suite, env_kwargs: Mapping[str, Any], episodes: int | None, seed: int
) -> tuple[Suite, list[EpisodeTask]]:
    """The suite as run on the robot of ``env_kwargs`` and its episodes: what ``evaluate`` and ``collect`` run.

    A suite with ``scale: leg_length`` is magnified by :func:`robot_scale` (:func:`scale_suite`; the result says
    ``scale: none``); then :func:`~agents.evaluation.suites.episode_tasks` lists its episodes.

    :param episodes: at most this many seeds per terrain entry (None: all).
    :param seed: offset added to every seed of the suite.
    :raises SuiteError: if the scaled suite is invalid; ``EnvArgumentError`` if the robot cannot be loaded.
    """
    if suite.scale == "leg_length":
        factor = robot_scale(env_kwargs.get("robot", "paper"))
        suite = dataclasses.replace(suite, scale="none") if factor == 1.0 else scale_suite(suite, factor)
    return suite, episode_tasks(suite, episodes, seed)


def robot_scale(robot: Any) -> float:
    """-: the leg length of ``robot`` (a name or a YAML path) over the paper robot's 0.42 m (1 for the paper's).

    :raises EnvArgumentError: naming ``env_kwargs.robot`` if it cannot be loaded.
    """
    from quad_uneven_env.robot.description import load_robot

    try:
        desc = load_robot(robot)
    except (ValueError, TypeError) as err:
        raise EnvArgumentError(f"env_kwargs.robot: {err}") from None
    return desc.length_ratio
