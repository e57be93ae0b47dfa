"""Episode metrics and their per-terrain summary (pure functions of recorded arrays; JSON-safe output)."""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np

from quad_uneven_env.constants import JOINT_KINDS

INDEX_OK_FRACTION = 0.99
"""A success 'keeps the index non-negative' when index >= 0 for at least this fraction of its time."""


def json_safe(value: Any) -> Any:
    """``value`` with numpy scalars/arrays turned into Python ones and NaN/Inf into None (valid strict JSON)."""
    if isinstance(value, Mapping):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    if isinstance(value, np.ndarray):
        return [json_safe(v) for v in value.tolist()]
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        v = float(value)
        return v if math.isfinite(v) else None
    return value


def cost_of_transport(work: float, mass: float, g: float, distance: float) -> float | None:
    """Mechanical cost of transport ``work / (m g distance)`` (dimensionless); None unless distance > 0.

    :param work: sum over time of |tau . qd| dt (J), the absolute joint power integrated.
    :param mass: kg. :param g: m/s^2. :param distance: m travelled along +x.
    """
    if not distance > 0.0 or not math.isfinite(work):
        return None
    return work / (mass * g * distance)


def stability_metrics(index: np.ndarray, dt: float) -> dict[str, float | None]:
    """Summary of the measured stability index (N m) sampled every ``dt`` s.

    ``-inf`` (fewer than 3 feet in contact: no support polygon) counts as negative in
    ``time_index_negative`` and is left out of the min and mean, which are over the steps with a
    support polygon (None if there is none).
    """
    index = np.asarray(index, dtype=float)
    finite = index[np.isfinite(index)]
    negative = int(np.count_nonzero(~(index >= 0.0)))  # -inf and NaN count as negative
    n = index.size
    return {
        "min_stability_index": float(finite.min()) if finite.size else None,
        "mean_stability_index": float(finite.mean()) if finite.size else None,
        "time_index_negative": negative * dt,
        "time_fewer_than_3_feet": int(np.count_nonzero(np.isneginf(index))) * dt,
        "fraction_index_nonnegative": (1.0 - negative / n) if n else None,
    }


TRACKING_WINDOW = 5.0
"""s: length of the consecutive windows of ``velocity_error_window`` (see :func:`command_metrics`)."""

COMMAND_METRICS: tuple[str, ...] = (
    "velocity_error", "velocity_error_window", "velocity_rmse", "yaw_rate_error", "heading_error",
)  # fmt: skip
"""The command-tracking fields of an episode record (None without a command)."""


