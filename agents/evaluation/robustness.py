"""Robustness curves (``quad-uneven robustness``): sweep one factor of the simulated world, the rest nominal.

For each value of the factor, every seed runs one episode of the policy on one terrain through the
evaluation machinery (:func:`agents.evaluation.run.evaluate`: one suite entry per value, its
``randomization`` fixing the factor at that value, a range ``[v, v]``); the curve is the success rate
and the mean stability index against the value.

Typical use::

    quad-uneven robustness --factor friction --out out/robust --workers 2 --seeds 5

writes ``DIR/robustness_friction.json`` (the numbers), ``DIR/robustness_friction.png`` (the curves) and
the evaluation itself under ``DIR/friction/`` (results.json, report.md: one suite entry per value).
Factors, values and units: :data:`FACTORS`; docs/robustness.md shows the expert's curves.

On another robot (``robot=``, ``--robot``) the sweep runs at the robot's scale: the terrain and goal magnified by its
leg length (the suite's ``scale: leg_length``) and the values read as the randomization presets' are, written for the
paper's robot and scaled by dynamic similarity (``scale: robot``: payload x mass ratio, impulse x m sqrt(s); friction,
motor strength and latency as written).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from agents.evaluation.metrics import json_safe
from agents.evaluation.run import evaluate
from agents.evaluation.suites import Suite, suite_from_dict
from agents.outputs import output_dir, write_json_atomic
from agents.plotting import pyplot, save
from quad_uneven_env.fields import excerpt


@dataclasses.dataclass(frozen=True)
class Factor:
    """One factor of the simulated world a robustness sweep varies."""

    name: str
    """the ``--factor`` name."""
    label: str
    """axis label with its unit."""
    values: tuple[float, ...]
    """default sweep values (in the unit of ``label``); the first is the nominal world."""
    randomization: Callable[[float], dict[str, Any]]
    """the env's ``randomization`` mapping that fixes the factor at a value."""


def _push(impulse: float) -> dict[str, Any]:
    # Pushes every 4-6 s (the `robust` suites' interval), 0.1 s long, in a uniform random direction.
    return {"push_impulse": [impulse, impulse], "push_interval": [4.0, 6.0], "push_duration": [0.1, 0.1]}


PAYLOAD_COM_X = 0.05
"""m: the payload of the ``payload`` sweep sits this far ahead of the trunk's centre of mass."""

FACTORS: dict[str, Factor] = {
    f.name: f
    for f in (
        Factor(
            "friction",
            "ground friction coefficient (-)",
            (1.0, 0.8, 0.6, 0.5, 0.45, 0.4, 0.35, 0.3),
            lambda v: {"friction": [v, v]},
        ),
        Factor(
            "payload",
            f"trunk payload (kg), {PAYLOAD_COM_X * 100:.0f} cm ahead of the trunk COM",
            (0.0, 5.0, 10.0, 15.0, 20.0, 25.0),
            lambda v: {"payload_mass": [v, v], "payload_com_x": [PAYLOAD_COM_X, PAYLOAD_COM_X]},
        ),
        Factor("push", "push impulse (N s), every 4-6 s for 0.1 s", (0.0, 5.0, 10.0, 15.0, 20.0, 25.0, 30.0), _push),
        Factor(
            "motor_strength",
            "motor strength (-): every joint's torque gain, saturated at its motor limit",
            (1.0, 0.9, 0.8, 0.7, 0.6, 0.5),
            lambda v: {"motor_strength": [v, v]},
        ),
        Factor(
            "latency",
            "actuation latency (ms)",
            (0.0, 2.0, 4.0, 6.0, 8.0, 10.0),
            lambda v: {"latency": [v / 1e3, v / 1e3]},
        ),
    )
}
"""The factors of ``quad-uneven robustness --factor``, by name."""

DEFAULT_TERRAIN: dict[str, Any] = {"kind": "rough", "params": {"amplitude": 0.05, "wavelength": 0.6}}
"""Terrain of the sweeps: rough, 5 cm (the `robust` suite's rough entry)."""


