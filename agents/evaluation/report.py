"""report.md and its PNG plots for an evaluation (tables per terrain kind and entry, episodes, failures)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from agents.evaluation.episode import EpisodeResult
from agents.evaluation.metrics import commanded_path
from agents.evaluation.plots import (
    plot_commanded_paths,
    plot_distance_per_episode,
    plot_stability_over_time,
    plot_terrain_paths,
)

MAX_STABILITY_PANELS = 6
"""At most this many episodes (the first of each terrain entry) in the stability plot."""

END_REASON_TEXT = {
    "time_limit": "time limit reached short of the goal",
    "wall_time_limit": "wall-clock limit of the episode reached short of the goal",
}
"""Wording of the failures that have no fall reason."""


def _f(value: Any, fmt: str = ".3g") -> str:
    if value is None:
        return "–"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return format(value, fmt)
    return str(value)


def _reasons(reasons: Mapping[str, int]) -> str:
    return "; ".join(f"{k} ×{v}" for k, v in sorted(reasons.items(), key=lambda kv: -kv[1])) or "–"


GROUP_HEADER = (
    "| episodes | success rate | mean distance (m) | mean speed (m/s) | min index (N m) | mean index (N m) "
    "| mean time index < 0 (s) | successes with index >= 0 for >= 99% of the time | mean CoT | end reasons |"
)


def _group_row(g: Mapping[str, Any]) -> str:
    cells = [
        str(g["episodes"]),
        f"{g['success_rate']:.0%} ({g['successes']})" if g["success_rate"] is not None else "–",
        _f(g["mean_distance"]),
        _f(g["mean_speed"]),
        _f(g["min_stability_index"]),
        _f(g["mean_stability_index"]),
        _f(g["mean_time_index_negative"]),
        f"{g['successes_index_ok']} / {g['successes']}",
        _f(g["mean_cost_of_transport"]),
        _reasons(g["end_reasons"]),
    ]
    return "| " + " | ".join(cells) + " |"


def _tables(summary: Mapping[str, Any]) -> list[str]:
    sep = "|" + "---|" * (GROUP_HEADER.count("|"))
    lines = ["## By terrain kind", "", "| kind " + GROUP_HEADER, sep]
    lines += [f"| {k} " + _group_row(g) for k, g in summary["by_kind"].items()]
    lines += ["| **all** " + _group_row(summary["overall"]), "", "## By terrain entry", ""]
    lines += ["| entry " + GROUP_HEADER, sep]
    lines += [f"| [{g['entry']}] {g['label']} " + _group_row(g) for g in summary["by_entry"]]
    return [*lines, ""]


def _factor_table(rows: Sequence[Mapping[str, Any]]) -> list[str]:
    """By randomization factor: one line per bin of each factor's drawn values (success, mean index)."""
    if not rows:
        return []
    head = "| factor | bin | drawn values | episodes | success rate | mean index (N m) | end reasons |"
    lines = [
        "## By randomization factor",
        "",
        "Randomized episodes binned by each factor's drawn value (`agents.evaluation.metrics.factor_bins`: fixed "
        "edges for friction, payload (kg), motor strength, latency (s) and the largest push (N s); thirds of the "
        "values for the others). Motor strength: the weakest joint; damping and frictionloss: the mean over the "
        "joints; pushes: the count and the largest impulse of those received, so an episode that falls early "
        "counts few.",
        "",
        head,
        "|" + "---|" * (head.count("|") - 1),
    ]
    for g in rows:
        cells = [
            g["factor"],
            g.get("bin", "–"),
            f"{g['low']:.3g}–{g['high']:.3g}",
            str(g["episodes"]),
            f"{g['success_rate']:.0%} ({g['successes']})",
            _f(g["mean_stability_index"]),
            _reasons(g["end_reasons"]),
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return [*lines, ""]


def _episode_table(records: Sequence[Mapping[str, Any]]) -> list[str]:
    head = (
        "| # | entry | seed | success | distance (m) | sim time (s) | speed (m/s) | min index (N m) "
        "| time index < 0 (s) | CoT | planner ms median / p95 | end | end COG (x, y, z) m | phase |"
    )
    lines = ["## Episodes", "", head, "|" + "---|" * (head.count("|") - 1)]
    for r in records:
        pos = ", ".join(f"{v:.2f}" for v in r["end_position"])
        cells = [
            str(r["index"]),
            str(r["entry"]),
            str(r["seed"]),
            _f(r["success"]),
            _f(r["distance"]),
            _f(r["sim_time"]),
            _f(r["mean_speed"]),
            _f(r["min_stability_index"]),
            _f(r["time_index_negative"]),
            _f(r["cost_of_transport"]),
            f"{_f(r['planner_ms_median'])} / {_f(r['planner_ms_p95'])}",
            r["end_reason"],
            pos,
            _f(r["end_phase"]),
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return [*lines, ""]


def _targets(rows: Sequence[Mapping[str, Any]]) -> list[str]:
    if not rows:
        return []
    head = (
        "| target | entry | episodes | success rate (required) | mean speed of successes, m/s (required) | "
        "successes with index >= 0 for >= 99% of the time | passed | why not |"
    )
    lines = ["## Targets", "", head, "|" + "---|" * (head.count("|") - 1)]
    for r in rows:
        cells = [
            r["target"],
            str(r["entry"]),
            str(r["episodes"]),
            f"{r['success_rate']:.0%} ({r['required_success_rate']:.0%})",
            f"{_f(r['mean_speed_success'])} ({_f(r['required_speed'])})",
            f"{r['successes_index_ok']} / {r['successes']}",
            "**yes**" if r["passed"] else "**no**",
            _f(r["why_not"]),
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return [*lines, ""]


COMMAND_HEADER = (
    "| entry | episodes | falls | success rate | velocity error, episode (m/s) | velocity error, "
    "5 s windows (m/s) | velocity RMSE, per step (m/s) | yaw-rate error (rad/s) | heading error, RMS (rad) |"
)


def _command_tables(summary: Mapping[str, Any], targets: Sequence[Mapping[str, Any]]) -> list[str]:
    """The command-tracking table per entry with a command (means over its episodes) and the command targets."""
    rows = [g for g in summary["by_entry"] if g.get("mean_velocity_error") is not None]
    if not rows:
        return []
    lines = [
        "## Command tracking",
        "",
        "Means over each entry's episodes (definitions: docs/commands.md, *Evaluation*): the velocity errors "
        "compare the COG with the path the command asks for from the measured heading; the yaw-rate error is "
        "the error of the episode's mean yaw rate; the heading error is the RMS of the measured minus the "
        "integrated commanded heading.",
        "",
        COMMAND_HEADER,
        "|" + "---|" * (COMMAND_HEADER.count("|") - 1),
    ]
    for g in rows:
        cells = [
            f"[{g['entry']}] {g['label']}",
            str(g["episodes"]),
            str(g["falls"]),
            f"{g['success_rate']:.0%}",
            _f(g["mean_velocity_error"]),
            _f(g["mean_velocity_error_window"]),
            _f(g["mean_velocity_rmse"]),
            _f(g["mean_yaw_rate_error"]),
            _f(g["mean_heading_error"]),
        ]
        lines.append("| " + " | ".join(cells) + " |")
    lines.append("")
    if targets:
        head = "| target | entries | episodes | measured | required | passed | why not |"
        lines += [head, "|" + "---|" * (head.count("|") - 1)]
        for t in targets:
            measured = ", ".join(f"{k} {_f(v)}" for k, v in t["measured"].items())
            required = ", ".join(f"{k} {v}" for k, v in t["required"].items())
            cells = [t["target"], ", ".join(map(str, t["entries"])), str(t["episodes"]), measured, required,
                     "**yes**" if t["passed"] else "**no**", _f(t["why_not"])]  # fmt: skip
            lines.append("| " + " | ".join(cells) + " |")
        lines.append("")
    return lines


def _command_plot(e: EpisodeResult, title: str, png: Path) -> Path:
    """The commanded and the measured path of an entry's first episode over its terrain."""
    tr, t = e.trace, e.terrain
    cmd = np.asarray(tr["command"], dtype=float).reshape(-1, 3)
    n = len(cmd)
    times = np.asarray(tr["time"], dtype=float)
    dt = float(times[1] - times[0]) if len(times) > 1 else 0.02
    cog = np.asarray(tr["cog"], dtype=float)[: n + 1, :2]
    path, _ = commanded_path(dt, cog[0], np.asarray(tr["yaw"], dtype=float)[: n + 1], cmd)
    panel: dict[str, Any] = {"cog": cog, "commanded": path, "label": f"seed {e.record['seed']}"}
    if "waypoints" in tr:
        panel["waypoints"] = np.asarray(tr["waypoints"])
        panel["radius"] = float(tr["waypoint_radius"])
    return plot_commanded_paths([panel], t["heights"], t["origin"], t["cell_size"], title, png)


def _failures(records: Sequence[Mapping[str, Any]], labels: Sequence[str]) -> list[str]:
    failed = [r for r in records if not r["success"]]
    lines = ["## Failures", ""]
    if not failed:
        return [*lines, "Every episode reached the goal.", ""]
    for r in failed:
        x, y, z = r["end_position"]
        how = r["fall_reason"] or END_REASON_TEXT.get(r["end_reason"], r["end_reason"])
        lines.append(
            f"- episode {r['index']} ([{r['entry']}] {labels[r['entry']]}, seed {r['seed']}): **{how}** at "
            f"t = {r['sim_time']:.2f} s, COG at x = {x:.2f} m (distance {r['distance']:.2f} m), y = {y:.2f} m, "
            f"z = {z:.2f} m; feet in contact: {', '.join(r['end_stance']) or 'none'}; "
            f"policy phase: {_f(r['end_phase'])}"
        )
        log = r.get("failure_log") or []
        if log:
            lines.append(f"  - policy failure log ({r['failure_count']} entries), last: " + " | ".join(log[-3:]))
    return [*lines, ""]


def write_report(
    results: Mapping[str, Any], episodes: Sequence[EpisodeResult], labels: Sequence[str], out: Path
) -> Path:
    """Write ``out/report.md`` and its PNGs (distance per episode, stability over time, paths over terrain)."""
    records = results["episodes"]
    meta = results["meta"]
    distance_png = plot_distance_per_episode(records, meta["goal_distance"], labels, out / "distance.png")
    plots = [("Distance per episode", distance_png)]
    firsts = [e for e in episodes if e.terrain is not None]
    traces = [
        (
            f"episode {e.record['index']}: [{e.record['entry']}] {labels[e.record['entry']]}, seed {e.record['seed']}",
            e.trace["time"],
            e.trace["index"],
        )
        for e in firsts[:MAX_STABILITY_PANELS]
    ]
    if traces:
        plots.append(("Measured stability index over time", plot_stability_over_time(traces, out / "stability.png")))
    for e in firsts:
        r, t = e.record, e.terrain
        title = f"[{r['entry']}] {labels[r['entry']]}, seed {r['seed']}"
        png = out / f"paths_entry{r['entry']}.png"
        tr = e.trace
        plot_terrain_paths(
            tr["cog"], tr["feet"], t["heights"], t["origin"], t["cell_size"], title, png, contact=tr["contact"]
        )
        plots.append((f"COG and foot paths over the terrain: {title}", png))
        if "command" in tr and len(tr["command"]):
            png = _command_plot(e, title, out / f"command_entry{r['entry']}.png")
            plots.append((f"Commanded and measured path: {title}", png))

    lines = [
        f"# Evaluation: suite `{results['suite']}`, policy `{results['policy']}`",
        "",
        f"Goal {meta['goal_distance']} m along +x within {meta['time_limit']} s of simulated time; "
        f"{len(records)} episodes (seed offset {meta['seed_offset']}, at most {_f(meta['episodes_per_entry'])} "
        f"per entry); suite file `{meta['suite_file']}`.",
        "",
        "Success = the COG travelled the goal distance before any fall and within the time limit. Stability "
        "index (N m) as measured by the environment every control step; min and mean are over steps with at "
        "least 3 feet in contact, while *time index < 0* also counts steps with fewer than 3 feet (index -inf). "
        "CoT = sum |tau . qd| dt / (m g distance), sampled every control step.",
        "",
        *_targets(results.get("targets", [])),
        *_tables(results["summary"]),
        *_factor_table(results["summary"].get("by_factor", [])),
        *_command_tables(results["summary"], results.get("command_targets", [])),
        *_failures(records, labels),
        *_episode_table(records),
        "## Plots",
        "",
    ]
    for title, png in plots:
        lines += [f"### {title}", "", f"![{title}]({png.name})", ""]
    videos = [r["video"] for r in records if r["video"]]
    if videos:
        lines += ["## Videos", "", *[f"- [{v}](videos/{v})" for v in videos], ""]
    path = out / "report.md"
    path.write_text("\n".join(lines))
    return path
