"""Terrain suites: named lists of terrains x seeds with a goal distance and a time limit (configs/suites/).

File format (every field required except ``scale``, ``params``, ``randomization``, ``command`` and
``waypoints``; no other fields)::

    name: rough-mild
    scale: leg_length       # optional: lengths in units of the robot's leg length / the paper robot's 0.42 m
    goal_distance: 5.0      # m along +x from the spawn point
    time_limit: 120.0       # s of simulated time per episode
    terrains:
      - kind: rough         # any terrain kind of the environment (docs/terrain.md)
        params: {amplitude: 0.04, wavelength: 0.6}
        randomization: mild # optional: a preset name or a mapping (docs/randomization.md); default nominal
        command: {vx: 0.1, yaw_rate: 0.2}  # optional: the env's command (docs/commands.md)
        waypoints: {points: [[1, 0], [2, 1]], radius: 0.3}  # optional (agents.waypoints.WaypointConfig)
        seeds: [0, 1, 2, 3, 4]

An entry with a ``command`` (and no waypoints) walks for the whole time limit: success is not falling
(nor leaving the terrain), and the goal distance is not used. An entry with ``waypoints`` succeeds once every
waypoint is reached (in order); its env gets the command ``{}`` (all zero) unless it gives one, which the
waypoint follower then steers (:mod:`agents.waypoints`).

With ``scale: leg_length`` (or ``quad-uneven evaluate --scale-terrain``) the suite is written for the paper's
robot and run on the evaluated robot at its own scale (:func:`scale_suite`): the whole terrain is magnified by
the robot's leg length over 0.42 m (every terrain parameter in m, defaults and the shared grid parameters
included: the same nodes at scaled positions and heights), so is the goal distance, and the time limit is
multiplied by the square root of it (equal Froude number).

Terrain parameters are validated by :func:`quad_uneven_env.terrain.parse_terrain_spec`. Errors are
``SuiteError`` (a ``ValueError``) whose message starts with the offending field, e.g.
``terrains[2].params.amplitude must be a number in [0, 0.3] (m), got 5``.
"""

from __future__ import annotations

import dataclasses
import os
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from agents.waypoints import load_waypoints
from quad_uneven_env.command import load_command
from quad_uneven_env.config import CONFIG_DIR, read_yaml, resolve_config_path
from quad_uneven_env.fields import REQUIRED, Param, excerpt
from quad_uneven_env.randomization import load_randomization
from quad_uneven_env.terrain import TERRAIN_KINDS, parse_terrain_spec
from quad_uneven_env.terrain.kinds import KINDS

SUITE_DIR = CONFIG_DIR / "suites"
"""Directory of the shipped suites (``configs/suites/NAME.yaml``)."""

SUITE_FIELDS = ("name", "goal_distance", "time_limit", "terrains")
"""Top-level fields of a suite file (all required)."""

SUITE_SCALES = ("none", "leg_length")
"""Values of a suite's optional ``scale`` field: as written, or in units of the robot's leg length."""

ENTRY_FIELDS = ("kind", "params", "seeds", "randomization", "command", "waypoints")
"""Fields of one ``terrains`` entry (``params`` optional, default ``{}``; ``randomization``, ``command`` and
``waypoints`` optional, default None)."""

EXIT_MARGIN = 0.3
"""m: the environment ends an episode whose base comes this close to the grid's edge ("left the terrain")."""


class SuiteError(ValueError):
    """An invalid suite; the message names the field (``terrains[1].seeds: ...``)."""


