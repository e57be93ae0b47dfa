"""The one reader of an evaluation's results: ``DIR/results.json`` and the episode records ``DIR/episodes/epNNN.json``.

``quad-uneven compare`` and ``select --reference`` read results.json, ``evaluate --resume`` reads the records
of the finished episodes (and builds results.json and the report from them), ``collect --resume`` the episode
files of a collection (a record with the episode's env arguments and step count, :func:`load_collected_episode`)
and its summary. Every field they use is checked
on the way in: a bool is a JSON bool (``"success": "yes"`` is refused, not counted), a number a finite number,
a list a list, a required key present; the file is strict JSON (no NaN or Infinity, no key given twice).
Anything else raises :class:`ResultsError`, whose message names the file and the field
(``out/a/results.json: episodes[2].success must be true or false (a JSON bool), got 'yes'``).
Fields this version does not know are left alone (a later version may add some).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any

from quad_uneven_env.fields import excerpt

__all__ = [
    "END_REASONS",
    "EPISODE_FIELDS",
    "RECORD_REQUIRED",
    "RESULTS_FILE",
    "ResultsError",
    "check_episode",
    "check_object",
    "load_collected_episode",
    "load_record",
    "load_results",
    "read_json",
]

RESULTS_FILE = "results.json"
"""An evaluation's results in its output directory."""

END_REASONS = ("goal", "waypoints", "time_limit", "wall_time_limit", "fall", "left_terrain", "diverged", "error")
"""How an episode ends (its record's ``end_reason``)."""


class ResultsError(ValueError):
    """A results.json or episode record that is not one quad-uneven wrote; the message names the file and the field."""


