"""Learning curves of a training run from its Monitor CSVs and EvalCallback log (no pandas needed).

Both are read through checked readers: a file that SB3 did not write (another format, a binary file, a column or
array missing, a value that is not a finite number, an episode length that is not a whole number of steps >= 1)
is refused with :class:`LearningCurveError` naming the file, the line and the field.
"""

from __future__ import annotations

import csv
import math
import textwrap
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

ROLLING = 20
"""Episodes in the rolling mean of the learning curve."""

MONITOR_COLUMNS = ("r", "l", "t")
"""The columns every Monitor CSV has: the episode's return, length (env steps) and end time (s since the start)."""

EVALUATION_ARRAYS = ("timesteps", "results", "ep_lengths")
"""The arrays of EvalCallback's ``evaluations.npz``: (n,) env steps, (n, episodes) returns and lengths (steps)."""


class LearningCurveError(ValueError):
    """A monitor or evaluation file of a training run that cannot be read; the message names the file and field."""


def _monitor_value(path: Path, line: int, row: dict[str, Any], key: str) -> float:
    """The Monitor CSV value ``row[key]`` checked: a finite number; ``l`` a whole number >= 1, ``t`` >= 0."""
    text = row.get(key)
    try:
        value = float(text)
    except (TypeError, ValueError):
        value = math.nan
    if key == "l":
        ok = math.isfinite(value) and value >= 1 and value == int(value)
        allowed = "a whole number of steps >= 1"
    else:
        ok = math.isfinite(value) and (key != "t" or value >= 0)
        allowed = "a number >= 0 (s)" if key == "t" else "a finite number"
    if not ok:
        raise LearningCurveError(f"{path} line {line}: {key} must be {allowed}, got {text!r}")
    return value


def _monitor_rows(path: Path) -> list[dict[str, Any]]:
    """The episodes of one Monitor CSV (its ``#`` header line skipped), each with checked ``r``, ``l``, ``t``."""
    try:
        lines = path.read_text().splitlines()
    except (OSError, UnicodeDecodeError) as err:
        raise LearningCurveError(f"{path}: not a Monitor CSV of a training run ({err})") from None
    offset = 1 if lines and lines[0].startswith("#") else 0
    try:
        reader = csv.DictReader(lines[offset:])
        missing = [c for c in MONITOR_COLUMNS if c not in (reader.fieldnames or [])]
        if missing:
            raise LearningCurveError(
                f"{path}: column(s) {missing} missing; a Monitor CSV has {list(MONITOR_COLUMNS)} (return, length in "
                f"steps, time in s), got {reader.fieldnames}"
            )
        rows = []
        for row in reader:
            line = offset + reader.line_num
            if None in row or None in row.values():
                raise LearningCurveError(f"{path} line {line}: {len(reader.fieldnames)} values expected per row")
            for key in MONITOR_COLUMNS:
                row[key] = _monitor_value(path, line, row, key)
            rows.append(row)
    except csv.Error as err:
        raise LearningCurveError(f"{path}: not a Monitor CSV of a training run ({err})") from None
    return rows


def read_monitor(monitor_dir: Path) -> dict[str, np.ndarray]:
    """Episodes of every ``*.monitor.csv`` in ``monitor_dir``, ordered by wall time.

    :return: ``timesteps`` (env steps of all envs at the end of the episode), ``r`` (return), ``l`` (steps),
        ``t`` (s since the start) and every extra column (e.g. ``ep_stability_mean``, N m), as float arrays
        (empty arrays if there is no finished episode; an extra value that is no number is NaN).
    :raises LearningCurveError: on a file that is not a Monitor CSV (named, with the line and column).
    """
    rows: list[dict[str, Any]] = []
    for path in sorted(Path(monitor_dir).glob("*.monitor.csv")):
        rows.extend(_monitor_rows(path))
    rows.sort(key=lambda row: row["t"])
    keys = list(rows[0]) if rows else list(MONITOR_COLUMNS)
    out = {k: np.array([_float(row.get(k)) for row in rows], dtype=float) for k in keys}
    out["timesteps"] = np.cumsum(out["l"]) if rows else np.zeros(0)
    return out


