"""The Minari side of a collected dataset: the lazy import, writing one from episode arrays, reading it back.

Minari is the optional ``datasets`` extra (``pip install 'quad-uneven[datasets]'``): :func:`import_minari` imports it
(``import agents`` never does) and turns its absence into :class:`DatasetsUnavailable`.

A dataset lives in ``DIR/DATASET_ID/data/`` (``metadata.json`` and ``main_data.hdf5``, Minari's HDF5 format), so
``MINARI_DATASETS_PATH=DIR`` makes ``minari.load_dataset(DATASET_ID)`` find it; :func:`load_collected` opens it from
``DIR`` directly. Each episode's group carries its metadata (:func:`episode_metadata`): seed, suite entry, terrain,
randomization and command settings, and the QuadUneven-v0 arguments that rebuild its env (:func:`episode_env`).
"""

from __future__ import annotations

import json
import os
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from types import ModuleType
from typing import Any

import gymnasium as gym
import numpy as np

from agents.datasets.files import SUMMARY_FILE, read_summary
from agents.evaluation.results_io import COUNT, STR, ResultsError, check_object, read_json
from quad_uneven_env.fields import clip, excerpt

__all__ = [
    "DATASETS_EXTRA_HINT",
    "DatasetError",
    "DatasetsUnavailable",
    "dataset_id_for",
    "episode_env",
    "episode_metadata",
    "import_minari",
    "load_collected",
    "open_dataset",
    "write_dataset",
]

DATASETS_EXTRA_HINT = 'pip install -e ".[datasets]"'
"""How to install Minari (the ``datasets`` extra)."""

EPISODE_JSON_KEYS = ("terrain", "randomization", "command", "waypoints", "env_kwargs", "randomization_drawn")
"""Episode metadata stored as JSON text (HDF5 attributes hold no None or nested mappings); decoded on reading."""


class DatasetsUnavailable(ValueError):
    """Minari is not installed; the message names the extra that installs it."""


def import_minari(what: str = "quad-uneven collect") -> ModuleType:
    """The ``minari`` module (with its HDF5 storage).

    :param what: the command or function that needs it (for the message).
    :raises DatasetsUnavailable: if Minari or h5py cannot be imported (one line naming the ``datasets`` extra).
    """
    try:
        import h5py  # noqa: F401  (Minari's HDF5 storage)
        import minari
    except ImportError as err:
        raise DatasetsUnavailable(f"{what} needs Minari, the 'datasets' extra: {DATASETS_EXTRA_HINT} ({err})") from None
    return minari


def dataset_id_for(suite_name: str, policy: str = "expert") -> str:
    """The dataset id of a suite's collection, e.g. ``quad-uneven-smoke-expert-v0`` (Minari's id syntax: letters,
    digits, ``-`` and ``_``; other characters of the suite name become ``_``)."""
    name = re.sub(r"[^-\w]", "_", f"quad-uneven-{suite_name}-{policy}")
    return f"{name}-v0"


def write_dataset(
    path: str | os.PathLike[str],
    dataset_id: str,
    env_spec: gym.envs.registration.EnvSpec,
    observation_space: gym.Space,
    action_space: gym.Space,
    episodes: Sequence[tuple[Mapping[str, np.ndarray], int, Mapping[str, Any]]],
    metadata: Mapping[str, Any],
) -> None:
    """Write a Minari dataset (HDF5) into the directory ``path`` (Minari's ``data`` folder; it must not hold one).

    :param episodes: per episode, in order: its arrays (:meth:`agents.datasets.recorder.EpisodeRecorder.arrays`),
        its reset seed and its metadata (JSON-safe values; the keys of :data:`EPISODE_JSON_KEYS` stored as JSON).
    :param metadata: dataset-level fields added to Minari's ``metadata.json`` (JSON-safe).
    """
    minari = import_minari()
    from minari.data_collector import EpisodeBuffer
    from minari.dataset.minari_storage import MinariStorage

    storage = MinariStorage.new(  # absolute: Minari's size count joins a relative path with itself
        Path(path).absolute(), observation_space=observation_space, action_space=action_space, env_spec=env_spec
    )
    storage.update_metadata({"dataset_id": dataset_id, "minari_version": minari.__version__, **dict(metadata)})
    buffers = [_buffer(EpisodeBuffer, i, arrays, seed) for i, (arrays, seed, _) in enumerate(episodes)]
    storage.update_episodes(buffers)
    storage.update_episode_metadata([_attrs(meta) for _, _, meta in episodes], range(len(episodes)))


def _buffer(cls: type, index: int, arrays: Mapping[str, np.ndarray], seed: int) -> Any:
    infos: dict[str, Any] = {}
    for key, value in arrays.items():
        if not key.startswith("infos/"):
            continue
        *parents, leaf = key.split("/")[1:]
        node = infos
        for p in parents:
            node = node.setdefault(p, {})
        node[leaf] = np.asarray(value)
    return cls(
        id=index,
        seed=int(seed),
        observations=np.asarray(arrays["observations"]),
        actions=np.asarray(arrays["actions"]),
        rewards=np.asarray(arrays["rewards"]),
        terminations=np.asarray(arrays["terminations"]),
        truncations=np.asarray(arrays["truncations"]),
        infos=infos,
    )


def _attrs(meta: Mapping[str, Any]) -> dict[str, Any]:
    """Episode metadata as HDF5 attributes: JSON text for :data:`EPISODE_JSON_KEYS`, None dropped."""
    out = {}
    for k, v in meta.items():
        if k in EPISODE_JSON_KEYS:
            out[k] = json.dumps(v)
        elif v is not None:
            out[k] = v
    return out


class DatasetError(ValueError):
    """A collected dataset that Minari cannot read, or not the one its collection recorded; the message names its
    folder and what is wrong."""


