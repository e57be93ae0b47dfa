"""Plots of evaluation results, written into a directory the user names."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from agents.plotting import LEG_COLOURS, pyplot, save
from quad_uneven_env.constants import LEG_NAMES

OUTCOME_COLOURS = {"goal": "tab:green", "time_limit": "tab:orange"}
"""Bar colours of the distance plot by end reason (anything else, i.e. a fall or an error: red)."""


def plot_distance_per_episode(records: list[dict], goal: float, labels: list[str], path: Path) -> Path:
    """Distance (m) travelled per episode, grouped by terrain entry, coloured by how the episode ended."""
    plt = pyplot()
    n = len(records)
    fig, ax = plt.subplots(figsize=(max(6.0, min(0.28 * n + 2.0, 18.0)), 4.2))
    x = np.arange(n)
    colours = [OUTCOME_COLOURS.get(r["end_reason"], "tab:red") for r in records]
    ax.bar(x, [r["distance"] for r in records], color=colours, width=0.8)
    ax.axhline(goal, color="k", ls="--", lw=1)
    ax.text(-0.5, goal, " goal", va="bottom", ha="left", fontsize=8)
    ax.set_xticks(x, [str(r["seed"]) for r in records], fontsize=7 if n > 30 else 9)
    ax.set_xlabel("episode (seed), grouped by terrain entry")
    ax.set_ylabel("distance along +x (m)")
    ax.set_xlim(-0.6, n - 0.4)
    top = max(goal, *(r["distance"] for r in records)) * 1.18
    ax.set_ylim(min(0.0, *(r["distance"] for r in records)), top)
    ax.scatter(x, [r["distance"] for r in records], c=colours, s=14, zorder=3)
    for e in sorted({r["entry"] for r in records}):
        idx = [i for i, r in enumerate(records) if r["entry"] == e]
        if idx[0] > 0:
            ax.axvline(idx[0] - 0.5, color="0.6", lw=0.8)
        text = (
            f"[{e}] {labels[e]}"
            if len(idx) >= 8
            else (f"[{e}] {labels[e].split('(')[0]}" if len(idx) >= 3 else f"[{e}]")
        )
        ax.text((idx[0] + idx[-1]) / 2, top * 0.985, text, ha="center", va="top", fontsize=7)
    ax.set_title("distance per episode ([entry] as in the report's 'By terrain entry' table)", fontsize=9)
    handles = [plt.Rectangle((0, 0), 1, 1, color=c) for c in ("tab:green", "tab:orange", "tab:red")]
    ax.legend(handles, ["goal reached", "time limit", "fall / error"], fontsize=8, loc="lower right")
    save(fig, path, dpi=110)
    return path


def plot_stability_over_time(traces: list[tuple[str, np.ndarray, np.ndarray]], path: Path) -> Path:
    """Measured stability index (N m) over time (s), one panel per (label, time, index) trace.

    Steps with fewer than 3 feet in contact (index -inf: no support polygon) are red marks on the zero line.
    """
    plt = pyplot()
    fig, axes = plt.subplots(len(traces), 1, figsize=(9, 1.9 * len(traces) + 0.6), squeeze=False)
    for ax, (label, t, index) in zip(axes[:, 0], traces, strict=True):
        finite = np.isfinite(index)
        ax.plot(t, np.where(finite, index, np.nan), lw=1.0, color="tab:blue")
        ax.axhline(0.0, color="k", lw=0.7)
        neg = np.isneginf(index)
        if neg.any():
            ax.plot(t[neg], np.zeros(neg.sum()), "|", color="tab:red", ms=6, label="< 3 feet in contact")
            ax.legend(fontsize=7, loc="upper right")
        below = finite & (index < 0)
        if below.any():
            ax.plot(t[below], index[below], ".", color="tab:red", ms=2)
        ax.set_title(label, fontsize=9, loc="left")
        ax.set_ylabel("index (N m)", fontsize=8)
        ax.tick_params(labelsize=8)
    axes[-1, 0].set_xlabel("time (s)")
    save(fig, path, dpi=110)
    return path


def plot_terrain_paths(
    cog: np.ndarray,
    feet: np.ndarray,
    heights: np.ndarray,
    origin: tuple,
    cell_size: float,
    title: str,
    path: Path,
    contact: np.ndarray | None = None,
) -> Path:
    """COG and foot paths (world, m) over the terrain: top view on the height map, side view on its profile.

    :param cog: (N, 3) COG positions. :param feet: (N, 4, 3) foot sites (LF, RF, LH, RH).
    :param heights: (nrow, ncol) terrain heights (m), rows along +y, columns along +x from ``origin``.
    :param contact: optional (N, 4) foot contact flags: touchdowns are marked on both views.
    """
    plt = pyplot()
    nrow, ncol = heights.shape
    xs = origin[0] + cell_size * np.arange(ncol)
    ys = origin[1] + cell_size * np.arange(nrow)
    lo = min(float(cog[:, 0].min()), float(feet[..., 0].min())) - 0.4
    hi = max(float(cog[:, 0].max()), float(feet[..., 0].max())) + 0.4
    if hi - lo < 2.5:  # a short walk still gets a readable window
        lo, hi = (lo + hi) / 2 - 1.25, (lo + hi) / 2 + 1.25
    cols = (xs >= lo) & (xs <= hi)
    rows = (ys >= -0.6) & (ys <= 0.6)
    fig, ax = plt.subplots(2, 1, figsize=(10, 6.4), height_ratios=[1.1, 1])
    sub = heights[np.ix_(rows, cols)]
    ext = (xs[cols][0], xs[cols][-1], ys[rows][0], ys[rows][-1])
    im = ax[0].imshow(sub, origin="lower", extent=ext, cmap="terrain", aspect="equal", interpolation="nearest")
    fig.colorbar(im, ax=ax[0], label="terrain height (m)", fraction=0.03, pad=0.01)
    colours = [LEG_COLOURS[leg] for leg in LEG_NAMES]
    ax[0].plot(cog[:, 0], cog[:, 1], "k-", lw=2, label="COG")
    for i, leg in enumerate(LEG_NAMES):
        ax[0].plot(feet[:, i, 0], feet[:, i, 1], "-", color=colours[i], lw=1, label=leg)
    if contact is not None and len(contact) > 1:
        c = np.asarray(contact, dtype=bool)
        down = c[1:] & ~c[:-1]
        for i in range(4):
            pts = feet[1:, i][down[:, i]]
            for k in (0, 1):
                ax[k].plot(pts[:, 0], pts[:, 1 if k == 0 else 2], "o", mfc="none", color=colours[i], ms=5)
        ax[0].plot([], [], "o", mfc="none", color="k", ms=5, label="touchdown")
    ax[0].set(xlabel="x (m)", ylabel="y (m)", title=f"{title}: top view")
    for sign, style in ((1, "-"), (-1, "--")):
        r = int(np.argmin(np.abs(ys - sign * 0.185)))
        side = "left" if sign > 0 else "right"
        label = f"terrain at y = {ys[r]:+.2f} m ({side})"
        ax[1].plot(xs[cols], heights[r, cols], style, color="0.4", lw=1.2, label=label)
    ax[1].plot(cog[:, 0], cog[:, 2], "k-", lw=2, label="COG")
    for i, leg in enumerate(LEG_NAMES):
        ax[1].plot(feet[:, i, 0], feet[:, i, 2], "-", color=colours[i], lw=1, label=leg)
    ax[1].set(xlabel="x (m)", ylabel="z (m)", title="side view (foot sites are 0.02 m above the surface)")
    ax[1].set_xlim(ext[0], ext[1])
    if contact is not None:
        ax[1].plot([], [], "o", mfc="none", color="k", ms=5, label="touchdown")
    ax[1].legend(fontsize=7, ncol=5, loc="upper left", bbox_to_anchor=(0.0, -0.18))
    save(fig, path, dpi=110, bbox_tight=True)
    return path


def plot_commanded_paths(
    panels: list[dict],
    heights: np.ndarray,
    origin: tuple,
    cell_size: float,
    title: str,
    path: Path,
) -> Path:
    """Commanded and measured COG paths (world, m) over the terrain's height map (top view).

    :param panels: one dict per episode drawn together: ``cog`` (N, 2) measured path, ``commanded`` (N, 2) the
        commanded path (:func:`agents.evaluation.metrics.commanded_path`), ``label`` (str), and optionally
        ``waypoints`` (K, 2) (m) and ``radius`` (m) of the waypoints.
    :param heights: (nrow, ncol) terrain heights (m), rows along +y, columns along +x from ``origin``.
    """
    plt = pyplot()
    nrow, ncol = heights.shape
    xs = origin[0] + cell_size * np.arange(ncol)
    ys = origin[1] + cell_size * np.arange(nrow)
    pts = [p[k] for p in panels for k in ("cog", "commanded")] + [p["waypoints"] for p in panels if "waypoints" in p]
    allp = np.vstack(pts)
    centre = 0.5 * (allp.min(axis=0) + allp.max(axis=0))
    half = max(0.5 * float(np.ptp(allp, axis=0).max()) + 0.4, 1.0)
    cols = (xs >= centre[0] - half) & (xs <= centre[0] + half)
    rows = (ys >= centre[1] - half) & (ys <= centre[1] + half)
    fig, ax = plt.subplots(figsize=(7.5, 6.5))
    sub = heights[np.ix_(rows, cols)]
    ext = (xs[cols][0], xs[cols][-1], ys[rows][0], ys[rows][-1])
    im = ax.imshow(sub, origin="lower", extent=ext, cmap="terrain", aspect="equal", interpolation="nearest")
    fig.colorbar(im, ax=ax, label="terrain height (m)", fraction=0.04, pad=0.01)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for k, p in enumerate(panels):
        c = colours[k % len(colours)]
        ax.plot(p["commanded"][:, 0], p["commanded"][:, 1], "--", color=c, lw=1.3, label=f"{p['label']}: commanded")
        ax.plot(p["cog"][:, 0], p["cog"][:, 1], "-", color=c, lw=2.0, label=f"{p['label']}: measured COG")
        ax.plot(p["cog"][-1, 0], p["cog"][-1, 1], "o", color=c, ms=5)
        if "waypoints" in p:
            wp = np.asarray(p["waypoints"])
            ax.plot(wp[:, 0], wp[:, 1], "x", color="k", ms=8, mew=2)
            for j, (x, y) in enumerate(wp):
                ax.add_patch(plt.Circle((x, y), float(p.get("radius", 0.3)), fill=False, color="k", lw=0.8))
                ax.text(x, y, f" {j + 1}", fontsize=8, va="bottom")
    ax.plot(allp[0, 0], allp[0, 1], "k^", ms=7, label="start")
    ax.set(xlabel="x (m)", ylabel="y (m)", title=title)
    ax.set_xlim(ext[0], ext[1])
    ax.set_ylim(ext[2], ext[3])
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(0.0, -0.09), ncol=2)
    save(fig, path, dpi=110, bbox_tight=True)
    return path