def _float(text: Any) -> float:
    try:
        return float(text) if text not in (None, "") else math.nan
    except ValueError:
        return math.nan


def rolling_mean(x: np.ndarray, window: int = ROLLING) -> np.ndarray:
    """Mean over the last ``window`` values (fewer at the start), NaNs ignored."""
    out = np.full(len(x), np.nan)
    for i in range(len(x)):
        chunk = x[max(0, i - window + 1) : i + 1]
        chunk = chunk[np.isfinite(chunk)]
        if chunk.size:
            out[i] = chunk.mean()
    return out


def read_evaluations(path: Path) -> dict[str, np.ndarray] | None:
    """EvalCallback's ``evaluations.npz``: ``timesteps`` and mean ``returns`` and ``lengths``; None if absent.

    :raises LearningCurveError: on a file that is not one EvalCallback wrote: unreadable, an array of
        :data:`EVALUATION_ARRAYS` missing or of another shape, a value that is not finite, a length < 1 step.
    """
    path = Path(path)
    if not path.is_file():
        return None

    def bad(why: str) -> LearningCurveError:
        return LearningCurveError(f"{path}: not an evaluations.npz of SB3's EvalCallback ({why})")

    try:
        with np.load(path, allow_pickle=False) as data:
            missing = [k for k in EVALUATION_ARRAYS if k not in data.files]
            if missing:
                raise bad(f"array(s) {missing} missing; it has {sorted(data.files)}")
            steps, returns, lengths = (np.asarray(data[k]) for k in EVALUATION_ARRAYS)
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as err:
        if isinstance(err, LearningCurveError):
            raise
        raise bad(str(err)) from None
    for name, a in zip(EVALUATION_ARRAYS, (steps, returns, lengths), strict=True):
        if a.dtype.kind not in "iuf":
            raise bad(f"{name} holds {a.dtype} values, not numbers")
    n = len(steps) if steps.ndim == 1 else -1
    if n < 0 or returns.shape != lengths.shape or returns.ndim != 2 or len(returns) != n or returns.shape[1] < 1:
        raise bad(f"shapes timesteps {steps.shape}, results {returns.shape}, ep_lengths {lengths.shape}; expected "
                  "(n,), (n, episodes), (n, episodes)")  # fmt: skip
    if not (np.all(np.isfinite(steps)) and np.all(steps >= 0)):
        raise bad("timesteps must be finite numbers >= 0")
    if not np.all(np.isfinite(returns)):
        raise bad("results must be finite numbers")
    if not (np.all(np.isfinite(lengths)) and np.all(lengths >= 1) and np.all(lengths == np.round(lengths))):
        raise bad("ep_lengths must be whole numbers of steps >= 1")
    return {
        "timesteps": steps.astype(float),
        "returns": returns.mean(axis=1),
        "lengths": lengths.mean(axis=1),
    }


def plot_learning_curve(monitor_dir: Path, eval_file: Path | None, out_png: Path, title: str = "") -> dict[str, Any]:
    """Episode return, mean stability index (N m) and distance (m) vs env steps; writes ``out_png``.

    :return: a summary of the last ``ROLLING`` training episodes (``episodes``, ``mean_return``,
        ``mean_stability_index``, ``mean_distance``, ``fall_rate``); NaN where there is no episode.
    """
    from agents.plotting import pyplot

    plt = pyplot()

    mon = read_monitor(monitor_dir)
    ev = read_evaluations(eval_file) if eval_file is not None else None
    ts = mon["timesteps"]
    panels = [
        ("r", "episode return", "training episodes"),
        ("ep_stability_mean", "mean stability index (N m)", "training episodes"),
        ("ep_distance", "distance (m)", "training episodes"),
    ]
    fig, axes = plt.subplots(len(panels), 1, figsize=(7, 8), sharex=True)
    for ax, (key, _, legend) in zip(axes, panels, strict=True):
        y = mon.get(key, np.full(len(ts), np.nan))
        ax.plot(ts, y, ".", ms=3, alpha=0.35, color="tab:blue", label=legend)
        if len(ts):
            ax.plot(ts, rolling_mean(y), "-", color="tab:blue", label=f"rolling mean ({ROLLING} episodes)")
        if key == "r" and ev is not None and len(ev["timesteps"]):
            ax.plot(ev["timesteps"], ev["returns"], "o-", color="tab:orange", label="evaluation (deterministic)")
    _finish(fig, axes, [label for _, label, _ in panels], title, out_png, legend_size=8)

    last = slice(-ROLLING, None)

    def mean(key: str) -> float:
        v = mon.get(key, np.zeros(0))[last]
        v = v[np.isfinite(v)]
        return float(v.mean()) if v.size else math.nan

    return {
        "episodes": len(ts),
        "mean_return": mean("r"),
        "mean_stability_index": mean("ep_stability_mean"),
        "mean_distance": mean("ep_distance"),
        "fall_rate": mean("ep_fell"),
    }


