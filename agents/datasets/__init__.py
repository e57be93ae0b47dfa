"""Datasets of the expert for learning from it: ``quad-uneven collect`` and the Minari datasets it writes.

Typical use::

    from agents.datasets import collect, load_collected
    summary = collect("smoke", "out/data/smoke", episodes=1)
    dataset = load_collected("out/data/smoke")          # a minari.MinariDataset
    env = dataset.recover_environment()                 # the first episode's env (QuadUneven-v0, torque actions)

Minari is the optional ``datasets`` extra; this package imports it only when a dataset is written or read.
Formats and what the recorded action is: docs/datasets.md.
"""

from agents.datasets.minari_io import (
    DatasetsUnavailable,
    dataset_id_for,
    episode_env,
    episode_metadata,
    import_minari,
    load_collected,
)
from agents.datasets.recorder import INFO_FIELDS, EpisodeRecorder, TorqueRecorder, TorqueReplay, recorded_action
from agents.datasets.run import CollectInterrupted, collect, collect_task

__all__ = [
    "INFO_FIELDS",
    "CollectInterrupted",
    "DatasetsUnavailable",
    "EpisodeRecorder",
    "TorqueRecorder",
    "TorqueReplay",
    "collect",
    "collect_task",
    "dataset_id_for",
    "episode_env",
    "episode_metadata",
    "import_minari",
    "load_collected",
    "recorded_action",
]
