"""``quad-uneven collect``: the scripted expert over the episodes of a suite, as a Minari dataset.

Typical use::

    quad-uneven collect --policy expert --suite rough --out out/data/rough --workers 2

The episodes are those ``quad-uneven evaluate`` runs (:func:`agents.evaluation.suites.episode_tasks`: tasks, seeds,
terrains, randomization, commands and waypoints; each ends at the suite's goal, a fall or the time limit as in
:func:`agents.evaluation.episode.run_task`), each recorded by :class:`agents.datasets.recorder.EpisodeRecorder`.

Layout of ``DIR``:

- ``run.json``: what defines the collection (suite content, expert settings, env kwargs, episode cap, seed offset),
  written once the preflight check has passed;
- per finished episode ``episodes/epNNN.npz`` (its arrays), then ``episodes/epNNN.json`` (its evaluation record and
  env arguments): each written to a temporary name and renamed, the record last, so a record means a finished
  episode (``--resume`` collects only the others);
- once every episode has finished, the Minari dataset ``DATASET_ID/data/`` (built in ``.DATASET_ID.tmp`` and renamed:
  a dataset folder is always a whole one), then ``collect.json`` (the summary); the ``.npz`` files, whose arrays the
  dataset now holds, are deleted last. ``--resume`` of a finished collection changes nothing. Formats:
  docs/datasets.md.
"""

from __future__ import annotations

import dataclasses
import importlib.metadata
import json
import os
import shutil
import sys
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from agents.datasets.files import (
    SUMMARY_FILE,
    TRANSITION_ARRAYS,
    check_arrays,
    npz_path,
    read_records,
    read_summary,
    write_episode,
)
from agents.datasets.minari_io import DatasetError, dataset_id_for, import_minari, open_dataset, write_dataset
from agents.datasets.recorder import INFO_FIELDS, EpisodeRecorder
from agents.evaluation.episode import (
    DEFAULT_WALL_TIME_LIMIT,
    EnvArgumentError,
    EpisodeResult,
    EvalConfig,
    check_env_kwargs,
    make_env,
    run_task,
)
from agents.evaluation.metrics import json_safe
from agents.evaluation.policies import PolicyError
from agents.evaluation.ray_backend import check_backend
from agents.evaluation.results_io import ResultsError
from agents.evaluation.run import EvaluationInterrupted, preflight, run_tasks, suite_episodes
from agents.evaluation.store import (
    IDENTITY_KEYS,
    RESUME_HINT,
    RUN_FILE,
    check_resume,
    open_output_dir,
    read_npz,
    run_identity,
)
from agents.evaluation.suites import EpisodeTask, Suite, load_suite
from agents.outputs import OutputError, write_json_atomic
from quad_uneven_env.fields import excerpt

__all__ = ["COLLECT_FORMAT", "COLLECT_OUTPUTS", "CollectInterrupted", "CollectedEpisode", "collect", "collect_task"]

COLLECT_FORMAT = "quad-uneven-collect/1"
"""Value of a collection's ``run.json`` ``format`` field."""

COLLECT_OUTPUTS = (RUN_FILE, "collect.json", "episodes", "quad-uneven-*", ".*.tmp")
"""Top-level names a collection writes in ``DIR`` (what ``--overwrite`` deletes; nothing else is touched)."""

COLLECT_IDENTITY_KEYS = (*IDENTITY_KEYS, "entries")
"""Fields of ``run.json`` that must be equal for ``--resume`` to continue a collection."""

POLICIES = ("expert",)
"""What ``collect`` can record."""


@dataclasses.dataclass
class CollectedEpisode:
    """One collected episode, as a worker returns it (picklable)."""

    record: dict[str, Any]
    """the evaluation's episode record (JSON-safe; :func:`agents.evaluation.episode.run_task`)."""
    arrays: dict[str, np.ndarray]
    """the episode's arrays (:meth:`agents.datasets.recorder.EpisodeRecorder.arrays`)."""
    env_kwargs: dict[str, Any]
    """the QuadUneven-v0 arguments its env was made with."""


