"""Training sweeps on Ray Tune (``quad-uneven sweep``): a grid or list of training runs, each evaluated on a suite.

Typical use::

    quad-uneven sweep --config configs/sweeps/example.yaml --out runs/sweep_example

The sweep file (:func:`load_sweep`; example: ``configs/sweeps/example.yaml``)::

    name: example
    config: null                  # base training config (null: configs/rl/<algo>_residual.yaml)
    base: {timesteps: 20000}      # TrainConfig fields of every run
    grid:                         # every combination is one run (or `runs:`, a list of field mappings)
      seed: [0, 1]
      residual_scale: [0.05, 0.1]
    evaluation: {suite: rough, episodes: 2, seed: 0}
    cpus_per_run: null            # Ray CPUs per run (null: its n_envs)

Each run is one Ray Tune trial doing exactly what ``quad-uneven train`` does
(:func:`agents.rl.training.train`) into ``DIR/runs/<name>/``; then every trained model is evaluated
(:func:`agents.evaluation.run.evaluate`, episodes as Ray tasks) into ``DIR/evals/<name>/``; the table
of both goes to ``DIR/summary.md``, ``summary.json``, ``summary.csv`` and ``summary.png`` (success rate
and mean stability index against the first swept field). Ray Tune's own state is in ``DIR/tune/``.
"""

from __future__ import annotations

import csv
import dataclasses
import itertools
import json
import math
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from agents.evaluation.metrics import json_safe
from agents.evaluation.ray_backend import import_tune, ray_session
from agents.evaluation.run import evaluate
from agents.evaluation.suites import SuiteError, load_suite
from agents.outputs import output_dir, write_json_atomic
from agents.plotting import pyplot, save
from agents.rl.config import TrainConfig, TrainConfigError, load_train_config, terrain_list, validate
from quad_uneven_env.config import read_yaml
from quad_uneven_env.fields import check_fields, clip, excerpt, from_mapping, param

__all__ = [
    "SWEEP_OUTPUTS",
    "Sweep",
    "SweepError",
    "SweepEvaluation",
    "SweepRun",
    "load_sweep",
    "plot_sweep",
    "run_sweep",
    "sweep_from_dict",
]

SWEEP_OUTPUTS = ("sweep.json", "runs", "evals", "tune", "summary.md", "summary.json", "summary.csv", "summary.png")
"""Top-level names a sweep writes in its ``--out`` (``--overwrite`` deletes what the manifest lists; with one of
these names present and no manifest, it refuses: :func:`agents.outputs.delete_recorded_outputs`)."""

SWEEP_KEYS = ("name", "config", "base", "grid", "runs", "evaluation", "cpus_per_run")
"""Top-level keys of a sweep file."""

TRAIN_FIGURES = ("timesteps", "wall_time", "steps_per_s", "episodes", "mean_return", "mean_stability_index",
                 "mean_distance", "fall_rate", "interrupted")  # fmt: skip
"""Figures of a run's ``train_summary.json`` copied into the summary (prefixed ``train_``)."""

EVAL_FIGURES = ("episodes", "successes", "success_rate", "mean_stability_index", "mean_distance")
"""Figures of a run's evaluation (``results.json`` summary, ``overall``) copied into the summary."""


class SweepError(ValueError):
    """An invalid sweep file; the message starts with the field (``grid.seed[1]``, ``evaluation.suite``, ...)."""


@dataclasses.dataclass(frozen=True)
class SweepEvaluation:
    """How every trained model of a sweep is evaluated."""

    suite: str = ""
    """shipped suite name or suite YAML path (required)."""
    episodes: int | None = param(None, kind="int", lo=1, none_ok=True)
    """at most this many seeds per terrain entry (null: all)."""
    seed: int = param(0, kind="int", lo=0)
    """offset added to every seed of the suite."""

    def __post_init__(self) -> None:
        check_fields(self, where="evaluation")
        if not isinstance(self.suite, str) or not self.suite:
            raise SweepError(f"evaluation.suite must be a suite name or YAML path, got {excerpt(self.suite)}")


@dataclasses.dataclass(frozen=True)
class SweepRun:
    """One training run of a sweep."""

    name: str
    """folder name under ``DIR/runs/`` and ``DIR/evals/``."""
    params: dict[str, Any]
    """the swept fields and their values of this run."""
    config: TrainConfig
    """the run's full, validated training config."""