@dataclasses.dataclass(frozen=True)
class TerrainEntry:
    """One ``terrains`` entry: a terrain kind, its parameters and the seeds to run it with."""

    kind: str
    """terrain kind (one of ``TERRAIN_KINDS``)."""
    params: dict[str, Any]
    """parameters as written in the file (defaults not filled; JSON-friendly)."""
    seeds: tuple[int, ...]
    """episode seeds (>= 0, distinct): each seeds the env's reset and hence the terrain."""
    randomization: str | dict[str, Any] | None = None
    """the env's ``randomization=`` argument as written (a preset name or a mapping; None: the nominal world)."""
    command: dict[str, Any] | None = None
    """the env's ``command=`` argument as written (None: no command; see docs/commands.md)."""
    waypoints: dict[str, Any] | None = None
    """the waypoints to follow as written (:class:`agents.waypoints.WaypointConfig` fields; None: none)."""

    @property
    def spec(self) -> dict[str, Any]:
        """The environment's ``terrain=`` argument: ``{"kind": ..., **params}``."""
        return {"kind": self.kind, **self.params}

    @property
    def label(self) -> str:
        """Short human-readable name, e.g. ``stairs(direction=up)`` or ``rough(amplitude=0.05) + mild``."""
        inner = ", ".join(f"{k}={v:.6g}" if isinstance(v, float) else f"{k}={v}" for k, v in self.params.items())
        label = f"{self.kind}({inner})" if inner else self.kind
        if self.command is not None:
            fixed = ", ".join(f"{k}={v}" for k, v in self.command.items() if k != "ranges")
            label += f" cmd({fixed}{', ranges' if 'ranges' in self.command else ''})"
        if self.waypoints is not None:
            label += f" {len(self.waypoints['points'])} waypoints"
        if self.randomization is None:
            return label
        return f"{label} + {self.randomization if isinstance(self.randomization, str) else 'randomization'}"


@dataclasses.dataclass(frozen=True)
class Suite:
    """A validated suite."""

    name: str
    """suite name."""
    goal_distance: float
    """m: COG travel along +x from the spawn point that counts as success."""
    time_limit: float
    """s of simulated time per episode."""
    terrains: tuple[TerrainEntry, ...]
    """the terrain entries, in file order."""
    source: str = ""
    """file the suite was read from ("" if built from a mapping)."""
    scale: str = "none"
    """"none" (lengths as written) or "leg_length" (to be scaled to the robot's leg length, :func:`scale_suite`)."""
    length_scale: float = 1.0
    """-: the factor :func:`scale_suite` magnified the written suite by (1: as written)."""


@dataclasses.dataclass(frozen=True)
class EpisodeTask:
    """One episode to run: the entry it comes from, its terrain and its seed."""

    index: int
    """position in the suite's episode list (results are ordered by it)."""
    entry: int
    """index of the ``terrains`` entry."""
    kind: str
    """terrain kind."""
    params: dict[str, Any]
    """terrain parameters as written in the suite."""
    seed: int
    """env reset seed (the entry's seed plus the seed offset)."""
    first_of_entry: bool
    """True for the entry's first episode (plotted, and filmed with --video)."""
    randomization: str | dict[str, Any] | None = None
    """the entry's ``randomization`` (None: the nominal world)."""
    command: dict[str, Any] | None = None
    """the entry's ``command`` (None: none)."""
    waypoints: dict[str, Any] | None = None
    """the entry's ``waypoints`` (None: none)."""


def suite_names() -> list[str]:
    """Names of the shipped suites in ``configs/suites/``."""
    return sorted(p.stem for p in SUITE_DIR.glob("*.yaml"))


def load_suite(name_or_path: str | os.PathLike[str]) -> Suite:
    """Read and validate a suite by name (``configs/suites/NAME.yaml``) or YAML path.

    :raises SuiteError: on an unknown name, an unreadable file or an invalid field (named in the message).
    """
    try:
        path = resolve_config_path(name_or_path, "suites")
        raw = read_yaml(path)
    except ValueError as e:
        raise SuiteError(str(e)) from None
    return suite_from_dict(raw, source=str(path))


GOAL_DISTANCE = Param("goal_distance", REQUIRED, "m", "distance along +x from the spawn point", lo=0.0, hi=500.0,
                      lo_open=True)  # fmt: skip
TIME_LIMIT = Param("time_limit", REQUIRED, "s", "simulated seconds per episode", lo=0.0, hi=3600.0, lo_open=True)
SEED = Param("seed", REQUIRED, "-", "terrain and reset seed", kind="int", lo=0)


def _check(p: Param, value: Any, where: str = "") -> Any:
    """``p.check`` with the error as a :class:`SuiteError`."""
    try:
        return p.check(value, where)
    except ValueError as e:
        raise SuiteError(str(e)) from None


