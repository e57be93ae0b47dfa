"""Reproduce the paper's planning figures (§6, Fig. 4-6) for the paper scenario.

Usage: ``python -m planners.paper_figures --out DIR`` writes ``fig4_swing_paths.png``,
``fig5_cog.png``, ``fig6_stability.png`` and ``plan.json`` (key numbers) into DIR.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from planners.cycle import GaitCyclePlan, plan_gait_cycle
from planners.scenario import paper_scenario
from planners.terrain_query import sphere_clearance
from quad_uneven_env.constants import LEG_NAMES

_COLOURS = {"LF": "tab:blue", "RF": "tab:orange", "LH": "tab:green", "RH": "tab:red"}


def _phase_lines(ax, plan: GaitCyclePlan) -> None:
    for ph in plan.phases[:-1]:
        ax.axvline(ph.t_end, color="0.6", lw=0.6, ls="--", zorder=0)
    for ph in plan.phases:
        if ph.swing_leg:
            ax.axvspan(ph.t_start, ph.t_end, color=_COLOURS[ph.swing_leg], alpha=0.06, lw=0)


def fig4_swing_paths(plan: GaitCyclePlan, path: Path) -> None:
    """Side views (x-z) of each swing path over the terrain profile under it."""
    import matplotlib.pyplot as plt

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
        ax.plot(p[:, 0], p[:, 2], color=_COLOURS[leg], lw=1.8, label="foot site path")
        ax.plot(p[:, 0], p[:, 2] - plan.foot_radius, color=_COLOURS[leg], lw=0.8, ls=":", label="sphere bottom")
        ax.plot(sw.knots[:, 0], sw.knots[:, 2], "o", ms=4, mfc="white", mec=_COLOURS[leg], label="knots")
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
    fig.tight_layout()
    fig.savefig(path, dpi=150)
    plt.close(fig)


def fig5_cog(plan: GaitCyclePlan, path: Path) -> None:
    """COG position, velocity and acceleration over the cycle (x, y, z)."""
    import matplotlib.pyplot as plt

    t = np.linspace(0.0, plan.duration, 1500)
    data = [plan.cog.position(t), plan.cog.velocity(t), plan.cog.acceleration(t)]
    labels = ["position (m)", "velocity (m/s)", "acceleration (m/s²)"]
    fig, axes = plt.subplots(3, 3, figsize=(9.5, 6.5), sharex=True)
    for r, (d, lab) in enumerate(zip(data, labels, strict=True)):
        for c, axis in enumerate("xyz"):
            ax = axes[r, c]
            _phase_lines(ax, plan)
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
    fig.tight_layout()
    fig.savefig(path, dpi=150)
    plt.close(fig)


def fig6_stability(plan: GaitCyclePlan, path: Path) -> None:
    """Stability index (N m) over the cycle with the margin epsilon."""
    import matplotlib.pyplot as plt

    t = np.linspace(0.0, plan.duration, 3000)
    idx = plan.stability(t)
    fig, ax = plt.subplots(figsize=(7.5, 3.4))
    _phase_lines(ax, plan)
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
    fig.tight_layout()
    fig.savefig(path, dpi=150)
    plt.close(fig)


def summary(plan: GaitCyclePlan) -> dict:
    """Key numbers of a plan (JSON-serialisable)."""
    t = np.linspace(0.0, plan.duration, 12001)
    clear = {}
    for leg, sw in plan.swing.items():
        ts = np.linspace(sw.spline.tau[1], sw.spline.tau[-2], 2000)
        clear[leg] = float(sphere_clearance(plan.terrain, sw.position(ts), plan.foot_radius).min())
    jumps = plan.cog.junction_jumps().max(axis=0)
    return {
        "duration_s": plan.duration,
        "min_stability_index_Nm": float(plan.stability(t).min()),
        "epsilon_Nm": plan.epsilon,
        "junction_jump_max": {
            "position_m": float(jumps[0]),
            "velocity_mps": float(jumps[1]),
            "acceleration_mps2": float(jumps[2]),
        },
        "swing_min_clearance_m": clear,
        "footholds_m": plan.footholds.tolist(),
        "cog_junction_m": plan.cog.position(plan.cog.t_knots).tolist(),
        "cog_solve_time_s": plan.stats["cog_solve_time"],
        "sqp_iterations": plan.stats["iterations"],
    }


def main(argv: Sequence[str] | None = None) -> int:
    """Plan the paper scenario and write Fig. 4-6 and plan.json into ``--out``."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", required=True, help="output directory (created if missing)")
    args = parser.parse_args(argv)
    import matplotlib

    matplotlib.use("Agg")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    plan = plan_gait_cycle(paper_scenario())
    fig4_swing_paths(plan, out / "fig4_swing_paths.png")
    fig5_cog(plan, out / "fig5_cog.png")
    fig6_stability(plan, out / "fig6_stability.png")
    info = summary(plan)
    (out / "plan.json").write_text(json.dumps(info, indent=2))
    print(json.dumps({k: info[k] for k in ("min_stability_index_Nm", "junction_jump_max", "swing_min_clearance_m")}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
