"""The evaluation's output directory: the run's identity, one record per finished episode, resuming.

Layout of ``DIR`` (docs/evaluation.md, "The output directory"):

- ``run.json``: what defines the run (suite content, policy and its file hash, algo, env kwargs,
  episode cap, seed offset), written once the preflight check has passed, before the first episode;
- per finished episode, in this order: ``traces/epNNN.npz``, for an entry's first episode
  ``episodes/epNNN_terrain.npz`` (the surface the report plots), and last ``episodes/epNNN.json``
  (the results.json record). Each is written to a temporary name and renamed, so the record exists
  only once everything of its episode is on disk: a record file means a finished episode;
- at the end, ``results.json``, ``report.md`` and the PNGs are rebuilt from the records.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import zipfile
import zlib
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from agents.evaluation.episode import EpisodeResult
from agents.evaluation.results_io import ResultsError, load_record, read_json
from agents.evaluation.suites import EpisodeTask, Suite
from agents.outputs import LOCK_FILE, MANIFEST_FILE, OutputError, OutputManifest, output_dir, write_json_atomic
from quad_uneven_env.fields import clip, excerpt

__all__ = [
    "EVAL_OUTPUTS",
    "RUN_FILE",
    "RUN_FORMAT",
    "check_resume",
    "episode_files",
    "load_records",
    "load_results_for_report",
    "open_output_dir",
    "run_identity",
    "start_run",
    "write_episode",
]

RUN_FILE = "run.json"
"""The run's identity in ``DIR``."""

RUN_FORMAT = "quad-uneven-eval/1"
"""Value of ``run.json``'s ``format`` field."""

EVAL_OUTPUTS = (RUN_FILE, "results.json", "report.md", "*.png", "episodes", "traces", "videos", ".*.tmp")
"""Top-level names an evaluation writes in ``DIR`` (``--overwrite`` deletes what the manifest lists; with one of
these names present and no manifest, it refuses: :func:`agents.outputs.delete_recorded_outputs`)."""

IDENTITY_KEYS = (
    "suite",
    "policy",
    "policy_sha256",
    "algo",
    "env_kwargs",
    "expert_config",
    "episodes_per_entry",
    "seed_offset",
)
"""Fields of ``run.json`` that must be equal for ``--resume`` to continue a run."""


