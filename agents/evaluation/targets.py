"""The expert's walking targets, checked against an evaluation's per-entry summary where they apply."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from typing import Any

from agents.evaluation.metrics import INDEX_OK_FRACTION
from agents.evaluation.suites import TerrainEntry
from quad_uneven_env.terrain import parse_terrain_spec
from quad_uneven_env.terrain.kinds import KINDS

MIN_SEEDS = 10
"""A target is judged on at least this many seeds of its terrain."""

MIN_GOAL_DISTANCE = 5.0
"""m: a target is judged on walks to a goal at least this far."""


@dataclasses.dataclass(frozen=True)
class Target:
    """A success-rate (and optionally speed) target for the terrain entries that match ``kind`` and ``params``."""

    name: str
    """human-readable name."""
    kind: str
    """terrain kind."""
    params: Mapping[str, Any]
    """parameter values (after defaults are filled) an entry must have."""
    success_rate: float
    """minimum success rate."""
    min_speed: float | None = None
    """m/s: minimum mean speed over the successful episodes (None: no speed target)."""


TARGETS: tuple[Target, ...] = (
    Target("flat", "flat", {}, 1.0, 0.1),
    Target("rough 4 cm", "rough", {"amplitude": 0.04}, 0.95, 0.1),
    Target("slope 10°", "slope", {"angle_deg": 10}, 0.90),
    Target("stairs 8 cm up", "stairs", {"riser": 0.08, "direction": "up"}, 0.90),
    Target("stairs 8 cm down", "stairs", {"riser": 0.08, "direction": "down"}, 0.90),
    Target("stepping stones", "stepping_stones", {}, 0.80),
)
"""The nominal walking targets (goal 5 m, >= 10 seeds); every target also asks that each success keeps the
measured stability index >= 0 for >= 99% of its time."""


def _matches(target: Target, entry: TerrainEntry, length_scale: float) -> bool:
    if entry.kind != target.kind or entry.randomization is not None:  # the targets are for the nominal world
        return False
    if entry.command is not None or entry.waypoints is not None:  # walking to the goal, not where it is told
        return False
    params = parse_terrain_spec(entry.spec).params
    units = {p.name: p.unit for p in KINDS[target.kind].all_params}
    for name, want in target.params.items():
        got = params.get(name)
        if units.get(name) == "m":
            if not (isinstance(got, int | float) and math.isclose(got, want * length_scale, rel_tol=1e-9)):
                return False
        elif got != want:
            return False
    return True


def check_targets(
    entries: Sequence[TerrainEntry],
    by_entry: Sequence[Mapping[str, Any]],
    goal_distance: float,
    length_scale: float = 1.0,
) -> list[dict[str, Any]]:
    """One row per (target, matching entry) with the measured values and ``passed``.

    A target is judged only where the suite is made to judge it: a goal of at least ``MIN_GOAL_DISTANCE`` and an
    entry with at least ``MIN_SEEDS`` seeds (a short check such as the ``smoke`` suite gives no rows).
    ``passed`` needs: >= ``MIN_SEEDS`` episodes run (fewer with ``--episodes``), the success rate, the speed
    (mean over successes) and every success with the index >= 0 for >= 99% of its time.

    :param length_scale: -, the factor the suite was magnified by for a robot (``scale: leg_length``): the targets'
        lengths (goal, terrain parameters in m) are judged times it and their speeds times its square root (the
        same Froude number).
    """
    rows: list[dict[str, Any]] = []
    if goal_distance < MIN_GOAL_DISTANCE * length_scale * (1 - 1e-9):
        return rows
    groups = {g["entry"]: g for g in by_entry}
    for target in TARGETS:
        for i, entry in enumerate(entries):
            if i not in groups or len(entry.seeds) < MIN_SEEDS or not _matches(target, entry, length_scale):
                continue
            g = groups[i]
            why = []
            if g["episodes"] < MIN_SEEDS:
                why.append(f"{g['episodes']} < {MIN_SEEDS} episodes")
            rate = g["success_rate"] or 0.0
            if rate < target.success_rate:
                why.append(f"success rate {rate:.0%} < {target.success_rate:.0%}")
            speed = g["mean_speed_success"]
            min_speed = None if target.min_speed is None else target.min_speed * math.sqrt(length_scale)
            if min_speed is not None and (speed is None or speed < min_speed):
                why.append(f"mean speed {speed if speed is None else round(speed, 3)} m/s < {min_speed:.4g} m/s")
            if g["successes_index_ok"] < g["successes"]:
                why.append(
                    f"{g['successes'] - g['successes_index_ok']} success(es) with the index < 0 for more than "
                    f"{1 - INDEX_OK_FRACTION:.0%} of the time"
                )
            rows.append(
                {
                    "target": target.name,
                    "entry": i,
                    "episodes": g["episodes"],
                    "success_rate": g["success_rate"],
                    "required_success_rate": target.success_rate,
                    "mean_speed_success": speed,
                    "required_speed": min_speed,
                    "successes_index_ok": g["successes_index_ok"],
                    "successes": g["successes"],
                    "passed": not why,
                    "why_not": "; ".join(why) or None,
                }
            )
    return rows


COMMAND_TERRAIN = ("rough", {"amplitude": 0.05})
"""The terrain the commanded-walking target is judged on: rough terrain of amplitude 0.05 m."""

COMMAND_TARGET = {"no_fall_rate": 0.95, "velocity_error": 0.03, "yaw_rate_error": 0.05}
"""Commanded walking (entries with a ``command`` on :data:`COMMAND_TERRAIN`, all together): at least this
fraction of episodes without a fall (nor leaving the terrain), at most this mean ``velocity_error`` (m/s)
and mean ``yaw_rate_error`` (rad/s) over the episodes."""

COURSE_TARGET = 0.9
"""Waypoint courses (entries with ``waypoints``, all together): at least this fraction reach every waypoint."""


def check_command_targets(
    entries: Sequence[TerrainEntry], records: Sequence[Mapping[str, Any]]
) -> list[dict[str, Any]]:
    """The commanded-walking and course targets over the matching entries of the nominal world (all pooled).

    Each row: ``target``, ``entries`` (indices), ``episodes``, ``measured`` and ``required`` (dicts of the
    values above), ``passed`` and ``why_not``. Each entry must have >= ``MIN_SEEDS`` episodes.
    """
    kind, params = COMMAND_TERRAIN
    rows = []

    def nominal(e: TerrainEntry) -> bool:
        return e.randomization is None

    def on_terrain(e: TerrainEntry) -> bool:
        p = parse_terrain_spec(e.spec).params
        return e.kind == kind and all(p.get(k) == v for k, v in params.items())

    commanded = [
        i
        for i, e in enumerate(entries)
        if nominal(e) and e.command is not None and e.waypoints is None and on_terrain(e)
    ]
    course = [i for i, e in enumerate(entries) if nominal(e) and e.waypoints is not None]
    groups = [("commanded walking (rough 5 cm)", commanded), ("course (every waypoint reached)", course)]
    for name, idx in groups:
        eps = [r for r in records if r["entry"] in idx]
        if not eps:
            continue
        why = [
            f"entry {i}: {n} < {MIN_SEEDS} episodes"
            for i in idx
            if (n := sum(r["entry"] == i for r in eps)) < MIN_SEEDS
        ]
        n = len(eps)
        if name.startswith("commanded"):
            no_fall = sum(r["end_reason"] not in ("fall", "diverged", "left_terrain", "error") for r in eps) / n
            v = [r["velocity_error"] for r in eps if r.get("velocity_error") is not None]
            y = [r["yaw_rate_error"] for r in eps if r.get("yaw_rate_error") is not None]
            measured = {
                "no_fall_rate": no_fall,
                "velocity_error": sum(v) / len(v) if v else None,
                "yaw_rate_error": sum(y) / len(y) if y else None,
            }
            required = dict(COMMAND_TARGET)
            if no_fall < required["no_fall_rate"]:
                why.append(f"no-fall rate {no_fall:.0%} < {required['no_fall_rate']:.0%}")
            for key, unit in (("velocity_error", "m/s"), ("yaw_rate_error", "rad/s")):
                if measured[key] is None or measured[key] > required[key]:
                    why.append(f"mean {key} {_round(measured[key])} {unit} > {required[key]} {unit}")
        else:
            rate = sum(bool(r["success"]) for r in eps) / n
            measured, required = {"success_rate": rate}, {"success_rate": COURSE_TARGET}
            if rate < COURSE_TARGET:
                why.append(f"success rate {rate:.0%} < {COURSE_TARGET:.0%}")
        rows.append(
            {
                "target": name,
                "entries": idx,
                "episodes": n,
                "measured": measured,
                "required": required,
                "passed": not why,
                "why_not": "; ".join(why) or None,
            }
        )
    return rows


def _round(v: float | None) -> float | None:
    return None if v is None else round(v, 4)