@dataclasses.dataclass(frozen=True)
class Sweep:
    """A validated sweep file."""

    name: str
    """the sweep's name (title of the summary)."""
    source: str
    """where it was read from."""
    runs: tuple[SweepRun, ...]
    """the runs, in file order (grid: the product in key order, the last key fastest)."""
    swept: tuple[str, ...]
    """TrainConfig fields that vary over the runs (the summary's parameter columns; the plot's x is the first)."""
    evaluation: SweepEvaluation
    """how the models are evaluated."""
    cpus_per_run: float | None = None
    """Ray CPUs each run requests (None: its ``n_envs``; capped at the cluster's CPUs)."""


_FIELDS = [f.name for f in dataclasses.fields(TrainConfig)]
_NAME_OK = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._=+-]*$")


def _run_config(config: Any, base: Mapping[str, Any], overrides: Mapping[str, Any], where: str) -> TrainConfig:
    """The TrainConfig of ``config`` (a path or None) with ``base`` then ``overrides``; SweepError at ``where``."""
    merged = {**base, **overrides}
    unknown = [k for k in merged if k not in _FIELDS]
    if unknown:
        raise SweepError(f"{where}.{clip(str(unknown[0]), 40)}: unknown TrainConfig field; allowed: {sorted(_FIELDS)}")
    try:
        cfg = load_train_config(config, {k: v for k, v in merged.items() if v is not None})
        nones = {k: None for k, v in merged.items() if v is None}  # e.g. randomization: null
        return validate(dataclasses.replace(cfg, **nones)) if nones else cfg
    except TrainConfigError as err:
        raise SweepError(f"{where}: {err}") from None


def _label(value: Any, index: int) -> str:
    if isinstance(value, bool) or value is None:
        return str(value).lower()
    if isinstance(value, int | float):
        return f"{value:g}"
    if isinstance(value, str):
        return re.sub(r"[^A-Za-z0-9._-]+", "-", Path(value).stem if value.endswith((".yaml", ".yml")) else value)
    return str(index)


def sweep_from_dict(raw: Any, source: str = "<dict>") -> Sweep:
    """A :class:`Sweep` from the content of a sweep file (see the module docstring).

    :raises SweepError: on an unknown key, a bad training field of any run (named as ``base.x``, ``grid.x[i]``
        or ``runs[i].x``), neither or both of ``grid`` and ``runs``, duplicate run names, or a bad evaluation.
    """
    if not isinstance(raw, Mapping):
        raise SweepError(f"a sweep file must be a mapping with keys from {list(SWEEP_KEYS)}, got {type(raw).__name__}")
    unknown = sorted(set(raw) - set(SWEEP_KEYS), key=str)
    if unknown:
        raise SweepError(f"{clip(str(unknown[0]), 40)}: unknown sweep key; allowed: {list(SWEEP_KEYS)}")
    name = raw.get("name", Path(source).stem)
    if not isinstance(name, str) or not name:
        raise SweepError(f"name must be a non-empty string, got {excerpt(name)}")
    config = raw.get("config")
    if config is not None and not isinstance(config, str):
        raise SweepError(f"config must be the path of a training config YAML or null, got {excerpt(config)}")
    base = raw.get("base") or {}
    if not isinstance(base, Mapping):
        raise SweepError(f"base must be a mapping of TrainConfig fields, got {excerpt(base)}")
    _run_config(config, base, {}, "base")
    if ("grid" in raw) == ("runs" in raw):
        raise SweepError("grid or runs: give exactly one (grid: field -> list of values; runs: list of field mappings)")
    runs: list[SweepRun] = []
    if "grid" in raw:
        grid = raw["grid"]
        if not isinstance(grid, Mapping) or not grid:
            raise SweepError(
                f"grid must be a non-empty mapping of TrainConfig field -> list of values, got {excerpt(grid)}"
            )
        for key, values in grid.items():
            if key not in _FIELDS:
                raise SweepError(f"grid.{clip(str(key), 40)}: unknown TrainConfig field; allowed: {sorted(_FIELDS)}")
            if not isinstance(values, list) or not values:
                raise SweepError(f"grid.{key} must be a non-empty list of values, got {excerpt(values)}")
            for i, v in enumerate(values):
                _run_config(config, base, {key: v}, f"grid.{key}[{i}]")
        swept = tuple(grid)
        for combo in itertools.product(*(list(enumerate(v)) for v in grid.values())):
            params = {k: v for k, (_, v) in zip(swept, combo, strict=True)}
            run_name = "_".join(f"{k}={_label(v, i)}" for k, (i, v) in zip(swept, combo, strict=True))
            runs.append(SweepRun(run_name, params, _run_config(config, base, params, f"grid ({run_name})")))
    else:
        items = raw["runs"]
        if not isinstance(items, list) or not items:
            raise SweepError(f"runs must be a non-empty list of TrainConfig field mappings, got {excerpt(items)}")
        for i, item in enumerate(items):
            if not isinstance(item, Mapping):
                raise SweepError(f"runs[{i}] must be a mapping of TrainConfig fields (and a name), got {excerpt(item)}")
            params = {k: v for k, v in item.items() if k != "name"}
            run_name = item.get("name", f"run{i:03d}")
            runs.append(SweepRun(run_name, params, _run_config(config, base, params, f"runs[{i}]")))
        swept = tuple(dict.fromkeys(k for r in runs for k in r.params))
    names = [r.name for r in runs]
    for i, n in enumerate(names):
        if not isinstance(n, str) or not _NAME_OK.match(n):
            raise SweepError(
                f"runs[{i}].name must be a folder name of letters, digits and ._=+- only, got {excerpt(n)}"
            )
        if names.index(n) != i:
            raise SweepError(f"runs[{i}].name: {excerpt(n)} is used by more than one run; run names must be distinct")
    try:
        evaluation = from_mapping(SweepEvaluation, raw.get("evaluation"), "evaluation")
    except SweepError:
        raise
    except ValueError as err:
        raise SweepError(str(err)) from None
    try:
        load_suite(evaluation.suite)
    except SuiteError as err:
        raise SweepError(f"evaluation.suite: {err}") from None
    cpus = raw.get("cpus_per_run")
    if cpus is not None and (isinstance(cpus, bool) or not isinstance(cpus, int | float) or not 0 < cpus < math.inf):
        raise SweepError(f"cpus_per_run must be a number > 0 or null (its n_envs), got {excerpt(cpus)}")
    return Sweep(name, source, tuple(runs), swept, evaluation, None if cpus is None else float(cpus))