def commanded_path(dt: float, xy0: np.ndarray, yaw: np.ndarray, commands: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The path the command asks for: positions (N + 1, 2) (m, world) and headings (N + 1,) (rad).

    Step k (1..N) of ``dt`` s starts at the measured heading ``yaw[k - 1]`` and moves by ``dt`` times the
    command ``commands[k - 1] = (vx, vy, yaw_rate)`` in effect during it, its (vx, vy) turned by that heading into
    the world frame; the commanded heading starts at ``yaw[0]`` and integrates the commanded yaw rate.

    :param xy0: (2,) start position (m). :param yaw: (N + 1,) measured (unwrapped) headings (rad).
    """
    c, s = np.cos(yaw[:-1]), np.sin(yaw[:-1])
    v = np.column_stack([c * commands[:, 0] - s * commands[:, 1], s * commands[:, 0] + c * commands[:, 1]])
    path = np.vstack([np.asarray(xy0, dtype=float)[None], xy0 + np.cumsum(dt * v, axis=0)])
    heading = yaw[0] + np.concatenate([[0.0], np.cumsum(dt * commands[:, 2])])
    return path, heading


def command_metrics(dt: float, xy: np.ndarray, yaw: np.ndarray, commands: np.ndarray) -> dict[str, float | None]:
    """How well an episode followed its command (all None when it has no step).

    :param dt: control step (s). :param xy: (N + 1, 2) measured COG positions (m, world) at reset and after
        every step. :param yaw: (N + 1,) measured trunk headings (rad, unwrapped). :param commands: (N, 3) the
        command in effect during each step (vx, vy m/s, yaw rate rad/s, yaw-aligned base frame).
    :return: with ``d = xy - commanded_path`` (m) (:func:`commanded_path`) and ``T = N dt``:

        - ``velocity_error`` (m/s): ``|d[N]| / T``, the error of the episode's mean velocity;
        - ``velocity_error_window`` (m/s): the mean over consecutive windows of :data:`TRACKING_WINDOW` s (a
          shorter last one dropped unless it is the only one) of each window's ``|d[end] - d[start]|`` over its
          length: the error of the mean velocity over a few seconds (errors cannot cancel over the episode);
        - ``velocity_rmse`` (m/s): the RMS over the steps of the step's mean velocity (its displacement over
          ``dt``) minus its command, in the world frame: what a per-step tracking reward sees, including the
          start-stop of a crawl within its gait cycle;
        - ``yaw_rate_error`` (rad/s): ``|(yaw[N] - yaw[0]) - integral of the commanded yaw rate| / T``;
        - ``heading_error`` (rad): the RMS over the steps of the measured minus the commanded heading.
    """
    xy, yaw, commands = (np.asarray(a, dtype=float) for a in (xy, yaw, commands))
    n = len(commands)
    if n == 0:
        return dict.fromkeys(COMMAND_METRICS)
    path, heading = commanded_path(dt, xy[0], yaw, commands)
    d = xy - path
    T = n * dt
    w = max(1, round(TRACKING_WINDOW / dt))
    ends = list(range(w, n + 1, w)) or [n]
    windows = [np.linalg.norm(d[b] - d[b - min(w, b)]) / (min(w, b) * dt) for b in ends]
    step_err = np.diff(d, axis=0) / dt
    return {
        "velocity_error": float(np.linalg.norm(d[-1]) / T),
        "velocity_error_window": float(np.mean(windows)),
        "velocity_rmse": float(np.sqrt(np.mean(np.sum(step_err**2, axis=1)))),
        "yaw_rate_error": float(abs((yaw[-1] - yaw[0]) - (heading[-1] - heading[0])) / T),
        "heading_error": float(np.sqrt(np.mean((yaw[1:] - heading[1:]) ** 2))),
    }


def torque_peak_fractions(peak_torque: np.ndarray, torque_limit: np.ndarray, strength: np.ndarray) -> dict[str, float]:
    """-: per joint type, the largest applied torque over its available torque, the worst of the four legs.

    :param peak_torque: (12,) N m, the largest |applied torque| of each joint over an episode (leg-major order).
    :param torque_limit: (12,) N m, the nominal motor limits.
    :param strength: (12,) -, each motor's torque factor (randomized motor strength; 1 nominal); a motor above 1
        still saturates at the nominal limit, so its available torque is ``min(strength, 1) x limit``.
    :returns: ``{"HAA": f, "HFE": f, "KFE": f}``, 1 where a motor gave all it had.
    """
    available = np.asarray(torque_limit, dtype=float) * np.minimum(np.asarray(strength, dtype=float), 1.0)
    fraction = (np.abs(np.asarray(peak_torque, dtype=float)) / available).reshape(4, 3).max(axis=0)
    return {name: float(f) for name, f in zip(JOINT_KINDS, fraction, strict=True)}


def timing_metrics(times_ms: Sequence[float] | None) -> dict[str, float | None]:
    """Median and 95th percentile (ms) of the policy's planner times; None if it exposes none."""
    if times_ms is None or len(times_ms) == 0:
        return {"planner_ms_median": None, "planner_ms_p95": None, "planner_calls": 0 if times_ms is not None else None}
    t = np.asarray(times_ms, dtype=float)
    return {
        "planner_ms_median": float(np.median(t)),
        "planner_ms_p95": float(np.percentile(t, 95)),
        "planner_calls": int(t.size),
    }