def collect_task(task: EpisodeTask, cfg: EvalConfig) -> CollectedEpisode:
    """Run and record one episode of the expert (never raises for an error inside the episode: see ``run_task``)."""
    recorder = EpisodeRecorder()
    result: EpisodeResult = run_task(task, cfg, observer=recorder)
    return CollectedEpisode(json_safe(result.record), recorder.arrays(), json_safe(recorder.env_kwargs))


class CollectInterrupted(EvaluationInterrupted):
    """A collection stopped by Ctrl-C or SIGTERM; its finished episodes are on disk (``--resume`` continues)."""

    def __init__(self, out: Path, finished: int, total: int) -> None:
        super().__init__(out, finished, total, unwritten="no dataset written")


def _resumed_episodes(
    out: Path, dataset_id: str, tasks: list[EpisodeTask], spaces: tuple
) -> tuple[dict[int, dict[str, Any]], dict[str, Any] | None]:
    """The finished episodes of a collection to resume in ``out``, and its summary if it is finished.

    Every record is read checked (:func:`agents.datasets.files.read_records`). A finished collection (a summary,
    every record) is returned as such only if its dataset passes :func:`agents.datasets.minari_io.open_dataset`
    against the summary; a damaged one is reported on stderr and built again, its episodes collected again where
    their arrays are gone (after a finished collection they are in the dataset only). Otherwise an episode is
    finished if its record and its arrays are there, the arrays checked against the record and the dataset's
    spaces (:func:`agents.datasets.files.check_arrays`).

    :return: (index -> {record, env_kwargs, steps} of the episodes not to run again, the summary or None).
    :raises ResultsError: naming a record or array file that is not one this collection wrote.
    """
    records = read_records(out, tasks)
    if len(records) == len(tasks) and (out / SUMMARY_FILE).is_file():
        try:
            summary = read_summary(out)
            steps = [r["steps"] for r in records.values()]
            recorded = (dataset_id, len(steps) - steps.count(0), sum(steps))
            if (summary["dataset_id"], summary["episodes"], summary["steps"]) != recorded:
                raise DatasetError(
                    f"{out / SUMMARY_FILE}: dataset_id, episodes and steps must be {list(recorded)} (the episode "
                    f"records'), got {[summary['dataset_id'], summary['episodes'], summary['steps']]}"
                )
            open_dataset(out / dataset_id / "data", dataset_id, summary["episodes"], summary["steps"])
        except (ResultsError, DatasetError) as err:
            print(f"warning: --resume: {err}; the dataset is built again", file=sys.stderr)
        else:
            return records, summary
    done = {}
    for t in tasks:
        if t.index in records and npz_path(out, t.index).is_file():
            check_arrays(npz_path(out, t.index), records[t.index]["steps"], spaces[1], spaces[2])
            done[t.index] = records[t.index]
    return done, None


def _check_one_observation_space(tasks: list[EpisodeTask], cfg: EvalConfig) -> Any:
    """The first episode's env spec and spaces; :raises ValueError: if an entry's observations differ in shape
    (an entry with a command or waypoints observes the command too), since one dataset holds one space."""
    first = make_env(tasks[0], cfg)
    try:
        spec, obs_space, act_space = first.spec, first.observation_space, first.action_space
    finally:
        first.close()
    for t in tasks[1:]:
        if not t.first_of_entry:
            continue
        env = make_env(t, cfg)
        try:
            shape = env.observation_space.shape
        finally:
            env.close()
        if shape != obs_space.shape:
            raise ValueError(
                f"suite: terrains[{t.entry}] observes {shape} values but terrains[{tasks[0].entry}] {obs_space.shape} "
                "(an entry with a command or waypoints observes the command too); one dataset holds one observation "
                "space: collect such entries in a suite of their own"
            )
    return spec, obs_space, act_space