DATASET_METADATA_FIELDS = {
    "dataset_id": STR,
    "minari_version": STR,
    "data_format": ("'hdf5'", lambda v: v == "hdf5"),
    "observation_space": STR,
    "action_space": STR,
    "env_spec": STR,
    "total_episodes": COUNT,
    "total_steps": COUNT,
}
"""Fields of a dataset's ``metadata.json`` checked before Minari reads it (its own loader asserts, or makes the env
of ``env_spec``, where one is missing)."""


def open_dataset(data_path: Path, dataset_id: str, episodes: int, steps: int) -> Any:
    """The ``minari.MinariDataset`` in ``data_path``, verified against what its collection recorded.

    Checked: ``metadata.json`` is strict JSON with the fields of :data:`DATASET_METADATA_FIELDS` and the id
    ``dataset_id``; Minari's own loader opens the folder; ``main_data.hdf5`` opens (h5py refuses a truncated file)
    and holds exactly ``episodes`` episode groups whose step counts (rows of ``actions``, one fewer than of
    ``observations``) add up to ``steps``, as the metadata's totals do.

    :param episodes: the episode count the collection recorded (``collect.json``).
    :param steps: the step count the collection recorded.
    :raises DatasetError: naming ``data_path`` and the first check that fails.
    """
    minari = import_minari("reading a collected dataset")
    import h5py

    where = str(data_path)
    try:
        meta = check_object(
            read_json(data_path / "metadata.json"), where, DATASET_METADATA_FIELDS, DATASET_METADATA_FIELDS
        )
    except ResultsError as err:
        raise DatasetError(f"{err}: not a dataset collect wrote") from None
    recorded = {"dataset_id": dataset_id, "total_episodes": episodes, "total_steps": steps}
    for key, value in recorded.items():
        if meta[key] != value:
            raise DatasetError(
                f"{where}: metadata.json {key} is {excerpt(meta[key])}, its collection recorded {excerpt(value)}"
            )
    try:
        dataset = minari.MinariDataset(data_path)
        counts = []
        with h5py.File(data_path / "main_data.hdf5", "r") as f:
            if len(f.keys()) != episodes:
                raise DatasetError(
                    f"{where}: main_data.hdf5 holds {len(f.keys())} episodes, its collection recorded {episodes}"
                )
            for i in range(episodes):
                group = f[f"episode_{i}"]
                n, rows = group["actions"].shape[0], group["observations"].shape[0]
                if rows != n + 1:
                    raise DatasetError(f"{where}: main_data.hdf5 episode_{i} has {n} actions but {rows} observations")
                counts.append(n)
    except DatasetError:
        raise
    except (OSError, ValueError, KeyError, TypeError, AttributeError, AssertionError, NotImplementedError) as err:
        raise DatasetError(f"{where}: Minari cannot read it ({type(err).__name__}: {clip(str(err))})") from None
    if sum(counts) != steps:
        raise DatasetError(f"{where}: main_data.hdf5 holds {sum(counts)} steps, its collection recorded {steps}")
    return dataset


def load_collected(out: str | os.PathLike[str]) -> Any:
    """The ``minari.MinariDataset`` that ``quad-uneven collect --out OUT`` wrote, verified (:func:`open_dataset`)
    against the collection's summary ``OUT/collect.json``.

    :raises FileNotFoundError: if ``OUT`` holds no finished dataset (naming ``OUT``).
    :raises DatasetError: if the summary is unreadable or the dataset is not the one it records (damaged, edited).
    """
    import_minari("load_collected")

    out = Path(out)
    found = sorted(p.parent for p in out.glob("*/data/metadata.json") if not p.parent.parent.name.startswith("."))
    if len(found) != 1:
        raise FileNotFoundError(
            f"{str(out)!r} holds {len(found)} finished datasets (DATASET_ID/data/metadata.json), expected one: "
            "run quad-uneven collect --out there (or --resume it) first"
        )
    if not (out / SUMMARY_FILE).is_file():
        raise FileNotFoundError(
            f"{str(out)!r} holds no {SUMMARY_FILE} (the collection did not finish): rerun quad-uneven collect "
            "--resume there first"
        )
    try:
        summary = read_summary(out)
    except ResultsError as err:
        raise DatasetError(f"{err}; rerun quad-uneven collect --resume there to rebuild it") from None
    if found[0] != out / summary["dataset_id"] / "data":
        raise DatasetError(
            f"{out / SUMMARY_FILE}: dataset_id is {excerpt(summary['dataset_id'])}, but the dataset in {str(out)!r} "
            f"is {found[0].parent.name!r}"
        )
    return open_dataset(found[0], summary["dataset_id"], summary["episodes"], summary["steps"])


def episode_metadata(dataset: Any, index: int) -> dict[str, Any]:
    """The metadata of episode ``index`` of a collected dataset, its JSON fields decoded (docs/datasets.md)."""
    (meta,) = list(dataset.storage.get_episode_metadata([int(index)]))
    out = {}
    for k, v in meta.items():
        if isinstance(v, np.generic):
            v = v.item()
        out[k] = json.loads(v) if k in EPISODE_JSON_KEYS and isinstance(v, str) else v
    return out


def episode_env(dataset: Any, index: int, **kwargs: Any) -> gym.Env:
    """The env episode ``index`` of a collected dataset was recorded in (its terrain, randomization, command and
    time limit); ``env.reset(seed=episode_metadata(dataset, index)["seed"])`` gives its terrain and world again.

    :param kwargs: QuadUneven-v0 arguments to change (e.g. ``render_mode``).
    """
    meta = episode_metadata(dataset, index)
    return gym.make("QuadUneven-v0", **{**meta["env_kwargs"], **kwargs})