def load_sweep(path: str | Path) -> Sweep:
    """The validated sweep of the YAML file ``path``; :raises SweepError: as :func:`sweep_from_dict`."""
    try:
        raw = read_yaml(path)
    except ValueError as err:
        raise SweepError(f"--config: {err}") from None
    return sweep_from_dict(raw, source=str(path))


def _portable(cfg: TrainConfig) -> dict[str, Any]:
    """``cfg`` as a dict whose file paths (terrain and randomization YAMLs) are absolute: a Tune trial runs in its
    own working directory."""

    def absolute(spec: Any) -> Any:
        if isinstance(spec, str) and spec.endswith((".yaml", ".yml")) and Path(spec).is_file():
            return str(Path(spec).resolve())
        return spec

    d = cfg.to_dict()
    terrains = [absolute(t) for t in terrain_list(cfg.terrain)]
    d["terrain"] = terrains if isinstance(cfg.terrain, list | tuple) else terrains[0]
    d["randomization"] = absolute(cfg.randomization)
    return d


def _trial(config: dict[str, Any]) -> None:
    """Ray Tune function trainable: one training run, ``quad-uneven train`` with the run's config into its folder."""
    from ray import tune

    from agents.rl.training import train  # deferred: SB3 and torch

    run = config["run"]
    summary = train(validate(TrainConfig(**run["config"])), run["out"], progress=False)
    tune.report({k: v for k, v in summary.items() if isinstance(v, int | float) and not isinstance(v, bool)})


def _trial_dirname(trial: Any) -> str:
    """Tune's folder of a trial (under ``DIR/tune/``): the run's name."""
    return str(trial.config["run"]["name"])


def _cpus(sweep: Sweep, cluster_cpus: float) -> float:
    want = sweep.cpus_per_run or max(r.config.n_envs for r in sweep.runs)
    return float(min(want, max(1.0, cluster_cpus)))