def _rename_terrain_error(msg: str, i: int) -> str:
    """Turn parse_terrain_spec's ``terrain[rough].amplitude ...`` into ``terrains[i].params.amplitude ...``."""
    msg = re.sub(r"^terrain\[[^\]]*\]\.", f"terrains[{i}].params.", msg)
    msg = re.sub(r"^terrain\[[^\]]*\]:", f"terrains[{i}].params:", msg)
    msg = re.sub(r"^terrain\.kind", f"terrains[{i}].kind", msg)
    msg = re.sub(r"^terrain\.params", f"terrains[{i}].params", msg)
    msg = re.sub(r"^terrain:", f"terrains[{i}].params:", msg)
    return msg if msg.startswith(f"terrains[{i}]") else f"terrains[{i}]: {msg}"


def _plain(value: Any) -> Any:
    """``value`` with mappings turned into dicts and tuples into lists (JSON-friendly, as written)."""
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    return value


def _seeds(value: Any, field: str) -> tuple[int, ...]:
    if not isinstance(value, list) or not value:
        raise SuiteError(f"{field} must be a non-empty list of integers >= 0, got {excerpt(value)}")
    value = [_check(dataclasses.replace(SEED, name=f"{field}[{k}]"), s) for k, s in enumerate(value)]
    if len(set(value)) != len(value):
        raise SuiteError(f"{field} must not repeat a seed, got {excerpt(value)}")
    return tuple(int(s) for s in value)


def _entry(raw: Any, i: int, goal_distance: float) -> TerrainEntry:
    where = f"terrains[{i}]"
    if not isinstance(raw, Mapping):
        raise SuiteError(f"{where} must be a mapping with fields {list(ENTRY_FIELDS)}, got {excerpt(raw)}")
    unknown = sorted(set(raw) - set(ENTRY_FIELDS), key=str)
    if unknown:
        raise SuiteError(f"{where}: unknown field(s) {excerpt(unknown)}; allowed: {list(ENTRY_FIELDS)}")
    for key in ("kind", "seeds"):
        if key not in raw:
            raise SuiteError(f"{where}.{key} is required")
    kind = raw["kind"]
    if not isinstance(kind, str) or kind not in TERRAIN_KINDS:
        raise SuiteError(f"{where}.kind must be one of {list(TERRAIN_KINDS)}, got {excerpt(kind)}")
    params = raw.get("params")
    params = {} if params is None else params
    if not isinstance(params, Mapping):
        raise SuiteError(f"{where}.params must be a mapping of parameter names to values, got {excerpt(params)}")
    if "kind" in params or "params" in params:
        raise SuiteError(f"{where}.params must not contain 'kind' or 'params'")
    try:
        spec = parse_terrain_spec({"kind": kind, **params})
    except ValueError as e:
        raise SuiteError(_rename_terrain_error(str(e), i)) from None
    seeds = _seeds(raw["seeds"], f"{where}.seeds")
    randomization = raw.get("randomization")
    if randomization is not None:
        if not isinstance(randomization, str | Mapping):
            raise SuiteError(f"{where}.randomization must be a preset name or a mapping, got {excerpt(randomization)}")
        try:
            load_randomization(randomization, f"{where}.randomization")
        except ValueError as e:
            raise SuiteError(str(e)) from None
        randomization = randomization if isinstance(randomization, str) else dict(randomization)
    command = raw.get("command")
    if command is not None:
        try:
            load_command(command)
        except ValueError as e:
            raise SuiteError(f"{where}.{e}") from None
        command = _plain(command)
    grid = KINDS[kind].grid(spec.params)
    waypoints = raw.get("waypoints")
    if waypoints is not None:
        try:
            wp = load_waypoints(waypoints, f"{where}.waypoints")
        except ValueError as e:
            raise SuiteError(str(e)) from None
        lo = [grid.origin[k] + EXIT_MARGIN for k in (0, 1)]
        hi = [grid.origin[k] + grid.size[k] - EXIT_MARGIN for k in (0, 1)]
        for k, (x, y) in enumerate(wp.points):
            if not (lo[0] < x < hi[0] and lo[1] < y < hi[1]):
                raise SuiteError(
                    f"{where}.waypoints.points[{k}] = [{x:g}, {y:g}] m is off the terrain: it must lie within x in "
                    f"({lo[0]:.2f}, {hi[0]:.2f}) m and y in ({lo[1]:.2f}, {hi[1]:.2f}) m (the grid less "
                    f"{EXIT_MARGIN} m)"
                )
        waypoints = _plain(waypoints)
    if command is not None or waypoints is not None:  # no goal distance: walks for the time limit or the waypoints
        return TerrainEntry(kind, dict(params), seeds, randomization, command, waypoints)
    x_exit = grid.origin[0] + grid.size[0] - EXIT_MARGIN
    if goal_distance >= x_exit:
        raise SuiteError(
            f"goal_distance {goal_distance} m cannot be reached on {where}: its grid ends at x = "
            f"{grid.origin[0] + grid.size[0]:.2f} m and an episode ends once the base passes x = {x_exit:.2f} m "
            f"(lengthen {where}.params.length or shorten goal_distance)"
        )
    return TerrainEntry(kind, dict(params), seeds, randomization)