def _sha256(path: str | os.PathLike[str]) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def run_identity(
    suite: Suite,
    policy: str,
    algo: str | None,
    env_kwargs: Mapping[str, Any],
    episodes: int | None,
    seed: int,
    n_tasks: int,
    expert_config: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """The ``run.json`` content: everything that decides which episodes run and how (JSON-safe).

    :param algo: the SB3 class of a model file, None for a named policy.
    :param n_tasks: number of episodes of the run.
    :param expert_config: the expert's settings given to the run (``{}``: its defaults).
    """
    is_file = policy not in ("zero", "expert") and Path(policy).is_file()
    return {
        "format": RUN_FORMAT,
        "suite": {
            "name": suite.name,
            "goal_distance": suite.goal_distance,
            "time_limit": suite.time_limit,
            "terrains": [{"kind": e.kind, "params": dict(e.params), "seeds": list(e.seeds)} for e in suite.terrains],
        },
        "suite_file": suite.source,
        "policy": str(policy),
        "policy_sha256": _sha256(policy) if is_file else None,
        "algo": algo,
        "env_kwargs": json.loads(json.dumps(dict(env_kwargs))),
        "expert_config": json.loads(json.dumps(dict(expert_config or {}))),
        "episodes_per_entry": episodes,
        "seed_offset": seed,
        "episodes": n_tasks,
    }


@contextlib.contextmanager
def open_output_dir(
    out: Path,
    resume: bool,
    overwrite: bool,
    outputs: Sequence[str] = EVAL_OUTPUTS,
    what: str = "evaluation",
    command: str = "evaluate",
) -> Iterator[OutputManifest]:
    """Own ``out`` while the ``with`` block runs (:func:`agents.outputs.output_dir`: checked, created and locked
    before any work): an earlier run's outputs are refused.

    With ``resume``, a directory holding an earlier run is kept (:func:`check_resume` compares it);
    with ``overwrite``, the files its manifest lists are deleted and other files kept (:mod:`agents.outputs`).

    :param what: the command's kind of directory, for the messages (``"evaluation"``, ``"collect"``).
    :param command: the command's name, recorded in the manifest and the lock.
    :return: the directory's manifest.
    :raises OutputError: naming the directory and what is wrong with it (``OutputInUse`` if another run holds it).
    """
    if resume and overwrite:
        raise OutputError("--resume and --overwrite exclude each other (continue a run, or start it again)")
    hint = (
        "pass --resume to continue the run recorded there, --overwrite to delete its outputs (other files are "
        "kept), or choose another directory"
    )
    with output_dir(out, command, outputs, overwrite=overwrite, keep=resume, field="--out", hint=hint) as manifest:
        present = [p for p in out.iterdir() if p.name not in (MANIFEST_FILE, LOCK_FILE)]
        if resume and present and not (out / RUN_FILE).is_file():
            raise OutputError(
                f"--resume: {str(out)!r} holds no {RUN_FILE} (not {'an' if what[0] in 'aeiou' else 'a'} {what} "
                "directory, or one that never started); pass --overwrite to start a new run there"
            )
        yield manifest


def check_resume(
    out: Path, identity: Mapping[str, Any], run_format: str = RUN_FORMAT, keys: Sequence[str] = IDENTITY_KEYS
) -> bool:
    """Whether ``out`` holds a run to continue; refuse one that differs from ``identity``.

    :param run_format: the ``format`` its ``run.json`` must have (default: an evaluation's).
    :param keys: the fields of ``run.json`` that must be equal (default ``IDENTITY_KEYS``).
    :return: False if ``out`` has no ``run.json`` (a fresh run), True if it has a matching one.
    :raises OutputError: if ``run.json`` is unreadable, of another format or differs in a field of ``keys`` (named).
    """
    path = out / RUN_FILE
    if not path.is_file():
        return False
    try:
        recorded = read_json(path)
    except ResultsError as err:
        raise OutputError(f"--resume: {err}; pass --overwrite to start over") from None
    if not isinstance(recorded, dict) or recorded.get("format") != run_format:
        raise OutputError(f"--resume: {path} is not a {run_format} run file; pass --overwrite to start over")
    for key in keys:
        if recorded.get(key, {} if key == "expert_config" else None) != identity.get(key):
            raise OutputError(
                f"--resume: {key} differs from the run recorded in {path} (recorded {excerpt(recorded.get(key))}, "
                f"now {excerpt(identity.get(key))}); pass --overwrite to start over or choose another --out"
            )
    return True


def start_run(out: Path, identity: Mapping[str, Any]) -> None:
    """Write ``run.json`` and create ``episodes/`` and ``traces/`` (after the preflight check)."""
    try:
        (out / "episodes").mkdir(exist_ok=True)
        (out / "traces").mkdir(exist_ok=True)
        write_json_atomic(out / RUN_FILE, dict(identity))
    except OSError as err:
        raise OutputError(f"--out {str(out)!r}: cannot write {RUN_FILE} ({err})") from None


def _savez_atomic(path: Path, arrays: Mapping[str, Any]) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        with tmp.open("wb") as f:
            np.savez_compressed(f, **arrays)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def _record_path(out: Path, index: int) -> Path:
    return out / "episodes" / f"ep{index:03d}.json"


def _terrain_path(out: Path, index: int) -> Path:
    return out / "episodes" / f"ep{index:03d}_terrain.npz"


def _trace_path(out: Path, index: int) -> Path:
    return out / "traces" / f"ep{index:03d}.npz"


def episode_files(out: Path, index: int, with_terrain: bool) -> list[Path]:
    """The files of finished episode ``index`` in ``out``: its trace, its terrain (``with_terrain``), its record."""
    return [_trace_path(out, index), *([_terrain_path(out, index)] if with_terrain else []), _record_path(out, index)]


def write_episode(out: Path, result: EpisodeResult) -> Path:
    """Write one finished episode: its trace, its terrain (first of an entry), then its record (the commit).

    :return: the record's path ``episodes/epNNN.json``.
    :raises OSError: if a file cannot be written (the episode then counts as unfinished).
    """
    index = int(result.record["index"])
    _savez_atomic(_trace_path(out, index), result.trace)
    if result.terrain is not None:
        t = result.terrain
        _savez_atomic(
            _terrain_path(out, index),
            {"heights": t["heights"], "origin": np.asarray(t["origin"]), "cell_size": np.asarray(t["cell_size"])},
        )
    return write_json_atomic(_record_path(out, index), result.record)


RESUME_HINT = "delete it to run that episode again, or pass --overwrite to start the run over"
"""What a refused episode file of a run to resume suggests."""


def load_records(out: Path, tasks: Sequence[EpisodeTask]) -> dict[int, dict[str, Any]]:
    """The records of the finished episodes of ``tasks`` in ``out`` (index -> record), checked.

    An episode counts as finished if its record exists and its trace (and, for an entry's first episode, its
    terrain) too; one whose trace is missing is run again. A record that is not one this run wrote (not strict
    JSON, a field of the wrong type or missing, another task's entry, terrain or seed) is refused.

    :raises ResultsError: naming the record file and the field (:func:`agents.evaluation.results_io.load_record`).
    """
    done: dict[int, dict[str, Any]] = {}
    for t in tasks:
        path = _record_path(out, t.index)
        if not path.is_file() or not _trace_path(out, t.index).is_file():
            continue
        if t.first_of_entry and not _terrain_path(out, t.index).is_file():
            continue
        try:
            record = load_record(path)
        except ResultsError as err:
            raise ResultsError(f"--resume: {err}; {RESUME_HINT}") from None
        check_task_record(path, record, t)
        done[t.index] = record
    return done


def check_task_record(path: Path, record: Mapping[str, Any], task: EpisodeTask) -> None:
    """Refuse the checked episode ``record`` read from ``path`` unless it is ``task``'s (index, entry, terrain, seed).

    :raises ResultsError: naming the file and the first field that differs.
    """
    for field, expected in (("index", task.index), ("entry", task.entry), ("terrain", task.kind), ("seed", task.seed)):
        if record[field] != expected:
            raise ResultsError(
                f"--resume: {path}: {field} must be {excerpt(expected)} (episode {task.index} of the run), got "
                f"{excerpt(record[field])}; {RESUME_HINT}"
            )


TRACE_ARRAYS = ("time", "cog", "feet", "index", "contact", "yaw")
"""Arrays every trace file holds (the report's plots read them)."""

TERRAIN_ARRAYS = ("heights", "origin", "cell_size")
"""Arrays every terrain file holds."""


def read_npz(path: Path, required: Sequence[str]) -> dict[str, np.ndarray]:
    """The arrays of ``path`` (no pickled objects).

    :raises ResultsError: if it is unreadable (a truncated or garbage file) or lacks one of ``required``.
    """
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error) as err:
        raise ResultsError(f"{path}: not an array file quad-uneven wrote ({clip(str(err))}); {RESUME_HINT}") from None
    missing = [k for k in required if k not in arrays]
    if missing:
        raise ResultsError(f"{path}: array {missing[0]!r} is missing (needed: {list(required)}); {RESUME_HINT}")
    return arrays


def load_results_for_report(out: Path, records: Sequence[Mapping[str, Any]], tasks: Sequence[EpisodeTask]) -> list:
    """:class:`EpisodeResult` of every entry's first episode (record, trace, terrain), read back for the plots.

    :raises ResultsError: naming a trace or terrain file that is unreadable or lacks an array.
    """
    firsts = []
    for t in tasks:
        if not t.first_of_entry:
            continue
        trace = read_npz(_trace_path(out, t.index), TRACE_ARRAYS)
        z = read_npz(_terrain_path(out, t.index), TERRAIN_ARRAYS)
        try:
            terrain = {"heights": z["heights"], "origin": tuple(z["origin"]), "cell_size": float(z["cell_size"])}
        except (TypeError, ValueError) as err:
            raise ResultsError(f"{_terrain_path(out, t.index)}: origin or cell_size is malformed ({err})") from None
        firsts.append(EpisodeResult(dict(records[t.index]), trace, terrain))
    return firsts