def robustness_sweep(
    factor: str,
    out: str | Path,
    values: Sequence[float] | None = None,
    seeds: int = 5,
    workers: int = 1,
    policy: str = "expert",
    terrain: Mapping[str, Any] | None = None,
    goal_distance: float = 3.0,
    time_limit: float = 60.0,
    expert_config: Mapping[str, Any] | None = None,
    robot: str | None = None,
    progress: bool = True,
) -> dict[str, Any]:
    """Sweep ``factor`` over ``values``; write ``out/robustness_<factor>.json`` and ``.png``; return the JSON content.

    :param factor: a key of :data:`FACTORS` (``friction``, ``payload``, ``push``, ``latency``).
    :param values: the factor's values in its unit (None: ``FACTORS[factor].values``).
    :param seeds: episodes per value (seeds 0 .. seeds - 1: the same terrains for every value).
    :param terrain: ``{"kind": ..., "params": {...}}`` (None: :data:`DEFAULT_TERRAIN`).
    :param goal_distance: m along +x that make an episode a success; ``time_limit`` s per episode.
    :param expert_config: fields of :class:`agents.expert.ExpertConfig` (e.g. ``{"model": "oracle"}``).
    :param robot: the env's ``robot`` (a shipped name or a robot YAML path; None: the paper's robot). Given, the
        terrain and goal are magnified to the robot (``goal_distance`` then reads in paper-robot metres) and the
        values are the paper robot's, scaled like the presets' (``scale: robot``).
    :raises ValueError: on an unknown factor, no values, ``seeds`` < 1, or what :func:`evaluate` rejects.
    """
    if factor not in FACTORS:
        raise ValueError(f"factor must be one of {list(FACTORS)}, got {excerpt(factor)}")
    f = FACTORS[factor]
    values = tuple(float(v) for v in (f.values if values is None else values))
    if not values:
        raise ValueError("values must not be empty")
    if not (isinstance(seeds, int) and seeds >= 1):
        raise ValueError(f"seeds must be an integer >= 1, got {excerpt(seeds)}")
    terrain = dict(terrain or DEFAULT_TERRAIN)
    out = Path(out)
    randomizations = [f.randomization(v) for v in values]
    if robot is not None:
        randomizations = [{"scale": "robot", **r} for r in randomizations]
    entry = {"kind": terrain["kind"], "params": dict(terrain.get("params", {})), "seeds": list(range(seeds))}
    raw_suite = {
        "name": f"robustness-{factor}",
        "goal_distance": goal_distance,
        "time_limit": time_limit,
        "terrains": [{**entry, "randomization": r} for r in randomizations],
    }
    if robot is not None:
        raw_suite["scale"] = "leg_length"
    suite = suite_from_dict(raw_suite, source=f"robustness {factor}")
    with output_dir(out, "robustness", keep=True) as manifest:
        out = manifest.out
        return _sweep(factor, out, suite, values, randomizations, seeds, workers, policy, terrain, goal_distance,
                      expert_config, robot, progress)  # fmt: skip


def _sweep(
    factor: str,
    out: Path,
    suite: Suite,
    values: Sequence[float],
    randomizations: Sequence[Mapping[str, Any]],
    seeds: int,
    workers: int,
    policy: str,
    terrain: Mapping[str, Any],
    goal_distance: float,
    expert_config: Mapping[str, Any] | None,
    robot: str | None,
    progress: bool,
) -> dict[str, Any]:
    """The evaluation and the files of :func:`robustness_sweep` (its arguments checked, ``out`` prepared)."""
    f = FACTORS[factor]
    # One evaluation, one entry per value: the workers start (and compile the controller) once.
    env_kwargs = None if robot is None else {"robot": robot}
    results = evaluate(suite, policy, out / factor, workers=workers, env_kwargs=env_kwargs,
                       expert_config=expert_config, progress=progress)  # fmt: skip
    points = []
    for i, (v, randomization) in enumerate(zip(values, randomizations, strict=True)):
        group = results["summary"]["by_entry"][i]
        episodes = [e for e in results["episodes"] if e["entry"] == i]
        points.append(
            {
                "value": v,
                "randomization": randomization,
                "episodes": group["episodes"],
                "successes": group["successes"],
                "success_rate": group["success_rate"],
                "mean_stability_index": group["mean_stability_index"],
                "mean_distance": group["mean_distance"],
                "errors": sum(1 for e in episodes if e["error"]),
                "diverged": sum(1 for e in episodes if e["end_reason"] == "diverged"),
                "end_reasons": group["end_reasons"],
            }
        )
    summary = json_safe(
        {
            "factor": factor,
            "label": f.label,
            "policy": policy,
            "expert_model": results["meta"].get("expert_model"),
            "expert_config": dict(expert_config or {}),
            "robot": robot,
            "terrain": terrain,
            "goal_distance": goal_distance,
            "seeds": seeds,
            "points": points,
        }
    )
    write_json_atomic(out / f"robustness_{factor}.json", summary)
    plot_robustness(summary, out / f"robustness_{factor}.png")
    return summary


def plot_robustness(summary: Mapping[str, Any], path: Path) -> Path:
    """Success rate (%) and mean stability index (N m) against the factor's value, from a sweep's JSON content."""
    plt = pyplot()
    pts = summary["points"]
    x = np.array([p["value"] for p in pts])
    rate = np.array([100.0 * (p["success_rate"] or 0.0) for p in pts])
    index = np.array([np.nan if p["mean_stability_index"] is None else p["mean_stability_index"] for p in pts])
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(9.0, 3.6))
    ax1.plot(x, rate, "o-", color="tab:blue")
    ax1.axhline(90.0, color="0.5", ls="--", lw=0.8)
    ax1.set_ylim(-5, 105)
    ax1.set_ylabel("success rate (%)")
    ax2.plot(x, index, "o-", color="tab:green")
    ax2.axhline(0.0, color="0.5", ls="--", lw=0.8)
    ax2.set_ylabel("mean stability index (N m)")
    for ax in (ax1, ax2):
        ax.set_xlabel(summary["label"])
        ax.grid(alpha=0.3)
    model = summary.get("expert_model")
    robot = summary.get("robot")
    fig.suptitle(
        f"{summary['policy']}{f' ({model[0]} model)' if model else ''}{f', {robot}' if robot else ''}: "
        f"{summary['terrain']['kind']}, "
        f"{summary['goal_distance']:g} m goal, {summary['seeds']} seeds per value",
        fontsize=10,
    )
    return save(fig, path)
