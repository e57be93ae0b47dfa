"""Fig. 9 of the simulated §6 run: a side-view (x-z) stick-figure animation as a GIF (matplotlib + pillow)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from agents.plotting import LEG_COLOURS, LEG_LINESTYLES, pyplot
from quad_uneven_env.constants import LEG_NAMES
from quad_uneven_env.fields import excerpt


def frame_indices(time: np.ndarray, fps: float) -> np.ndarray:
    """Indices into ``time`` (s, increasing) of one frame every ``1 / fps`` s (the first sample included)."""
    time = np.asarray(time, dtype=float)
    if time.size == 0:
        return np.zeros(0, dtype=int)
    if not fps > 0:
        raise ValueError(f"fps must be > 0, got {excerpt(fps)}")
    want = np.arange(time[0], time[-1] + 1e-9, 1.0 / fps)
    return np.unique(np.clip(np.searchsorted(time, want - 1e-9), 0, len(time) - 1))


def write_stick_animation(run, path: Path, fps: float = 20.0, size: tuple[float, float] = (5.6, 3.0),
                          dpi: int = 64) -> Path:  # fmt: skip
    """Write the stick figure of ``run`` (a :class:`agents.paper.simulation.PaperRun`) to ``path`` (GIF).

    Side view: terrain profiles under the left (y > 0, solid) and right (y < 0, lighter) feet, the
    trunk between the hips, each leg hip -> knee -> foot site, the measured COG (dot) and the planned
    one (cross). ``fps`` frames per simulated second (real-time playback); ``size`` in inches.
    """
    plt = pyplot()
    from PIL import Image

    a, plan = run.arrays, run.plan
    ks = frame_indices(run.time, fps)
    fig, ax = plt.subplots(figsize=size, dpi=dpi)
    x = np.linspace(-0.55, 0.8, 500)
    y_left, y_right = plan.feet_start[0, 1], plan.feet_start[1, 1]
    ax.fill_between(x, 0.0, plan.terrain.height(x, np.full_like(x, y_right)), color="0.85", lw=0, label="terrain y<0")
    ax.plot(x, plan.terrain.height(x, np.full_like(x, y_left)), color="0.25", lw=1.0, label="terrain y>0")
    ax.plot(a["cog_plan"][:, 0], a["cog_plan"][:, 2], color="k", ls=":", lw=0.8)
    trunk = ax.plot([], [], color="k", lw=4, solid_capstyle="round")[0]
    legs = {leg: ax.plot([], [], color=c, ls=ls, lw=2, marker="o", ms=3, label=leg)[0]
            for leg, c, ls in ((g, LEG_COLOURS[g], LEG_LINESTYLES[g]) for g in LEG_COLOURS)}  # fmt: skip
    cog = ax.plot([], [], "o", color="tab:purple", ms=6, label="COG")[0]
    cog_ref = ax.plot([], [], "x", color="k", ms=7, label="COG planned")[0]
    text = ax.text(0.01, 0.97, "", transform=ax.transAxes, va="top", fontsize=8)
    ax.set_xlim(x[0], x[-1])
    ax.set_ylim(0.0, 0.75)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("z (m)")
    ax.set_title("Fig. 9 (simulated): stick figure, side view", fontsize=9)
    ax.legend(loc="upper right", fontsize=6, ncol=4)
    fig.tight_layout()
    frames = []
    for k in ks:
        hips, knees, feet = a["hips"][k], a["knees"][k], a["feet"][k]
        front = hips[:2].mean(axis=0)
        hind = hips[2:].mean(axis=0)
        trunk.set_data([hind[0], front[0]], [hind[2], front[2]])
        for i, leg in enumerate(LEG_NAMES):
            pts = np.stack([hips[i], knees[i], feet[i]])
            legs[leg].set_data(pts[:, 0], pts[:, 2])
        cog.set_data([a["cog"][k, 0]], [a["cog"][k, 2]])
        cog_ref.set_data([a["cog_plan"][k, 0]], [a["cog_plan"][k, 2]])
        stance = "".join(leg if s else "--" for leg, s in zip(LEG_NAMES, a["stance"][k], strict=True))
        text.set_text(f"t = {run.time[k]:5.2f} s   planned stance {stance}")
        fig.canvas.draw()
        frames.append(np.asarray(fig.canvas.buffer_rgba())[..., :3].copy())
    plt.close(fig)
    path = Path(path)
    # A shared 32-colour palette keeps the GIF small (the figure has few colours).
    first = Image.fromarray(frames[0]).quantize(colors=32)
    images = [first] + [Image.fromarray(f).quantize(palette=first) for f in frames[1:]]
    images[0].save(path, save_all=True, append_images=images[1:], duration=round(1000.0 / fps), loop=0, optimize=True)
    return path
