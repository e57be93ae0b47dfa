"""Robot descriptions by name or YAML path: :func:`load_robot` and the types it returns.

A robot is a :class:`~quad_uneven_env.robot.quadruped.RobotDescription` (:mod:`quad_uneven_env.robot.quadruped`:
the data, its checks and the robot facts), built from one YAML:

- a Table-1 YAML (the paper's robot, ``configs/robot/paper.yaml``): :mod:`quad_uneven_env.robot.table1`;
- a YAML naming a ``urdf``: the URDF read through Pinocchio, plus what a URDF does not say (leg joint and foot
  frame names, foot radius, armature, torque limits where the URDF's are unusable):
  :mod:`quad_uneven_env.robot.urdf`.

:func:`load_robot` keeps the descriptions it built, keyed by the contents of the YAML and of the URDF and SRDF it
names: an edited file is read again.
"""

from __future__ import annotations

import hashlib
import os
import threading
from pathlib import Path
from typing import Any

from quad_uneven_env.config import CONFIG_DIR, read_yaml, resolve_config_path
from quad_uneven_env.robot.quadruped import (
    AXIS_TOLERANCE,
    MIN_INERTIA,
    PAPER_LEG_LENGTH,
    PAPER_MASS,
    PAPER_STANDING_HEIGHT,
    GaitSettings,
    JointDescription,
    LegDescription,
    LinkInertia,
    RobotDescription,
    TwoLinkLegs,
)
from quad_uneven_env.robot.table1 import from_table1
from quad_uneven_env.robot.urdf import DATA_PACKAGE, RANGE_KEYS, from_urdf, from_urdf_yaml, model_files, robot_data_dir

__all__ = [
    "AXIS_TOLERANCE",
    "DATA_PACKAGE",
    "MIN_INERTIA",
    "PAPER_LEG_LENGTH",
    "PAPER_MASS",
    "PAPER_STANDING_HEIGHT",
    "RANGE_KEYS",
    "GaitSettings",
    "JointDescription",
    "LegDescription",
    "LinkInertia",
    "RobotDescription",
    "TwoLinkLegs",
    "from_urdf",
    "load_robot",
    "robot_data_dir",
    "robot_names",
]

CACHE_SIZE = 16
"""Descriptions :func:`load_robot` keeps (the least recently used go first)."""


def robot_names() -> list[str]:
    """Names of the shipped robots (``configs/robot/*.yaml``)."""
    return sorted(p.stem for p in (CONFIG_DIR / "robot").glob("*.yaml"))


def load_robot(name_or_path: str | os.PathLike[str] = "paper") -> RobotDescription:
    """A robot by name (``configs/robot/NAME.yaml``) or YAML path: a URDF robot if its YAML names a ``urdf``,
    else a Table-1 robot. The same files give the same (cached) description.

    :raises ValueError: naming the file and the field.
    """
    path = resolve_config_path(name_or_path, "robot")
    where = f"robot {path.name}"
    yaml_key = (str(path.resolve()), _digest([path]))
    parsed = _cached(_PARSED, yaml_key)
    if parsed is None:
        raw = read_yaml(path)
        files = model_files(raw, path.parent, where) if "urdf" in raw else ()
        parsed = _store(_PARSED, yaml_key, (raw, tuple(p for p in files if p is not None)))
    raw, files = parsed
    key = (*yaml_key, _digest(list(files)))
    desc = _cached(_CACHE, key)
    if desc is None:
        desc = from_urdf_yaml(raw, path.parent, where) if "urdf" in raw else from_table1(raw, where)
        _store(_CACHE, key, desc)
    return desc


def _digest(files: list[Path]) -> str:
    h = hashlib.sha256()
    for p in files:
        try:
            data = p.read_bytes()
        except OSError as err:
            raise ValueError(f"robot file {str(p)!r} cannot be read: {err}") from None
        h.update(len(data).to_bytes(8, "little") + data)
    return h.hexdigest()


def _cached(cache: dict, key: tuple) -> Any:
    with _LOCK:
        hit = cache.pop(key, None)
        if hit is not None:
            cache[key] = hit  # the most recently used last
        return hit


def _store(cache: dict, key: tuple, value: Any) -> Any:
    with _LOCK:
        cache[key] = value
        while len(cache) > CACHE_SIZE:
            cache.pop(next(iter(cache)))
    return value


_PARSED: dict[tuple[str, str], tuple[dict[str, Any], tuple[Path, ...]]] = {}
"""Each YAML's mapping and the model files it names, by (YAML path, SHA-256 of the YAML)."""
_CACHE: dict[tuple[str, str, str], RobotDescription] = {}
"""Descriptions by (YAML path, SHA-256 of the YAML, SHA-256 of its URDF and SRDF), least recently used first."""
_LOCK = threading.Lock()
