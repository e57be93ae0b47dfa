"""What every figure of the project shares: leg colours, gait-phase shading, the headless backend, saving, GIFs.

All plotting goes through :func:`pyplot` (matplotlib with the non-interactive Agg backend, imported
on first use so that importing a module that plots stays cheap) and :func:`save`.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

LEG_COLOURS: dict[str, str] = {"LF": "tab:blue", "RF": "tab:orange", "LH": "tab:green", "RH": "tab:red"}
"""Colour of each leg in every figure."""

LEG_LINESTYLES: dict[str, str] = {"LF": "-", "RF": "--", "LH": "-", "RH": "--"}
"""Line style of each leg where left and right legs overlap (side views)."""

GIF_SIZE = (320, 240)
"""Width and height (px) of a time-lapse GIF."""

GIF_FPS = 10
"""Frames per second of a time-lapse GIF."""

GIF_SECONDS = 4.0
"""Playing time (s) of a time-lapse GIF, whatever the length of the video it is made from."""


def pyplot() -> Any:
    """``matplotlib.pyplot`` on the headless Agg backend."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save(fig: Any, path: Path, dpi: int = 130, tight: bool = True, bbox_tight: bool = False) -> Path:
    """Write ``fig`` to ``path`` (PNG at ``dpi``) and close it; returns ``path``."""
    if tight:
        fig.tight_layout()
    fig.savefig(path, dpi=dpi, **({"bbox_inches": "tight"} if bbox_tight else {}))
    pyplot().close(fig)
    return Path(path)


def shade_phases(
    ax: Any,
    phases: Sequence[Any],
    *,
    boundary_style: str = ":",
    alpha: float = 0.08,
    shade: bool = True,
    label: bool | str = False,
    t_label_max: float = float("inf"),
) -> None:
    """Gait-phase boundaries as vertical lines and swing phases shaded in the swing leg's colour.

    :param phases: objects with ``t_start``, ``t_end`` (s) and ``swing_leg`` (leg name or None).
    :param label: True: "LF swing" above each swing phase; ``"short"``: the leg name only.
    :param t_label_max: s, no labels for phases ending after this time.
    """
    for ph in phases[:-1]:
        ax.axvline(ph.t_end, color="0.55", lw=0.6, ls=boundary_style, zorder=0)
    for ph in phases:
        if not ph.swing_leg:
            continue
        colour = LEG_COLOURS[ph.swing_leg]
        if shade:
            ax.axvspan(ph.t_start, ph.t_end, color=colour, alpha=alpha, lw=0, zorder=0)
        if label and ph.t_end <= t_label_max + 1e-9:
            text = ph.swing_leg if label == "short" else f"{ph.swing_leg} swing"
            ax.text(0.5 * (ph.t_start + ph.t_end), 1.0, text, transform=ax.get_xaxis_transform(),
                    ha="center", va="bottom", fontsize=7, color=colour)  # fmt: skip


def video_to_gif(
    video: Path,
    gif: Path,
    seconds: float = GIF_SECONDS,
    fps: int = GIF_FPS,
    size: tuple[int, int] = GIF_SIZE,
    colors: int = 64,
) -> Path:
    """A time-lapse GIF of a whole video (an MP4): ``round(seconds * fps)`` frames spread evenly over it, resized.

    The frames share one palette of ``colors`` colours (taken from the middle frame, no dithering), which keeps the
    file small; the GIF loops and plays for ``seconds`` at ``fps``. Returns ``gif``.

    :raises ValueError: when ``seconds``, ``fps``, ``size`` or ``colors`` is out of range, or the video has no frame.
    """
    import imageio.v2 as iio
    from PIL import Image

    n_out = round(seconds * fps)
    if n_out < 1 or fps < 1:
        raise ValueError(f"video_to_gif.seconds * fps must be >= 1 frame, got {seconds} s at {fps} fps")
    if len(size) != 2 or min(size) < 1:
        raise ValueError(f"video_to_gif.size must be (width, height) in px >= 1, got {size}")
    if not 2 <= colors <= 256:
        raise ValueError(f"video_to_gif.colors must be an integer in [2, 256], got {colors}")
    with iio.get_reader(video, format="FFMPEG") as reader:
        n_in = reader.count_frames()
        if n_in < 1:
            raise ValueError(f"video_to_gif.video must hold at least one frame, got none in {video}")
        n = min(n_out, n_in)
        picks = {round(i * (n_in - 1) / max(n - 1, 1)) for i in range(n)}
        frames = [Image.fromarray(f).resize(size, Image.Resampling.LANCZOS) for k, f in enumerate(reader) if k in picks]
    palette = frames[len(frames) // 2].quantize(colors=colors, dither=Image.Dither.NONE)
    images = [frame.quantize(palette=palette, dither=Image.Dither.NONE) for frame in frames]
    gif = Path(gif)
    gif.parent.mkdir(parents=True, exist_ok=True)
    images[0].save(gif, save_all=True, append_images=images[1:], duration=round(1000.0 / fps), loop=0, optimize=True)
    return gif
