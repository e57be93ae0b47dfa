"""Learning curves of a training run from its Monitor CSVs and EvalCallback log (no pandas needed)."""

from __future__ import annotations

import csv
import math
import textwrap
from pathlib import Path
from typing import Any

import numpy as np

ROLLING = 20
"""Episodes in the rolling mean of the learning curve."""


def read_monitor(monitor_dir: Path) -> dict[str, np.ndarray]:
    """Episodes of every ``*.monitor.csv`` in ``monitor_dir``, ordered by wall time.

    :return: ``timesteps`` (env steps of all envs at the end of the episode), ``r`` (return), ``l`` (steps),
        ``t`` (s since the start) and every extra column (e.g. ``ep_stability_mean``, N m), as float arrays
        (empty arrays if there is no finished episode).
    """
    rows: list[dict[str, str]] = []
    for path in sorted(Path(monitor_dir).glob("*.monitor.csv")):
        with path.open() as f:
            first = f.readline()
            if not first.startswith("#"):
                f.seek(0)
            rows.extend(csv.DictReader(f))
    rows.sort(key=lambda row: float(row["t"]))
    keys = list(rows[0]) if rows else ["r", "l", "t"]
    out = {k: np.array([_float(row.get(k)) for row in rows], dtype=float) for k in keys}
    out["timesteps"] = np.cumsum(out["l"]) if rows else np.zeros(0)
    return out


def _float(text: str | None) -> float:
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
    """EvalCallback's ``evaluations.npz``: ``timesteps`` and mean ``returns`` and ``lengths``; None if absent."""
    if not Path(path).is_file():
        return None
    data = np.load(path)
    return {
        "timesteps": data["timesteps"].astype(float),
        "returns": data["results"].mean(axis=1),
        "lengths": data["ep_lengths"].mean(axis=1),
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
    :raises ValueError: ``RUN: ...`` naming a folder without a finished training episode.
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


__all__ = ["plot_learning_curve", "plot_learning_curves", "read_evaluations", "read_monitor", "rolling_mean"]