def _train_all(sweep: Sweep, out: Path, cpus: float, progress: bool) -> dict[str, str | None]:
    """Every run as a Tune trial; returns run name -> error text (None: trained)."""
    tune = import_tune("sweep")
    specs = [{"name": r.name, "config": _portable(r.config), "out": str(out / "runs" / r.name)} for r in sweep.runs]
    tuner = tune.Tuner(
        tune.with_resources(_trial, {"cpu": cpus}),
        param_space={"run": tune.grid_search(specs)},
        tune_config=tune.TuneConfig(
            num_samples=1, trial_dirname_creator=_trial_dirname, trial_name_creator=_trial_dirname
        ),
        run_config=tune.RunConfig(
            name="tune",
            storage_path=str(out),
            verbose=1 if progress else 0,
            failure_config=tune.FailureConfig(max_failures=0),
        ),
    )
    grid = tuner.fit()
    errors: dict[str, str | None] = {r.name: "not run" for r in sweep.runs}
    for result in grid:
        name = result.config["run"]["name"]
        errors[name] = None if result.error is None else " ".join(str(result.error).split())[-300:]
    return errors


def _row(run: SweepRun, out: Path, error: str | None, results: Mapping[str, Any] | None) -> dict[str, Any]:
    row: dict[str, Any] = {"name": run.name, "params": dict(run.params), "error": error}
    summary_file = out / "runs" / run.name / "train_summary.json"
    train = json.loads(summary_file.read_text()) if summary_file.is_file() else {}
    row["train"] = {k: train.get(k) for k in TRAIN_FIGURES}
    overall = (results or {}).get("summary", {}).get("overall", {})
    row["evaluation"] = {k: overall.get(k) for k in EVAL_FIGURES}
    return row


def run_sweep(
    sweep: Sweep,
    out: str | Path,
    address: str | None = None,
    num_cpus: int | None = None,
    overwrite: bool = False,
    progress: bool = True,
    ship_code: bool = False,
) -> dict[str, Any]:
    """Train every run of ``sweep`` as a Ray Tune trial, evaluate every model, write the summary; return it.

    :param out: output directory (checked first: a non-empty one is refused unless ``overwrite``). On a
        multi-node cluster it must be on a filesystem every node mounts at the same path (docs/distributed.md).
    :param address: the Ray cluster to join (None: the running Ray session, else a local Ray of ``num_cpus`` CPUs).
    :param ship_code: a Ray session started here uploads this source tree to the workers
        (:func:`agents.evaluation.ray_backend.code_runtime_env`); else they import their installed package.
    :param overwrite: delete an earlier sweep's outputs in ``out`` (``SWEEP_OUTPUTS``; other files are kept).
    :return: the ``summary.json`` content: ``sweep``, ``suite``, ``swept`` fields and one row per run with its
        ``params``, ``train`` figures (``train_summary.json``), ``evaluation`` figures (overall success rate,
        mean stability index in N m, ...) and ``error`` (None, or why the run or its evaluation failed).
    :raises RayUnavailable: without the ``distributed`` extra; ``OutputError`` on an unusable ``out``.
    """
    import_tune("sweep")  # without the extra, fail before anything is written
    with output_dir(Path(out).absolute(), "sweep", SWEEP_OUTPUTS, overwrite=overwrite) as manifest:
        out = manifest.out
        write_json_atomic(
            out / "sweep.json",
            json_safe({"name": sweep.name, "source": sweep.source, "swept": list(sweep.swept),
                       "evaluation": dataclasses.asdict(sweep.evaluation), "cpus_per_run": sweep.cpus_per_run,
                       "runs": [{"name": r.name, "params": r.params, "config": r.config.to_dict()}
                                for r in sweep.runs]}),
        )  # fmt: skip
        suite = load_suite(sweep.evaluation.suite)
        rows = []
        with ray_session(address, num_cpus, what="sweep", ship_code=ship_code) as ray:
            errors = _train_all(sweep, out, _cpus(sweep, ray.cluster_resources().get("CPU", 1.0)), progress)
            for run in sweep.runs:
                results, error = None, errors[run.name]
                model = out / "runs" / run.name / "model.zip"
                if error is None:
                    try:
                        results = evaluate(
                            suite,
                            str(model),
                            out / "evals" / run.name,
                            episodes=sweep.evaluation.episodes,
                            seed=sweep.evaluation.seed,
                            algo=run.config.algo,
                            progress=progress,
                            backend="ray",
                        )
                    except ValueError as err:  # an unusable model: the other runs still get their row
                        error = f"evaluation: {' '.join(str(err).split())}"
                rows.append(_row(run, out, error, results))
        summary = json_safe({"sweep": sweep.name, "suite": suite.name, "swept": list(sweep.swept), "runs": rows})
        write_json_atomic(out / "summary.json", summary)
        write_summary_table(summary, out)
        plot_sweep(summary, out / "summary.png")
    return summary


