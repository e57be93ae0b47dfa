"""The files of a collection folder ``DIR`` besides the dataset: each episode's arrays and record, the summary.

Per finished episode ``DIR/episodes/epNNN.npz`` (its arrays, :meth:`agents.datasets.recorder.EpisodeRecorder.arrays`)
is written first, then ``DIR/episodes/epNNN.json`` (its evaluation record, env arguments and step count), each to a
temporary name and renamed: a record means a finished episode. ``collect --resume`` reads them back through the
strict reader of :mod:`agents.evaluation.results_io` and checks the arrays against the record and the dataset's
spaces, so a file a run did not write (truncated, edited, another episode's) is refused in one line naming the file
and the field, never built into a dataset. ``DIR/collect.json`` is the summary written once the dataset is whole.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from agents.evaluation.results_io import (
    COUNT,
    STR,
    ResultsError,
    check_object,
    list_of,
    load_collected_episode,
    read_json,
)
from agents.evaluation.store import RESUME_HINT, check_task_record, read_npz
from agents.evaluation.suites import EpisodeTask
from agents.outputs import write_json_atomic

__all__ = ["SUMMARY_FILE", "check_arrays", "npz_path", "read_records", "read_summary", "record_path", "write_episode"]

SUMMARY_FILE = "collect.json"
"""The summary written last (dataset id and path, episodes, steps, successes, speed)."""

TRANSITION_ARRAYS = ("observations", "actions", "rewards", "terminations", "truncations")
"""Arrays every episode file holds besides its ``infos/...`` ones."""

SUMMARY_FIELDS = {
    "dataset_id": STR,
    "dataset_path": STR,
    "episodes": COUNT,
    "episodes_without_steps": list_of(COUNT),
    "steps": COUNT,
    "successes": COUNT,
}
"""Fields of ``collect.json`` that ``--resume`` and :func:`agents.datasets.load_collected` read (all required)."""


def npz_path(out: Path, index: int) -> Path:
    """``out/episodes/epNNN.npz``: the arrays of episode ``index`` until the dataset holds them."""
    return out / "episodes" / f"ep{index:03d}.npz"


def record_path(out: Path, index: int) -> Path:
    """``out/episodes/epNNN.json``: the record of finished episode ``index``."""
    return out / "episodes" / f"ep{index:03d}.json"


def write_episode(
    out: Path, index: int, arrays: Mapping[str, np.ndarray], record: Mapping[str, Any], env_kwargs: Mapping[str, Any]
) -> None:
    """The episode's arrays, then its record (the commit); :raises OSError: if a file cannot be written."""
    path = npz_path(out, index)
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        with tmp.open("wb") as f:
            np.savez(f, **arrays)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    saved = {"record": dict(record), "env_kwargs": dict(env_kwargs), "steps": len(arrays["actions"])}
    write_json_atomic(record_path(out, index), saved)


def read_records(out: Path, tasks: Sequence[EpisodeTask]) -> dict[int, dict[str, Any]]:
    """The episode files of ``tasks`` in ``out`` (index -> {record, env_kwargs, steps}), each checked.

    :raises ResultsError: naming the file and the field of a record that is not one this collection wrote (not
        strict JSON, a field missing or of the wrong type, another task's entry, terrain or seed).
    """
    done = {}
    for t in tasks:
        path = record_path(out, t.index)
        if not path.is_file():
            continue
        try:
            saved = load_collected_episode(path)
        except ResultsError as err:
            raise ResultsError(f"--resume: {err}; {RESUME_HINT}") from None
        check_task_record(path, saved["record"], t)
        done[t.index] = saved
    return done


def check_arrays(path: Path, steps: int, observation_space: gym.Space, action_space: gym.Space) -> None:
    """Refuse the episode arrays in ``path`` unless they are ``steps`` transitions of the dataset's spaces.

    Checked: a readable ``.npz`` of plain arrays holding :data:`TRANSITION_ARRAYS`; ``observations`` of shape
    (steps + 1, *observation shape) and the space's dtype, ``actions`` (steps, *action shape) of its dtype,
    ``rewards`` a number and ``terminations``, ``truncations`` a bool per step, every ``infos/...`` array one row
    per observation.

    :raises ResultsError: naming the file and the array.
    """
    try:
        arrays = read_npz(path, TRANSITION_ARRAYS)
    except ResultsError as err:
        raise ResultsError(f"--resume: {err}") from None
    expected = {
        "observations": ((steps + 1, *observation_space.shape), observation_space.dtype),
        "actions": ((steps, *action_space.shape), action_space.dtype),
        "rewards": ((steps,), None),
        "terminations": ((steps,), np.dtype(bool)),
        "truncations": ((steps,), np.dtype(bool)),
    }
    for name, (shape, dtype) in expected.items():
        a = arrays[name]
        if a.shape != shape or (dtype is not None and a.dtype != dtype) or a.dtype.kind not in "biuf":
            want = f"shape {shape} of {dtype if dtype is not None else 'numbers'}"
            raise ResultsError(
                f"--resume: {path}: {name} must have {want} (its record counts {steps} steps), got shape "
                f"{a.shape} of {a.dtype}; {RESUME_HINT}"
            )
    for name, a in arrays.items():
        if name in expected:
            continue
        if not name.startswith("infos/") or a.ndim == 0 or len(a) != steps + 1 or a.dtype.kind not in "biuf":
            raise ResultsError(
                f"--resume: {path}: {name} must be an infos/ array of numbers with {steps + 1} rows (one per "
                f"observation), got shape {a.shape} of {a.dtype}; {RESUME_HINT}"
            )


def read_summary(out: Path) -> dict[str, Any]:
    """The checked ``out/collect.json``.

    :raises ResultsError: naming the file and the field if it is missing, not strict JSON or lacks a field of
        :data:`SUMMARY_FIELDS` (of its type).
    """
    path = out / SUMMARY_FILE
    return check_object(read_json(path), str(path), SUMMARY_FIELDS, SUMMARY_FIELDS)