Kind = tuple[str, Callable[[Any], bool]]
"""A field's allowed values: (their description for messages, the check)."""


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _is_number(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


INT: Kind = ("an integer", _is_int)
COUNT: Kind = ("an integer >= 0", lambda v: _is_int(v) and v >= 0)
NUMBER: Kind = ("a finite number", _is_number)
BOOL: Kind = ("true or false (a JSON bool)", lambda v: isinstance(v, bool))
STR: Kind = ("a string", lambda v: isinstance(v, str))
OBJECT: Kind = ("a JSON object", lambda v: isinstance(v, dict))
LIST: Kind = ("a list", lambda v: isinstance(v, list))


def optional(kind: Kind) -> Kind:
    """``kind`` or null."""
    return (f"{kind[0]} or null", lambda v: v is None or kind[1](v))


def list_of(kind: Kind, length: int | None = None) -> Kind:
    """A list (of ``length`` items if given) of ``kind``."""
    size = "" if length is None else f"{length} "
    return (
        f"a list of {size}items each {kind[0]}",
        lambda v: isinstance(v, list) and (length is None or len(v) == length) and all(kind[1](x) for x in v),
    )


def object_of(kind: Kind) -> Kind:
    """A JSON object whose values are ``kind``."""
    return (f"a JSON object of {kind[0]} values", lambda v: isinstance(v, dict) and all(kind[1](x) for x in v.values()))


PUSH: Kind = (
    "an object with finite numbers 'start' and 'impulse'",
    lambda v: isinstance(v, dict) and _is_number(v.get("start")) and _is_number(v.get("impulse")),
)

_OPTIONAL_NUMBERS = (
    "mean_speed", "min_stability_index", "mean_stability_index", "fraction_index_nonnegative", "cost_of_transport",
    "planner_ms_median", "planner_ms_p95", "mean_residual_torque", "velocity_error", "velocity_error_window",
    "velocity_rmse", "yaw_rate_error", "heading_error", "realtime_factor",
)  # fmt: skip

EPISODE_FIELDS: dict[str, Kind] = {
    "index": COUNT,
    "entry": COUNT,
    "terrain": STR,
    "params": OBJECT,
    "seed": INT,
    "success": BOOL,
    "distance": NUMBER,
    "sim_time": NUMBER,
    "time_index_negative": NUMBER,
    "time_fewer_than_3_feet": NUMBER,
    "mechanical_work": NUMBER,
    "wall_time": NUMBER,
    **{name: optional(NUMBER) for name in _OPTIONAL_NUMBERS},
    "planner_calls": optional(COUNT),
    "fall_reason": optional(STR),
    "end_reason": (f"one of {list(END_REASONS)}", lambda v: v in END_REASONS),
    "end_position": list_of(NUMBER, 3),
    "end_phase": optional(STR),
    "end_stance": list_of(STR),
    "failure_log": optional(list_of(STR)),
    "failure_count": optional(COUNT),
    "expert_model": optional(STR),
    "command": optional(OBJECT),
    "waypoints_reached": optional(COUNT),
    "waypoints_total": optional(COUNT),
    "error": optional(STR),
    "machine": optional(object_of(STR)),
    "randomization": optional(OBJECT),
    "factors": optional(object_of(NUMBER)),
    "torque_peak_fraction": optional(object_of(NUMBER)),
    "pushes": optional(list_of(PUSH)),
    "video": optional(STR),
}
"""Every field of an episode record the commands read, with its allowed values."""

COMPARE_REQUIRED = ("entry", "seed", "success")
"""Fields every episode of a results.json must have (what pairs the episodes and what they are counted by)."""

RECORD_REQUIRED = (
    "index", "entry", "terrain", "seed", "success", "distance", "sim_time", "mean_speed", "min_stability_index",
    "mean_stability_index", "time_index_negative", "fraction_index_nonnegative", "cost_of_transport",
    "planner_ms_median", "planner_ms_p95", "fall_reason", "end_reason", "end_position", "end_phase", "end_stance",
    "error", "video",
)  # fmt: skip
"""Fields an episode record read back by ``--resume`` must have: those results.json's summary and the report use."""

META_FIELDS: dict[str, Kind] = {
    "entries": list_of(STR),
    "seed_offset": INT,
    "episodes_per_entry": optional(COUNT),
}
"""Fields of results.json's ``meta`` the commands read (each optional)."""

OVERALL_FIELDS: dict[str, Kind] = {
    "episodes": COUNT,
    "successes": COUNT,
    "falls": COUNT,
    "mean_stability_index": optional(NUMBER),
}
"""Fields of results.json's ``summary.overall`` that ``select --reference`` reads (required when asked for)."""


def _check(where: str, field: str, value: Any, kind: Kind) -> None:
    if not kind[1](value):
        raise ResultsError(f"{where}: {field} must be {kind[0]}, got {excerpt(value)}")


def _check_fields(
    where: str, prefix: str, data: Mapping[str, Any], fields: Mapping[str, Kind], required: Iterable[str]
) -> None:
    for name in required:
        if name not in data:
            raise ResultsError(f"{where}: {prefix}{name} is missing ({fields[name][0]} is required)")
    for name, kind in fields.items():
        if name in data:
            _check(where, f"{prefix}{name}", data[name], kind)


def check_episode(record: Any, where: str, field: str = "record", required: Iterable[str] = RECORD_REQUIRED) -> dict:
    """``record`` if it is an episode record whose known fields have their types and which has the ``required`` ones.

    :param where: the file, for the message.
    :param field: the record's name in that file (``episodes[3]``).
    :raises ResultsError: naming ``where`` and ``field.name``.
    """
    _check(where, field, record, OBJECT)
    _check_fields(where, f"{field}.", record, EPISODE_FIELDS, required)
    return record


def _unique_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    keys = [k for k, _ in pairs]
    repeated = sorted({k for k in keys if keys.count(k) > 1})
    if repeated:
        raise ValueError(f"key {excerpt(repeated[0])} given more than once in one object")
    return dict(pairs)


def _no_constant(name: str) -> Any:
    raise ValueError(f"{name} is not a JSON number")


def read_json(path: Path) -> Any:
    """The content of the strict JSON file ``path`` (no NaN or Infinity, no key given twice in an object).

    :raises ResultsError: naming ``path`` if it is missing, unreadable or not strict JSON.
    """
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise ResultsError(f"{path}: no such file") from None
    except (OSError, UnicodeDecodeError) as err:
        raise ResultsError(f"{path}: cannot be read ({err})") from None
    try:
        return json.loads(text, object_pairs_hook=_unique_keys, parse_constant=_no_constant)
    except ValueError as err:  # json.JSONDecodeError is one
        raise ResultsError(f"{path}: not a JSON file quad-uneven wrote ({err})") from None


def load_results(folder: str | Path, summary: bool = False) -> dict[str, Any]:
    """The checked content of an evaluation's ``results.json`` (``folder`` is its output directory or the file).

    Checked: an object with ``episodes`` (a list of episode records, each with ``entry``, ``seed``, ``success``
    and every other known field of its type, no (entry, seed) twice) and ``meta`` (an object; ``entries``,
    ``seed_offset``, ``episodes_per_entry`` of their types when present); ``suite`` and ``policy`` strings when
    present; with ``summary``, ``summary.overall``'s counts.

    :raises ResultsError: naming the file and the field.
    """
    p = Path(folder)
    path = p / RESULTS_FILE if p.is_dir() or p.suffix != ".json" else p
    if not path.is_file():
        raise ResultsError(
            f"{p}: no {RESULTS_FILE} (not an evaluation folder, or one that did not finish: "
            f"run quad-uneven evaluate --out {p}, or --resume it)"
        )
    data = read_json(path)
    where = str(path)
    _check(where, "the top level", data, OBJECT)
    _check_fields(where, "", data, {"episodes": LIST, "meta": OBJECT}, ("episodes", "meta"))
    _check_fields(where, "", data, {"suite": STR, "policy": STR}, ())
    _check_fields(where, "meta.", data["meta"], META_FIELDS, ())
    seen: dict[tuple[int, int], int] = {}
    for i, record in enumerate(data["episodes"]):
        check_episode(record, where, f"episodes[{i}]", COMPARE_REQUIRED)
        key = (record["entry"], record["seed"])
        if key in seen:
            raise ResultsError(
                f"{where}: episodes[{i}] repeats entry {key[0]}, seed {key[1]} of episodes[{seen[key]}] "
                "(each episode is recorded once)"
            )
        seen[key] = i
    if summary:
        _check_fields(where, "", data, {"summary": OBJECT}, ("summary",))
        _check_fields(where, "summary.", data["summary"], {"overall": OBJECT}, ("overall",))
        _check_fields(where, "summary.overall.", data["summary"]["overall"], OVERALL_FIELDS, OVERALL_FIELDS)
    return data


COLLECTED_EPISODE_FIELDS: dict[str, Kind] = {"record": OBJECT, "env_kwargs": OBJECT, "steps": COUNT}
"""Fields of a collection's episode file ``DIR/episodes/epNNN.json`` (all required; ``record`` as
:func:`load_record` checks it)."""


def check_object(data: Any, where: str, fields: Mapping[str, Kind], required: Iterable[str], prefix: str = "") -> dict:
    """``data`` if it is a JSON object whose ``fields`` have their kinds and which has the ``required`` ones.

    :param where: the file, for the message.
    :param prefix: the object's name in that file followed by a dot (``"summary."``), or "" at the top level.
    :raises ResultsError: naming ``where`` and the field.
    """
    _check(where, prefix[:-1] or "the top level", data, OBJECT)
    _check_fields(where, prefix, data, fields, required)
    return data


def load_collected_episode(path: Path) -> dict[str, Any]:
    """The checked episode file of a collection (``DIR/episodes/epNNN.json``): ``record`` (every field an episode
    record read back needs, of its type), ``env_kwargs`` (an object) and ``steps`` (an integer >= 0).

    :raises ResultsError: naming the file and the field.
    """
    where = str(path)
    data = check_object(read_json(path), where, COLLECTED_EPISODE_FIELDS, COLLECTED_EPISODE_FIELDS)
    check_episode(data["record"], where, "record")
    return data


def load_record(path: Path) -> dict[str, Any]:
    """The checked episode record in ``path`` (``DIR/episodes/epNNN.json``), with every field the report uses.

    :raises ResultsError: naming the file and the field.
    """
    return check_episode(read_json(path), str(path))