def suite_from_dict(raw: Mapping[str, Any], source: str = "") -> Suite:
    """Validate a suite mapping (the parsed YAML file).

    :raises SuiteError: naming the offending field and its allowed values.
    """
    if not isinstance(raw, Mapping):
        raise SuiteError(f"a suite must be a mapping with fields {list(SUITE_FIELDS)}, got {type(raw).__name__}")
    unknown = sorted(set(raw) - set(SUITE_FIELDS) - {"scale"}, key=str)
    if unknown:
        raise SuiteError(f"unknown field(s) {excerpt(unknown)}; allowed: {[*SUITE_FIELDS, 'scale']}")
    scale = raw.get("scale", "none")
    if scale not in SUITE_SCALES:
        raise SuiteError(f"scale must be one of {list(SUITE_SCALES)}, got {excerpt(scale)}")
    missing = [k for k in SUITE_FIELDS if k not in raw]
    if missing:
        raise SuiteError(f"missing field(s) {missing}; a suite needs {list(SUITE_FIELDS)}")
    name = raw["name"]
    if not isinstance(name, str) or not name.strip():
        raise SuiteError(f"name must be a non-empty string, got {excerpt(name)}")
    goal = _check(GOAL_DISTANCE, raw["goal_distance"])
    limit = _check(TIME_LIMIT, raw["time_limit"])
    terrains = raw["terrains"]
    if not isinstance(terrains, list) or not terrains:
        raise SuiteError(
            f"terrains must be a non-empty list of {{kind, params, seeds}} entries, got {excerpt(terrains)}"
        )
    entries = tuple(_entry(t, i, goal) for i, t in enumerate(terrains))
    return Suite(name, goal, limit, entries, source, scale)


def scale_suite(suite: Suite, factor: float) -> Suite:
    """``suite`` magnified by ``factor`` (-): every length times ``factor``, its time limit times ``sqrt(factor)``.

    Lengths: each entry's terrain parameters in m, its kind's defaults filled in where the suite does not give
    them, the shared grid parameters (``length``, ``width``, ``cell_size``, ``x_start``, ``spawn_radius``)
    included, a heightmap's inline heights and ``origin`` too; the ``paper`` kind's ``scale`` (its scripted blocks)
    is multiplied as well. The scaled terrain is the written one magnified: the same nodes, each at ``factor``
    times its position and height. The goal distance is multiplied too (the room the suite leaves before the end
    of each grid grows with it). The result says ``scale: none``; its name records the factor. A factor of 1
    gives the suite's own terrains, goal and time limit.

    :raises SuiteError: if a scaled parameter leaves its allowed range (e.g. ``cell_size`` outside [0.005, 0.5]
        m), if a heightmap's heights are a .npy path, or if the scaled goal lies beyond a grid's exit (naming it).
    """
    if not (factor > 0 and factor < 100):
        raise SuiteError(f"scale factor must be a number in (0, 100), got {excerpt(factor)}")
    terrains = []
    for i, e in enumerate(suite.terrains):
        try:
            params = scale_terrain_params(e.kind, e.params, factor)
        except ValueError as err:
            raise SuiteError(f"terrains[{i}].params.{err}") from None
        raw = {"kind": e.kind, "params": params, "seeds": list(e.seeds)}
        for key in ("randomization", "command", "waypoints"):
            if getattr(e, key) is not None:
                raw[key] = getattr(e, key)
        terrains.append(raw)
    raw_suite = {
        "name": f"{suite.name} (lengths x{factor:.3f})",
        "goal_distance": suite.goal_distance * factor,
        "time_limit": suite.time_limit * factor**0.5,
        "terrains": terrains,
    }
    try:
        scaled = suite_from_dict(raw_suite, suite.source)
    except SuiteError as err:
        raise SuiteError(f"scaled by {factor:.3f}: {err}") from None
    return dataclasses.replace(scaled, length_scale=suite.length_scale * factor)


