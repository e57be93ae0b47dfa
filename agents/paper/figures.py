"""Figs 4-8 of the §6 scenario (PNG): swing paths, COG, stability index, torques, contact forces.

``planned_fig4..6(plan, path)`` draw the plan alone (a :class:`planners.cycle.GaitCyclePlan`, no simulator).

Each ``figN_*(run, path)`` takes an :class:`agents.paper.simulation.PaperRun` and writes one PNG;
``FIGURES`` maps the file names to them. Planned quantities are drawn dashed/black, measured
ones in colour; phase boundaries are dotted lines, swing phases shaded in the swing leg's colour.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from agents.plotting import LEG_COLOURS, pyplot, save, shade_phases
from quad_uneven_env.constants import JOINT_KINDS, LEG_NAMES


def _phases(ax, run, label: bool | str = False, shade: bool = True) -> None:
    """Phase boundaries, swing phases shaded by leg (``shade``), labels on top (``"short"``: leg only)."""
    plan = run.plan
    t_end = float(run.time[-1]) if len(run.time) else 0.0
    shade_phases(ax, plan.phases, shade=shade, label=label, t_label_max=t_end)
    if t_end > plan.duration:
        ax.axvspan(plan.duration, t_end, color="0.5", alpha=0.08, lw=0, zorder=0)
    ax.set_xlim(0.0, max(t_end, 1e-3))


def _robust_limits(*series: np.ndarray, pad: float = 0.1) -> tuple[float, float]:
    """y-limits covering 99 % of the finite samples of all ``series`` (impact spikes run off the axes)."""
    x = np.concatenate([np.asarray(s, dtype=float).ravel() for s in series])
    x = x[np.isfinite(x)]
    if x.size == 0:
        return -1.0, 1.0
    lo, hi = np.percentile(x, [0.5, 99.5])
    span = max(hi - lo, 1e-3)
    return lo - pad * span, hi + pad * span


def fig4_swing_paths(run, path: Path) -> None:
    """Side views (x-z) of each swing over the terrain profile, planned vs measured; a top view (x-y)."""
    plt = pyplot()

    plan, a = run.plan, run.arrays
    t = run.time
    fig = plt.figure(figsize=(10.0, 8.2))
    gs = fig.add_gridspec(3, 2, height_ratios=(1.0, 1.0, 1.25))
    for n, leg in enumerate(("RH", "RF", "LH", "LF")):
        ax = fig.add_subplot(gs[n // 2, n % 2])
        i = LEG_NAMES.index(leg)
        sw = plan.swing[leg]
        tp = np.linspace(sw.t_start, sw.t_end, 400)
        p = sw.position(tp)
        x = np.linspace(min(plan.feet_start[i, 0], p[:, 0].min()) - 0.1, max(plan.footholds[i, 0], p[:, 0].max()) + 0.1,
                        600)  # fmt: skip
        ground = plan.terrain.height(x, np.full_like(x, plan.feet_start[i, 1]))
        ax.fill_between(x, 0.0, ground, color="0.82", label="terrain (block profile)")
        ax.plot(x, ground, color="0.3", lw=0.8)
        ax.plot(p[:, 0], p[:, 2], color="k", ls="--", lw=1.2, label="planned foot site")
        sel = (t >= sw.t_start - 0.05) & (t <= sw.t_end + 0.05)
        if sel.any():
            ax.plot(
                a["feet"][sel, i, 0], a["feet"][sel, i, 2], color=LEG_COLOURS[leg], lw=1.8, label="measured foot site"
            )
        ax.plot(sw.knots[:, 0], sw.knots[:, 2], "o", ms=4, mfc="white", mec="k", label="spline knots")
        ax.set_title(f"{leg} swing, t = {sw.t_start:g}-{sw.t_end:g} s (y = {plan.feet_start[i, 1]:+.3f} m)",
                     fontsize=9)  # fmt: skip
        ax.set_xlabel("x (m)")
        ax.set_ylabel("z (m)")
        ax.set_ylim(0.0, max(0.4, p[:, 2].max() + 0.05))
        ax.grid(alpha=0.3)
        if n == 0:
            ax.legend(loc="upper left", fontsize=7)
    ax = fig.add_subplot(gs[2, :])
    hf = plan.terrain
    xs, ys = np.asarray(hf.xs), np.asarray(hf.ys)
    cx = (xs >= -0.5) & (xs <= 0.75)
    cy = (ys >= -0.35) & (ys <= 0.35)
    h = np.asarray(hf.heights)[np.ix_(cy, cx)]
    im = ax.imshow(h, origin="lower", extent=(xs[cx][0], xs[cx][-1], ys[cy][0], ys[cy][-1]), cmap="Greys",
                   vmin=0.0, vmax=max(0.3, float(h.max())), aspect="equal")  # fmt: skip
    fig.colorbar(im, ax=ax, label="terrain height (m)", fraction=0.025, pad=0.01)
    for i, leg in enumerate(LEG_NAMES):
        sw = plan.swing[leg]
        p = sw.position(np.linspace(sw.t_start, sw.t_end, 200))
        ax.plot(p[:, 0], p[:, 1], color="k", ls="--", lw=1.0)
        ax.plot(a["feet"][:, i, 0], a["feet"][:, i, 1], color=LEG_COLOURS[leg], lw=1.6, label=f"{leg} foot (measured)")
        ax.plot(*plan.feet_start[i, :2], "s", mfc="none", mec=LEG_COLOURS[leg], ms=7)
        ax.plot(*plan.footholds[i, :2], "^", mfc="none", mec=LEG_COLOURS[leg], ms=7)
    ax.plot(a["cog_plan"][:, 0], a["cog_plan"][:, 1], color="k", ls="--", lw=1.0, label="planned (dashed)")
    ax.plot(a["cog"][:, 0], a["cog"][:, 1], color="tab:purple", lw=1.6, label="COG (measured)")
    ax.plot([], [], "s", mfc="none", mec="k", label="start foothold")
    ax.plot([], [], "^", mfc="none", mec="k", label="target foothold")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title("top view: foot and COG paths over the block terrain", fontsize=9)
    handles, labels = ax.get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower left", bbox_to_anchor=(0.03, 0.06), fontsize=8, title="top view")
    fig.suptitle("Fig. 4 (simulated): swing-leg foot paths over the terrain")
    save(fig, path)


def fig5_cog(run, path: Path) -> None:
    """COG position, velocity and acceleration (x, y, z), planned vs measured."""
    plt = pyplot()

    a, t = run.arrays, run.time
    rows = [("cog", "position (m)"), ("cog_vel", "velocity (m/s)"), ("cog_acc", "acceleration (m/s²)")]
    fig, axes = plt.subplots(3, 3, figsize=(10.5, 7.0), sharex=True)
    for r, (key, lab) in enumerate(rows):
        for c, axis in enumerate("xyz"):
            ax = axes[r, c]
            _phases(ax, run, label="short" if r == 0 else False)
            ax.plot(t, a[key][:, c], color="tab:blue", lw=1.1, label="measured")
            ax.plot(t, a[key + "_plan"][:, c], color="k", ls="--", lw=1.1, label="planned")
            ax.set_ylim(*_robust_limits(a[key][:, c], a[key + "_plan"][:, c]))
            ax.set_ylabel(f"{axis} {lab}", fontsize=8)
            ax.grid(alpha=0.3)
            if r == 2:
                ax.set_xlabel("t (s)")
    axes[0, 0].legend(fontsize=7, loc="lower right")
    err = np.linalg.norm(a["cog"] - a["cog_plan"], axis=1)
    fig.suptitle(
        f"Fig. 5 (simulated): COG, planned vs measured (max tracking error {1000 * err.max():.2f} mm); "
        "measured acceleration = contact forces / m + g (impact spikes clipped)",
        fontsize=10,
    )
    save(fig, path)


def fig6_stability(run, path: Path) -> None:
    """Stability index (N m), planned vs measured, with the margin epsilon; no-support spans shaded."""
    plt = pyplot()

    a, t = run.arrays, run.time
    fig, ax = plt.subplots(figsize=(9.0, 3.8))
    _phases(ax, run, label=True)
    meas = np.where(np.isfinite(a["index"]), a["index"], np.nan)
    ax.plot(t, meas, color="tab:blue", lw=1.0, label="measured (contact forces, measured COG)")
    ax.plot(t, a["index_plan"], color="k", ls="--", lw=1.3, label="planned")
    ax.axhline(run.plan.epsilon, color="tab:red", lw=1.0, ls="-.", label=f"ε = {run.plan.epsilon:g} N m")
    ax.axhline(0.0, color="0.3", lw=0.6)
    none = np.isneginf(a["index"])
    if none.any():
        ax.fill_between(t, 0, 1, where=none, transform=ax.get_xaxis_transform(), color="tab:red", alpha=0.25, lw=0,
                        label="< 3 feet in contact (index −∞)")  # fmt: skip
    lo, hi = _robust_limits(meas, a["index_plan"])
    ax.set_ylim(min(lo, -0.05 * hi), hi)
    ax.set_xlabel("t (s)")
    ax.set_ylabel("stability index (N m)")
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right", fontsize=7)
    ax.set_title("Fig. 6 (simulated): stability index = min tumbling moment over the support polygon edges",
                 fontsize=10, pad=14)  # fmt: skip
    save(fig, path)


def fig7_torques(run, path: Path) -> None:
    """The 12 joint torques (N m), one subplot per leg."""
    plt = pyplot()

    a, t = run.arrays, run.time
    fig, axes = plt.subplots(2, 2, figsize=(10.0, 6.0), sharex=True, sharey=True)
    styles = {"HAA": ":", "HFE": "--", "KFE": "-"}
    lim = float(run.torque_limit.max())
    for i, leg in enumerate(LEG_NAMES):
        ax = axes.ravel()[i]
        _phases(ax, run)
        for j, kind in enumerate(JOINT_KINDS):
            ax.plot(t, a["tau"][:, 3 * i + j], color=LEG_COLOURS[leg], ls=styles[kind], lw=1.2, label=kind)
        peak = np.abs(a["tau"][:, 3 * i : 3 * i + 3]).max() if len(t) else 0.0
        ax.set_title(f"{leg} (peak {peak:.1f} N m)", fontsize=9)
        ax.axhline(lim, color="0.4", lw=0.7, ls="-.")
        ax.axhline(-lim, color="0.4", lw=0.7, ls="-.")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="lower left", ncol=3)
    for ax in axes[:, 0]:
        ax.set_ylabel("joint torque (N m)")
    for ax in axes[1]:
        ax.set_xlabel("t (s)")
    fig.suptitle(f"Fig. 7 (simulated): joint torques (dash-dot: motor limit ±{lim:g} N m); shaded: swing phases")
    save(fig, path)


def fig8_contact_forces(run, path: Path) -> None:
    """Normal contact force per foot (N) with the planned swing phases shaded."""
    plt = pyplot()

    a, t = run.arrays, run.time
    fig, axes = plt.subplots(4, 1, figsize=(9.0, 7.5), sharex=True, sharey=True)
    for i, leg in enumerate(LEG_NAMES):
        ax = axes[i]
        _phases(ax, run, shade=False)
        ax.plot(t, a["normal_force"][:, i], color=LEG_COLOURS[leg], lw=1.2, label=f"{leg} vertical force")
        swing = ~a["stance"][:, i]
        if swing.any():
            ax.fill_between(t, 0, 1, where=swing, transform=ax.get_xaxis_transform(), color="0.3", alpha=0.18, lw=0,
                            label="planned swing")  # fmt: skip
        ax.axhline(0.0, color="0.3", lw=0.6)
        ax.set_ylabel("F_n (N)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="upper right")
    axes[-1].set_xlabel("t (s)")
    total = run.mass * 9.81
    fig.suptitle(f"Fig. 8 (simulated): vertical contact forces (weight m g = {total:.0f} N); positive in stance, "
                 "zero in swing", fontsize=10)  # fmt: skip
    save(fig, path)


# ----------------------------------------------------------------- the plan alone (no simulator)
def _plan_phases(ax, plan) -> None:
    shade_phases(ax, plan.phases, boundary_style="--", alpha=0.06)


def planned_fig4_swing_paths(plan, path: Path) -> None:
    """Side views (x-z) of each swing path over the terrain profile under it."""
    plt = pyplot()

    fig, axes = plt.subplots(2, 2, figsize=(8.0, 5.2), sharey=True)
    for ax, leg in zip(axes.ravel(), ("RH", "RF", "LH", "LF"), strict=True):
        sw = plan.swing[leg]
        i = LEG_NAMES.index(leg)
        t = np.linspace(sw.t_start, sw.t_end, 400)
        p = sw.position(t)
        x = np.linspace(p[:, 0].min() - 0.08, p[:, 0].max() + 0.08, 600)
        ground = plan.terrain.height(x, np.full_like(x, plan.feet_start[i, 1]))
        ax.fill_between(x, 0.0, ground, color="0.8", step=None, label="terrain")
        ax.plot(x, ground, color="0.3", lw=0.8)
        ax.plot(p[:, 0], p[:, 2], color=LEG_COLOURS[leg], lw=1.8, label="foot site path")
        ax.plot(p[:, 0], p[:, 2] - plan.foot_radius, color=LEG_COLOURS[leg], lw=0.8, ls=":", label="sphere bottom")
        ax.plot(sw.knots[:, 0], sw.knots[:, 2], "o", ms=4, mfc="white", mec=LEG_COLOURS[leg], label="knots")
        ax.set_title(
            f"{leg}: t = {sw.t_start:.1f}-{sw.t_end:.1f} s, clearance {100 * sw.min_clearance:.1f} cm", fontsize=9
        )
        ax.set_xlabel("x (m)")
        ax.set_ylim(0.0, max(0.4, p[:, 2].max() + 0.05))
        ax.grid(alpha=0.3)
    axes[0, 0].set_ylabel("z (m)")
    axes[1, 0].set_ylabel("z (m)")
    axes[0, 0].legend(loc="upper left", fontsize=7)
    fig.suptitle("Fig. 4: swing-leg foot paths over the terrain (y = foothold y)")
    save(fig, path, dpi=150)


def planned_fig5_cog(plan, path: Path) -> None:
    """COG position, velocity and acceleration over the cycle (x, y, z)."""
    plt = pyplot()

    t = np.linspace(0.0, plan.duration, 1500)
    data = [plan.cog.position(t), plan.cog.velocity(t), plan.cog.acceleration(t)]
    labels = ["position (m)", "velocity (m/s)", "acceleration (m/s²)"]
    fig, axes = plt.subplots(3, 3, figsize=(9.5, 6.5), sharex=True)
    for r, (d, lab) in enumerate(zip(data, labels, strict=True)):
        for c, axis in enumerate("xyz"):
            ax = axes[r, c]
            _plan_phases(ax, plan)
            ax.plot(t, d[:, c], color="k", lw=1.3)
            if r == 0:
                ax.plot(plan.cog.t_knots[1:-1], plan.targets[:, c], "x", color="tab:red", ms=5, label="desired")
                ax.set_title(f"COG {axis}")
            ax.set_ylabel(f"{axis} {lab}", fontsize=8)
            ax.grid(alpha=0.3)
            if r == 2:
                ax.set_xlabel("t (s)")
    axes[0, 0].legend(fontsize=7)
    fig.suptitle("Fig. 5: COG path (8th-order pieces, C² at the junctions); shaded: swing phases")
    save(fig, path, dpi=150)


def planned_fig6_stability(plan, path: Path) -> None:
    """Stability index (N m) over the cycle with the margin epsilon."""
    plt = pyplot()

    t = np.linspace(0.0, plan.duration, 3000)
    idx = plan.stability(t)
    fig, ax = plt.subplots(figsize=(7.5, 3.4))
    _plan_phases(ax, plan)
    ax.plot(t, idx, color="k", lw=1.3, label="stability index")
    ax.axhline(plan.epsilon, color="tab:red", lw=1.0, ls="--", label=f"ε = {plan.epsilon:g} N m")
    for ph in plan.phases:
        label = ph.swing_leg or "4 legs"
        ax.text(0.5 * (ph.t_start + ph.t_end), ax.get_ylim()[1] * 0.95, label, ha="center", va="top", fontsize=7)
    ax.set_xlabel("t (s)")
    ax.set_ylabel("index (N m)")
    ax.set_ylim(bottom=min(0.0, idx.min()))
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right", fontsize=8)
    ax.set_title("Fig. 6: stability index (min tumbling moment over the support polygon edges)")
    save(fig, path, dpi=150)


FIGURES: dict[str, Callable[..., None]] = {
    "fig4_swing_paths.png": fig4_swing_paths,
    "fig5_cog.png": fig5_cog,
    "fig6_stability.png": fig6_stability,
    "fig7_torques.png": fig7_torques,
    "fig8_contact_forces.png": fig8_contact_forces,
}
"""File name -> drawing function (run, path) of the PNG figures."""
