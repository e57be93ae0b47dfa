"""Plots and a short Markdown report of an episode, written into a directory the user names."""

from __future__ import annotations

from pathlib import Path

import imageio.v3 as iio
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from agents.rollout import EpisodeRecord
from quad_uneven_env.constants import LEG_NAMES


def plot_stability(rec: EpisodeRecord, mass: float, path: Path, g: float = 9.81) -> Path:
    """Stability index (N m, and normalised in m) over time, with the stance count."""
    fig, ax = plt.subplots(2, 1, figsize=(8, 5), sharex=True, height_ratios=[3, 1])
    idx = np.where(np.isfinite(rec.stability_index), rec.stability_index, np.nan)
    ax[0].plot(rec.time, idx, lw=1.2, label="measured index")
    ax[0].axhline(0.0, color="k", lw=0.8)
    ax[0].set_ylabel("stability index (N m)")
    sec = ax[0].secondary_yaxis("right", functions=(lambda v: v / (mass * g), lambda v: v * mass * g))
    sec.set_ylabel("normalised (m)")
    no_support = ~np.isfinite(rec.stability_index)
    if no_support.any():
        ax[0].plot(rec.time[no_support], np.zeros(no_support.sum()), "rx", ms=3, label="< 3 feet in contact")
    ax[0].legend(loc="best")
    ax[1].step(rec.time, rec.foot_contact.sum(axis=1), where="post")
    ax[1].set_ylabel("feet in contact")
    ax[1].set_xlabel("time (s)")
    ax[1].set_ylim(-0.2, 4.2)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def plot_paths(rec: EpisodeRecord, path: Path) -> Path:
    """COG and foot paths seen from above and from the side."""
    fig, ax = plt.subplots(1, 2, figsize=(10, 4))
    ax[0].plot(rec.cog[:, 0], rec.cog[:, 1], "k-", lw=2, label="COG")
    ax[1].plot(rec.cog[:, 0], rec.cog[:, 2], "k-", lw=2, label="COG")
    for i, leg in enumerate(LEG_NAMES):
        ax[0].plot(rec.feet_pos[:, i, 0], rec.feet_pos[:, i, 1], lw=1, label=leg)
        ax[1].plot(rec.feet_pos[:, i, 0], rec.feet_pos[:, i, 2], lw=1, label=leg)
    ax[0].set(xlabel="x (m)", ylabel="y (m)", title="top view")
    ax[0].axis("equal")
    ax[1].set(xlabel="x (m)", ylabel="z (m)", title="side view")
    ax[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def plot_forces_and_torques(rec: EpisodeRecord, path: Path) -> Path:
    """Normal contact forces per foot and joint torques over time."""
    fig, ax = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    for i, leg in enumerate(LEG_NAMES):
        ax[0].plot(rec.time, rec.contact_forces[:, i, 2], lw=1, label=leg)
    ax[0].set_ylabel("vertical contact force (N)")
    ax[0].legend(fontsize=8, ncol=4)
    ax[1].plot(rec.time, rec.torques, lw=0.8)
    ax[1].set_ylabel("joint torques (N m)")
    ax[1].set_xlabel("time (s)")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def write_frames(frames: list[np.ndarray], out: Path, stem: str = "frame") -> list[Path]:
    """Save rendered frames as PNG files."""
    paths = []
    for k, frame in enumerate(frames):
        p = out / f"{stem}_{k:02d}.png"
        iio.imwrite(p, frame)
        paths.append(p)
    return paths


def write_video(frames: list[np.ndarray], path: Path, fps: int) -> Path:
    """Write frames as an MP4 (H.264 through imageio-ffmpeg)."""
    iio.imwrite(path, np.stack(frames), fps=fps, codec="libx264", macro_block_size=8)
    return path