def _episode_metadata(t: EpisodeTask, saved: Mapping[str, Any], suite: Suite) -> dict[str, Any]:
    r = saved["record"]
    return {
        "suite": suite.name,
        "suite_index": t.index,
        "entry": t.entry,
        "terrain_kind": t.kind,
        "terrain": {"kind": t.kind, **t.params},
        "randomization": t.randomization,
        "command": t.command,
        "waypoints": t.waypoints,
        "env_kwargs": saved["env_kwargs"],
        "randomization_drawn": r.get("randomization"),
        "success": bool(r["success"]),
        "end_reason": str(r["end_reason"]),
        "fall_reason": r.get("fall_reason"),
        "distance": float(r["distance"]),
        "sim_time": float(r["sim_time"]),
    }


def _requirements() -> list[str]:
    try:
        return [f"quad-uneven=={importlib.metadata.version('quad-uneven')}"]
    except importlib.metadata.PackageNotFoundError:
        return []


def _assemble(
    out: Path, dataset_id: str, tasks: list[EpisodeTask], done: Mapping[int, Mapping[str, Any]], suite: Suite,
    spaces: tuple, meta: Mapping[str, Any],
) -> tuple[Path, list[int]]:  # fmt: skip
    """Build the Minari dataset from the finished episodes in ``.DATASET_ID.tmp`` and rename it ``DATASET_ID``.

    :return: the dataset's ``data`` folder and the suite indices of the episodes left out (no step recorded).
    """
    spec, obs_space, act_space = spaces
    episodes, skipped = [], []
    first: tuple[Path, dict[str, Any]] | None = None
    for t in tasks:
        path = npz_path(out, t.index)
        arrays = read_npz(path, TRANSITION_ARRAYS)
        if len(arrays["actions"]) == 0:
            skipped.append(t.index)
            continue
        layout = {k: (a.shape[1:], a.dtype) for k, a in arrays.items()}
        if first is None:
            first = (path, layout)
        elif layout != first[1]:
            raise ResultsError(
                f"{path}: its arrays differ from those of {first[0]} in names, shapes or types (one dataset holds one "
                f"layout); {RESUME_HINT}"
            )
        episodes.append((arrays, t.seed, _episode_metadata(t, done[t.index], suite)))
    final, staging = out / dataset_id, out / f".{dataset_id}.tmp"
    shutil.rmtree(staging, ignore_errors=True)
    staging.mkdir()
    try:
        write_dataset(staging / "data", dataset_id, spec, obs_space, act_space, episodes, meta)
        if final.exists():
            shutil.rmtree(final)
        os.replace(staging, final)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    return final / "data", skipped