def _flat(summary: Mapping[str, Any]) -> tuple[list[str], list[list[Any]]]:
    swept = list(summary["swept"])
    header = ["name", *swept, *(f"train_{k}" for k in TRAIN_FIGURES), *EVAL_FIGURES, "error"]
    lines = []
    for r in summary["runs"]:
        params = [r["params"].get(k, "") for k in swept]
        lines.append([r["name"], *params, *(r["train"][k] for k in TRAIN_FIGURES),
                      *(r["evaluation"][k] for k in EVAL_FIGURES), r["error"] or ""])  # fmt: skip
    return header, lines


def write_summary_table(summary: Mapping[str, Any], out: Path) -> tuple[Path, Path]:
    """``out/summary.csv`` (every figure) and ``out/summary.md`` (the main ones) from a sweep's summary."""
    header, lines = _flat(summary)
    with (out / "summary.csv").open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(header)
        writer.writerows([["" if v is None else v for v in line] for line in lines])

    def fmt(v: Any) -> str:
        if v is None:
            return "-"
        if isinstance(v, float):
            return f"{v:.3g}"
        return str(v).replace("|", "/")

    swept = list(summary["swept"])
    cols = ["run", *swept, "train steps", "train wall (s)", "train mean return", "train fall rate", "success",
            "mean index (N m)", "error"]  # fmt: skip
    md = [f"# Sweep {summary['sweep']}: evaluation on the {summary['suite']} suite", "",
          "| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]  # fmt: skip
    for r in summary["runs"]:
        t, e = r["train"], r["evaluation"]
        success = "-" if e["episodes"] is None else f"{e['successes']}/{e['episodes']}"
        cells = [r["name"], *(fmt(r["params"].get(k)) for k in swept), fmt(t["timesteps"]), fmt(t["wall_time"]),
                 fmt(t["mean_return"]), fmt(t["fall_rate"]), success, fmt(e["mean_stability_index"]),
                 fmt(r["error"])]  # fmt: skip
        md.append("| " + " | ".join(cells) + " |")
    (out / "summary.md").write_text("\n".join(md) + "\n")
    return out / "summary.csv", out / "summary.md"


def plot_sweep(summary: Mapping[str, Any], path: Path) -> Path:
    """Success rate (%) and mean stability index (N m) against the first swept field, one line per value of the
    other swept fields (runs without an evaluation are left out)."""
    plt = pyplot()
    swept: Sequence[str] = summary["swept"]
    runs = summary["runs"]
    x_key = swept[0] if swept else None
    xs = [r["params"].get(x_key) if x_key else r["name"] for r in runs]
    numeric = all(isinstance(v, int | float) and not isinstance(v, bool) for v in xs)
    ticks = list(dict.fromkeys(json.dumps(v) for v in xs))
    pos = [float(v) if numeric else float(ticks.index(json.dumps(v))) for v in xs]
    groups: dict[str, list[int]] = {}
    for i, r in enumerate(runs):
        key = ", ".join(f"{k}={r['params'].get(k)}" for k in swept[1:])
        groups.setdefault(key, []).append(i)
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(9.0, 3.6))
    for label, idx in groups.items():
        idx = sorted(idx, key=lambda i: pos[i])
        rate = [100.0 * (runs[i]["evaluation"]["success_rate"] or 0.0) if runs[i]["evaluation"]["episodes"]
                else np.nan for i in idx]  # fmt: skip
        index = [np.nan if runs[i]["evaluation"]["mean_stability_index"] is None
                 else runs[i]["evaluation"]["mean_stability_index"] for i in idx]  # fmt: skip
        ax1.plot([pos[i] for i in idx], rate, "o-", label=label or None)
        ax2.plot([pos[i] for i in idx], index, "o-", label=label or None)
    ax1.set_ylim(-5, 105)
    ax1.set_ylabel("success rate (%)")
    ax2.axhline(0.0, color="0.5", ls="--", lw=0.8)
    ax2.set_ylabel("mean stability index (N m)")
    for ax in (ax1, ax2):
        ax.set_xlabel(x_key or "run")
        ax.grid(alpha=0.3)
        if not numeric:
            ax.set_xticks(range(len(ticks)), [str(json.loads(t)) for t in ticks])
    if any(groups):
        ax1.legend(fontsize=8)
    fig.suptitle(f"sweep {summary['sweep']}: {summary['suite']} suite", fontsize=10)
    return save(fig, path)