def reason_category(reason: str | None) -> str | None:
    """A fall reason with its numbers replaced by ``#``, so that like reasons count together."""
    if reason is None:
        return None
    return re.sub(r"-?\d+(\.\d+)?(e-?\d+)?", "#", reason)


def _mean(values: Iterable[float | None]) -> float | None:
    v = [x for x in values if x is not None]
    return float(np.mean(v)) if v else None


def _min(values: Iterable[float | None]) -> float | None:
    v = [x for x in values if x is not None]
    return float(min(v)) if v else None


def group_summary(episodes: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """Success rate and means over ``episodes`` (records of :func:`agents.evaluation.episode.run_task`).

    ``min_stability_index`` is the minimum over episodes, the other ``mean_*`` the mean of the episodes'
    values (episodes with None left out); ``mean_speed_success`` is over successes only;
    ``successes_index_ok`` counts successes whose index was >= 0 for >= 99% of their time; ``falls`` counts the
    episodes that fell (or diverged); ``mean_<m>`` of every :data:`COMMAND_METRICS` field is over the episodes
    with a command (None if none has one).
    """
    n = len(episodes)
    successes = [e for e in episodes if e["success"]]
    reasons: dict[str, int] = {}
    for e in episodes:
        key = reason_category(e["fall_reason"]) if e["fall_reason"] else None
        if key is None and not e["success"]:
            key = e.get("end_reason") or "unknown"
        if key is not None:
            reasons[key] = reasons.get(key, 0) + 1
    ok = [e for e in successes if (e["fraction_index_nonnegative"] or 0.0) >= INDEX_OK_FRACTION]
    return {
        "episodes": n,
        "successes": len(successes),
        "success_rate": len(successes) / n if n else None,
        "mean_distance": _mean(e["distance"] for e in episodes),
        "mean_speed": _mean(e["mean_speed"] for e in episodes),
        "mean_speed_success": _mean(e["mean_speed"] for e in successes),
        "mean_sim_time": _mean(e["sim_time"] for e in episodes),
        "min_stability_index": _min(e["min_stability_index"] for e in episodes),
        "mean_stability_index": _mean(e["mean_stability_index"] for e in episodes),
        "mean_time_index_negative": _mean(e["time_index_negative"] for e in episodes),
        "mean_cost_of_transport": _mean(e["cost_of_transport"] for e in episodes),
        "successes_index_ok": len(ok),
        "planner_ms_median": _mean(e["planner_ms_median"] for e in episodes),
        "planner_ms_p95": _max_or_none(e["planner_ms_p95"] for e in episodes),
        "end_reasons": reasons,
        "falls": sum(e.get("end_reason") in ("fall", "diverged") for e in episodes),
        **{f"mean_{m}": _mean(e.get(m) for e in episodes) for m in COMMAND_METRICS},
    }


def _max_or_none(values: Iterable[float | None]) -> float | None:
    v = [x for x in values if x is not None]
    return float(max(v)) if v else None


def summarize(episodes: Sequence[Mapping[str, Any]], entry_labels: Sequence[str]) -> dict[str, Any]:
    """``{"by_kind": {kind: group}, "by_entry": [group + label], "overall": group}`` (see :func:`group_summary`)."""
    kinds: dict[str, list[Mapping[str, Any]]] = {}
    for e in episodes:
        kinds.setdefault(e["terrain"], []).append(e)
    by_entry = []
    for i, label in enumerate(entry_labels):
        group = [e for e in episodes if e["entry"] == i]
        if group:
            by_entry.append({"entry": i, "label": label, **group_summary(group)})
    return {
        "by_kind": {k: group_summary(v) for k, v in kinds.items()},
        "by_entry": by_entry,
        "overall": group_summary(episodes),
    }


FACTOR_BINS = 3
"""A factor without :data:`FACTOR_EDGES` is split into this many groups of (nearly) equal size by value."""

FACTOR_EDGES: dict[str, tuple[float, ...]] = {
    "friction": (0.35, 0.45, 0.6, 0.8, 1.0),
    "payload_mass": (5.0, 10.0, 15.0, 20.0),
    "motor_strength_min": (0.6, 0.7, 0.75, 0.8, 0.9),
    "latency": (0.003, 0.007),
    "push_impulse_max": (10.0, 20.0),
}
"""Fixed bin edges of the factors every report bins the same way (the unit of the factor: friction -, payload
kg, motor strength -, latency s, largest push N s), so that figures of different runs and seed sets line up:
a bin holds the values ``edges[k - 1] <= v < edges[k]``, the first everything below ``edges[0]``, the last
everything from ``edges[-1]`` on. The friction edges are values of ``quad-uneven robustness --factor friction``
(its sweep fixes the friction where these bins hold drawn ones); docs/robustness.md quotes the worlds below
0.45 as the slippery ones. The weakest of twelve motors drawn in ``[0.7, 1.3]`` (the
``hard`` preset) lies below 0.8 in 89 % of the worlds, hence the fine edges there."""


def factor_bins(factor: str, values: Sequence[float]) -> list[tuple[str, np.ndarray]]:
    """The groups of ``values`` (one factor's drawn values) a report shows: ``(label, indices)`` in value order,
    empty groups left out.

    A factor of :data:`FACTOR_EDGES` is cut at its edges (labels ``< 0.35``, ``0.35-0.45``, ``>= 1``); another
    with at most :data:`FACTOR_BINS` distinct values gets one group per value (label: the value); any other
    :data:`FACTOR_BINS` groups of (nearly) equal size in value order (label ``thirds k/3``).
    """
    v = np.asarray(values, dtype=float)
    edges = FACTOR_EDGES.get(factor)
    if edges is not None:
        which = np.searchsorted(np.asarray(edges), v, side="right")  # bin k: edges[k-1] <= v < edges[k]
        bins = []
        for k in range(len(edges) + 1):
            idx = np.flatnonzero(which == k)
            if idx.size:
                label = (
                    f"< {edges[0]:g}"
                    if k == 0
                    else f">= {edges[-1]:g}"
                    if k == len(edges)
                    else (f"{edges[k - 1]:g}-{edges[k]:g}")
                )
                bins.append((label, idx))
        return bins
    distinct = np.unique(v)
    if distinct.size <= FACTOR_BINS:
        return [(f"{d:g}", np.flatnonzero(v == d)) for d in distinct]
    parts = np.array_split(np.argsort(v, kind="stable"), FACTOR_BINS)
    return [(f"thirds {k + 1}/{FACTOR_BINS}", np.sort(g)) for k, g in enumerate(parts) if g.size]


def factor_summary(episodes: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Per randomization factor that varies over the randomized episodes: the episodes in groups by its value
    (:func:`factor_bins`), each with :func:`group_summary`, its ``bin`` label and its drawn ``low``/``high``.

    Uses each episode's ``factors`` (see :func:`quad_uneven_env.randomization.factor_values`); episodes without
    them (nominal world) are left out; a factor with one value only is skipped.
    """
    randomized = [e for e in episodes if e.get("factors")]
    rows: list[dict[str, Any]] = []
    for factor in dict.fromkeys(k for e in randomized for k in e["factors"]):
        values = np.array([float(e["factors"][factor]) for e in randomized])
        if np.unique(values).size == 1:
            continue
        for label, group in factor_bins(factor, values):
            rows.append(
                {
                    "factor": factor,
                    "bin": label,
                    "low": float(values[group].min()),
                    "high": float(values[group].max()),
                    **group_summary([randomized[i] for i in group]),
                }
            )
    return rows