def scale_terrain_params(kind: str, params: Mapping[str, Any], factor: float) -> dict[str, Any]:
    """The parameters of a ``kind`` terrain magnified by ``factor`` (-), as :func:`scale_suite` does for each entry.

    Every parameter in m (the kind's defaults filled in where ``params`` does not give them, the shared grid
    parameters included) and every one in :data:`SCALED_FACTORS` is multiplied; the others are kept as given.
    The result is not validated (:func:`quad_uneven_env.terrain.parse_terrain_spec` does that).

    :raises ValueError: ``"NAME cannot be scaled ..."`` for a parameter given as a file path (a heightmap's .npy).
    """
    out = dict(params)
    for p in KINDS[kind].all_params:
        value = out.get(p.name, p.default)
        if p.name == "x_start" and out.get("origin") is not None:
            continue  # a heightmap placed by its origin (scaled) takes no x_start
        if p.unit == "m" or p.name in SCALED_FACTORS:
            try:
                scaled = _magnified(value, factor)
            except TypeError:
                raise ValueError(
                    f"{p.name} cannot be scaled to the robot: give the values (m) in the suite, not a file "
                    f"({excerpt(value)})"
                ) from None
            if scaled is not None:
                out[p.name] = scaled
    return out


SCALED_FACTORS = ("scale",)
"""Terrain parameters without a unit that :func:`scale_suite` multiplies too (the ``paper`` kind's block scale)."""


def _magnified(value: Any, factor: float) -> Any:
    """``value`` (a length in m, an (x, y) pair or a 2-D list of heights) times ``factor``; None if it has no number.

    Not rounded: a scaled grid keeps every node where the written one has it (features on node edges stay there).

    :raises TypeError: if ``value`` is a string (a file path).
    """
    if isinstance(value, bool) or value is None or value is REQUIRED:
        return None
    if isinstance(value, str | os.PathLike):
        raise TypeError(value)
    if isinstance(value, int | float):
        return float(value) * factor
    if isinstance(value, list | tuple):
        return [_magnified(v, factor) for v in value]
    if isinstance(value, np.ndarray):
        return (np.asarray(value, dtype=np.float64) * factor).tolist()
    return None


def episode_tasks(suite: Suite, episodes: int | None = None, seed_offset: int = 0) -> list[EpisodeTask]:
    """The suite's episodes in order: per entry, its first ``episodes`` seeds (all if None), plus ``seed_offset``.

    :raises ValueError: if ``episodes`` < 1 or an offset seed is negative.
    """
    if episodes is not None and episodes < 1:
        raise ValueError(f"episodes must be an integer >= 1 (episodes per terrain entry), got {episodes}")
    tasks: list[EpisodeTask] = []
    for e, entry in enumerate(suite.terrains):
        for k, s in enumerate(entry.seeds[:episodes]):
            seed = s + seed_offset
            if seed < 0:
                raise ValueError(f"seed: offset {seed_offset} makes terrains[{e}] seed {s} negative")
            first = k == 0
            task = EpisodeTask(
                len(tasks), e, entry.kind, dict(entry.params), seed, first, entry.randomization, entry.command,
                entry.waypoints,
            )  # fmt: skip
            tasks.append(task)
    return tasks


def suite_path(name: str) -> Path:
    """Path of the shipped suite ``name``."""
    return SUITE_DIR / f"{name}.yaml"