CURVE_COLOURS = ("tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown")
"""Colour of each run in :func:`plot_learning_curves`, in order (then repeated)."""


def plot_learning_curves(runs: list[tuple[str, Path]], out_png: Path, title: str = "") -> Path:
    """Several training runs' curves side by side: per run, the rolling mean of the training episodes' return,
    distance (m) and fall rate, and the deterministic evaluations' mean return, against env steps.

    :param runs: (label, ``quad-uneven train`` folder) pairs; each folder needs ``monitor/*.monitor.csv``.
    :param out_png: the figure (PNG) written.
    :raises ValueError: ``RUN: ...`` naming a folder without a finished training episode;
        :class:`LearningCurveError` on a monitor or evaluation file it cannot read.
    """
    from agents.plotting import pyplot

    curves = []
    for label, folder in runs:
        mon = read_monitor(Path(folder) / "monitor")
        if not len(mon["timesteps"]):
            raise ValueError(
                f"RUN: {str(folder)!r} has no finished training episode in monitor/*.monitor.csv "
                "(a quad-uneven train folder?)"
            )
        curves.append((label, mon, read_evaluations(Path(folder) / "eval" / "evaluations.npz")))
    plt = pyplot()
    panels = [
        ("r", "episode return"),
        ("ep_distance", "distance per episode (m)"),
        ("ep_fell", "fall rate"),
    ]
    fig, axes = plt.subplots(len(panels), 1, figsize=(7, 8), sharex=True)
    for i, (label, mon, ev) in enumerate(curves):
        colour = CURVE_COLOURS[i % len(CURVE_COLOURS)]
        for ax, (key, _) in zip(axes, panels, strict=True):
            y = mon.get(key, np.full(len(mon["timesteps"]), np.nan))
            ax.plot(
                mon["timesteps"], rolling_mean(y), "-", color=colour, label=f"{label} (training, rolling {ROLLING})"
            )
            if key == "r" and ev is not None and len(ev["timesteps"]):
                ax.plot(ev["timesteps"], ev["returns"], "o--", ms=4, color=colour, label=f"{label} (evaluation)")
    return _finish(fig, axes, [name for _, name in panels], title, out_png, legend_size=7)


def _finish(fig: Any, axes: Any, ylabels: list[str], title: str | None, out_png: Path, legend_size: int) -> Path:
    """Label, grid and legend every panel, title the first, save the figure to ``out_png``; :return: its path."""
    from agents.plotting import save

    for ax, name in zip(axes, ylabels, strict=True):
        ax.set_ylabel(name)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=legend_size, loc="best")
    axes[-1].set_xlabel("environment steps")
    if title:
        axes[0].set_title(textwrap.fill(title, 70), fontsize=10)
    fig.tight_layout()
    out_png.parent.mkdir(parents=True, exist_ok=True)
    return save(fig, out_png, dpi=110, tight=False)


__all__ = [
    "LearningCurveError",
    "plot_learning_curve",
    "plot_learning_curves",
    "read_evaluations",
    "read_monitor",
    "rolling_mean",
]