def collect(
    suite: Suite | str | Path,
    out: str | Path,
    policy: str = "expert",
    episodes: int | None = None,
    seed: int = 0,
    workers: int = 1,
    env_kwargs: Mapping[str, Any] | None = None,
    expert_config: Mapping[str, Any] | None = None,
    progress: bool = True,
    resume: bool = False,
    overwrite: bool = False,
    wall_time_limit: float = DEFAULT_WALL_TIME_LIMIT,
    backend: str = "pool",
    address: str | None = None,
    ship_code: bool = False,
) -> dict[str, Any]:
    """Record ``policy`` on every (terrain entry, seed) of ``suite`` as a Minari dataset in ``out/DATASET_ID/data``.

    :param suite: a :class:`Suite`, a shipped suite name or a suite YAML path.
    :param policy: ``"expert"`` (the only policy it records).
    :param episodes: at most this many seeds per terrain entry (None: all).
    :param seed: offset added to every seed of the suite.
    :param workers: episodes run in this many spawned processes (1: in this process); the dataset is the same.
    :param env_kwargs: extra QuadUneven-v0 arguments (``action_mode`` must stay ``"torque"``).
    :param expert_config: fields of :class:`agents.expert.ExpertConfig` (None: the defaults).
    :param resume: continue the collection recorded in ``out`` (its finished episodes are kept, not run again).
    :param overwrite: delete an earlier collection's outputs in ``out`` first (other files are kept).
    :param wall_time_limit: s of wall-clock time per episode before it is ended (``wall_time_limit``).
    :param backend: ``"pool"`` (``workers`` processes here) or ``"ray"`` (one Ray task per episode: the running
        session, else the cluster at ``address``, else a local Ray of ``workers`` CPUs); the same dataset.
    :param address: the Ray cluster to join (``backend="ray"`` only).
    :param ship_code: a Ray session started here uploads this source tree to its workers.
    :return: the summary written to ``out/collect.json``: dataset id and path, episodes, steps, successes, the
        collection's speed (env steps/s of this call) and the dataset's size.
    :raises DatasetsUnavailable: without Minari (the ``datasets`` extra), before anything is written.
    :raises SuiteError: on an invalid suite; ``PolicyError`` on another policy; ``EnvArgumentError`` on env
        arguments the environment rejects; ``OutputError`` on an unusable ``out``; ``ValueError`` on other bad
        arguments (entries with different observation spaces included).
    """
    import_minari()
    if policy not in POLICIES:
        raise PolicyError(
            f"policy must be one of {list(POLICIES)} (collect records the scripted expert), got {excerpt(policy)}"
        )
    if not isinstance(suite, Suite):
        suite = load_suite(suite)
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers must be an integer >= 1, got {excerpt(workers)}")
    if isinstance(wall_time_limit, bool) or not (isinstance(wall_time_limit, int | float) and wall_time_limit > 0):
        raise ValueError(f"wall_time_limit must be a number > 0 (s), got {excerpt(wall_time_limit)}")
    check_backend(backend, address, ship_code)
    env_kwargs = check_env_kwargs(dict(env_kwargs or {}) if isinstance(env_kwargs, Mapping) else env_kwargs or {})
    if env_kwargs.get("action_mode", "torque") != "torque":
        raise EnvArgumentError(
            f"env_kwargs.action_mode must be 'torque' (the expert's torques are the recorded actions), "
            f"got {excerpt(env_kwargs['action_mode'])}"
        )
    suite, tasks = suite_episodes(suite, env_kwargs, episodes, seed)
    out = Path(out)
    with open_output_dir(out, resume, overwrite, COLLECT_OUTPUTS, "collect", "collect"):  # --overwrite: only ours
        entries = [
            {"kind": e.kind, "params": e.params, "seeds": list(e.seeds), "randomization": e.randomization,
             "command": e.command, "waypoints": e.waypoints}
            for e in suite.terrains
        ]  # fmt: skip
        identity = {
            **run_identity(suite, policy, None, env_kwargs, episodes, seed, len(tasks), expert_config),
            "format": COLLECT_FORMAT,
            "entries": json.loads(json.dumps(entries)),
        }
        resuming = resume and check_resume(out, identity, COLLECT_FORMAT, COLLECT_IDENTITY_KEYS)
        cfg = EvalConfig(
            policy=policy,
            goal_distance=suite.goal_distance,
            time_limit=suite.time_limit,
            env_kwargs=env_kwargs,
            wall_time_limit=float(wall_time_limit),
            expert_config=dict(expert_config or {}),
        )
        preflight(tasks, cfg)
        spaces = _check_one_observation_space(tasks, cfg)
        if not resuming:
            try:
                (out / "episodes").mkdir(exist_ok=True)
                write_json_atomic(out / RUN_FILE, identity)
            except OSError as err:
                raise OutputError(f"--out {str(out)!r}: cannot write {RUN_FILE} ({err})") from None
        dataset_id = dataset_id_for(suite.name, policy)
        done, finished = _resumed_episodes(out, dataset_id, tasks, spaces) if resuming else ({}, None)
        if finished is not None:  # a finished collection: nothing to do
            for t in tasks:
                npz_path(out, t.index).unlink(missing_ok=True)  # left by an interrupt after the summary was written
            return finished
        todo = [t for t in tasks if t.index not in done]
        new_steps = 0

        def keep(episode: CollectedEpisode) -> None:
            nonlocal new_steps
            index = int(episode.record["index"])
            try:
                write_episode(out, index, episode.arrays, episode.record, episode.env_kwargs)
            except OSError as err:
                raise OutputError(f"--out {str(out)!r}: cannot write episode {index} ({err})") from None
            done[index] = {
                "record": episode.record,
                "env_kwargs": episode.env_kwargs,
                "steps": len(episode.arrays["actions"]),
            }
            new_steps += len(episode.arrays["actions"])

        wall0 = time.perf_counter()
        try:
            n = workers if backend == "ray" else min(workers, max(1, len(todo)))
            run_tasks(todo, cfg, n, progress, keep, backend, address, ship_code, runner=collect_task)
        except KeyboardInterrupt:
            raise CollectInterrupted(out, len(done), len(tasks)) from None
        wall = time.perf_counter() - wall0

        u_spec = spaces[0]
        meta = json_safe(
            {
                "algorithm_name": "quad-uneven scripted expert (gait planner + computed-torque control)",
                "description": (
                    f"The scripted expert of quad-uneven on the suite {suite.name!r}: {len(tasks)} episodes. actions: "
                    "the mean joint torque applied over each control step / motor limit (action_mode='torque'); "
                    "infos/torques: the torques at each physics step. Formats: docs/datasets.md of quad-uneven."
                ),
                "requirements": _requirements(),
                "quad_uneven": {
                    "suite": suite.name,
                    "suite_file": suite.source,
                    "goal_distance": suite.goal_distance,
                    "time_limit": suite.time_limit,
                    "episodes_per_entry": episodes,
                    "seed_offset": seed,
                    "policy": policy,
                    "expert_config": dict(expert_config or {}),
                    "env_kwargs": env_kwargs,
                    "entries": entries,
                    "env_spec_episode": 0,
                    "max_episode_steps": u_spec.max_episode_steps,
                    "info_fields": {k: {"unit": u, "meaning": m} for k, (u, m) in INFO_FIELDS.items()},
                },
            }
        )
        try:
            data_path, skipped = _assemble(out, dataset_id, tasks, done, suite, spaces, meta)
        except OSError as err:
            raise OutputError(
                f"--out {str(out)!r}: cannot write the dataset ({err}); the finished episodes are kept in "
                f"{out / 'episodes'} (fix the cause and rerun with --resume)"
            ) from None
        steps = sum(int(done[t.index]["steps"]) for t in tasks)
        size = sum(p.stat().st_size for p in data_path.iterdir() if p.is_file())
        records = [done[t.index]["record"] for t in tasks]
        summary = {
            "dataset_id": dataset_id,
            "dataset_path": str(data_path),
            "episodes": len(tasks) - len(skipped),
            "episodes_without_steps": skipped,
            "steps": steps,
            "successes": sum(bool(r["success"]) for r in records),
            "end_reasons": {
                k: [r["end_reason"] for r in records].count(k) for k in sorted({r["end_reason"] for r in records})
            },
            "resumed_episodes": len(tasks) - len(todo),
            "collected_steps": new_steps,
            "collect_wall_time": wall,
            "steps_per_second": new_steps / wall if new_steps and wall > 0 else None,
            "dataset_bytes": size,
            "bytes_per_1000_steps": 1000.0 * size / steps if steps else None,
            "workers": workers,
            "backend": backend,
        }
        write_json_atomic(out / SUMMARY_FILE, json_safe(summary))
        for t in tasks:  # their arrays are in the dataset now
            npz_path(out, t.index).unlink(missing_ok=True)
        return summary
